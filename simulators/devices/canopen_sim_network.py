"""canopen's Network on simulated time, for a simulated CANopen device (simulators/devices/cia402_exciter.py):
periodic frames (the NMT heartbeat) go out from the device's tick(), a silent device neither sends nor
hears, SDO requests are ignored while the node is NMT STOPPED, and the consumed host heartbeat is
subscribed to on demand."""

from __future__ import annotations

import threading
from typing import Protocol

import can
import canopen

from simulators.coupling import SimulatedClock

READER_POLL_S = 0.02
NMT_HEARTBEAT_BASE = 0x700


class SimulatedNode(Protocol):
    """What the network needs of its device."""

    clock: SimulatedClock
    silent: bool
    node: canopen.LocalNode

    def on_host_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None: ...


class SimulatedTimeNetwork(canopen.Network):
    """canopen's Network for the simulated drive: periodic frames (the NMT heartbeat) go out on simulated
    time from tick(), not from a python-can timer thread; a silent drive neither sends nor hears; SDO
    requests are ignored while the node is NMT STOPPED."""

    def __init__(self, drive: SimulatedNode) -> None:
        super().__init__()
        self.NOTIFIER_CYCLE = READER_POLL_S  # close() waits at most this long for the reader thread
        self._drive = drive
        self._periodic: list[SimulatedPeriodicTask] = []
        self._periodic_lock = threading.Lock()
        self._host_node: int | None = None
        self.periodic_frames_sent = 0
        self.frames_ignored = 0
        """Frames heard while silent (tests wait on it to know a request reached the drive)."""

    def send_periodic(  # type: ignore[override]
        self, can_id: int, data: bytes, period: float, remote: bool = False
    ) -> SimulatedPeriodicTask:
        task = SimulatedPeriodicTask(self, can_id, bytes(data), period, self._drive.clock.now_s())
        with self._periodic_lock:
            self._periodic.append(task)
        task.send_due(self._drive.clock.now_s())  # python-can sends the first one at once too
        return task

    def remove_periodic(self, task: SimulatedPeriodicTask) -> None:
        with self._periodic_lock:
            if task in self._periodic:
                self._periodic.remove(task)

    def send_due_periodic(self, now_s: float) -> None:
        with self._periodic_lock:
            tasks = list(self._periodic)
        for task in tasks:
            task.send_due(now_s)

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        if not self._drive.silent:
            super().send_message(can_id, data, remote)

    def send_periodic_frame(self, can_id: int, data: bytes) -> None:
        """One frame of a periodic task; a silent drive skips it (no backlog once it speaks again)."""
        if self._drive.silent:
            return
        try:
            super().send_message(can_id, data)
        except (can.CanError, RuntimeError):
            return  # bus closing under the tick
        self.periodic_frames_sent += 1

    def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self._drive.silent:
            self.frames_ignored += 1
            return
        if can_id == self._drive.node.sdo.rx_cobid and self._drive.node.nmt.state == "STOPPED":
            return
        super().notify(can_id, data, timestamp)

    def subscribe_host(self, host_node: int | None) -> None:
        """Hear the heartbeat of `host_node` (None: of nobody)."""
        self.unsubscribe_host()
        if host_node is not None:
            self._host_node = host_node
            self.subscribe(NMT_HEARTBEAT_BASE + host_node, self._drive.on_host_heartbeat)

    def unsubscribe_host(self) -> None:
        if self._host_node is not None:
            self.unsubscribe(NMT_HEARTBEAT_BASE + self._host_node, self._drive.on_host_heartbeat)
            self._host_node = None


class SimulatedPeriodicTask:
    """What canopen's NMT slave expects of a periodic task (stop, update), run on simulated time."""

    def __init__(
        self, network: SimulatedTimeNetwork, can_id: int, data: bytes, period_s: float, now_s: float
    ) -> None:
        self.network = network
        self.can_id = can_id
        self.data = data
        self.period_s = period_s
        self.next_s = now_s
        self._lock = threading.Lock()

    def stop(self) -> None:
        self.network.remove_periodic(self)

    def update(self, data: bytes) -> None:
        self.data = bytes(data)

    def send_due(self, now_s: float) -> None:
        with self._lock:
            due = 0
            while self.next_s <= now_s + 1e-12:
                self.next_s += self.period_s
                due += 1
        if due:  # one frame however many periods passed: a late tick does not send a backlog
            self.network.send_periodic_frame(self.can_id, self.data)
