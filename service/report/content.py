"""The report's content, independent of how it is rendered: what went into it (`ReportInput`: a stored
identification result and what is known about its test), and the sheet itself (`ReportContent`: titled
sections of paragraphs, tables and plots, every value already written out as text).

service.report.html and service.report.pdf render the same `ReportContent`, so the HTML page and the PDF
sheet say the same things in the same order. A field the test did not record is "not recorded"; a figure
the estimator could not compute is "not estimated": nothing is filled in.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any, Literal

from pydantic import ValidationError

from estimator.errors import UserError
from estimator.frame_guides import GUIDE_FRICTION_NAMES, GUIDED_MASSES
from estimator.verdict import (
    ThresholdsError,
    VerdictThresholds,
    imbalance_outcome,
    judge,
    relative_difference_percent,
)
from service.api.results import AxleInspectionOut, CurveOut, DiagnoseResult, IdentifyResult, InspectionOut
from service.doctor_words import fit_verdict, shape

if TYPE_CHECKING:
    from estimator.recording import Recording

NOT_RECORDED = "not recorded"
NOT_ESTIMATED = "not estimated"
CORNER_NAMES = {"single": "wheel", "left": "left", "right": "right"}


class ReportInputError(UserError, ValueError):
    """A result that is not an identification's (one line naming the problem)."""


@dataclass(frozen=True)
class RecordedTest:
    """What is known about the test beyond its result; None: not recorded."""

    vehicle_id: str | None = None
    operator: str | None = None
    lane: str | None = None
    bench: str | None = None
    date: datetime | str | None = None
    """When the sweep ran: a datetime (shown in UTC) or the text a recording states."""
    tyre_pressure_bar: float | None = None
    sweep_id: int | None = None
    job_id: int | None = None


@dataclass(frozen=True)
class ChainRecord:
    """The result's link in its lane's hash chain (service.store.result_chain)."""

    lane: str
    sequence: int | None
    hash: str
    job_id: int


@dataclass(frozen=True)
class ReportInput:
    """Everything a report is made from. `result`: the stored JSON of an identify job (or `shockbench
    identify --json`); `recording`: the sweep's recording, for the plots over time and frequency; the
    notes say why a part is missing."""

    result: dict[str, Any]
    test: RecordedTest = field(default_factory=RecordedTest)
    chain: ChainRecord | None = None
    chain_note: str = "not recorded: this result was not stored by the service"
    diagnosis: dict[str, Any] | None = None
    """The stored JSON of the model doctor's newest diagnosis of the sweep, when one was run."""
    diagnosis_job_id: int | None = None
    diagnosis_note: str = "not run on this test"
    recording: Recording | None = None
    recording_note: str = "no recording given"
    software: str = ""


# ---- the sheet ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Paragraph:
    text: str
    style: Literal["", "note", "outcome-pass", "outcome-check", "outcome-fail", "outcome-none", "mono"] = ""


@dataclass(frozen=True)
class Table:
    rows: tuple[tuple[str, ...], ...]
    header: tuple[str, ...] | None = None
    widths: tuple[float, ...] | None = None
    """Relative column widths (equal when None)."""


PlotKind = Literal["curves", "sweep", "transmissibility"]


@dataclass(frozen=True)
class Plot:
    kind: PlotKind
    caption: str
    height_in: float
    panels: int = 1


Block = Paragraph | Table | Plot


@dataclass(frozen=True)
class Section:
    title: str
    blocks: tuple[Block, ...]


@dataclass(frozen=True)
class ReportContent:
    title: str
    subtitle: str
    sections: tuple[Section, ...]
    curves: tuple[CurveOut, ...]
    """What the damper-curve plot draws."""
    recording: Recording | None
    """What the plots over time and frequency draw (None: those plots are left out)."""
    sweep_band_Hz: tuple[float, float] | None
    footer: str


# ---- text of values ----------------------------------------------------------------------------------------


def number(value: float | None, unit: str = "", digits: int = 3, missing: str = NOT_ESTIMATED) -> str:
    """`value` with `digits` significant digits (a whole number from 10^(digits-1) up) and its unit."""
    if value is None:
        return missing
    text = f"{value:.0f}" if abs(value) >= 10 ** (digits - 1) else f"{value:.{digits}g}"
    return f"{text}{'' if unit == '°' else ' '}{unit}" if unit else text


def interval(pair: list[float] | None, scale: float = 1.0, unit: str = "", digits: int = 4) -> str:
    if not pair:
        return "—"
    return f"{number(pair[0] * scale, '', digits)} – {number(pair[1] * scale, unit, digits)}"


def recorded(value: object) -> str:
    if value is None or (isinstance(value, str) and not value.strip()):
        return NOT_RECORDED
    if isinstance(value, datetime):
        return value.astimezone(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    return str(value)


# ---- building it -------------------------------------------------------------------------------------------


def identify_result(raw: object) -> IdentifyResult:
    """The stored JSON as the typed identification result (ReportInputError, one line, otherwise)."""
    if not isinstance(raw, dict):
        raise ReportInputError(f"not an identification result (a JSON {type(raw).__name__}, not an object)")
    try:
        return IdentifyResult.model_validate(raw)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "the result"
        raise ReportInputError(f"not an identification result: {where}: {first['msg']}") from None


def _limits(verdict: dict[str, Any] | None) -> tuple[VerdictThresholds, bool]:
    """The thresholds the stored verdict was judged by, and whether the result carried them (else the
    defaults judge it here)."""
    if verdict is None:
        return VerdictThresholds(), False
    try:
        table = {"version": verdict["thresholds_version"], **verdict["thresholds"]}
        return VerdictThresholds.from_table(table), True
    except (ThresholdsError, KeyError, TypeError):
        return VerdictThresholds(), False


def _corner_figures(name: str, figures: InspectionOut, limits: VerdictThresholds) -> tuple[str, ...]:
    judged = judge(figures.model_dump(), limits)
    return (
        CORNER_NAMES.get(name, name),
        number(figures.eusama_percent, "%"),
        number(figures.phase_shift_min_deg, "°"),
        number(figures.damping_ratio, "", 2),
        number(figures.equivalent_damping_Ns_per_m, "N·s/m"),
        judged.outcome.value.upper(),
    )


def _imbalance_row(inspection: AxleInspectionOut, limits: VerdictThresholds) -> tuple[str, ...]:
    """The axle's left/right row: the EUSAMA difference (points, and relative as the verdict judges it)
    and the equivalent damping's difference, as stored."""
    left, right, stored = inspection.left, inspection.right, inspection.imbalance
    eusama, outcome = "—", "CHECK"  # a figure missing is a check, as estimator.verdict judges a corner's
    if left.eusama_percent is not None and right.eusama_percent is not None:
        points = abs(left.eusama_percent - right.eusama_percent)
        relative = relative_difference_percent(left.eusama_percent, right.eusama_percent)
        eusama = f"Δ {number(points, 'points', 2)} ({number(relative, '%', 2)} of the larger)"
        outcome = imbalance_outcome(relative, limits).value.upper()
    damping = stored.damping_difference_percent if stored is not None else None
    return ("left/right", eusama, "—", "—", f"Δ {number(damping, '%', 2)}", outcome)


def limits_text(limits: VerdictThresholds, axle: bool) -> str:
    text = (
        f"least phase angle fails below {limits.phase_fail_below_deg:g}°; EUSAMA passes from "
        f"{limits.eusama_pass_from_percent:g} %, fails below {limits.eusama_fail_below_percent:g} %"
    )
    if axle:
        text += (
            f"; left/right EUSAMA difference: check above {limits.imbalance_check_above_percent:g} %, fail "
            f"above {limits.imbalance_fail_above_percent:g} % of the larger"
        )
    return text


def verdict_section(result: IdentifyResult) -> Section:
    """The verdict per corner (and for the axle's left/right balance), with the thresholds that judged it
    and the lane figures it was judged on."""
    stored = result.verdict.model_dump() if result.verdict is not None else None
    limits, carried = _limits(stored)
    inspection = result.inspection
    if isinstance(inspection, AxleInspectionOut):
        rows = [_corner_figures(side, getattr(inspection, side), limits) for side in ("left", "right")]
        rows.append(_imbalance_row(inspection, limits))
    else:
        rows = [_corner_figures("single", inspection, limits)]
    overall = judge(result.model_dump(mode="json")["inspection"], limits)
    outcome = stored["outcome"] if stored is not None and carried else overall.outcome.value
    reasons = stored["reasons"] if stored is not None and carried else overall.reasons
    origin = (
        f"Judged by the thresholds {limits.version} when the result was stored"
        if carried
        else f"The result carries no verdict: judged here by the default thresholds {limits.version}"
    )
    blocks: list[Block] = [
        Paragraph(f"Verdict: {outcome.upper()}", f"outcome-{outcome}"),  # type: ignore[arg-type]
        Paragraph(f"{origin}: {limits_text(limits, len(rows) > 1)}.", "note"),
        Table(
            tuple(rows),
            ("corner", "EUSAMA", "min. phase angle", "damping ratio", "equivalent damping", "verdict"),
            (1.0, 1.9, 1.2, 1.0, 1.4, 0.8),
        ),
    ]
    blocks += [Paragraph(f"• {reason}") for reason in reasons]
    blocks.append(
        Paragraph(
            "The lane figures are estimated from the measured displacements and the identified model, "
            "not measured on a force plate; the damper curve is the test's own result.",
            "note",
        )
    )
    return Section("Verdict and lane figures", tuple(blocks))


def _origin(name: str, stiffness: Any) -> str:
    return "identified" if stiffness is not None and name in stiffness.identified else "vehicle file"


def estimates_section(result: IdentifyResult) -> Section:
    """The masses, stiffnesses, tyre damping (and a lab rig's frame guides' friction) with their 95% intervals
    and where each comes from."""
    masses, spread = result.masses_kg, result.masses_kg_interval
    stiffness, stiffness_spread = result.stiffness_N_per_m, result.stiffness_N_per_m_interval
    rows = [
        (
            "sprung mass",
            number(masses.sprung, "kg", 4),
            interval(spread.sprung if spread else None, 1, "kg"),
            "identified",
        ),
        (
            "unsprung mass (per wheel)",
            number(masses.unsprung, "kg", 4),
            interval(spread.unsprung if spread else None, 1, "kg"),
            "identified",
        ),
    ]
    names = (("spring", "spring stiffness"), ("tyre", "tyre stiffness"), ("anti_roll_bar", "anti-roll bar"))
    for key, label in names:
        value = getattr(stiffness, key, None) if stiffness is not None else None
        if value is None and key == "anti_roll_bar":
            continue
        pair = getattr(stiffness_spread, key, None) if stiffness_spread is not None else None
        rows.append(
            (
                label,
                number(value / 1e3 if value else None, "kN/m"),
                interval(pair, 1e-3, "kN/m"),
                _origin(key, stiffness),
            )
        )
    rows.append(
        (
            "tyre damping",
            number(result.tyre_damping_Ns_per_m, "N·s/m"),
            interval(result.tyre_damping_Ns_per_m_interval, 1, "N·s/m"),
            "identified",
        )
    )
    effects, effects_spread = result.effects, result.effects_interval or {}
    for name, mass in zip(GUIDE_FRICTION_NAMES, GUIDED_MASSES, strict=True):
        value = getattr(effects, name, None) if effects is not None else None
        if value is not None:  # a lab rig's frame guides (its vehicle file says so)
            pair = effects_spread.get(name)
            rows.append(
                (f"frame guides' friction, {mass}", number(value, "N"), interval(pair, 1, "N"), "identified")
            )
    if result.roll_inertia_kg_m2 is not None:
        rows.append(
            (
                "roll inertia",
                number(result.roll_inertia_kg_m2, "kg·m²"),
                interval(result.roll_inertia_kg_m2_interval, 1, "kg·m²"),
                "identified",
            )
        )
    if result.tyre_relaxation_time_s is not None:
        theta = "identified" if result.tyre_viscoelastic_identified else "vehicle file"
        rows.append(("tyre relaxation time", number(result.tyre_relaxation_time_s * 1e3, "ms"), "—", theta))
    gap = (
        "model diverged when simulated"
        if result.gap_diverged
        else number(result.gap_m * 1e6 if result.gap_m is not None else None, "µm rms")
    )
    blocks: list[Block] = [
        Table(tuple(rows), ("quantity", "value", "95% interval", "from"), (1.6, 1.0, 1.6, 0.9)),
        Paragraph(
            f"Tyre model {result.tyre_model.value}, solver {result.solver.value}; output-error gap {gap} "
            "(the identified model driven by the measured plate, against the measured body and wheel).",
            "note",
        ),
    ]
    return Section("Masses and stiffnesses", tuple(blocks))


def record_section(test: RecordedTest) -> Section:
    pressure = f"{test.tyre_pressure_bar:g} bar" if test.tyre_pressure_bar is not None else None
    rows = (
        ("vehicle id", recorded(test.vehicle_id), "date", recorded(test.date)),
        ("operator", recorded(test.operator), "tyre pressure", recorded(pressure)),
        ("lane", recorded(test.lane), "sweep", recorded(test.sweep_id)),
        ("bench", recorded(test.bench), "identification job", recorded(test.job_id)),
    )
    return Section("Test", (Table(rows, None, (1.0, 2.0, 1.2, 2.0)),))


def doctor_section(source: ReportInput) -> Section:
    if source.diagnosis is None:
        return Section("Model doctor", (Paragraph(f"Model doctor: {source.diagnosis_note}.", "note"),))
    try:
        diagnosis = DiagnoseResult.model_validate(source.diagnosis)
    except ValidationError:
        return Section(
            "Model doctor", (Paragraph("Model doctor: its stored result cannot be read.", "note"),)
        )

    def micro(value: float | None) -> str:
        return "diverged" if value is None else number(value * 1e6, "µm")

    job = f" (job {source.diagnosis_job_id})" if source.diagnosis_job_id is not None else ""
    verdict = fit_verdict(diagnosis.p_value, diagnosis.alpha, diagnosis.unexplained, diagnosis.where)
    blocks: list[Block] = [
        Paragraph(f"Conclusion{job}: {diagnosis.conclusion}"),
        Paragraph(
            f"Gap before {micro(diagnosis.gap_before_m)}, after {micro(diagnosis.gap_after_m)}; the final "
            f"model on synthetic recordings of itself reaches {micro(diagnosis.expected_gap_m)}. Goodness "
            f"of fit: {verdict}. Final model: "
            f"{', '.join(diagnosis.final_effects) or 'the vehicle file with a spring tyre'}.",
            "note",
        ),
    ]
    if diagnosis.steps:
        rows = tuple(
            (str(n), step.effect, micro(step.gap_after_m), step.evidence, shape(step.effect, step.parameters))
            for n, step in enumerate(diagnosis.steps, start=1)
        )
        header = ("step", "effect added", "gap after", "evidence", "fitted shape")
        blocks.append(Table(rows, header, (0.4, 1.2, 0.9, 2.2, 2.2)))
    return Section("Model doctor", tuple(blocks))


def chain_section(source: ReportInput) -> Section:
    chain = source.chain
    if chain is None:
        return Section("Hash-chain record", (Paragraph(f"Hash-chain record: {source.chain_note}.", "note"),))
    rows = (
        ("lane", recorded(chain.lane)),
        ("sequence", recorded(chain.sequence)),
        ("job", str(chain.job_id)),
        ("result hash", chain.hash),
    )
    verify = f"shockbench verify --lane {chain.lane}" if chain.lane else "shockbench verify"
    return Section(
        "Hash-chain record",
        (
            Table(rows, None, (1.0, 4.0)),
            Paragraph(
                f"Link {recorded(chain.sequence)} of lane {recorded(chain.lane)}'s chain holds this result; "
                f"`{verify}` checks that the stored result still matches it.",
                "note",
            ),
        ),
    )


def _band(source: ReportInput) -> tuple[float, float] | None:
    meta = source.recording.metadata if source.recording is not None else {}
    try:
        return float(meta["sweep_start_Hz"]), float(meta["sweep_stop_Hz"])
    except (KeyError, ValueError):
        return None


def build_report(source: ReportInput) -> ReportContent:
    """The sheet for `source` (ReportInputError when its result is not an identification's)."""
    result = identify_result(source.result)
    axle = isinstance(result.inspection, AxleInspectionOut)
    curve = Plot(
        "curves",
        "Damper force over suspension velocity: identified points with their 95% band and the tanh fit"
        + (", left and right overlaid" if axle else ""),
        3.3,
    )
    sweep: tuple[Block, ...] = (
        Paragraph(f"Sweep over time and transmissibility: {source.recording_note}.", "note"),
    )
    if source.recording is not None:
        sides = 2 if axle else 1
        sweep = (
            Plot(
                "sweep", "The sweep over time: plate, wheel and body displacement", 1.5 + 1.1 * sides, sides
            ),
            Plot(
                "transmissibility", "Transmissibility: wheel and body over plate amplitude, by frequency", 2.4
            ),
        )
    sections = [
        record_section(source.test),
        verdict_section(result),
        Section("Damper curve", (curve,)),
        estimates_section(result),
        Section("The sweep", sweep),
        doctor_section(source),
        chain_section(source),
    ]
    if result.warnings:
        sections.append(Section("Warnings", tuple(Paragraph(f"• {w}") for w in result.warnings)))
    vehicle = source.test.vehicle_id
    what = [f"sweep {source.test.sweep_id}" if source.test.sweep_id is not None else None]
    what.append(f"job {source.test.job_id}" if source.test.job_id is not None else None)
    named = ", ".join(w for w in what if w)
    return ReportContent(
        title="Shock absorber test" + (f": vehicle {vehicle}" if vehicle else ""),
        subtitle=("axle" if axle else "quarter car") + (f"; {named}" if named else ""),
        sections=tuple(sections),
        curves=tuple(result.curves),
        recording=source.recording,
        sweep_band_Hz=_band(source),
        footer=f"shockbench {source.software}".rstrip() + (f" — {named}" if named else ""),
    )
