"""The service on a simulated bench in real time, for the benchmarks: `shockbench sim-devices` (simulated
lasers and exciter on real transports, on the wall clock) and `python -m service.cli.serve --config` on it,
each its own process with its output in a log file, stopped (SIGINT, then kill) on the way out."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "service"))

from live_server import wait_until  # the tests' deadline-bounded wait, shared


def start(command: list[str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("w") as out:
        return subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)


def url_from(log: Path, process: subprocess.Popen[bytes]) -> str:
    """The URL a starting service prints (RuntimeError with its log if it exits first)."""

    def found() -> str | None:
        if process.poll() is not None:
            raise RuntimeError(f"the service exited:\n{log.read_text()}")
        match = re.search(r"listening on (http://\S+)", log.read_text())
        return match.group(1) if match else None

    return wait_until(found, 120, "service start-up", 0.1)


def stop(*processes: subprocess.Popen[bytes] | None) -> None:
    for process in processes:
        if process is not None and process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(60)
            except subprocess.TimeoutExpired:
                process.kill()


@contextmanager
def realtime_service(folder: Path, keys_toml: str, *serve_args: str) -> Iterator[tuple[str, int]]:
    """(URL, pid) of `serve --config` on simulated devices in real time, data in folder/data, keys from
    the TOML text `keys_toml`; more `serve` options in `serve_args`."""
    (folder / "keys.toml").write_text(keys_toml)
    bench_toml = folder / "bench.toml"
    devices = start(
        [sys.executable, "-m", "service.cli.main", "sim-devices", "--config", str(bench_toml)],
        folder / "devices.log",
    )
    service: subprocess.Popen[bytes] | None = None
    try:
        wait_until(lambda: bench_toml.exists() or devices.poll() is not None, 120, "sim-devices", 0.1)
        command = [sys.executable, "-m", "service.cli.serve", "--port", "0", "--config", str(bench_toml)]
        command += ["--data", str(folder / "data"), "--keys", str(folder / "keys.toml"), *serve_args]
        service = start(command, folder / "service.log")
        yield url_from(folder / "service.log", service), service.pid
    except Exception:
        if (folder / "service.log").exists():
            print((folder / "service.log").read_text()[-3000:], file=sys.stderr)
        raise
    finally:
        stop(service, devices)


def recording_rows(h5_bytes: bytes) -> tuple[int, int]:
    """(rows, gap samples) of a sweep's HDF5 recording as GET /sweeps/{id}/recording.h5 sends it: a lost
    sample is a gap there."""
    import h5py

    with tempfile.NamedTemporaryFile(suffix=".h5") as h5:
        h5.write(h5_bytes)
        h5.flush()
        with h5py.File(h5.name, "r") as f:
            return int(f["time"].shape[0]), int(f.attrs["gap_samples"])


def sweep_status(sweep: dict[str, Any]) -> str:
    """A sweep's status, and its reason when it has one, for a benchmark's table."""
    return sweep["status"] + (f" ({sweep['reason']})" if sweep["reason"] else "")
