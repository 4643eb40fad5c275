"""estimator.forked_map: the model doctor's fits in forked processes must give exactly what running
them in turn gives, in the items' order, and fail as loudly: a child's exception is raised in the parent
with its traceback, a child that dies without its results is an error, not missing data."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from estimator.forked_map import forked_map

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="the platform cannot fork: items run in turn")


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_results_are_the_items_in_turn_in_their_order(workers: int) -> None:
    shared = np.arange(1000.0)  # the children read the parent's memory as it is at the map

    def work(k: int) -> tuple[int, float, int]:
        return k, float(shared[: k + 1].sum()), os.getpid()

    results = forked_map(work, list(range(25)), workers)
    assert [(k, s) for k, s, _ in results] == [(k, float(shared[: k + 1].sum())) for k in range(25)]
    pids = {pid for _, _, pid in results}
    assert (os.getpid() in pids) == (workers == 1)
    assert len(pids) <= workers


def test_large_results_from_every_child_do_not_block_the_pipes() -> None:
    results = forked_map(lambda k: np.full(200_000, float(k)), list(range(6)), 2)  # 1.6 MB each
    assert [float(r[0]) for r in results] == [float(k) for k in range(6)]
    assert all(r.size == 200_000 for r in results)


def test_an_exception_in_a_child_is_raised_in_the_parent_with_where_it_happened() -> None:
    def work(k: int) -> int:
        if k == 3:
            raise ValueError(f"item {k} is bad")
        return k

    with pytest.raises(ValueError, match="item 3 is bad") as raised:
        forked_map(work, list(range(8)), 2)
    assert any("worker process" in note and "in work" in note for note in raised.value.__notes__)


def test_a_child_that_dies_without_its_results_is_an_error() -> None:
    def work(k: int) -> int:
        if k == 2:
            os._exit(9)  # as if killed
        return k

    with pytest.raises(ChildProcessError, match="ended without its results"):
        forked_map(work, list(range(6)), 2)


def test_a_result_that_cannot_be_returned_says_what_it_was() -> None:
    with pytest.raises(RuntimeError, match="while returning a result"):
        forked_map(lambda k: threading.Lock(), [0, 1], 2)
