"""A re-analysis worker reads each recording from its own scratch folder, named by its process id. A worker
killed before its exit handler ran leaves that folder behind; the next worker to start removes the folders
of processes that no longer run, and keeps those of running ones."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from service.reanalyse.task import SCRATCH_PREFIX, remove_orphaned_scratch

pytestmark = pytest.mark.skipif(os.name != "posix", reason="process ids are probed with os.kill(pid, 0)")


def _ended_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_the_folders_of_ended_workers_go_and_the_running_ones_stay(tmp_path: Path) -> None:
    ended = tmp_path / f"{SCRATCH_PREFIX}{_ended_pid()}-k1ll3d"
    running = tmp_path / f"{SCRATCH_PREFIX}{os.getpid()}-4l1v3"
    unrelated = tmp_path / f"{SCRATCH_PREFIX}bench"  # a benchmark's work folder, not a worker's
    for folder in (ended, running, unrelated):
        folder.mkdir()
        (folder / "recording.csv").write_text("t,x_r\n")
    assert remove_orphaned_scratch(tmp_path) == [ended]
    assert not ended.exists() and running.exists() and unrelated.exists()
