"""Re-analysis on a real cluster with no shared folder (issue 33, items 2 and 3): `dask scheduler` and two
`dask worker` processes, each in a working directory of its own; an archive imported into PostgreSQL and
its folder deleted; `shockbench reanalyse --database URL --scheduler ADDRESS` run, and one worker that
holds a task SIGKILLed once the first result is stored. Every recording ends in the run exactly once, the
workers each ran with one BLAS thread."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa
from live_server import simulated_inputs
from pg_server import PostgresServer

from service.store.database import Database
from service.store.models import ReanalysisResultRow
from service.store.reanalysis_runs import RunStore
from service.store.recordings import RecordingStore

pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[2]
DASK = Path(sys.executable).with_name("dask")
COPIES = 8
"""Copies of each of two simulated recordings, each with bytes of its own (a comment line differs)."""
DEADLINE_S = 120.0
POLL_S = 0.05


def wait_for(what: str, ready: Callable[[], bool], deadline_s: float = DEADLINE_S) -> None:
    """Poll `ready` until it holds; fail naming `what` after deadline_s."""
    end = time.monotonic() + deadline_s
    while not ready():
        if time.monotonic() > end:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(POLL_S)


def make_archive(folder: Path) -> int:
    """2 × COPIES recording CSVs of 6 s with one vehicle.toml; how many."""
    count = 0
    for seed in (1, 2):
        made = simulated_inputs(folder / "sim", seconds=6.0, seed=seed)
        text = made.recording.read_text()
        made.recording.unlink()
        for copy in range(COPIES):
            (folder / f"rec-{seed}-{copy}.csv").write_text(f"# copy: {copy}\n{text}")
            count += 1
    shutil.move(folder / "sim" / "vehicle.toml", folder / "vehicle.toml")
    (folder / "sim").rmdir()
    return count


@pytest.fixture
def cluster(tmp_path: Path) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """A scheduler and two single-threaded workers without nannies (a worker is its own process), each
    started in a folder of its own; (scheduler address, the worker processes)."""
    started: list[subprocess.Popen[bytes]] = []
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        environment.pop(name, None)  # one BLAS thread is the workers' own doing (WorkerSetup)

    def start(name: str, *args: str) -> subprocess.Popen[bytes]:
        folder = tmp_path / name
        folder.mkdir()
        log = (folder / "log").open("wb")
        process = subprocess.Popen([str(DASK), *args], cwd=folder, env=environment, stdout=log, stderr=log)
        started.append(process)
        return process

    file = tmp_path / "scheduler" / "scheduler.json"
    try:
        start(
            "scheduler",
            "scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--no-dashboard",
            "--scheduler-file",
            str(file),
        )
        wait_for("the scheduler file", file.is_file)
        address = json.loads(file.read_text())["address"]
        workers = [
            start(
                f"worker{n}",
                "worker",
                "--scheduler-file",
                str(file),
                "--nthreads",
                "1",
                "--no-nanny",
                "--no-dashboard",
                "--local-directory",
                str(tmp_path / f"worker{n}"),
            )
            for n in (1, 2)
        ]
        yield address, workers
    finally:
        for process in reversed(started):
            if process.poll() is None:
                process.terminate()
                try:
                    process.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()


def test_a_worker_killed_mid_run_leaves_every_recording_exactly_once(
    postgres: PostgresServer, tmp_path: Path, cluster: tuple[str, list[subprocess.Popen[bytes]]]
) -> None:
    from dask.distributed import Client

    address, workers = cluster
    url = postgres.new_database()
    archive = tmp_path / "archive"
    count = make_archive(archive)
    imported = subprocess.run(
        [sys.executable, "-m", "service.cli.main", "archive", "import", str(archive), "--database", url],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert imported.returncode == 0, imported.stderr
    shutil.rmtree(archive)  # the workers cannot read it: they get the bytes

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(2, timeout=DEADLINE_S)
        pids = {pid: addr for addr, pid in client.run(os.getpid).items()}
        assert set(pids) == {w.pid for w in workers}
        log = (tmp_path / "reanalyse.log").open("w")
        run = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "service.cli.main",
                "reanalyse",
                "--database",
                url,
                "--scheduler",
                address,
                "--batch",
                "1",
            ],
            stdout=log,
            stderr=log,
            text=True,
        )
        database = Database(url)
        try:
            runs = RunStore(database)
            wait_for("the first stored result", lambda: runs.get(1) is not None and runs.count(1) >= 1)
            busy = {addr for addr, keys in client.processing().items() if keys}
            victim = next(w for w in workers if pids[w.pid] in busy)  # a worker that holds a task now
            os.kill(victim.pid, signal.SIGKILL)
            assert victim.wait(timeout=30) == -signal.SIGKILL
            assert run.wait(timeout=300) == 0, (tmp_path / "reanalyse.log").read_text()

            finished = runs.get(1)
            assert finished is not None and finished.finished_at is not None
            assert (finished.recordings, finished.succeeded, finished.failed) == (count, count, 0)
            with database.sessions() as session:
                rows = session.execute(sa.select(ReanalysisResultRow.recording_sha256)).scalars().all()
            stored = {r.sha256 for r in RecordingStore(database).listing()}
            assert sorted(rows) == sorted(stored) and len(rows) == count  # each exactly once
            assert all(result is not None for result in runs.results(1).values())

            def blas_threads() -> list[int]:  # nested: sent to the worker by value
                from threadpoolctl import threadpool_info

                return sorted({i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"})

            assert set(client.scheduler_info()["workers"]) == {
                pids[w.pid] for w in workers if w is not victim
            }
            survivor = next(w for w in workers if w is not victim)
            blas = client.run(blas_threads, workers=[pids[survivor.pid]])
            assert list(blas.values()) == [[1]]
        finally:
            database.dispose()
            if run.poll() is None:
                run.kill()
            log.close()
