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
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

from service.cli.declared import Shown, add_options, options, values
from service.cli.errors import EXIT_FAILED, CliError, run_command
from service.service_limits import SERVE_UNITS, ServiceLimits, WorkerLimits

if TYPE_CHECKING:
    from estimator.verdict import VerdictThresholds

DEFAULT_PORT = 8000
ENV_PREFIX = "SHOCKBENCH_"
ENV_NAMES = {"database": "SHOCKBENCH_DATABASE_URL"}
"""The options whose variable is not ENV_PREFIX + the option's name in capitals."""
TRUE_WORDS = ("1", "true", "yes", "on")
FALSE_WORDS = ("0", "false", "no", "off")
TYPE_WORDS = {int: "a whole number", float: "a number"}
LIMIT_OPTIONS = options(
    ServiceLimits,
    tuple(f.name for f in fields(ServiceLimits)),
    {name: Shown(*shown) for name, shown in SERVE_UNITS.items()},
)
"""--max-upload-mb ... --retain-days: the service's limits as service.service_limits declares them (sizes
in MiB and KiB here, bytes in the service)."""
WORKER_OPTIONS = options(WorkerLimits, ("worker_nice", "job_lease_s"))
"""--worker-nice and --job-lease-s, as service.service_limits declares them."""


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
    limits = values(args, LIMIT_OPTIONS)  # each in its declared range (CliError naming the option)
    worker = values(args, WORKER_OPTIONS)
    limits["retain_days"] = limits["retain_days"] or None  # 0: retention off
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

    settings = ServiceSettings(
        data_dir=Path(args.data).resolve(),
        keys=keys,
        database_url=args.database,
        local_store=args.database is not None and not args.shared_queue,
        bench_config=Path(args.config).resolve() if args.config else None,
        simulated=args.simulated,
        **limits,
        worker=WorkerSettings(nice=worker["worker_nice"], lease_s=worker["job_lease_s"]),
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
    add_options(p, LIMIT_OPTIONS)
    add_options(p, WORKER_OPTIONS)
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
