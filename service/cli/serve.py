"""`shockbench serve`: run the bench service (FastAPI under uvicorn, with its worker process).

    shockbench serve [--config BENCH.toml] [--simulated] [--host H] [--port P] [--keys KEYS.toml]
                     [--data DIR] [--database URL [--shared-queue] [--require-database]]
                     [--max-upload-mb N] [--max-streams-per-key N] [--body-timeout-s S]
                     [--max-json-kb N] [--header-timeout-s S] [--body-min-rate-bytes-s N]
                     [--body-rate-grace-s S] [--body-total-timeout-s S] [--max-connections-per-address N]
                     [--max-queued-jobs-per-key N] [--max-scheduled-tests-per-key N]
                     [--min-free-mb N] [--retain-days DAYS] [--worker-nice N] [--job-lease-s S]
                     [--lane NAME] [--verdict-thresholds FILE.toml] [--metrics-access admin|key|open]
                     [--log-level LEVEL] [--log-format text|json] [--access-log]

Listens on loopback by default; any other address needs a keys file. Without a keys file an operator key
is generated and printed at start-up (as Jupyter prints its token). Port 0 takes a free port; the line
"listening on http://HOST:PORT" says which. Also runnable as `python -m service.cli.serve ...`.

Every option can also be given by an environment variable, SHOCKBENCH_ and the option's name in capitals
(`--max-upload-mb` is SHOCKBENCH_MAX_UPLOAD_MB), but `--database`, which is SHOCKBENCH_DATABASE_URL
(`env_name`); `--help` shows each one. The command line wins over the environment. A switch takes 1, true,
yes, on or 0, false, no, off; an empty variable counts as unset. So a systemd unit's EnvironmentFile can
hold the database password instead of the process list (deploy/).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from service.cli.errors import EXIT_FAILED, CliError, run_command

if TYPE_CHECKING:
    from estimator.verdict import VerdictThresholds

DEFAULT_PORT = 8000
ENV_PREFIX = "SHOCKBENCH_"
ENV_NAMES = {"database": "SHOCKBENCH_DATABASE_URL"}
"""The options whose variable is not ENV_PREFIX + the option's name in capitals."""
TRUE_WORDS = ("1", "true", "yes", "on")
FALSE_WORDS = ("0", "false", "no", "off")
TYPE_WORDS = {int: "a whole number", float: "a number"}


def env_name(dest: str) -> str:
    """The environment variable of the option stored as `dest` (the one place names are made)."""
    return ENV_NAMES.get(dest, ENV_PREFIX + dest.upper())


@dataclass(frozen=True)
class EnvValue:
    """An option's default taken from the environment, converted (and checked) by `resolve_environment`
    when the command runs, so that a bad value is the command's one-line error, not argparse's usage."""

    name: str
    raw: str
    action: argparse.Action

    def value(self) -> object:
        flag = self.action.option_strings[-1]
        where = f"{self.name}={self.raw!r} (for {flag})"
        if self.action.nargs == 0:  # a switch (store_true)
            word = self.raw.strip().lower()
            if word not in TRUE_WORDS + FALSE_WORDS:
                raise CliError(f"{where}: must be one of {', '.join(TRUE_WORDS + FALSE_WORDS)}")
            return word in TRUE_WORDS
        converter = self.action.type
        try:
            value = converter(self.raw) if callable(converter) else self.raw
        except ValueError:
            raise CliError(f"{where}: not {TYPE_WORDS.get(converter, 'a valid value')}") from None  # type: ignore[call-overload]
        if self.action.choices is not None and value not in self.action.choices:
            raise CliError(f"{where}: must be one of {', '.join(map(str, self.action.choices))}")
        return value


def add_environment(parser: argparse.ArgumentParser, environ: Mapping[str, str] = os.environ) -> None:
    """Each option of `parser` also from its variable (`env_name`): named in its help, and its default when
    set (not empty); the command line still wins."""
    for action in parser._actions:
        if not action.option_strings or action.dest == "help":
            continue
        name = env_name(action.dest)
        action.help = f"{action.help or ''} [env {name}]".strip()
        raw = environ.get(name, "")
        if raw != "":
            action.default = EnvValue(name, raw, action)


def resolve_environment(args: argparse.Namespace) -> None:
    """Replace the defaults taken from the environment by their values (CliError naming the variable)."""
    for dest, given in vars(args).items():
        if isinstance(given, EnvValue):
            setattr(args, dest, given.value())


def is_loopback(host: str) -> bool:
    import ipaddress  # here: every command imports this module

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def run_serve(args: argparse.Namespace) -> int:
    resolve_environment(args)
    if not 0 <= args.port <= 65535:
        raise CliError("--port must lie between 0 and 65535")
    if not is_loopback(args.host) and args.keys is None:
        raise CliError(
            f"--host {args.host} is not a loopback address: serving beyond this machine needs --keys"
        )
    if args.config is not None and not Path(args.config).is_file():
        raise CliError(f"{args.config}: no such bench configuration")
    if not 0.5 <= args.job_lease_s <= 3600:
        raise CliError("--job-lease-s must lie in [0.5, 3600]")
    if not args.max_upload_mb > 0:
        raise CliError("--max-upload-mb must be > 0")
    if args.max_streams_per_key is not None and not args.max_streams_per_key >= 1:
        raise CliError("--max-streams-per-key must be at least 1")
    if args.body_timeout_s is not None and not 0 < args.body_timeout_s <= 3600:
        raise CliError("--body-timeout-s must lie in (0, 3600]")
    check_connection_limits(args)
    for flag, count in (
        ("--max-queued-jobs-per-key", args.max_queued_jobs_per_key),
        ("--max-scheduled-tests-per-key", args.max_scheduled_tests_per_key),
    ):
        if count is not None and not count >= 1:
            raise CliError(f"{flag} must be at least 1")
    if args.min_free_mb is not None and not args.min_free_mb >= 0:
        raise CliError("--min-free-mb must be >= 0")
    if args.retain_days is not None and not args.retain_days >= 0:
        raise CliError("--retain-days must be >= 0 (0: keep everything)")
    for flag, given in (("--shared-queue", args.shared_queue), ("--require-database", args.require_database)):
        if given and args.database is None:
            raise CliError(f"{flag} needs --database URL (the central database)")
    import logging
    import logging.config

    from service.access import KeyRing, load_keys  # here, not at the top: every command imports this module
    from service.api.logging_setup import log_config

    logging_config = log_config(args.log_level, args.log_format, args.access_log)

    verdict = load_verdict_thresholds(Path(args.verdict_thresholds)) if args.verdict_thresholds else None
    generated_key = None
    if args.keys is not None:
        keys = load_keys(args.keys)
    else:
        keys, generated_key = KeyRing.generated()
    # loaded after the checks of the arguments: a mistake is reported without loading the service
    from service.api import ServiceSettings, create_app
    from service.api.server import ServiceServer, bind, url_of
    from service.jobs.manager import WorkerSettings
    from service.store.database import Database

    limits = {  # those given; the others keep the service's defaults (service.api.settings)
        name: value
        for name, value in (
            ("max_streams_per_key", args.max_streams_per_key),
            ("body_timeout_s", args.body_timeout_s),
            ("max_json_bytes", None if args.max_json_kb is None else args.max_json_kb * 1024),
            ("header_timeout_s", args.header_timeout_s),
            ("body_min_rate_bytes_s", args.body_min_rate_bytes_s),
            ("body_rate_grace_s", args.body_rate_grace_s),
            ("body_total_timeout_s", args.body_total_timeout_s),
            ("max_connections_per_address", args.max_connections_per_address),
            ("max_queued_jobs_per_key", args.max_queued_jobs_per_key),
            ("max_scheduled_tests_per_key", args.max_scheduled_tests_per_key),
            ("min_free_bytes", None if args.min_free_mb is None else int(args.min_free_mb * 2**20)),
        )
        if value is not None
    }
    if args.retain_days is not None:
        limits["retain_days"] = args.retain_days or None  # 0: retention off
    settings = ServiceSettings(
        data_dir=Path(args.data).resolve(),
        keys=keys,
        database_url=args.database,
        local_store=args.database is not None and not args.shared_queue,
        bench_config=Path(args.config).resolve() if args.config else None,
        simulated=args.simulated,
        max_upload_bytes=int(args.max_upload_mb * 2**20),
        **limits,  # type: ignore[arg-type]
        worker=WorkerSettings(nice=args.worker_nice, lease_s=args.job_lease_s),
        metrics_access=args.metrics_access,
        **({"verdict": verdict} if verdict is not None else {}),  # type: ignore[arg-type]
        **({"lane": args.lane} if args.lane else {}),  # type: ignore[arg-type]
    )
    central_note = reach_central(settings.central_url, args.require_database)
    database = Database(settings.resolved_database_url)  # a bad URL or an unreachable server: one line now
    try:
        database.upgrade_schema()
    finally:
        database.dispose()
    # after the checks above, so that a refusal stays one line on stderr (no schema records before it)
    logging.config.dictConfig(logging_config)
    announce = announcer(args.log_format)
    try:
        sock = bind(args.host, args.port)
    except OSError as exc:
        raise CliError(f"cannot listen on {args.host}:{args.port} ({exc.strerror or exc})") from None
    url = url_of(sock)
    announce(f"listening on {url} (API {url}/api/v1, docs {url}/docs, probes {url}/healthz {url}/readyz)")
    announce(f"lane {settings.lane!r}, data in {settings.data_dir}, database {database.safe_url}")
    if central_note is not None:
        announce(central_note)
    if generated_key is not None:
        announce(
            "no keys file, so this operator key was generated for this run; send it as "
            f"'Authorization: Bearer KEY':\n    {generated_key}"
        )
    server = ServiceServer(create_app(settings), log_config=logging_config, access_log=args.access_log)
    with contextlib.suppress(KeyboardInterrupt):  # uvicorn stops gracefully on Ctrl-C, then re-raises it
        server.run(sockets=[sock])
    return 0 if server.started else EXIT_FAILED


def announcer(log_format: str) -> Callable[[str], None]:
    """How serve says where it listens and with what: a line on standard output ("shockbench serve: ..."),
    or with --log-format json a record of the log (so that every line of the output is one JSON object)."""
    if log_format == "json":
        import logging

        return logging.getLogger("shockbench.serve").info
    return lambda message: print(f"shockbench serve: {message}", flush=True)


def check_connection_limits(args: argparse.Namespace) -> None:
    """The request and connection limits given (None: the default), each in its range (CliError)."""
    ranges = (
        ("--max-json-kb", args.max_json_kb, 1, 2**20),
        ("--header-timeout-s", args.header_timeout_s, 0.01, 3600),
        ("--body-min-rate-bytes-s", args.body_min_rate_bytes_s, 0, 2**30),
        ("--body-rate-grace-s", args.body_rate_grace_s, 0, 3600),
        ("--body-total-timeout-s", args.body_total_timeout_s, 0.01, 86400),
        ("--max-connections-per-address", args.max_connections_per_address, 1, 100_000),
    )
    for flag, value, low, high in ranges:
        if value is not None and not low <= value <= high:
            raise CliError(f"{flag} must lie in [{low:g}, {high:g}]")


def reach_central(url: str | None, required: bool) -> str | None:
    """With a local store: bring the central database's schema up to date now if it answers, and say in
    one line what the lane does (None without a local store). Unreachable: a CliError when `required`
    (--require-database), else the lane starts on its local store. A bad URL, or a central schema newer
    than this shockbench knows, is refused (one line) either way."""
    if url is None:
        return None
    from service.store.database import Database, DatabaseError

    central = Database(url)
    try:
        central.upgrade_schema()
    except DatabaseError as exc:
        if required:
            raise CliError(f"{exc} (--require-database: not starting without it)") from None
        return (
            f"central {exc}; the lane starts on its local store and syncs to the central database when "
            "it is reachable"
        )
    finally:
        central.dispose()
    return f"local store in the data directory, synced to the central database {central.safe_url}"


def load_verdict_thresholds(path: Path) -> VerdictThresholds:
    """The [verdict] table of a TOML file (CliError, one line naming the file and the problem)."""
    import tomllib

    from estimator.verdict import ThresholdsError, VerdictThresholds

    if not path.is_file():
        raise CliError(f"{path}: no such verdict thresholds file")
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CliError(f"{path}: not valid TOML ({str(exc).splitlines()[0]})") from None
    table = document.get("verdict")
    if not isinstance(table, dict):
        raise CliError(f"{path}: no [verdict] table")
    try:
        return VerdictThresholds.from_table(table)
    except (ThresholdsError, TypeError) as exc:
        raise CliError(f"{path}: {exc}") from None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="run the bench service (REST API under /api/v1, docs at /docs)",
        description="Run the bench service: REST API, identification jobs in a worker process, "
        "persistent jobs, live progress.",
    )
    p.add_argument("--config", default=None, help="bench configuration (TOML)")
    p.add_argument("--simulated", action="store_true", help="start simulated devices (nothing attached)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument(
        "--port", type=int, default=DEFAULT_PORT, help=f"port (default {DEFAULT_PORT}; 0: any free)"
    )
    p.add_argument(
        "--keys",
        default=None,
        help="keys file (TOML: viewer/operator/admin = [keys]); required off loopback; without it an "
        "operator key is generated and printed",
    )
    p.add_argument(
        "--verdict-thresholds",
        default=None,
        metavar="FILE.toml",
        help="the limits verdicts are judged by: a [verdict] table (version, phase_fail_below_deg, "
        "eusama_pass_from_percent, eusama_fail_below_percent, imbalance_check_above_percent, "
        "imbalance_fail_above_percent); default: EGEA SPECSUS2018 and EUSAMA practice (README)",
    )
    p.add_argument(
        "--lane",
        default=None,
        help="this instance's lane: stamped on its sweeps, jobs and tests, its scheduler runs only its "
        "own (default: the host name)",
    )
    p.add_argument("--data", default="shockbench-data", help="data directory (default ./shockbench-data)")
    p.add_argument(
        "--database",
        default=None,
        help="the central database, an SQLAlchemy URL: the lane runs on a local store (SQLite in the data "
        "directory) and syncs its finished sweeps and jobs there when it is reachable (default: no central "
        "database, SQLite in the data directory)",
    )
    p.add_argument(
        "--shared-queue",
        action="store_true",
        help="run on the --database itself, no local store: jobs go to the queue all instances share, and "
        "the central database must stay up",
    )
    p.add_argument(
        "--require-database",
        action="store_true",
        help="refuse to start (exit 2) when the --database cannot be reached",
    )
    p.add_argument("--max-upload-mb", type=float, default=64.0, help="upload size limit in MiB (default 64)")
    p.add_argument(
        "--max-streams-per-key",
        type=int,
        default=None,
        help="event streams one key may hold open at once; one more is answered 429 (default 8)",
    )
    p.add_argument(
        "--body-timeout-s",
        type=float,
        default=None,
        help="a request body that brings nothing for this long before it is complete is answered 408 "
        "(default 30)",
    )
    p.add_argument(
        "--max-json-kb",
        type=int,
        default=None,
        help="size limit (KiB) of a request body on every route but the uploads, all JSON (default 1088: "
        "1 MiB + 64 KiB)",
    )
    p.add_argument(
        "--header-timeout-s",
        type=float,
        default=None,
        help="a connection whose request headers are not complete within this long is closed (default 10)",
    )
    p.add_argument(
        "--body-min-rate-bytes-s",
        type=float,
        default=None,
        help="after --body-rate-grace-s, a request body slower than this on average is answered 408 "
        "(default 1024; 0: no minimum)",
    )
    p.add_argument(
        "--body-rate-grace-s",
        type=float,
        default=None,
        help="time a request body has before its minimum rate applies (default 5)",
    )
    p.add_argument(
        "--body-total-timeout-s",
        type=float,
        default=None,
        help="a request body not complete within this long is answered 408 (default 300)",
    )
    p.add_argument(
        "--max-connections-per-address",
        type=int,
        default=None,
        help="open connections one client address may hold; one more is closed at once (default 64; "
        "behind a reverse proxy all clients share its address)",
    )
    p.add_argument(
        "--max-queued-jobs-per-key",
        type=int,
        default=None,
        help="jobs one key may have queued or running at once; one more submit is answered 429 (default 20)",
    )
    p.add_argument(
        "--max-scheduled-tests-per-key",
        type=int,
        default=None,
        help="scheduled tests one key may have waiting or running at once; one more is answered 429 "
        "(default 100)",
    )
    p.add_argument(
        "--min-free-mb",
        type=float,
        default=None,
        help="free disk (MiB) kept on the data directory's file system: an upload that would leave less "
        "is answered 507 (default 1024)",
    )
    p.add_argument(
        "--retain-days",
        type=float,
        default=None,
        help="uploaded inputs of finished jobs and sweep recordings older than this are deleted, at start "
        "and every 6 h, each logged; 0 keeps everything (default 90)",
    )
    p.add_argument("--worker-nice", type=int, default=5, help="nice increment of the worker (default 5)")
    p.add_argument(
        "--job-lease-s",
        type=float,
        default=30.0,
        help="a job's claim in the shared queue lasts this long unless renewed; another instance runs "
        "the job again after it if this one dies (default 30)",
    )
    p.add_argument(
        "--metrics-access",
        default="admin",
        choices=["admin", "key", "open"],
        help="who may read GET /metrics (Prometheus): an admin key, any valid key, or anyone (default admin)",
    )
    p.add_argument(
        "--log-level",
        default="info",
        choices=["critical", "error", "warning", "info", "debug"],
        help="the least severe records logged, the service's and uvicorn's alike (default info)",
    )
    p.add_argument(
        "--log-format",
        default="text",
        choices=["text", "json"],
        help="text: a UTC timestamp, the level, the logger and the message; json: one object per line with "
        "time, level, logger and message, for log collectors (default text)",
    )
    p.add_argument(
        "--access-log",
        action="store_true",
        help="log a line per HTTP request (client, request line, status; never a key) (default off)",
    )
    p.set_defaults(handler=run_serve)
    add_environment(p)


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m service.cli.serve ...`, with the CLI's one-line errors."""
    parser = argparse.ArgumentParser(prog="shockbench")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["serve", *(sys.argv[1:] if argv is None else argv)])
    return run_command("serve", lambda: args.handler(args), say_interrupted=False)


if __name__ == "__main__":
    sys.exit(main())
