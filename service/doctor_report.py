"""The model doctor's report: Markdown with PNG plots in one folder, every file written atomically.

Contents: the conclusion; the gap before and after each step (plot and table); per step the effect, its
fitted parameters, the gap before and after and the evidence in words; measured-versus-simulated overlays
of the starting and the final model; the output-error residual's spectra and its RMS per band of the sweep
before and after each step; where the starting model disagrees (residual against suspension velocity,
deflection and tyre deflection); the fitted spring curve when spring_curve was named; the goodness-of-fit
test (p-value, and where the final model disagrees when unexplained); every candidate's tests per round;
the catalog.
"""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from daq.formats.atomic import atomic_write
from estimator.doctor.catalog import CATALOG, EffectName
from estimator.doctor.parameters import spring_curve_points
from estimator.doctor.residuals import Localisation
from estimator.doctor.result import DiagnosisResult
from service.doctor_words import fit_verdict, micrometres, shape

REPORT_NAME = "report.md"
ZOOM_S = 0.6


def _save(fig: plt.Figure, path: Path) -> str:
    buffer = io.BytesIO()
    try:
        fig.savefig(buffer, format="png", dpi=110)
    finally:
        plt.close(fig)
    with atomic_write(path, "wb") as handle:
        handle.write(buffer.getvalue())
    return path.name


def _stages(result: DiagnosisResult) -> list[tuple[str, dict[str, np.ndarray], Localisation, float]]:
    """(label, predicted readings, localisation, gap) of the starting model and after each step."""
    stages = [("starting model", result.predicted_before, result.located_before, result.gap_before_m)]
    for number, step in enumerate(result.steps, start=1):
        stages.append(
            (
                f"after step {number} (+{step.effect})",
                step.predicted_after,
                step.located_after,
                step.gap_after_m,
            )
        )
    return stages


def gap_figure(result: DiagnosisResult) -> plt.Figure:
    stages = _stages(result)
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    gaps = [g * 1e6 if np.isfinite(g) else np.nan for *_, g in stages]
    labels = [label.replace(" (", "\n(") for label, *_ in stages]
    finite = [g for g in gaps if np.isfinite(g) and g > 0]
    floor = min(finite) if finite else 1.0
    ax.bar(range(len(gaps)), np.nan_to_num(gaps), color=["tab:red"] + ["tab:blue"] * (len(gaps) - 1))
    for k, g in enumerate(gaps):
        label = "diverged" if np.isnan(g) else f"{g:.1f}"
        ax.text(k, floor if np.isnan(g) else g, label, ha="center", va="bottom", fontsize=8)
    if np.isfinite(result.expected_gap_m):
        ax.axhline(result.expected_gap_m * 1e6, color="0.3", ls="--", lw=1, label="final model's own draws")
    ax.axhline(result.noise_floor_m * 1e6, color="0.6", ls=":", lw=1, label="sensor noise")
    if finite and max(finite) > 20 * min(finite):
        ax.set_yscale("log")  # a gap that falls a hundredfold stays readable
    ax.set_xticks(range(len(gaps)), labels, fontsize=8)
    ax.set_ylabel("gap: RMS of simulated − measured (µm)")
    ax.set_title("Gap before and after each step")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def overlay_figure(result: DiagnosisResult) -> plt.Figure:
    """Per channel: measured, starting model and final model over the recording, and a zoom where the
    starting model is furthest off."""
    channels = list(result.measured)
    fig, axes = plt.subplots(len(channels), 2, figsize=(11.0, 2.4 * len(channels)), squeeze=False)
    t = result.time_s
    final = result.predicted_after
    for row, name in enumerate(channels):
        measured = result.measured[name] * 1e3
        before = result.predicted_before[name] * 1e3
        after = final[name] * 1e3
        worst = int(np.nanargmax(np.abs(np.nan_to_num(before - measured, nan=0.0, posinf=0.0, neginf=0.0))))
        zoom = (t >= t[worst] - ZOOM_S / 2) & (t <= t[worst] + ZOOM_S / 2)
        for ax, mask in ((axes[row, 0], slice(None)), (axes[row, 1], zoom)):
            ax.plot(t[mask], measured[mask], color="k", lw=0.8, label="measured")
            ax.plot(t[mask], before[mask], color="tab:red", lw=0.8, label="starting model")
            if result.steps:
                ax.plot(t[mask], after[mask], color="tab:blue", lw=0.8, ls="--", label="final model")
            ax.set_ylabel(f"{name} (mm)")
            ax.grid(True, alpha=0.3)
        axes[row, 1].set_title(
            f"zoom where the starting model is furthest off ({t[worst]:.2f} s)", fontsize=8
        )
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    fig.suptitle("Measured and simulated (model driven by the measured plate)")
    fig.tight_layout()
    return fig


def spectra_figure(result: DiagnosisResult) -> plt.Figure:
    """Output-error residual: power density and RMS per band of the sweep, per channel, before and after
    each step."""
    stages = _stages(result)
    channels = list(result.measured)
    fig, axes = plt.subplots(len(channels), 2, figsize=(11.0, 2.6 * len(channels)), squeeze=False)
    colours = plt.cm.viridis(np.linspace(0.0, 0.85, len(stages)))
    for row, name in enumerate(channels):
        for (label, _, located, _), colour in zip(stages, colours, strict=True):
            if name in located.spectra:
                f, p = located.spectra[name]
                axes[row, 0].semilogy(f, p, color=colour, lw=0.9, label=label)
            bands = located.output_bands
            if name in bands.values:
                centres = 0.5 * (bands.edges[:-1] + bands.edges[1:])
                axes[row, 1].plot(centres, bands.values[name] * 1e6, "o-", color=colour, ms=3, label=label)
        axes[row, 0].set_xlim(0, 60)
        axes[row, 0].set_ylabel(f"{name}: m²/Hz")
        axes[row, 1].set_ylabel(f"{name}: RMS (µm)")
        for ax in axes[row]:
            ax.grid(True, alpha=0.3)
    axes[0, 0].set_title("residual spectrum", fontsize=9)
    axes[0, 1].set_title("residual by band of the sweep", fontsize=9)
    axes[0, 1].legend(fontsize=7)
    axes[-1, 0].set_xlabel("frequency (Hz)")
    axes[-1, 1].set_xlabel("sweep frequency (Hz)")
    fig.tight_layout()
    return fig


def spring_figure(result: DiagnosisResult) -> plt.Figure | None:
    """The final model's suspension spring force against deflection beside the stated rate's line, when
    the diagnosis named spring_curve (None otherwise)."""
    model = result.final_model
    if model is None or EffectName.SPRING_CURVE.value not in model.structure.labels:
        return None
    deflection, force = spring_curve_points(model)
    stated = float(model.vehicle.spring_stiffness_N_per_m or 0.0) * deflection
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    ax.plot(deflection * 1e3, force, "o-", color="tab:blue", label="fitted spring curve")
    ax.plot(deflection * 1e3, stated, "--", color="0.4", label="stated rate")
    for knot in model.knots_m:
        ax.axvline(knot * 1e3, color="0.8", lw=0.8)
    ax.set_xlabel("suspension deflection (mm, extension > 0)")
    ax.set_ylabel("spring force change from static (N)")
    ax.set_title("Suspension spring curve (knots: grey lines)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _p(value: float | None) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.2g}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    clean = [[c.replace("|", "/").replace("\n", " ") for c in row] for row in rows]
    return [
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
        *["| " + " | ".join(r) + " |" for r in clean],
    ]


def _locate_lines(located: Localisation) -> list[str]:
    lines = [located.describe(), ""]
    rows = []
    for profile in located.by_variable:
        for equation, values in profile.values.items():
            scale = 1e3 if profile.unit == "m" else 1.0
            unit = "mm" if profile.unit == "m" else profile.unit
            cells = [
                f"{lo * scale:+.3g}..{hi * scale:+.3g}: {v:.1f}"
                for lo, hi, v in zip(profile.edges[:-1], profile.edges[1:], values, strict=True)
            ]
            rows.append([f"{profile.variable} ({unit})", equation, "; ".join(cells)])
    lines += _table(["binned by", "equation", "residual RMS (N) per bin"], rows)
    return lines


def markdown(result: DiagnosisResult, title: str, images: dict[str, str]) -> str:
    lines = [f"# Model doctor: {title}", "", f"**{result.conclusion}**", ""]
    lines += [
        f"Starting model: {', '.join(result.starting_effects) or 'the vehicle file with a spring tyre'}; "
        f"final model: {', '.join(result.final_effects) or 'the same'}. "
        f"Gap before {micrometres(result.gap_before_m)}, "
        f"after {micrometres(result.gap_after_m)}; sensor noise {micrometres(result.noise_floor_m)}. "
        f"Unexplained: {'yes' if result.unexplained else 'no'}.",
        "",
        f"Goodness of fit of the final model against {micrometres(result.expected_gap_m)}, the mean gap of "
        f"itself re-identified on synthetic recordings with this recording's noise: "
        f"{fit_verdict(result.p_value, result.alpha, result.unexplained, result.where)}.",
        "",
        f"![gap per step]({images['gap']})",
        "",
        "## Steps",
        "",
    ]
    rows = [
        [
            str(n),
            s.effect,
            shape(s.effect, s.parameters),
            micrometres(s.gap_before_m),
            micrometres(s.gap_after_m),
            _p(s.p_value),
            s.evidence,
        ]
        for n, s in enumerate(result.steps, start=1)
    ]
    lines += (
        _table(["step", "effect", "fitted shape", "gap before", "gap after", "p", "evidence"], rows)
        if rows
        else ["No effect named."]
    )
    if rows:  # a family named early is fitted again beside the later ones: what the model handed out holds
        final = [[name, shape(name, values)] for name, values in result.final_parameters.items()]
        lines += ["", "In the final model, each effect fitted beside the others:", ""]
        lines += _table(["effect", "fitted shape"], final)
    if "spring" in images:
        lines += ["", f"![spring curve]({images['spring']})"]
    lines += ["", "## Measured and simulated", "", f"![overlays]({images['overlay']})", ""]
    lines += ["## Residual spectra before and after", "", f"![residual spectra]({images['spectra']})", ""]
    lines += ["## Where the starting model disagrees", "", *_locate_lines(result.located_before), ""]
    if result.steps:
        lines += ["## Where the final model disagrees", "", *_locate_lines(result.located_after), ""]
    lines += ["## Candidates judged", ""]
    lines += [
        f"Each candidate's p-value is the larger of its two tests' (both must reject); a round names the "
        f"smallest when it is at most α/m, m the candidates tested (α = {result.alpha:g}).",
        "",
    ]
    for number, round_ in enumerate(result.rounds, start=1):
        lines += [f"Round {number}:", ""]
        rows = [
            [
                c.effect,
                str(c.unknowns),
                f"{c.equation_statistic:.1f} (p {_p(c.equation_p)})",
                "-" if c.gap_m is None else micrometres(c.gap_m),
                "-" if c.gap_m is None else f"{c.simulation_statistic:.1f} (p {_p(c.simulation_p)})",
                _p(c.p_value),
                c.verdict,
            ]
            for c in round_
        ]
        header = ["candidate", "unknowns", "Wald (equations)", "gap", "likelihood ratio (gap)", "p"]
        lines += _table([*header, "verdict"], rows)
        lines.append("")
    lines += ["## Catalog", ""]
    lines += _table(
        ["effect", "what it is", "signature when missing"],
        [[e.name.value, e.summary, e.signature] for e in CATALOG.values()],
    )
    return "\n".join(lines) + "\n"


def write_report(result: DiagnosisResult, folder: Path | str, title: str = "diagnosis") -> Path:
    """Write report.md and its PNG plots into `folder` (created if missing); returns the report's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    images = {
        "gap": _save(gap_figure(result), folder / "gap_per_step.png"),
        "overlay": _save(overlay_figure(result), folder / "measured_vs_simulated.png"),
        "spectra": _save(spectra_figure(result), folder / "residual_spectra.png"),
    }
    spring = spring_figure(result)
    if spring is not None:
        images["spring"] = _save(spring, folder / "spring_curve.png")
    path = folder / REPORT_NAME
    with atomic_write(path, "w") as handle:
        handle.write(markdown(result, title, images))
    return path
