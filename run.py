"""Set-up and entry point for a fresh machine that has only Python.

    python3 run.py demo    # simulate a sweep on the embedded default bench, identify the damper curve
    python3 run.py test    # run the whole test suite (what CI runs)

Both create (or reuse) a virtual environment in .venv and install the project from pyproject.toml into it,
so nothing but a Python >= 3.11 interpreter is needed beforehand. `demo` installs the core alone (a single
bench on SQLite); `test` adds every extra, the test tools, PostgreSQL's driver and Dask, since the suite
exercises them all. Any further arguments are passed on (`python3 run.py test -k compoway`,
`python3 run.py demo --seed 3`).
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
STAMP = VENV / ".installed-from"


def _python() -> Path:
    return BIN / ("python.exe" if os.name == "nt" else "python")


EXTRAS: dict[str, str] = {"demo": "", "test": "[test,postgres,cluster]"}
"""What each command installs beside the core (pyproject.toml's optional dependencies): the demo needs none,
the whole test suite every one."""


def ensure_environment(extras: str) -> None:
    """Create .venv and install the project with `extras`, again only when pyproject.toml or the extras
    changed (the stamp records both: `demo` after `test` keeps the larger install, which has the core)."""
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    if _python().exists() and STAMP.exists() and _covers(STAMP.read_text(), digest, extras):
        return
    if not STAMP.exists():
        # no finished install on record: an interrupted creation leaves a .venv without pip, so start afresh
        print("creating virtual environment in .venv", flush=True)
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV)
    print(f"installing shockbench{extras} and its dependencies into .venv", flush=True)
    subprocess.run([str(_python()), "-m", "pip", "install", "-q", "--upgrade", "pip"], check=True)
    subprocess.run([str(_python()), "-m", "pip", "install", "-q", "-e", f"{ROOT}{extras}"], check=True)
    STAMP.write_text(f"{digest} {extras}".rstrip())


def _covers(stamp: str, digest: str, extras: str) -> bool:
    """Whether the install the stamp records (pyproject digest, then the extras installed) has `extras`."""
    recorded_digest, _, recorded_extras = stamp.partition(" ")
    wanted = set(extras.strip("[]").split(",")) - {""}
    return recorded_digest == digest and wanted <= set(recorded_extras.strip("[]").split(","))


def main(argv: list[str]) -> int:
    if sys.version_info < (3, 11):  # noqa: UP036 - run.py is the first thing a user runs, maybe with an old Python
        print(f"shockbench needs Python >= 3.11, this is {sys.version.split()[0]}", file=sys.stderr)
        return 2
    if not argv or argv[0] not in {"demo", "test"}:
        print(__doc__)
        return 2
    command, rest = argv[0], argv[1:]
    ensure_environment(EXTRAS[command])
    if command == "demo":
        cmd = [str(BIN / "shockbench"), "demo", *rest]
    else:
        cmd = [str(_python()), "-m", "pytest", *rest]
    return subprocess.run(cmd, cwd=ROOT).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
