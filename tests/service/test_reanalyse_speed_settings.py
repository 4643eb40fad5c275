"""What keeps `reanalyse` near the in-process speed (issue 33, item 4): batches that shrink towards the
end, the local cluster's workers started with glibc's allocator keeping freed memory and with Dask's
dashboard-only chores cut down, and a closing worker's objects frozen before its process ends."""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from types import SimpleNamespace

import pytest
from hypothesis import given
from hypothesis import strategies as st

from service.reanalyse.run import (
    KEEP_FREED_MEMORY,
    NO_MALLOC_TRIM,
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


def _worker_settings() -> dict[str, object]:
    return {
        "environment": {name: os.environ.get(name) for name in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TOP_PAD_")},
        "config": {key: dask.config.get(key) for key in QUIET_CLUSTER},
    }


def test_the_local_cluster_workers_keep_freed_memory_and_skip_the_dashboard_chores(client: Client) -> None:
    (settings,) = client.run(_worker_settings).values()
    assert settings["environment"] == {
        key.rsplit(".", 1)[1]: value for key, value in KEEP_FREED_MEMORY.items()
    }
    assert settings["config"] == QUIET_CLUSTER
    assert settings["config"]["distributed.worker.profile.enabled"] is False


def test_the_local_cluster_settings_are_dask_keys_set_once() -> None:
    """Keys Dask knows (a misspelt one would be ignored silently), none set twice."""
    keys = [*NO_MALLOC_TRIM, *KEEP_FREED_MEMORY, *ONE_BLAS_THREAD, *QUIET_CLUSTER]
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
