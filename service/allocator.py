"""glibc's allocator set up for a process that only computes (a short-lived command, a re-analysis
worker): freed memory is kept for reuse instead of being returned to the system at once.

Why: identify and diagnose allocate and free arrays of megabytes many times over (residual systems, filter
buffers, Newton steps). By default glibc maps each allocation above 128 KiB from the system and unmaps it when
freed (it raises that threshold only after the first few), and trims the heap's top beyond 128 KiB; every
fresh mapping then costs its page faults again. `shockbench identify` of the 12 s benchmark recording spends
about 10 ms of its 175 ms on that (benchmarks/bench_identify_process.py, BENCHMARKS.md); a re-analysis
worker about 17 ms of system time a recording (service.reanalyse.worker_setup). Long-lived processes
(`serve`, the simulated devices) keep glibc's defaults, which return memory to the system sooner.
"""

from __future__ import annotations

import ctypes
import sys

M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_THRESHOLD = -3
"""mallopt's parameter numbers (glibc's malloc.h)."""
SETTINGS: dict[int, int] = {
    M_MMAP_THRESHOLD: 64 << 20,  # allocations up to 64 MiB come from the heap, where freed memory is reused
    M_TRIM_THRESHOLD: 256 << 20,  # the heap's top is given back only beyond 256 MiB free
    M_TOP_PAD: 64 << 20,  # and grown 64 MiB at a time
}


def keep_freed_memory() -> bool:
    """Apply SETTINGS with glibc's mallopt; False (nothing changed) where there is no glibc (other systems,
    musl) or it refuses one."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return all(mallopt(parameter, value) == 1 for parameter, value in SETTINGS.items())
