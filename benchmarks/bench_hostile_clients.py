"""Benchmark: GET /api/v1/status and the emergency stop while hostile clients hit the service (issue 30).

    .venv/bin/python benchmarks/bench_hostile_clients.py                   # 5 x 40 MB, 200 slow loris
    .venv/bin/python benchmarks/bench_hostile_clients.py --samples 100 --no-keyed-uploads

`python -m service.cli.serve --simulated` runs in its own process on 127.0.0.1 (port 0, a keys file, a fresh
data directory, the default limits). One keep-alive httpx client with the operator's key then calls GET
/api/v1/status and POST /api/v1/emergency-stop (the simulated bench's drive), alternately, `--samples`
times each, every 20 ms, in three phases:

1. idle;
2. under attack: `--bodies` anonymous clients each POST a `--body-mb` MB multipart body to /api/v1/jobs,
   as fast as loopback takes it, and start again as soon as the service drops them; meanwhile `--loris`
   slow-loris connections from 127.0.0.2 send their request headers one byte per second (half of them) or
   complete anonymous headers and then a body at one byte every 2 s (the others), each reopened when
   closed;
3. (unless --no-keyed-uploads) `--bodies` clients with the operator's key upload a `--body-mb` MB recording
   CSV each, back to back: the service reads, parses and stores each (the input checker then refuses the
   junk rows); this is the multipart parsing on the event loop at full size.

Each call is timed from request to parsed response. The table gives p50 and max per phase and endpoint;
the target of the issue: both under 100 ms while the attack runs. The attackers' tallies say what the
service did to them: answered 401 after how many bytes, header deadline, per-address cap.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import multiprocessing
import os
import platform
import re
import selectors
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from multiprocessing.queues import Queue
from multiprocessing.synchronize import Event as EventType
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))

from live_server import wait_until  # the tests' deadline-bounded wait, shared

KEY = "benchmark-operator-key-0123456789"
TARGET_MS = 100.0
BOUNDARY = "hostilebenchboundary"
CHUNK = 256 * 1024
CLOSED_LATE = "loris closed by the service after it sent (late per-address cap, or header deadline)"


def start_service(folder: Path) -> tuple[subprocess.Popen[str], str]:
    keys = folder / "keys.toml"
    keys.write_text(f'operator = ["{KEY}"]\n')
    command = [sys.executable, "-m", "service.cli.serve", "--simulated", "--port", "0"]
    command += ["--data", str(folder / "data"), "--keys", str(keys), "--log-level", "error"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None
    for line in process.stdout:
        match = re.search(r"listening on (http://\S+)", line)
        if match:
            return process, match.group(1)
    raise RuntimeError(f"the service exited with {process.wait()}")


def upload_head(address: tuple[str, int], length: int, key: str | None) -> bytes:
    lines = [
        "POST /api/v1/jobs HTTP/1.1",
        f"Host: {address[0]}:{address[1]}",
        f"Content-Type: multipart/form-data; boundary={BOUNDARY}",
        f"Content-Length: {length}",
    ]
    if key is not None:
        lines.append(f"Authorization: Bearer {key}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def multipart_body(size: int) -> bytes:
    """A recording part of about `size` bytes (junk rows: the input check refuses them) and a vehicle part."""
    start = (
        f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="recording"; filename="r.csv"\r\n'
        "Content-Type: text/csv\r\n\r\nt,x_s,x_t,x_r\n"
    ).encode()
    end = (
        f'\r\n--{BOUNDARY}\r\nContent-Disposition: form-data; name="vehicle"; filename="v.toml"\r\n\r\n'
        f"[vehicle]\r\n--{BOUNDARY}--\r\n"
    ).encode()
    row = b"0.001,0.0012345,x,0.0034567\n"
    return start + row * max(1, (size - len(start) - len(end)) // len(row)) + end


class Attack:
    """The attackers, each in a thread, until `stop` is set; `tally` counts what happened to them."""

    def __init__(self, address: tuple[str, int], body: bytes) -> None:
        self.address = address
        self.body = body
        self.stop = threading.Event()
        self.tally: Counter[str] = Counter()
        self.sent_before_answer: list[int] = []
        self.loris_lifetimes: list[float] = []
        self.lock = threading.Lock()
        self.threads: list[threading.Thread] = []

    def count(self, what: str, n: int = 1) -> None:
        with self.lock:
            self.tally[what] += n

    def start(self, bodies: int, loris: int, key: str | None) -> None:
        for _ in range(bodies):
            self.threads.append(threading.Thread(target=self.big_bodies, args=(key,), daemon=True))
        if loris:
            self.threads.append(threading.Thread(target=self.slow_loris, args=(loris,), daemon=True))
        for thread in self.threads:
            thread.start()

    def join(self) -> None:
        self.stop.set()
        for thread in self.threads:
            thread.join(60)

    def big_bodies(self, key: str | None) -> None:
        """POST the body again and again; note the answer and how much was sent before it came."""
        head = upload_head(self.address, len(self.body), key)
        while not self.stop.is_set():
            sent = 0
            try:
                with socket.create_connection(self.address, timeout=120) as sock:
                    sock.sendall(head)
                    sock.setblocking(False)
                    answer = b""
                    view = memoryview(self.body)
                    while key is not None or not self.stop.is_set():  # a keyed upload is finished
                        ready = selectors.DefaultSelector()
                        events = selectors.EVENT_READ | (selectors.EVENT_WRITE if sent < len(view) else 0)
                        ready.register(sock, events)
                        for _, mask in ready.select(1.0):
                            if mask & selectors.EVENT_READ:
                                chunk = sock.recv(65536)
                                if not chunk:
                                    raise ConnectionResetError
                                answer += chunk
                            elif mask & selectors.EVENT_WRITE:
                                sent += sock.send(view[sent : sent + CHUNK])
                        ready.close()
                        if b"\r\n\r\n" in answer:
                            break
                status = answer.split(b" ", 2)[1].decode() if answer.startswith(b"HTTP/") else "none"
                self.count(f"{'keyed' if key else 'anonymous'} body answered {status}")
                with self.lock:
                    self.sent_before_answer.append(sent)
            except OSError:
                self.count("body connection cut without an answer")

    def slow_loris(self, n: int) -> None:
        """`n` connections from 127.0.0.2: half send their headers a byte a second, half send them whole
        and then a body a byte every 2 s; each is reopened when the service closes or answers it."""
        head = upload_head(self.address, 10**6, None)
        alive: dict[int, Loris] = {}
        while not self.stop.is_set():
            now = time.monotonic()
            for slot in range(n):
                loris = alive.get(slot)
                if loris is None:
                    alive[slot] = Loris.open(self.address, slot % 2 == 1, now)
                    self.count("loris connections opened")
                elif now >= loris.due:
                    outcome = loris.step(head, now)
                    if outcome is not None:
                        self.count(outcome)
                        if outcome == CLOSED_LATE:
                            with self.lock:
                                self.loris_lifetimes.append(now - loris.opened)
                        loris.sock.close()
                        del alive[slot]
            self.stop.wait(0.05)
        for loris in alive.values():
            loris.sock.close()


@dataclass
class Loris:
    sock: socket.socket
    whole_headers: bool
    opened: float
    due: float
    sent: int = 0

    @classmethod
    def open(cls, address: tuple[str, int], whole_headers: bool, now: float) -> Loris:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.bind(("127.0.0.2", 0))
        sock.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            sock.connect(address)
        return cls(sock, whole_headers, now, now + 0.2)

    def ended(self) -> str:
        return CLOSED_LATE if self.sent else "loris refused at once (per-address cap)"

    def step(self, head: bytes, now: float) -> str | None:
        """Send the next byte(s); None while the connection lives, else what happened to it."""
        try:
            return "loris answered (401)" if self.sock.recv(1, socket.MSG_PEEK) else self.ended()
        except BlockingIOError:
            pass
        except OSError as exc:
            return None if exc.errno == errno.ENOTCONN else self.ended()  # ENOTCONN: still connecting
        if self.sent < len(head):
            data = head[self.sent :] if self.whole_headers else head[self.sent : self.sent + 1]
        else:
            data = b"x"
        try:
            self.sent += self.sock.send(data)
        except BlockingIOError:
            pass
        except OSError:
            return self.ended()
        self.due = now + (2.0 if self.sent >= len(head) else 1.0)
        return None


def run_attack(
    address: tuple[str, int],
    body_bytes: int,
    bodies: int,
    loris: int,
    key: str | None,
    stop: EventType,
    out: Queue,
) -> None:
    """In a process of its own (the attackers' threads do not share the measuring client's interpreter
    lock): attack until `stop`, then put the tallies in `out`."""
    attack = Attack(address, multipart_body(body_bytes))
    attack.start(bodies, loris, key)
    stop.wait()
    attack.join()
    cpu = os.times()
    out.put((dict(attack.tally), attack.sent_before_answer, attack.loris_lifetimes, cpu.user + cpu.system))


@dataclass
class Phase:
    name: str
    times: dict[str, list[float]]
    tally: dict[str, int] = field(default_factory=dict)
    sent_before_answer: list[int] = field(default_factory=list)
    loris_lifetimes: list[float] = field(default_factory=list)
    wall_s: float = 0.0
    service_cpu_s: float = 0.0
    """CPU time of the service's process (its event loop and threads; not the worker) in the phase."""
    attackers_cpu_s: float = 0.0


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process `pid` so far (Linux /proc; 0 elsewhere)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def measure(client: httpx.Client, samples: int, duration_s: float) -> dict[str, list[float]]:
    """Call each endpoint alternately every ~20 ms, `samples` times at least and for `duration_s`."""
    times: dict[str, list[float]] = {"GET /api/v1/status": [], "POST /api/v1/emergency-stop": []}
    until = time.monotonic() + duration_s
    while len(times["GET /api/v1/status"]) < samples or time.monotonic() < until:
        for name in times:
            method, path = name.split(" ")
            start = time.perf_counter()
            response = client.request(method, path)
            response.json()
            times[name].append(time.perf_counter() - start)
            response.raise_for_status()
            time.sleep(0.01)
    return times


def attacked_phase(
    name: str,
    client: httpx.Client,
    address: tuple[str, int],
    args: argparse.Namespace,
    key: str | None,
    service_pid: int,
) -> Phase:
    context = multiprocessing.get_context("spawn")
    stop, out = context.Event(), context.Queue()
    loris = 0 if key else args.loris
    attackers = context.Process(
        target=run_attack, args=(address, int(args.body_mb * 1e6), args.bodies, loris, key, stop, out)
    )
    attackers.start()
    try:
        time.sleep(3.0)  # the attackers start up, every body under way, the loris set open
        began, service_cpu = time.monotonic(), cpu_seconds(service_pid)
        times = measure(client, args.samples, args.attack_s)
        wall, service_cpu = time.monotonic() - began, cpu_seconds(service_pid) - service_cpu
    finally:
        stop.set()
    tally, sent, lifetimes, attackers_cpu = out.get(timeout=600)
    attackers.join(60)
    return Phase(name, times, tally, sent, lifetimes, wall, service_cpu, attackers_cpu)


def row(phase: str, name: str, samples: list[float]) -> str:
    ms = [s * 1e3 for s in samples]
    return f"| {phase} | {name} | {len(ms)} | {statistics.median(ms):.1f} | {max(ms):.1f} |"


def report(phases: list[Phase], args: argparse.Namespace) -> None:
    print(
        f"\n{args.bodies} bodies of {args.body_mb:g} MB each, {args.loris} slow-loris connections; each "
        f"endpoint called every ~20 ms by one keep-alive client, {args.attack_s:g} s at least under attack\n"
    )
    print("| phase | endpoint | calls | p50 (ms) | max (ms) |")
    print("|---|---|---:|---:|---:|")
    for phase in phases:
        for name, samples in phase.times.items():
            print(row(phase.name, name, samples))
    for phase in phases[1:]:
        print(
            f"\n{phase.name}: the service's process used {phase.service_cpu_s:.1f} s of CPU in "
            f"{phase.wall_s:.1f} s of measuring; the attackers {phase.attackers_cpu_s:.1f} s in all"
        )
        for what, n in sorted(phase.tally.items()):
            print(f"  {what}: {n}")
        if phase.sent_before_answer:
            sent = phase.sent_before_answer
            print(
                "  bytes a body client had sent when the answer came: median "
                f"{statistics.median(sent) / 1e6:.2f} MB, max {max(sent) / 1e6:.2f} MB "
                "(for an anonymous body: in the kernel's socket buffers, never read)"
            )
        if phase.loris_lifetimes:
            lives = phase.loris_lifetimes
            print(
                f"  loris held until closed: median {statistics.median(lives):.1f} s, max {max(lives):.1f} s"
            )
    attack = phases[1].times
    worst = max(max(samples) * 1e3 for samples in attack.values())
    print(
        f"\nworst call under attack {worst:.1f} ms; target < {TARGET_MS:g} ms: "
        f"{'met' if worst < TARGET_MS else 'NOT met'}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=5, help="concurrent big bodies (default 5)")
    parser.add_argument("--body-mb", type=float, default=40.0, help="size of each body, MB (default 40)")
    parser.add_argument("--loris", type=int, default=200, help="slow-loris connections (default 200)")
    parser.add_argument(
        "--samples", type=int, default=200, help="calls of each endpoint per phase (default 200)"
    )
    parser.add_argument(
        "--attack-s",
        type=float,
        default=15.0,
        help="least time under attack (default 15: past the header deadline)",
    )
    parser.add_argument("--no-keyed-uploads", action="store_true", help="skip phase 3")
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.2f} at start"
    )
    phases: list[Phase] = []
    with tempfile.TemporaryDirectory() as tmp:
        process, url = start_service(Path(tmp))
        host, port = url.removeprefix("http://").split(":")
        address = (host, int(port))
        try:
            with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {KEY}"}, timeout=60) as client:
                wait_until(lambda: client.get("/api/v1/status").json()["worker"]["ready"], 120, "ready", 0.2)
                phases.append(Phase("idle", measure(client, args.samples, 0)))
                pid = process.pid
                phases.append(
                    attacked_phase("anonymous bodies + slow loris", client, address, args, None, pid)
                )
                if not args.no_keyed_uploads:
                    name = f"{args.bodies} keyed uploads"
                    phases.append(attacked_phase(name, client, address, args, KEY, pid))
        finally:
            process.send_signal(signal.SIGINT)
            process.wait(60)
    report(phases, args)
    print(f"load average {os.getloadavg()[0]:.2f} at the end (other work on the machine delays every call)")


if __name__ == "__main__":
    main()
