"""shockbench's version, as `shockbench --version` says it.

The installed distribution's metadata (importlib.metadata) is the truth; a source tree that was never
installed (run as `python -m service.cli.main` from a checkout) has none, so the version is read from the
pyproject.toml beside the sources, and "0+unknown" when neither is there.
"""

from __future__ import annotations

from pathlib import Path

DISTRIBUTION = "shockbench"
PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
"""The source tree's pyproject.toml (the service package sits beside it)."""
UNKNOWN = "0+unknown"


def source_version(pyproject: Path | None = None) -> str | None:
    """[project] version of `pyproject` (default: the source tree's), None when there is none or it has
    none."""
    import tomllib

    try:
        with (pyproject or PYPROJECT).open("rb") as handle:
            version = tomllib.load(handle).get("project", {}).get("version")
    except (OSError, tomllib.TOMLDecodeError):
        return None
    return version if isinstance(version, str) else None


def shockbench_version() -> str:
    """The installed distribution's version, else the source tree's, else UNKNOWN."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(DISTRIBUTION)
    except PackageNotFoundError:
        return source_version() or UNKNOWN
