// Start a test: the vehicle (mass-only form or pasted TOML), the test's record (vehicle id, tyre pressure,
// operator) and the sweep settings, checked by the API; its field errors are shown beside the field.

import { ApiFailure, api } from "./api.js";
import { can } from "./roles.js";

const $ = (id) => document.getElementById(id);

/** The vehicle file written from the form: model and mass (and track for an axle). */
export function vehicleToml({ model, mass, track }) {
  const lines = ["[vehicle]", `model = "${model}"`, `mass_kg = ${mass}`];
  if (model === "axle") lines.push(`track_m = ${track}`);
  return lines.join("\n") + "\n";
}

function numberOrNull(id) {
  const text = $(id).value.trim();
  return text === "" ? null : Number(text);
}

function textOrNull(id) {
  const text = $(id).value.trim();
  return text === "" ? null : text;
}

/** The POST /sweeps body from the form (without values left empty, so that the API's defaults apply). */
export function sweepBody() {
  const fromToml = $("vehicle-source-toml").checked;
  const body = {
    vehicle_toml: fromToml
      ? $("vehicle-toml").value
      : vehicleToml({ model: $("vehicle-model").value, mass: $("mass-kg").value.trim(),
          track: $("track-m").value.trim() }),
    vehicle_id: textOrNull("vehicle-id"),
    tyre_pressure_bar: numberOrNull("tyre-pressure"),
    operator_name: textOrNull("operator-name"),
    start_Hz: numberOrNull("start-hz"),
    stop_Hz: numberOrNull("stop-hz"),
    amplitude_m: numberOrNull("amplitude-mm") === null ? null : numberOrNull("amplitude-mm") / 1000,
    duration_s: numberOrNull("duration-s"),
    settle_s: numberOrNull("settle-s"),
    law: $("law").value,
  };
  return Object.fromEntries(Object.entries(body).filter(([, value]) => value !== null));
}

/** The form's inputs by the API field they send. */
function inputForField(field) {
  if (!field) return null;
  const name = field.split(".")[0];
  if (name === "vehicle_toml" && !$("vehicle-source-toml").checked) return $("mass-kg");
  return document.querySelector(`#start-form [data-field="${name}"]`);
}

export function clearErrors() {
  for (const node of document.querySelectorAll("#start-form .field-error")) node.textContent = "";
  for (const node of document.querySelectorAll("#start-form [aria-invalid]")) node.removeAttribute("aria-invalid");
  $("start-error").textContent = "";
}

/** Show an API error beside the input it names, else at the top of the form. */
export function showError(error) {
  const input = error instanceof ApiFailure ? inputForField(error.field) : null;
  if (input) {
    input.setAttribute("aria-invalid", "true");
    $(input.getAttribute("aria-describedby")).textContent = error.message;
    input.focus();
  } else {
    $("start-error").textContent = error.message;
  }
}

function syncVehicleSource() {
  const fromToml = $("vehicle-source-toml").checked;
  $("vehicle-form-fields").hidden = fromToml;
  $("vehicle-toml-fields").hidden = !fromToml;
  $("track-field").hidden = $("vehicle-model").value !== "axle";
}

/** Wire the form: `onStarted(sweep, body)` after the API accepted the sweep. */
export function initStartForm(onStarted) {
  for (const id of ["vehicle-source-form", "vehicle-source-toml", "vehicle-model"]) {
    $(id).addEventListener("change", syncVehicleSource);
  }
  syncVehicleSource();
  $("start-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    if (!can("operator")) return;
    clearErrors();
    const button = $("start-sweep");
    button.disabled = true;
    const body = sweepBody();
    try {
      const sweep = await api("/sweeps", { method: "POST", body });
      onStarted(sweep, body);
    } catch (error) {
      showError(error);
    } finally {
      button.disabled = !can("operator");
    }
  });
}
