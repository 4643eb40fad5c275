"""The service's logging: one handler, one format, for uvicorn's loggers and the app's alike.

`log_config(level, log_format, access_log)` is a `logging.config.dictConfig` dictionary, given to uvicorn as
its `log_config` (so that uvicorn applies the same configuration it would otherwise replace with its own)
and applied by `shockbench serve` before anything logs. Every record goes to one handler on the root
logger (standard error); uvicorn's loggers keep no handler of their own and propagate to it, so each record
is written once, in one format:

- text: `2026-11-27T08:15:02.123Z INFO     shockbench.jobs: job 12 succeeded` (UTC, ISO 8601, ms);
- json: one object per line, `{"time": ..., "level": ..., "logger": ..., "message": ...}`, plus
  "exception" (the traceback) when there is one: for journald, Loki, Elasticsearch and the like.

uvicorn's access log (one line per request: client, request line, status) is off unless asked for
(`access_log`, serve --access-log): a bench polled by its operator page every second would log little
else. Its lines never show a key (keys travel in the Authorization header, which it does not log).
"""

from __future__ import annotations

import json
import logging
import time
from typing import Any, Literal

LogFormat = Literal["text", "json"]
LOG_FORMATS: tuple[LogFormat, ...] = ("text", "json")
LOG_LEVELS = ("critical", "error", "warning", "info", "debug")
TEXT_FORMAT = "%(asctime)s %(levelname)-8s %(name)s: %(message)s"
UVICORN_LOGGERS = ("uvicorn", "uvicorn.error", "uvicorn.access", "uvicorn.asgi")


def utc_timestamp(created: float) -> str:
    """A record's time as ISO 8601 in UTC with milliseconds: 2026-11-27T08:15:02.123Z."""
    seconds = int(created)
    return (
        time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(seconds)) + f".{int((created - seconds) * 1000):03d}Z"
    )


class TextFormatter(logging.Formatter):
    """TEXT_FORMAT with `utc_timestamp` times."""

    def __init__(self) -> None:
        super().__init__(TEXT_FORMAT)

    def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
        return utc_timestamp(record.created)


class JsonFormatter(logging.Formatter):
    """One JSON object per record, on one line (newlines in a message or traceback are escaped)."""

    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, Any] = {
            "time": utc_timestamp(record.created),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        elif record.exc_text:
            entry["exception"] = record.exc_text
        return json.dumps(entry, ensure_ascii=False)


FORMATTERS: dict[LogFormat, type[logging.Formatter]] = {"text": TextFormatter, "json": JsonFormatter}


def log_config(
    level: str = "info", log_format: LogFormat = "text", access_log: bool = False
) -> dict[str, Any]:
    """The dictConfig dictionary (see the module docstring). `level`: one of LOG_LEVELS, for the root and
    uvicorn's loggers; the access log, when on, logs at INFO whatever the level."""
    if log_format not in FORMATTERS:
        raise ValueError(f"log format must be one of {', '.join(LOG_FORMATS)}, not {log_format!r}")
    if level.lower() not in LOG_LEVELS:
        raise ValueError(f"log level must be one of {', '.join(LOG_LEVELS)}, not {level!r}")
    threshold = level.upper()
    loggers: dict[str, Any] = {
        name: {"handlers": [], "propagate": True, "level": threshold} for name in UVICORN_LOGGERS
    }
    loggers["uvicorn.access"] = {
        "handlers": [],
        "propagate": access_log,
        "level": "INFO" if access_log else "CRITICAL",
    }
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {"service": {"()": FORMATTERS[log_format]}},
        "handlers": {
            "stderr": {"class": "logging.StreamHandler", "stream": "ext://sys.stderr", "formatter": "service"}
        },
        "root": {"level": threshold, "handlers": ["stderr"]},
        "loggers": loggers,
    }
