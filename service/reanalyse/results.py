"""The output folder of `shockbench reanalyse`: one result file per recording and analysis, written
atomically (a reader or a re-run never sees half a file), and the summary table.

DIR/<name>.identify.json (and .diagnose.json) holds

    {"name", "analysis", "recording", "vehicle" (null: the HDF5 recording's own text), "input_sha256"
     (sources.input_digest), "options" {"tyre", "points"}, "seconds" (worker wall time),
     "result": what `shockbench identify --json` (`diagnose --json`) prints}

A re-run skips an analysis whose file exists with the same input digest and options. DIR/summary.csv has
one row per recording: name, status (ok/failed), reason ("identify: why", "identify, diagnose: why" when
both failed alike; different reasons joined by "; "), the identified masses (kg), the output-error gap (m),
EUSAMA (%, "left/right" for an axle), the seconds spent, the recording's path and, with the doctor, its
conclusion.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from daq.formats.atomic import atomic_write
from service.reanalyse.sources import Item
from service.reanalyse.task import Analysis, AnalysisOptions, Outcome

SUMMARY_FILE = "summary.csv"
COLUMNS = (
    "name",
    "status",
    "reason",
    "sprung_mass_kg",
    "unsprung_mass_kg",
    "gap_m",
    "eusama_percent",
    "seconds",
    "recording",
)
DIAGNOSIS_COLUMN = "diagnosis"


def result_path(out: Path, name: str, analysis: Analysis) -> Path:
    return out / f"{name}.{analysis.value}.json"


@dataclass(frozen=True)
class Done:
    """One analysis of one recording: its stored document when it succeeded (now or in an earlier run),
    else the one-line reason it failed."""

    document: dict[str, Any] | None
    reason: str | None = None


def stored(out: Path, item: Item, analysis: Analysis, digest: str, options: AnalysisOptions) -> Done | None:
    """The result an earlier run stored for this input and options, or None (none, unreadable, or made
    from another input or with other options: run it again)."""
    path = result_path(out, item.name, analysis)
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(document, dict):
        return None
    if document.get("input_sha256") != digest or document.get("options") != options.as_dict():
        return None
    return Done(document)


def save(out: Path | None, outcome: Outcome, digest: str) -> Done:
    """Store a finished analysis: its result file when it succeeded; when it failed, any older result of
    this recording is removed (it belongs to another input or options). Without `out` (a run stored in the
    database only), nothing is written."""
    task = outcome.task
    if out is not None and not outcome.ok:
        result_path(out, task.item.name, task.analysis).unlink(missing_ok=True)
    if not outcome.ok:
        return Done(None, outcome.reason)
    document = {
        "name": task.item.name,
        "analysis": task.analysis.value,
        "recording": str(task.item.recording),
        "vehicle": str(task.item.vehicle) if task.item.vehicle is not None else None,
        "input_sha256": digest,
        "options": task.options.as_dict(),
        "seconds": round(outcome.seconds, 3),
        "result": outcome.result,
    }
    if out is None:
        return Done(document)
    with atomic_write(result_path(out, task.item.name, task.analysis)) as handle:
        json.dump(document, handle, allow_nan=False)
        handle.write("\n")
    return Done(document)


def _number(value: Any) -> str:
    return "" if value is None else f"{float(value):.6g}"


def _eusama(inspection: Mapping[str, Any]) -> str:
    if "eusama_percent" in inspection:
        return _number(inspection["eusama_percent"])
    sides = [inspection[side]["eusama_percent"] for side in ("left", "right") if side in inspection]
    return "/".join(_number(value) for value in sides)


def summary_row(item: Item, done: Mapping[Analysis, Done]) -> dict[str, str]:
    """The summary's row of one recording from its analyses (identify's figures, the doctor's words)."""
    reasons: dict[str, list[str]] = {}  # the same reason for both analyses (an unreadable file) said once
    for analysis, d in done.items():
        if d.document is None:
            reasons.setdefault(str(d.reason), []).append(analysis.value)
    failed = [f"{', '.join(analyses)}: {reason}" for reason, analyses in reasons.items()]
    seconds = sum(float(d.document.get("seconds", 0.0)) for d in done.values() if d.document is not None)
    row = dict.fromkeys(COLUMNS, "")
    row |= {
        "name": item.name,
        "status": "failed" if failed else "ok",
        "reason": "; ".join(failed),
        "seconds": f"{seconds:.2f}",
        "recording": str(item.recording),
    }
    identified = done.get(Analysis.IDENTIFY)
    if identified is not None and identified.document is not None:
        result = identified.document["result"]
        row |= {
            "sprung_mass_kg": _number(result["masses_kg"]["sprung"]),
            "unsprung_mass_kg": _number(result["masses_kg"]["unsprung"]),
            "gap_m": _number(result.get("gap_m")),
            "eusama_percent": _eusama(result["inspection"]),
        }
    diagnosed = done.get(Analysis.DIAGNOSE)
    if diagnosed is not None:
        conclusion = diagnosed.document["result"]["conclusion"] if diagnosed.document is not None else ""
        row[DIAGNOSIS_COLUMN] = " ".join(str(conclusion).split())
    return row


def write_summary(out: Path, rows: Iterable[dict[str, str]], diagnose: bool) -> Path:
    """DIR/summary.csv, written atomically; returns its path."""
    path = out / SUMMARY_FILE
    columns = [*COLUMNS, DIAGNOSIS_COLUMN] if diagnose else list(COLUMNS)
    with atomic_write(path) as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return path
