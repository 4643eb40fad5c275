// The result of a test: the curve(s) (the product's own result), the model figures, the lane figures
// (estimates, kept apart), the verdict, the downloads and the model doctor's report.

import { api, download, fetchBlob, waitForJob } from "./api.js";
import { can } from "./roles.js";
import { curveSvg } from "./curve.js";

const $ = (id) => document.getElementById(id);

/** A number with `digits` significant digits and its unit, or "—" when there is none. */
export function fmt(value, unit = "", digits = 3) {
  if (value === null || value === undefined || !Number.isFinite(value)) return "—";
  const text = Math.abs(value) >= 10 ** digits ? value.toFixed(0) : Number(value.toPrecision(digits)).toString();
  return unit ? `${text} ${unit}` : text;
}

function interval(pair, scale = 1, unit = "") {
  return pair ? ` (95%: ${fmt(pair[0] * scale)}–${fmt(pair[1] * scale, unit)})` : "";
}

function rows(table, entries) {
  table.replaceChildren();
  for (const [label, value] of entries) {
    const row = table.insertRow();
    const th = document.createElement("th");
    th.scope = "row";
    th.textContent = label;
    row.append(th);
    row.insertCell().textContent = value;
  }
}

function modelFigures(result) {
  const stiffness = result.stiffness_N_per_m ?? {};
  const found = new Set(stiffness.identified ?? []);
  const stiffnessInterval = result.stiffness_N_per_m_interval ?? {};
  const tag = (name) => (found.has(name) ? " (identified)" : " (vehicle file)");
  const entries = [
    ["Sprung mass", fmt(result.masses_kg.sprung, "kg") + interval(result.masses_kg_interval?.sprung, 1, "kg")],
    ["Unsprung mass (per wheel)",
      fmt(result.masses_kg.unsprung, "kg") + interval(result.masses_kg_interval?.unsprung, 1, "kg")],
    ["Spring stiffness",
      fmt(stiffness.spring / 1000, "kN/m") + tag("spring") + interval(stiffnessInterval.spring, 1e-3, "kN/m")],
    ["Tyre stiffness",
      fmt(stiffness.tyre / 1000, "kN/m") + tag("tyre") + interval(stiffnessInterval.tyre, 1e-3, "kN/m")],
  ];
  if (stiffness.anti_roll_bar !== undefined && stiffness.anti_roll_bar !== null) {
    entries.push(["Anti-roll bar", fmt(stiffness.anti_roll_bar / 1000, "kN/m") + tag("anti_roll_bar")]);
  }
  entries.push(
    ["Tyre damping", fmt(result.tyre_damping_Ns_per_m, "N·s/m") +
      interval(result.tyre_damping_Ns_per_m_interval, 1, "N·s/m")],
    ...guideFigures(result),
    ["Tyre model", result.tyre_model],
    ["Output-error gap", result.gap_diverged ? "model diverged when simulated" : fmt(result.gap_m * 1000, "mm rms")],
  );
  if (result.certified_gap !== null && result.certified_gap !== undefined) {
    entries.push(["Certified optimality gap", fmt(result.certified_gap * 100, "%", 2)]);
  }
  return entries;
}

/** A lab rig's frame guides' friction on the body and on the wheel, where identify fitted it (its vehicle
 * file says `frame_guides = true`; the result's `effects` then holds both). */
function guideFigures(result) {
  const effects = result.effects ?? {};
  const spread = result.effects_interval ?? {};
  return [["body", "guide_body_friction_N"], ["wheel", "guide_wheel_friction_N"]]
    .filter(([, key]) => effects[key] !== undefined && effects[key] !== null)
    .map(([mass, key]) => [`Frame guides' friction, ${mass}`,
      fmt(effects[key], "N") + " (identified)" + interval(spread[key], 1, "N")]);
}

function laneFigures(inspection) {
  const corner = (label, figures) => [
    [`EUSAMA${label}`, fmt(figures.eusama_percent, "%")],
    [`Minimum phase angle${label}`, fmt(figures.phase_shift_min_deg, "°")],
    [`Damping ratio${label}`, fmt(figures.damping_ratio, "", 2)],
  ];
  if (!inspection.left) return { eusama: fmt(inspection.eusama_percent, "%"), entries: corner("", inspection) };
  const imbalance = inspection.imbalance ?? {};
  return {
    eusama: `left ${fmt(inspection.left.eusama_percent, "%")}, right ${fmt(inspection.right.eusama_percent, "%")}`,
    entries: [
      ...corner(" left", inspection.left),
      ...corner(" right", inspection.right),
      ["Left/right EUSAMA difference", fmt(imbalance.eusama_difference_points, "points")],
      ["Left/right damping difference", fmt(imbalance.damping_difference_percent, "%")],
    ],
  };
}

function showVerdict(verdict) {
  const box = $("verdict");
  const outcome = verdict?.outcome ?? "none";
  box.dataset.outcome = outcome;
  $("verdict-outcome").textContent = verdict ? outcome.toUpperCase() : "no verdict (figures missing)";
  $("verdict-version").textContent = verdict ? `thresholds ${verdict.thresholds_version}` : "";
  const reasons = $("verdict-reasons");
  reasons.replaceChildren(...(verdict?.reasons ?? []).map((text) => {
    const item = document.createElement("li");
    item.textContent = text;
    return item;
  }));
}

/** The test's record in words: tyre pressure, operator, sweep settings (the title names the vehicle, the
 * history says when). */
function record(sweep) {
  const test = sweep.test ?? {};
  const settings = sweep.settings ?? {};
  const parts = [
    test.tyre_pressure_bar ? `tyre pressure ${test.tyre_pressure_bar} bar` : null,
    test.operator_name ? `operator ${test.operator_name}` : null,
    settings.duration_s ? `sweep ${settings.start_Hz}-${settings.stop_Hz} Hz over ${settings.duration_s} s, ` +
      `±${fmt(settings.amplitude_m * 1000, "mm", 2)}` : null,
  ];
  return parts.filter(Boolean).join("; ");
}

/** The result view for `sweep` and its succeeded identify `job`. */
export function showResult(sweep, job) {
  const result = job.result;
  $("result").hidden = false;
  $("result-title").textContent = `Result of sweep ${sweep.id}` +
    (sweep.test?.vehicle_id ? ` — vehicle ${sweep.test.vehicle_id}` : "");
  $("result-record").textContent = record(sweep);
  $("result-curves").replaceChildren(...result.curves.map(curveSvg));
  rows($("model-figures"), modelFigures(result));
  const lane = laneFigures(result.inspection);
  $("eusama-value").textContent = lane.eusama;
  rows($("lane-figures"), lane.entries);
  showVerdict(result.verdict ?? null);
  const warnings = $("result-warnings");
  warnings.replaceChildren(...(result.warnings ?? []).map((text) => {
    const item = document.createElement("li");
    item.textContent = text;
    return item;
  }));
  wireDownloads(sweep, job);
  $("doctor-report").hidden = true;
  $("doctor-status").textContent = "";
  $("run-doctor").onclick = () => runDoctor(sweep);
}

/** Show that the result of `sweep` is not (yet) there, with why. */
export function showPending(sweep, message) {
  $("result").hidden = false;
  $("result-title").textContent = `Sweep ${sweep.id}`;
  $("result-record").textContent = record(sweep);
  $("result-curves").replaceChildren(Object.assign(document.createElement("p"), { textContent: message }));
  rows($("model-figures"), []);
  rows($("lane-figures"), []);
  $("eusama-value").textContent = "—";
  showVerdict(null);
  $("verdict-outcome").textContent = "—";
}

function wireDownloads(sweep, job) {
  const report = $("open-report");
  report.disabled = !sweep.links.report_pdf;
  report.onclick = () => openReport(sweep.links.report_pdf, `sweep-${sweep.id}-report.pdf`);
  const links = {
    "dl-report-html": [sweep.links.report_html, `sweep-${sweep.id}-report.html`],
    "dl-csv": [sweep.links.recording_csv, `sweep-${sweep.id}.csv`],
    "dl-h5": [sweep.links.recording_h5 ?? `${sweep.links.self}/recording.h5`, `sweep-${sweep.id}.h5`],
    "dl-json": [job.links.self, `job-${job.id}.json`],
    "dl-png": [job.links.plot_png, `job-${job.id}.png`],
    "dl-svg": [job.links.plot_svg, `job-${job.id}.svg`],
  };
  for (const [id, [link, name]] of Object.entries(links)) {
    const button = $(id);
    button.disabled = !link;
    button.onclick = async () => {
      $("download-status").textContent = `downloading ${name}…`;
      try {
        await download(link, name);
        $("download-status").textContent = `saved ${name}`;
      } catch (error) {
        $("download-status").textContent = `${name}: ${error.message}`;
      }
    };
  }
}

/** Open the test's report (PDF) in a new tab: fetched with the key (a link could not send it), shown
 * from an object URL. The tab is opened at the click, so that a popup blocker lets it through; when it is
 * blocked all the same, the report is saved instead. */
async function openReport(link, filename) {
  const status = $("download-status");
  const tab = window.open("", "_blank");
  status.textContent = "preparing the report…";
  try {
    if (!tab) {
      await download(link, filename);
      status.textContent = `saved ${filename} (the new tab was blocked)`;
      return;
    }
    const url = URL.createObjectURL(await fetchBlob(link));
    tab.location.href = url;
    status.textContent = "report opened in a new tab";
    setTimeout(() => URL.revokeObjectURL(url), 60_000);
  } catch (error) {
    tab?.close();
    status.textContent = `report: ${error.message}`;
  }
}

async function runDoctor(sweep) {
  const status = $("doctor-status");
  const button = $("run-doctor");
  button.disabled = true;
  status.textContent = "submitting the diagnosis…";
  try {
    const submitted = await api(`/sweeps/${sweep.id}/diagnoses`, { method: "POST", body: {} });
    const job = await waitForJob(submitted.links.self, (now) => {
      const phase = now.progress ? ` (${now.progress.stage ?? now.progress.phase ?? ""})` : "";
      status.textContent = `diagnosis ${now.id}: ${now.status}${phase}`;
    });
    if (job.status !== "succeeded") throw new Error(`diagnosis ${job.status}: ${job.error ?? ""}`);
    const report = job.links.files?.["report.md"];
    $("doctor-text").textContent = report ? await (await fetchBlob(report)).text() : job.result.conclusion;
    $("doctor-report").hidden = false;
    status.textContent = `diagnosis ${job.id}: ${job.result.conclusion}`;
  } catch (error) {
    status.textContent = `the doctor could not run: ${error.message}`;
  } finally {
    button.disabled = !can("operator");
  }
}
