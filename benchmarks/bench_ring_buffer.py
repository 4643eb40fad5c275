"""Benchmark: ring buffer ingest rate (daq/ring_buffer.py), 6 channels, one reader draining.

    .venv/bin/python benchmarks/bench_ring_buffer.py            # 2 000 000 samples per write mode
    .venv/bin/python benchmarks/bench_ring_buffer.py --quick    # 200 000 samples per write mode

The writer (main thread) writes pre-generated samples with single-sample writes (`write`) and with block
writes (`write_block`, 10 and 100 samples per block) as fast as it can; a reader thread drains the buffer
(`read()` then a 1 ms wait, the way a recorder polls) for the whole run. The rate is samples written per
second of writer wall time, median of a few repeats. Target of the issue: at least 1 million samples/s.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import threading
import time

import numpy as np

from daq.ring_buffer import Clock, RingBuffer

CHANNELS = 6
CAPACITY = 1 << 16
TARGET_PER_S = 1_000_000


def run_once(samples: int, block: int) -> tuple[float, int, int]:
    """Write `samples` samples in blocks of `block` (1: single-sample writes). Returns (writer seconds,
    samples received by the reader, samples it lost)."""
    buffer = RingBuffer(CAPACITY, CHANNELS, clock=Clock.DEVICE)
    reader = buffer.reader("recorder")
    rng = np.random.default_rng(0)
    values = rng.normal(size=(samples, CHANNELS))
    timestamps = np.arange(samples) * 1e-3
    done = threading.Event()

    def drain() -> None:
        while True:
            finished = done.is_set()
            reader.read()
            if finished:
                return
            done.wait(0.001)

    thread = threading.Thread(target=drain)
    thread.start()
    start = time.perf_counter()
    if block == 1:
        write = buffer.write
        rows = list(values)  # one (6,) array per sample, as a driver would hand them over
        ts = timestamps.tolist()
        for i in range(samples):
            write(ts[i], rows[i])
    else:
        write_block = buffer.write_block
        for i in range(0, samples, block):
            write_block(timestamps[i : i + block], values[i : i + block])
    elapsed = time.perf_counter() - start
    done.set()
    thread.join()
    assert reader.received + reader.lost == samples
    return elapsed, reader.received, reader.lost


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 000 samples per mode instead of 2 000 000")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    samples = 200_000 if args.quick else 2_000_000
    command = " ".join([".venv/bin/python", "benchmarks/bench_ring_buffer.py", *sys.argv[1:]])
    print(f"command: {command}")
    print(
        f"machine: {platform.machine()}, {platform.processor() or 'cpu'}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}"
    )
    print(
        f"{samples} samples × {CHANNELS} channels per mode, capacity {CAPACITY}, one reader draining every "
        f"1 ms; median of {args.repeats}"
    )
    print()
    print("| write mode | samples/write | time (s) | samples/s | reader received | reader lost | ≥ 1 M/s |")
    print("|---|---:|---:|---:|---:|---:|:---:|")
    for block in (1, 10, 100):
        runs = [run_once(samples, block) for _ in range(args.repeats)]
        elapsed, received, lost = sorted(runs)[len(runs) // 2]
        rate = samples / elapsed
        mode = "write (single)" if block == 1 else "write_block"
        met = "yes" if rate >= TARGET_PER_S else "no"
        print(f"| {mode} | {block} | {elapsed:.3f} | {rate:,.0f} | {received} | {lost} | {met} |")


if __name__ == "__main__":
    main()
