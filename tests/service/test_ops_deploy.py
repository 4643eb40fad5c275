"""deploy/ (issue 31, item 3): the systemd unit runs `shockbench serve` from an EnvironmentFile as its own
user, restarts on failure and is hardened; `systemd-analyze verify` accepts it without a warning; every
SHOCKBENCH_* variable of the example environment file is a serve option with a value serve accepts; the
example bench configuration loads."""

from __future__ import annotations

import configparser
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from test_ops_serve import parse_serve, serve_parser

from daq.bench_config import load_bench_config
from service.cli.errors import LOG_DIR_ENV
from service.cli.serve import env_name

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
UNIT = DEPLOY / "shockbench.service"
ENV_EXAMPLE = DEPLOY / "shockbench.env.example"
ASSIGNMENT = re.compile(r"^#?(SHOCKBENCH_[A-Z0-9_]+)=(.*)$")
NOT_SERVE_OPTIONS = {LOG_DIR_ENV}
"""Variables of the example that the CLI reads for every command, not as a serve option."""


def read_unit(path: Path) -> configparser.ConfigParser:
    """The unit as systemd's INI dialect: sections, case-kept keys, '#' comments, no interpolation; a key
    given twice is an error here (this unit needs none)."""
    unit = configparser.ConfigParser(interpolation=None, strict=True, comment_prefixes=("#", ";"))
    unit.optionxform = str  # type: ignore[assignment,method-assign]
    unit.read_string(path.read_text(encoding="utf-8"), source=str(path))
    return unit


def example_variables() -> dict[str, tuple[str, bool]]:
    """Name -> (value, set: not commented out) of every SHOCKBENCH_ assignment in the example."""
    found = {}
    for line in ENV_EXAMPLE.read_text(encoding="utf-8").splitlines():
        match = ASSIGNMENT.match(line)
        if match:
            found[match[1]] = (match[2], not line.startswith("#"))
    return found


def test_the_unit_runs_serve_from_its_environment_file_as_its_own_user() -> None:
    unit = read_unit(UNIT)
    assert set(unit.sections()) == {"Unit", "Service", "Install"}
    service = unit["Service"]
    program, *arguments = service["ExecStart"].split()
    assert program.endswith("/bin/shockbench") and arguments == ["serve"]  # every option from the file
    assert service["EnvironmentFile"] == "/etc/shockbench/shockbench.env"
    assert service["User"] == "shockbench" and service["Group"] == "shockbench"
    assert service["Restart"] == "on-failure"
    assert service["KillMode"] == "mixed"  # serve stops its worker itself
    assert unit["Install"]["WantedBy"] == "multi-user.target"
    data = f"/var/lib/{service['StateDirectory']}"
    assert service["WorkingDirectory"] == data
    assert example_variables()["SHOCKBENCH_DATA"] == (data, True)
    log_dir = example_variables()[LOG_DIR_ENV][0]
    assert log_dir.startswith(data + "/")  # writable under ProtectSystem=strict, kept beyond PrivateTmp


def test_the_unit_is_hardened() -> None:
    service = read_unit(UNIT)["Service"]
    for key, expected in {
        "NoNewPrivileges": "yes",
        "CapabilityBoundingSet": "",
        "ProtectSystem": "strict",
        "ProtectHome": "yes",
        "PrivateTmp": "yes",
        "ProtectKernelTunables": "yes",
        "ProtectKernelModules": "yes",
        "ProtectControlGroups": "yes",
        "RestrictSUIDSGID": "yes",
        "SystemCallFilter": "@system-service",
        "UMask": "0027",
    }.items():
        assert service.get(key) == expected, key
    assert "AF_CAN" in service["RestrictAddressFamilies"]  # CAN drives
    assert "MemoryDenyWriteExecute" not in service  # numba compiles at run time
    assert "PrivateDevices" not in service  # the lasers' serial lines are devices


def test_systemd_analyze_verifies_the_unit_without_a_warning(tmp_path: Path) -> None:
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        if os.environ.get("CI"):
            pytest.fail("CI is set, so systemd-analyze must be there (Debian's systemd)")
        pytest.skip("systemd-analyze not installed (the parsing tests above still ran)")
    shockbench = Path(sys.executable).parent / "shockbench"  # the unit's program, as installed here
    assert shockbench.is_file()
    text = UNIT.read_text(encoding="utf-8")
    copy = tmp_path / UNIT.name
    copy.write_text(re.sub(r"^ExecStart=\S+", f"ExecStart={shockbench}", text, flags=re.M), encoding="utf-8")
    done = subprocess.run([analyze, "verify", str(copy)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout + done.stderr == "", done.stdout + done.stderr


def test_every_variable_of_the_example_is_a_serve_option() -> None:
    names = {env_name(a.dest) for a in serve_parser()._actions if a.option_strings and a.dest != "help"}
    variables = example_variables()
    assert len(variables) >= 25
    unknown = sorted(set(variables) - names - NOT_SERVE_OPTIONS)
    assert unknown == [], f"not serve options: {unknown}"
    assert sorted(names - set(variables)) == []  # and the example names every option


@pytest.mark.parametrize("which", ["set", "all"])
def test_serve_accepts_the_example_values(monkeypatch: pytest.MonkeyPatch, which: str) -> None:
    """The variables set in the example, then all of them uncommented: each value is one serve accepts."""
    for name, (value, set_) in example_variables().items():
        if name not in NOT_SERVE_OPTIONS and (set_ or which == "all"):
            monkeypatch.setenv(name, value)
    args = parse_serve()
    assert args.host == "0.0.0.0" and args.port == 8000 and args.log_format == "json"
    assert args.keys == "/etc/shockbench/keys.toml" and args.config == "/etc/shockbench/bench.toml"
    if which == "all":
        assert args.database.startswith("postgresql+psycopg://") and args.simulated is False


def test_the_example_bench_configuration_loads() -> None:
    config = load_bench_config(DEPLOY / "bench.example.toml")
    assert str(config.model) == "quarter-car"
    assert sorted(laser.channel for laser in config.lasers) == ["x_r", "x_s", "x_t"]


def test_the_operations_guide_names_every_variable() -> None:
    guide = (DEPLOY.parent / "docs" / "operations.md").read_text(encoding="utf-8")
    names = {env_name(a.dest) for a in serve_parser()._actions if a.option_strings and a.dest != "help"}
    assert sorted(name for name in names if f"`{name}`" not in guide) == []
