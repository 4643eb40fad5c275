"""The input checker's helper process ends with the service, even when the service is killed outright
(SIGKILL cannot run any shutdown): before, every killed service left its helper behind as an orphan."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

SERVICE = """
import os, signal
from service.api.input_check import InputChecker
checker = InputChecker()
checker.start()
print(*checker._pool._processes, flush=True)  # the helper's pid
os.kill(os.getpid(), signal.SIGKILL)
"""


def alive(pid: int) -> bool:
    """The process exists and is not a zombie waiting to be reaped."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def test_a_killed_service_leaves_no_checker_behind() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", SERVICE], capture_output=True, text=True, env=env, timeout=120, check=False
    )
    assert done.returncode == -9, done.stderr  # killed, so no shutdown of the pool ran
    (helper,) = (int(pid) for pid in done.stdout.split())
    deadline = time.monotonic() + 30  # a deadline for the kernel's and the helper's part, not a wait
    while alive(helper) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not alive(helper), f"checker helper {helper} outlived its killed service"
