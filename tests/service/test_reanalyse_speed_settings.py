"""What keeps `reanalyse` near the in-process speed (issue 33, item 4): batches that shrink towards the
end, the workers set up with glibc's allocator keeping freed memory, the local cluster's with Dask's
dashboard-only chores cut down and forked from a warm single-threaded server, and a closing worker's objects
frozen before its process ends."""

from __future__ import annotations

import ctypes
import math
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from service.reanalyse.run import (
    ONE_BLAS_THREAD,
    QUIET_CLUSTER,
    RunSettings,
    batch_size,
    batched,
    dask_client,
)

pytest.importorskip("distributed")

import dask
from distributed import Client
from distributed.core import Status

from service.reanalyse import worker_setup
from service.reanalyse.forkserver import PRELOAD, start_forkserver


@given(st.integers(0, 400), st.integers(1, 8), st.integers(1, 6))
def test_batches_hold_every_recording_once_in_order_and_shrink_to_single_ones(
    recordings: int, size: int, workers: int
) -> None:
    work = list(range(recordings))
    batches = batched(work, size, workers)
    assert [item for batch in batches for item in batch] == work
    left = recordings
    for batch in batches:
        assert 1 <= len(batch) <= min(size, max(1, math.ceil(left / (2 * workers))))
        left -= len(batch)
    assert [len(batch) for batch in batches] == sorted((len(batch) for batch in batches), reverse=True)
    if batches:
        assert len(batches[-1]) == 1


def test_a_hundred_recordings_on_two_workers_take_19_tasks() -> None:
    """Batches of 8, then shorter ones down to four single recordings (37 tasks when batches of 4 ended in
    16 single recordings)."""
    sizes = [len(batch) for batch in batched(list(range(100)), batch_size(100, 2), 2)]
    assert sizes == [8] * 9 + [7, 6, 4, 3, 2, 2, 1, 1, 1, 1]


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Client]:
    with dask_client(RunSettings(out=tmp_path_factory.mktemp("unused"), workers=1)) as running:
        yield running


class MallInfo2(ctypes.Structure):
    """glibc's struct mallinfo2 (malloc.h): hblkhd is the bytes held in mappings of their own."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            *("arena", "ordblks", "smblks", "hblks", "hblkhd"),
            *("usmblks", "fsmblks", "uordblks", "fordblks", "keepcost"),
        )
    ]


def mapped_for_a_40_mib_array() -> int:
    """Bytes glibc mapped from the system for one 40 MiB array in this process: all of it with glibc's
    defaults (its adaptive threshold stops at 32 MiB), none with freed memory kept (heap up to 64 MiB)."""
    import numpy as np

    mallinfo2 = ctypes.CDLL("libc.so.6").mallinfo2
    mallinfo2.restype = MallInfo2
    before = mallinfo2().hblkhd
    array = np.ones(40 << 20, dtype=np.uint8)
    mapped = int(mallinfo2().hblkhd - before)
    del array
    return mapped


linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator is Linux's")


@linux_only
def test_a_fresh_process_maps_a_40_mib_array_of_its_own() -> None:
    """The measure below tells the settings apart: glibc's defaults map the array."""
    here = Path(__file__).parent
    code = f"import sys; sys.path.insert(0, {str(here)!r}); from {Path(__file__).stem} import "
    code += "mapped_for_a_40_mib_array as mapped; print(mapped())"
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert int(child.stdout) >= 40 << 20


@linux_only
def test_the_workers_keep_freed_memory(client: Client) -> None:
    (mapped,) = client.run(mapped_for_a_40_mib_array).values()
    assert mapped == 0


def _parent_and_blas() -> tuple[int, str, list[int], bool]:
    """In a worker: its parent's pid and command line, its BLAS pools' thread counts, and whether the
    estimator was loaded (by the server it was forked from) before any task."""
    import os

    from threadpoolctl import threadpool_info

    parent = os.getppid()
    command = Path(f"/proc/{parent}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    blas = sorted({i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"})
    return parent, command, blas, "estimator.identify" in sys.modules


@linux_only
def test_the_local_cluster_forks_its_workers_from_a_warm_single_threaded_server(client: Client) -> None:
    """The workers are children of multiprocessing's forkserver, which preloaded Dask and the estimator
    with one BLAS thread and runs no thread of its own (a fork copies no lock another thread holds)."""
    ((parent, command, blas, loaded),) = client.run(_parent_and_blas).values()
    assert "multiprocessing.forkserver" in command and all(m in command for m in PRELOAD)
    assert blas == [1] and loaded
    status = Path(f"/proc/{parent}/status").read_text()
    assert "\nThreads:\t1\n" in status


def test_starting_the_forkserver_leaves_this_process_environment_as_it_was(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "7")
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert start_forkserver()  # started, or running already for the module's cluster
    assert os.environ["OPENBLAS_NUM_THREADS"] == "7" and "OMP_NUM_THREADS" not in os.environ


def _dask_settings() -> dict[str, object]:
    return {key: dask.config.get(key) for key in QUIET_CLUSTER}


def test_the_local_cluster_workers_skip_the_dashboard_chores(client: Client) -> None:
    (settings,) = client.run(_dask_settings).values()
    assert settings == QUIET_CLUSTER
    assert settings["distributed.worker.profile.enabled"] is False


def test_the_local_cluster_settings_are_dask_keys_set_once() -> None:
    """Keys Dask knows (a misspelt one would be ignored silently), none set twice."""
    keys = [*ONE_BLAS_THREAD, *QUIET_CLUSTER]
    assert len(keys) == len(set(keys))
    for key in keys:
        known = key.rsplit(".", 1)[0] if ".pre-spawn-environ." in key else key
        assert dask.config.get(known, default=KeyError) is not KeyError, key


@pytest.mark.parametrize(
    ("status", "frozen"),
    [(Status.closing, True), (Status.closing_gracefully, True), (Status.running, False)],
)
def test_a_closing_worker_freezes_its_objects_a_running_one_does_not(
    monkeypatch: pytest.MonkeyPatch, status: Status, frozen: bool
) -> None:
    calls: list[str] = []
    monkeypatch.setattr(worker_setup.gc, "freeze", lambda: calls.append("freeze"))
    worker_setup.WorkerSetup().teardown(SimpleNamespace(status=status))
    assert calls == (["freeze"] if frozen else [])


def test_the_help_states_the_batch_size_the_run_uses(capsys: pytest.CaptureFixture[str]) -> None:
    """`reanalyse --help` says the default batch in words (the CLI does not import the run module to parse
    its arguments), so it must say the run's own MAX_BATCH."""
    from service.cli.main import main
    from service.reanalyse.run import MAX_BATCH

    with pytest.raises(SystemExit):
        main(["reanalyse", "--help"])
    assert f"up to {MAX_BATCH}," in " ".join(capsys.readouterr().out.split())


def test_the_doctor_in_a_task_runs_in_the_workers_own_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """A task's diagnosis forks no processes of its own (DiagnoseOptions.workers = 1): the cluster runs a
    worker per core already, and a worker runs Dask's threads, which a fork would copy mid-lock."""
    import service.analysis
    from service.reanalyse.sources import Item
    from service.reanalyse.task import Analysis, AnalysisOptions, Payload, Task, analyse

    seen = []

    def diagnosed(recording, vehicle, options):  # type: ignore[no-untyped-def]
        seen.append(options)
        return SimpleNamespace(to_json=lambda: {"diagnosed": True})

    monkeypatch.setattr(service.analysis, "diagnose_recording", diagnosed)
    monkeypatch.setattr("daq.formats.recording_file.read_recording_file", lambda path: None)
    monkeypatch.setattr("daq.formats.vehicle_file.parse_vehicle", lambda text, source: None)
    task = Task(Item("rec", Path("rec.csv"), None), Analysis.DIAGNOSE, AnalysisOptions(points=30))
    payload = Payload("rec.csv", b"", False, "[vehicle]\n", "rec.toml")
    assert analyse(task, Path("rec.csv"), payload) == {"diagnosed": True}
    (options,) = seen
    assert options.workers == 1 and options.points == 30
