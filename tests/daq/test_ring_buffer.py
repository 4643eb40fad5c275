"""Acquisition ring buffer: wrap-around, independent readers, exact overrun accounting, threads, and a
property test against a plain list model."""

from __future__ import annotations

import sys
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.ring_buffer import Clock, ClockMismatchError, ReadResult, RingBuffer

CHANNELS = 6


def _samples(first: int, n: int, channels: int = CHANNELS) -> tuple[np.ndarray, np.ndarray]:
    """Samples first..first+n-1: timestamp = index ms, value[c] = index * 10 + c (identifiable, untorn)."""
    index = np.arange(first, first + n, dtype=np.float64)
    return index * 1e-3, index[:, None] * 10 + np.arange(channels)


def _indices(result: ReadResult) -> np.ndarray:
    """Absolute indices encoded in the returned samples, checking every channel agrees with the timestamp."""
    index = np.rint(result.timestamps_s * 1e3).astype(np.int64)
    np.testing.assert_array_equal(result.values, index[:, None] * 10.0 + np.arange(result.values.shape[1]))
    return index


def _write(buffer: RingBuffer, first: int, n: int) -> int:
    ts, vals = _samples(first, n, buffer.channels)
    buffer.write_block(ts, vals)
    return first + n


def test_block_writes_crossing_the_end_read_back_in_order() -> None:
    buffer = RingBuffer(10, CHANNELS, clock=Clock.DEVICE)
    reader = buffer.reader("recorder")
    written = 0
    for n in (7, 7, 3, 9, 10, 1):  # blocks straddle the end of the ring at different offsets
        written = _write(buffer, written, n)
        result = reader.read()
        assert result.lost == 0 and result.count == n
        assert result.first_index == written - n
        np.testing.assert_array_equal(_indices(result), np.arange(written - n, written))
    assert buffer.total_written == written


def test_single_writes_and_block_writes_mix() -> None:
    buffer = RingBuffer(4, 3, clock=Clock.HOST_MONOTONIC, flags=True)
    reader = buffer.reader("display")
    buffer.write(0.0, [1.0, 2.0, 3.0], flag=5)
    buffer.write_block([0.001, 0.002, 0.003], np.ones((3, 3)), flags=[1, 2, 3])
    buffer.write(0.004, np.array([7.0, 8.0, 9.0]))
    result = reader.read()
    assert result.clock is Clock.HOST_MONOTONIC
    # 5 samples written into 4 slots between two reads: the first one was overwritten
    assert result.lost == 1 and result.first_index == 1
    np.testing.assert_array_equal(result.timestamps_s, [0.001, 0.002, 0.003, 0.004])
    np.testing.assert_array_equal(result.flags, [1, 2, 3, 0])
    np.testing.assert_array_equal(result.values, [[1.0, 1.0, 1.0]] * 3 + [[7.0, 8.0, 9.0]])


def test_block_longer_than_capacity_keeps_the_tail_and_counts_the_rest_lost() -> None:
    buffer = RingBuffer(8, CHANNELS, clock=Clock.DEVICE)
    reader = buffer.reader("recorder")
    _write(buffer, 0, 3)
    _write(buffer, 3, 21)
    result = reader.read()
    assert result.lost == 24 - 8 and result.first_index == 16
    np.testing.assert_array_equal(_indices(result), np.arange(16, 24))


def test_readers_at_different_paces_each_see_every_sample_once_in_order() -> None:
    buffer = RingBuffer(64, CHANNELS, clock=Clock.DEVICE)
    fast, slow = buffer.reader("display"), buffer.reader("recorder")
    chunked = buffer.reader("watchdog")
    seen: dict[str, list[np.ndarray]] = {"display": [], "recorder": [], "watchdog": []}
    rng = np.random.default_rng(1)
    written = 0
    for step in range(200):
        written = _write(buffer, written, int(rng.integers(1, 9)))
        seen["display"].append(_indices(fast.read()))
        if step % 7 == 6:  # behind by at most 7 blocks of <= 8 samples: 56 < 64, never lapped
            seen["recorder"].append(_indices(slow.read()))
        seen["watchdog"].append(_indices(chunked.read(max_samples=5)))  # may trail, catches up below
    seen["recorder"].append(_indices(slow.read()))
    seen["watchdog"].append(_indices(chunked.read()))
    for name, parts in seen.items():
        np.testing.assert_array_equal(np.concatenate(parts), np.arange(written), err_msg=name)
    stats = buffer.statistics()
    assert stats.total_written == written and stats.total_lost == 0
    for reader in (fast, slow, chunked):
        assert reader.lost == 0 and reader.received == written
        assert stats.readers[reader.name].pending == 0


@pytest.mark.parametrize("behind", [1, 5, 32, 100])
def test_reader_falling_behind_by_k_beyond_capacity_loses_exactly_k(behind: int) -> None:
    capacity = 32
    buffer = RingBuffer(capacity, CHANNELS, clock=Clock.DEVICE)
    keeping_up, lagging = buffer.reader("display"), buffer.reader("recorder")
    written = _write(buffer, 0, 10)
    assert lagging.read().count == 10
    assert keeping_up.read().count == 10
    for _ in range(capacity + behind):  # single writes, the display keeps up, the recorder does not
        ts, vals = _samples(written, 1)
        buffer.write(float(ts[0]), vals[0])
        written += 1
        assert keeping_up.read().count == 1

    stats = buffer.statistics()
    assert stats.readers["recorder"].pending == capacity and stats.readers["recorder"].fill_fraction == 1.0
    assert stats.fill_fraction == 1.0
    result = lagging.read()
    assert result.lost == behind
    assert result.first_index == 10 + behind
    np.testing.assert_array_equal(_indices(result), np.arange(written - capacity, written))

    stats = buffer.statistics()
    assert stats.total_lost == behind and stats.total_written == written
    assert stats.readers["recorder"].lost == behind and stats.readers["recorder"].overruns == 1
    assert stats.readers["display"].lost == 0 and stats.readers["display"].overruns == 0
    assert lagging.received + lagging.lost == written
    # back in step: no further loss
    written = _write(buffer, written, 3)
    assert lagging.read().lost == 0


def test_new_reader_starts_at_next_sample_or_oldest_held() -> None:
    buffer = RingBuffer(8, CHANNELS, clock=Clock.DEVICE)
    written = _write(buffer, 0, 12)
    late, history = buffer.reader("late"), buffer.reader("history", from_oldest=True)
    assert late.read().count == 0
    np.testing.assert_array_equal(_indices(history.read()), np.arange(4, 12))
    assert history.lost == 0  # samples gone before it joined are not its loss
    _write(buffer, written, 2)
    np.testing.assert_array_equal(_indices(late.read()), [12, 13])


def test_closed_reader_is_forgotten_but_its_losses_are_kept() -> None:
    buffer = RingBuffer(4, CHANNELS, clock=Clock.DEVICE)
    reader = buffer.reader("watchdog")
    _write(buffer, 0, 10)
    assert reader.read().lost == 6
    reader.close()
    reader.close()
    stats = buffer.statistics()
    assert "watchdog" not in stats.readers and stats.total_lost == 6 and stats.fill_fraction == 0.0
    with pytest.raises(RuntimeError):
        reader.read()
    buffer.reader("watchdog")  # the name is free again


def test_bad_input_is_refused() -> None:
    buffer = RingBuffer(4, 3, clock=Clock.DEVICE)
    buffer.reader("a")
    with pytest.raises(ValueError, match="already open"):
        buffer.reader("a")
    with pytest.raises(ValueError, match="expected 3 values"):
        buffer.write(0.0, [1.0, 2.0])
    with pytest.raises(ValueError, match="expected timestamps"):
        buffer.write_block([0.0, 1.0], np.zeros((2, 4)))
    with pytest.raises(ValueError, match="no flags"):
        buffer.write_block([0.0], np.zeros((1, 3)), flags=[1])
    with pytest.raises(ClockMismatchError):
        buffer.write(0.0, [1.0, 2.0, 3.0], clock=Clock.HOST_MONOTONIC)
    with pytest.raises(ClockMismatchError):
        buffer.write_block([0.0], np.zeros((1, 3)), clock=Clock.HOST_MONOTONIC)
    buffer.write(0.0, [1.0, 2.0, 3.0], clock=Clock.DEVICE)
    with pytest.raises(ValueError):
        RingBuffer(0, 3, clock=Clock.DEVICE)
    assert buffer.total_written == 1


@pytest.mark.parametrize(("overwrite", "expected_first"), [(3, 11), (8, 16), (20, 28)])
def test_samples_overwritten_while_a_reader_copies_are_dropped_and_counted(
    monkeypatch: pytest.MonkeyPatch, overwrite: int, expected_first: int
) -> None:
    """The writer runs while a reader copies (outside the lock): copied samples it may have overwritten are
    not returned (they could be torn) but counted lost; the rest are returned."""
    buffer = RingBuffer(8, CHANNELS, clock=Clock.DEVICE)
    reader = buffer.reader("recorder")
    written = _write(buffer, 0, 16)  # reader at 0, buffer holds 8..15: it will copy 8..15
    copy_out = RingBuffer._copy_out

    def copy_then_writer_runs(self: RingBuffer, start: int, end: int):
        copied = copy_out(self, start, end)
        _write(self, written, overwrite)  # overwrites samples 8 .. 8 + overwrite - 1 (and more)
        return copied

    monkeypatch.setattr(RingBuffer, "_copy_out", copy_then_writer_runs)
    result = reader.read()
    monkeypatch.undo()
    assert result.first_index == min(expected_first, 16)
    np.testing.assert_array_equal(_indices(result), np.arange(min(expected_first, 16), 16))
    assert result.lost == min(expected_first, 16)
    following = reader.read()
    assert following.lost == max(0, expected_first - 16)
    assert reader.received + reader.lost == written + overwrite == buffer.statistics().total_written
    assert buffer.statistics().total_lost == reader.lost


@pytest.fixture
def fast_thread_switching():
    """Switch threads every 10 µs instead of 5 ms, so writes land in the middle of a reader's copy."""
    before = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    yield
    sys.setswitchinterval(before)


@pytest.mark.usefixtures("fast_thread_switching")
@pytest.mark.parametrize("capacity", [16, 256, 1 << 16])
def test_writer_and_reader_threads_account_for_every_sample(capacity: int) -> None:
    """Small capacities: overruns happen; every sample is either received (untorn, in order) or counted
    lost. Capacity above the total: nothing may be lost."""
    buffer = RingBuffer(capacity, CHANNELS, clock=Clock.DEVICE)
    reader = buffer.reader("recorder")
    done = threading.Event()
    received: list[np.ndarray] = []
    lost = [0]
    errors: list[BaseException] = []
    total = 40_000

    def consume() -> None:
        try:
            position = 0
            while True:
                finished = done.is_set()  # look before reading: after the writer ends, one last full drain
                result = reader.read()
                assert result.first_index == position + result.lost
                received.append(_indices(result))  # checks no torn sample
                lost[0] += result.lost
                position = result.first_index + result.count
                if finished:
                    return
        except BaseException as exc:  # reported in the main thread
            errors.append(exc)

    def produce() -> None:
        rng = np.random.default_rng(7)
        written = 0
        while written < total:
            n = int(rng.integers(1, 40))
            if n < 5:
                for _ in range(n):
                    ts, vals = _samples(written, 1)
                    buffer.write(float(ts[0]), vals[0])
                    written += 1
            else:
                written = _write(buffer, written, n)
        done.set()

    threads = [threading.Thread(target=consume), threading.Thread(target=produce)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
        assert not thread.is_alive()
    assert not errors, errors
    indices = np.concatenate(received)
    written = buffer.total_written
    assert indices.size + lost[0] == written
    assert np.all(np.diff(indices) > 0) and (indices.size == 0 or indices[-1] == written - 1)
    stats = buffer.statistics()
    assert stats.total_lost == lost[0] == reader.lost
    assert stats.readers["recorder"].read == indices.size
    if capacity > written:
        assert lost[0] == 0


# ---- property test against a list model ------------------------------------------------------------------

operations = st.lists(
    st.one_of(
        st.tuples(st.just("write"), st.integers(0, 30)),
        st.tuples(st.just("single"), st.integers(0, 2)),
        st.tuples(st.just("read"), st.integers(0, 2), st.one_of(st.none(), st.integers(0, 20))),
    ),
    max_size=60,
)


@settings(max_examples=300, deadline=None)
@given(capacity=st.integers(1, 17), ops=operations)
def test_matches_a_list_model(capacity: int, ops: list[tuple]) -> None:
    buffer = RingBuffer(capacity, 2, clock=Clock.DEVICE, flags=True)
    readers = [buffer.reader(f"r{i}") for i in range(3)]
    model: list[int] = []  # every sample ever written, by index
    cursors, model_lost = [0, 0, 0], [0, 0, 0]
    for op in ops:
        if op[0] == "write":
            index = np.arange(len(model), len(model) + op[1])
            buffer.write_block(index * 1e-3, np.stack([index, -index], axis=1), flags=index % 7)
            model.extend(index.tolist())
        elif op[0] == "single":
            i = len(model)
            buffer.write(i * 1e-3, [i, -i], flag=i % 7)
            model.append(i)
        else:
            _, which, max_samples = op
            start = max(cursors[which], len(model) - capacity)
            end = len(model) if max_samples is None else min(len(model), start + max_samples)
            expected_lost = start - cursors[which]
            cursors[which] = end
            model_lost[which] += expected_lost
            result = readers[which].read(max_samples)
            assert result.lost == expected_lost
            assert result.first_index == start
            expected = np.array(model[start:end], dtype=np.float64)
            np.testing.assert_array_equal(result.timestamps_s, expected * 1e-3)
            np.testing.assert_array_equal(result.values, np.stack([expected, -expected], axis=1))
            np.testing.assert_array_equal(result.flags, expected.astype(np.int64) % 7)
    stats = buffer.statistics()
    assert stats.total_written == len(model)
    assert stats.held == min(len(model), capacity)
    assert stats.total_lost == sum(model_lost)
    for which, reader in enumerate(readers):
        pending = len(model) - max(cursors[which], len(model) - capacity)
        assert stats.readers[reader.name].pending == pending
        assert stats.readers[reader.name].lost == model_lost[which]
        final = reader.read()
        assert reader.received + reader.lost == len(model)
        assert final.count == pending
