"""Re-analysis runs and what they change (issue 33, items 3 and 5): a result is written once per run,
recording and analysis however often it is written (SQLite and PostgreSQL); --compare measures how far
curves, masses and verdicts moved, per vehicle and over the fleet, largest first, against another run or
the lanes' original results; the progress is a bar with rate and ETA on a terminal, plain lines elsewhere."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest

from service.reanalyse.compare import CompareError, compare, compare_runs, render
from service.reanalyse.progress import RunProgress, bar_line
from service.reanalyse.sources import Item
from service.reanalyse.task import Analysis, AnalysisOptions, Outcome, Task
from service.store.database import Database
from service.store.jobs import JobFiles, JobStore
from service.store.reanalysis_runs import RunStore, Written
from service.store.recordings import RecordingStore

PASSING = {"phase_shift_min_deg": 60.0, "eusama_percent": 70.0}
FAILING = {"phase_shift_min_deg": 60.0, "eusama_percent": 10.0}


def result(scale: float = 1.0, sprung_kg: float = 400.0, inspection: dict[str, Any] = PASSING) -> dict:
    """An identify result: a linear damper curve of 1000·scale N·s/m, the masses and the inspection."""
    velocity = [-1.0, 0.0, 1.0]
    return {
        "curves": [{"velocity_m_s": velocity, "force_N": [1000 * scale * v for v in velocity]}],
        "masses_kg": {"sprung": sprung_kg, "unsprung": 40.0},
        "inspection": inspection,
    }


def test_a_result_is_written_once_however_often_it_is_written(database: Database) -> None:
    runs = RunStore(database)
    run = runs.begin("1.2.3", {"analyses": ["identify"]}, recordings=2)
    assert runs.record(run, "a" * 64, "identify", result(), None, 0.5)
    assert not runs.record(run, "a" * 64, "identify", result(2.0), None, 0.7)  # a retried task
    assert runs.record(run, "b" * 64, "identify", None, "broken.csv:3: NaN", 0.1)
    finished = runs.finish(run)
    assert (finished.recordings, finished.succeeded, finished.failed) == (2, 1, 1)
    assert finished.software_version == "1.2.3" and finished.finished_at is not None
    assert runs.count(run) == 2 and runs.results(run)["a" * 64] == result()  # the first write stands


def test_a_batch_stores_its_new_results_and_leaves_those_stored_before(database: Database) -> None:
    """record_many writes a batch in one statement: a result stored before (a retried batch's) stays as
    it was, the others are new, and a result written twice within the batch counts once."""
    runs = RunStore(database)
    run = runs.begin("1.2.3", {"analyses": ["identify"]}, recordings=3)
    assert runs.record(run, "a" * 64, "identify", result(), None, 0.5)
    batch = [
        Written("a" * 64, "identify", result(2.0), None, 0.7),
        Written("b" * 64, "identify", result(3.0), None, 0.6),
        Written("c" * 64, "identify", None, "broken.csv:3: NaN", 0.1),
        Written("b" * 64, "identify", result(4.0), None, 0.6),
    ]
    assert runs.record_many(run, batch) == 2
    assert runs.record_many(run, batch) == 0
    stored = runs.results(run)
    assert stored["a" * 64] == result() and stored["b" * 64] == result(3.0) and stored["c" * 64] is None
    assert runs.count(run) == 3


def test_compare_finds_the_largest_changes_and_the_verdict_flips() -> None:
    a = {"1" * 64: result(), "2" * 64: result(), "3" * 64: result(), "4" * 64: result(), "5" * 64: None}
    b = {
        "1" * 64: result(1.01),
        "2" * 64: result(1.10, sprung_kg=410.0),
        "3" * 64: result(1.0, inspection=FAILING),
        "4" * 64: None,
        "5" * 64: result(),
    }
    names = {k: (f"rec-{k[0]}", "car-A" if k[0] in "12" else "car-B") for k in a}
    c = compare("1", "2", a, b, names)
    assert [ch.name for ch in c.changes] == ["rec-2", "rec-1", "rec-3"]  # largest curve change first
    assert c.changes[0].curve_percent == pytest.approx(10 / 3**0.5, rel=0.01)  # RMS over ±1 m/s
    assert (c.changes[0].sprung_kg, c.changes[0].sprung_percent) == pytest.approx((10.0, 2.5))
    flips = [ch for ch in c.changes if ch.flipped]
    assert [(ch.name, ch.verdict_a, ch.verdict_b, ch.verdict_steps) for ch in flips] == [
        ("rec-3", "pass", "fail", 2)
    ]
    assert (c.only_a, c.only_b) == (["rec-4"], ["rec-5"])
    assert c.fleet.recordings == 3 and dict(c.fleet.flips) == {"pass->fail": 1}
    assert [(g.name, g.recordings) for g in c.vehicles] == [("car-A", 2), ("car-B", 1)]
    text = render(c)
    assert "verdict flips: 1\n  rec-3: pass->fail" in text
    assert text.index("rec-2  [car-A]") < text.index("rec-1  [car-A]") < text.index("rec-3  [car-B]")
    with pytest.raises(CompareError, match="no identified recording in common"):
        compare("1", "2", {"1" * 64: None}, {"1" * 64: result()}, names)


def test_a_run_is_compared_with_the_lanes_original_results(database: Database, tmp_path: Path) -> None:
    content = b"t,x_s,x_t,x_r\n0,0,0,0\n"
    sha = RecordingStore(database).put(content, name="r", file_format="csv", vehicle_text="").sha256
    jobs = JobStore(database, lane="north")
    (tmp_path / "r.csv").write_bytes(content)
    job = jobs.create("identify", {}, lambda _i: JobFiles(tmp_path / "r.csv", tmp_path / "v", tmp_path))
    assert jobs.mark_running(job.id) and jobs.succeed(job.id, result(), {}, None)
    runs = RunStore(database)
    run = runs.begin("2.0", {}, 1)
    runs.record(run, sha, "identify", result(1.05, inspection=FAILING), None, 0.2)
    c = compare_runs(database, "original", str(run))
    (change,) = c.changes
    assert (change.name, change.flipped) == ("r", True)
    assert change.curve_percent == pytest.approx(5 / 3**0.5, rel=0.01)


def outcome(ok: bool) -> Outcome:
    task = Task(Item("rec", Path("rec.csv"), None), Analysis.IDENTIFY, AnalysisOptions())
    return Outcome(task, {} if ok else None, None if ok else "rec.csv:3: NaN", 0.25)


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_a_bar_with_rate_and_eta_on_a_terminal_and_lines_elsewhere() -> None:
    assert bar_line(2, 4, 2.0, 0).endswith("] 2/4  2.0/s  ETA 1 s")
    now = [0.0]
    terminal = Terminal()
    bar = RunProgress(terminal, clock=lambda: now[0])
    bar.dashboard("http://127.0.0.1:8787/status")
    for number in range(1, 5):
        now[0] += 0.5
        bar(number, 4, outcome(number != 3))
    bar.close()
    shown = terminal.getvalue()
    assert shown.startswith("\r\x1b[KDask dashboard: http://127.0.0.1:8787/status\n")
    assert "\r\x1b[K[1/4] rec identify: failed: rec.csv:3: NaN\n" in shown.replace("[3/4]", "[1/4]")
    assert "] 2/4  2.0/s  ETA 1 s" in shown and shown.endswith("] 4/4  2.0/s  ETA -  1 failed\n")

    log = io.StringIO()
    lines = RunProgress(log)
    lines.dashboard(None)  # no dashboard: nothing said
    lines(1, 2, outcome(True))
    lines(2, 2, outcome(False))
    assert log.getvalue().splitlines() == [
        "[1/2] rec identify: ok in 0.2 s",
        "[2/2] rec identify: failed: rec.csv:3: NaN",
    ]


def test_the_dashboards_address_is_said_only_when_it_answers() -> None:
    """run.dashboard_link: Dask names a dashboard address even when the scheduler serves none (no bokeh
    there); only an address that answers is printed."""
    import threading
    from http.server import BaseHTTPRequestHandler, HTTPServer
    from types import SimpleNamespace

    from service.reanalyse.run import dashboard_link

    class Status(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200 if self.path == "/status" else 404)
            self.end_headers()

        def log_message(self, *_: object) -> None:
            pass

    with HTTPServer(("127.0.0.1", 0), Status) as server:
        threading.Thread(target=server.serve_forever, daemon=True).start()
        base = f"http://127.0.0.1:{server.server_address[1]}"
        try:
            assert dashboard_link(SimpleNamespace(dashboard_link=f"{base}/status")) == f"{base}/status"
            assert dashboard_link(SimpleNamespace(dashboard_link=f"{base}/none")) is None
        finally:
            server.shutdown()
    assert dashboard_link(SimpleNamespace(dashboard_link="http://127.0.0.1:9/status")) is None  # nobody there
