"""The live view: decimated rows for screens, each reader with its own cursor, bounded memory."""

from __future__ import annotations

import numpy as np

from daq.live_view import LiveView


def _add(view: LiveView, first: int, count: int) -> None:
    rows = np.arange(first, first + count)
    view.add(rows, rows * 1e-3, {"x_s": rows * 1.0, "x_t": rows * 2.0, "x_r": -rows * 1.0})


def test_readers_get_every_decimated_row_once_whatever_the_block_sizes() -> None:
    rng = np.random.default_rng(3)
    view = LiveView(every=10, capacity_rows=10_000)
    view.start(("x_s", "x_t", "x_r"), label="7")
    cursors = {"a": (0, None), "b": (0, None)}
    got: dict[str, list[float]] = {"a": [], "b": []}
    row = 0
    for _ in range(200):
        count = int(rng.integers(1, 60))
        _add(view, row, count)
        row += count
        reader = "a" if rng.random() < 0.7 else "b"  # b reads seldom, a often
        part = view.since(*cursors[reader])
        cursors[reader] = (part.cursor, part.run)
        got[reader] += part.channels["x_s"].tolist()
        assert part.label == "7" and part.missed == 0
    for reader in got:
        part = view.since(*cursors[reader])
        got[reader] += part.channels["x_s"].tolist()
        assert got[reader] == list(np.arange(0, row, 10, dtype=float))


def test_a_reader_far_behind_gets_the_newest_and_the_count_it_missed() -> None:
    view = LiveView(every=1, capacity_rows=100)
    view.start(("x_s", "x_t", "x_r"))
    _add(view, 0, 50)
    first = view.since(0, None)
    _add(view, 50, 300)
    part = view.since(first.cursor, first.run)
    assert part.missed == 200  # rows 50..249 fell out of the 100 held
    assert part.time_s.size == 100 and np.allclose(part.channels["x_t"], np.arange(250, 350) * 2.0)


def test_a_new_sweep_starts_every_reader_afresh() -> None:
    view = LiveView(every=2)
    view.start(("x_s", "x_t", "x_r"), label="1")
    _add(view, 0, 40)
    old = view.since(0, None)
    view.start(("x_s", "x_t", "x_r"), label="2")
    _add(view, 0, 10)
    part = view.since(old.cursor, old.run)
    assert part.run != old.run and part.label == "2"
    assert part.time_s.tolist() == [0.0, 0.002, 0.004, 0.006, 0.008]


def test_nothing_is_kept_before_a_sweep_starts() -> None:
    view = LiveView()
    _add(view, 0, 100)
    assert view.since(0, None).time_s.size == 0
