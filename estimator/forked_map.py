"""Independent fits side by side on the machine's cores (the model doctor's candidates of a round, its
bootstrap draws): one function mapped over items in forked processes.

Why processes and not threads: most of a fit holds the interpreter lock (numpy's small products, the
compiled filters), so two threads ran a doctor's round 1.1-1.3× faster than one on two cores; two processes
run it about twice as fast. Why fork: the children see the parent's memory as it is at the map (the
recording, its systems, the current model), copy-on-write, so nothing crosses between the processes but the
items' indices and the results (pickled: keep them small). Items are handed out one at a time from a pipe
(a 4-byte write or read is atomic), so a child that draws cheap items takes more of them. Not
multiprocessing: its processes cannot be started from a daemonic one, as the service's job worker is.

Where the platform cannot fork, or for one worker or one item, the items run in turn in this process. An
exception in a child is raised again in the parent (the first item's that failed); a child that dies
without its results (killed) raises ChildProcessError.
"""

from __future__ import annotations

import os
import pickle
import selectors
import struct
import traceback
from collections.abc import Callable, Sequence
from typing import TypeVar

Item = TypeVar("Item")
Value = TypeVar("Value")

_INDEX = struct.Struct("<i")
_LENGTH = struct.Struct("<q")


def forked_map(function: Callable[[Item], Value], items: Sequence[Item], workers: int) -> list[Value]:
    """[function(item) for item in items], computed by up to `workers` forked children."""
    workers = min(workers, len(items))
    if workers <= 1 or not hasattr(os, "fork"):
        return [function(item) for item in items]
    tasks_read, tasks_write = os.pipe()
    _write_all(tasks_write, b"".join(_INDEX.pack(k) for k in range(len(items))))
    os.close(tasks_write)  # the children read to the end of the queue
    children: dict[int, int] = {}  # result pipe → pid
    try:
        for _ in range(workers):
            results_read, results_write = os.pipe()
            pid = os.fork()
            if pid == 0:  # the child: never returns into the caller
                status = 1
                try:
                    os.close(results_read)
                    for other in children:
                        os.close(other)
                    _serve(function, items, tasks_read, results_write)
                    status = 0
                finally:
                    os._exit(status)
            os.close(results_write)
            children[results_read] = pid
    finally:
        os.close(tasks_read)
    frames = _read_until_closed(list(children))
    statuses = [os.waitpid(pid, 0)[1] for pid in children.values()]
    outcomes = dict(pickle.loads(frame) for frame in frames)
    if len(outcomes) < len(items):
        raise ChildProcessError(f"a worker process ended without its results (wait statuses {statuses})")
    for k in range(len(items)):
        failed, value = outcomes[k]
        if failed:
            raise value
    return [outcomes[k][1] for k in range(len(items))]


def _serve(function: Callable, items: Sequence, tasks: int, results: int) -> None:
    """The child's loop: take an index, compute, send (index, (failed, value)) as a length-prefixed pickle."""
    while len(index := os.read(tasks, _INDEX.size)) == _INDEX.size:
        (k,) = _INDEX.unpack(index)
        try:
            outcome: tuple[bool, object] = (False, function(items[k]))
        except Exception as error:  # raised again in the parent, with where it happened
            error.add_note("in a worker process (estimator.forked_map):\n" + traceback.format_exc())
            outcome = (True, error)
        try:
            frame = pickle.dumps((k, outcome), protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as error:  # an unpicklable result or exception: say what it was
            message = f"{type(error).__name__} while returning a result: {error}"
            frame = pickle.dumps((k, (True, RuntimeError(message))))
        _write_all(results, _LENGTH.pack(len(frame)) + frame)


def _write_all(descriptor: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(descriptor, view) :]


def _read_until_closed(descriptors: list[int]) -> list[bytes]:
    """Every frame the children write, read from all their pipes at once (a child blocks on a full pipe
    until the parent reads it), until each pipe is closed."""
    buffers = {d: bytearray() for d in descriptors}
    with selectors.DefaultSelector() as selector:
        for descriptor in descriptors:
            selector.register(descriptor, selectors.EVENT_READ)
        while selector.get_map():
            for key, _ in selector.select():
                chunk = os.read(key.fd, 1 << 20)
                if chunk:
                    buffers[key.fd] += chunk
                else:
                    selector.unregister(key.fd)
                    os.close(key.fd)
    frames = []
    for data in buffers.values():
        position = 0
        while position + _LENGTH.size <= len(data):
            (length,) = _LENGTH.unpack_from(data, position)
            start = position + _LENGTH.size
            if start + length > len(data):
                break  # cut short: the child died while writing
            frames.append(bytes(data[start : start + length]))
            position = start + length
    return frames
