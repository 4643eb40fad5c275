// The operator page: sign-in, the bench (state, devices, emergency stop), the live sweep, and the flow from
// a finished sweep to its result. The other parts live in their modules (form, live, result, history).

import { ApiFailure, api, forgetKey, pause, storeKey, storedKey } from "./api.js";
import { initStartForm } from "./form.js";
import { initHistory, loadHistory, loadSchedules } from "./history.js";
import { BenchFeed, LiveChart } from "./live.js";
import { can, setRole } from "./roles.js";
import { showPending, showResult } from "./result.js";

const $ = (id) => document.getElementById(id);

const page = {
  feed: null,
  chart: null,
  following: null, // the sweep id the live view shows
  startedHere: new Set(), // sweeps this tab started: it submits their identification
  opening: 0, // the latest result request; an older one that answers late is dropped
  statusTimer: null, // refreshes the lane's sync state
};

const STATUS_REFRESH_MS = 5000;

// ---- sign-in ---------------------------------------------------------------------------------------------

async function signIn(key) {
  storeKey(key);
  try {
    const me = await api("/whoami");
    enter(me);
  } catch (error) {
    forgetKey();
    $("login-error").textContent =
      error.status === 401 ? "This key is not valid for this service." : `Cannot sign in: ${error.message}`;
    $("login-key").setAttribute("aria-invalid", "true");
    $("login-key").focus();
  }
}

function enter(me) {
  setRole(me.role);
  $("abort-sweep").disabled = true; // until the bench says a sweep runs
  $("login").hidden = true;
  $("app").hidden = false;
  $("session-actions").hidden = false;
  $("whoami").textContent = me.role;
  $("whoami").title = `key id ${me.key_id}`;
  $("login-key").value = "";
  page.chart = new LiveChart($("live-chart"), $("live-legend"));
  page.feed = new BenchFeed({ onState, onSamples: (s) => page.chart.add(s), onError: feedError });
  loadBench();
  loadStatus();
  page.statusTimer = setInterval(loadStatus, STATUS_REFRESH_MS);
  loadHistory(openSweep);
  loadSchedules();
}

function signOut(message = "signed out") {
  page.feed?.stop();
  page.feed = null;
  clearInterval(page.statusTimer);
  page.statusTimer = null;
  forgetKey();
  setRole(null);
  $("app").hidden = true;
  $("session-actions").hidden = true;
  $("login").hidden = false;
  $("bench-status").textContent = message;
  $("login-key").focus();
}

function feedError(error) {
  if (error instanceof ApiFailure && error.status === 401) signOut("the key is no longer valid: sign in again");
  else $("bench-status").textContent = `bench: ${error.message} (reconnecting)`;
}

// ---- the bench -------------------------------------------------------------------------------------------

async function loadBench() {
  try {
    const bench = await api("/bench");
    $("bench-name").textContent = `${bench.name}${bench.simulated ? " (simulated)" : ""}`;
    $("bench-model").textContent = bench.model;
    onState({ busy: bench.busy, sweep_id: bench.sweep_id, progress: bench.progress });
    const { devices } = await api("/bench/devices");
    renderDevices(devices);
  } catch (error) {
    $("bench-name").textContent = error.message;
  }
}

/** The service's lane, and where its results go: its own database, or a central one it syncs to (with the
 * backlog waiting while that database is away). */
async function loadStatus() {
  try {
    const status = await api("/status");
    $("bench-lane").textContent = status.lane;
    $("bench-sync").textContent = syncText(status.sync);
  } catch (error) {
    $("bench-sync").textContent = `unknown: ${error.message}`;
  }
}

function syncText(sync) {
  if (!sync) return "none: results stay in this lane's database";
  const waiting = `${sync.backlog} result${sync.backlog === 1 ? "" : "s"} waiting to sync`;
  if (sync.reachable === null) return `connecting; ${waiting}`;
  if (sync.reachable) return `reachable; ${waiting}`;
  return `away: results are kept here; ${waiting}${sync.last_error ? ` (${sync.last_error})` : ""}`;
}

/** The phases the followed sweep went through, in data-phases (a short phase may pass between looks). */
function notePhase(phase) {
  const seen = $("sweep-progress").dataset;
  const phases = (seen.phases ?? "").split(" ").filter(Boolean);
  if (!phases.includes(phase)) seen.phases = [...phases, phase].join(" ");
}

/** Each configured device and its state in words (the live stream's `state` events carry them too). */
function renderDevices(devices) {
  $("devices").replaceChildren(...devices.map((d) => {
    const item = document.createElement("li");
    const where = [d.channel, d.head].filter(Boolean).join(", ");
    item.textContent = `${d.name}: ${d.kind}${where ? ` (${where})` : ""} — ${d.url}`;
    if (d.state) {
      const state = document.createElement("div");
      state.className = "device-state";
      state.dataset.testid = "device-state";
      state.textContent = d.state;
      item.append(state);
    }
    return item;
  }));
}

function onState({ busy, sweep_id: sweepId, progress, devices }) {
  if (devices && devices.length) renderDevices(devices);
  const moving = busy && progress && progress.phase !== "done";
  $("bench-status").textContent = busy
    ? `Bench busy: sweep ${sweepId ?? "?"}${progress ? `, ${progress.phase}` : ""}`
    : "Bench idle: the plate is at rest";
  $("plate-state").textContent = moving ? `moving (${progress.phase})` : busy ? "busy" : "at rest";
  $("running-sweep").textContent = sweepId ? `sweep ${sweepId}` : "none";
  document.body.classList.toggle("plate-moving", Boolean(busy));
  $("abort-sweep").disabled = !(busy && sweepId && can("operator"));
  if (busy && sweepId && sweepId !== page.following) {
    page.following = sweepId;
    page.chart.clear(sweepId);
    $("sweep-progress").dataset.phases = "";
  }
  if (progress) {
    notePhase(progress.phase);
    $("progress-bar").value = progress.fraction;
    $("progress-phase").textContent = progress.phase;
    $("progress-elapsed").textContent = `${progress.elapsed_s.toFixed(1)} s of ${progress.total_s.toFixed(1)} s`;
    $("progress-frequency").textContent = `${progress.frequency_Hz.toFixed(2)} Hz`;
  }
  if (!busy && page.following !== null) {
    const ended = page.following;
    page.following = null;
    $("progress-phase").textContent = "ended";
    sweepEnded(ended);
  }
}

async function emergencyStop() {
  const status = $("estop-status");
  status.textContent = "stopping…";
  try {
    const answer = await api("/emergency-stop", { method: "POST" });
    status.textContent = `Stopped: ${answer.done}`;
  } catch (error) {
    status.textContent = `EMERGENCY STOP FAILED: ${error.message}`;
  }
}

async function abortSweep() {
  const id = page.following;
  if (!id) return;
  try {
    await api(`/sweeps/${id}/abort`, { method: "POST" });
  } catch (error) {
    $("bench-status").textContent = `stop test ${id}: ${error.message}`;
  }
}

// ---- from a sweep to its result --------------------------------------------------------------------------

function sweepStarted(sweep) {
  page.startedHere.add(sweep.id);
  $("result-status").textContent = "";
  $("bench-status").textContent = `Sweep ${sweep.id} requested`;
  loadHistory(openSweep);
}

async function sweepEnded(id) {
  loadHistory(openSweep);
  await openSweep({ id }, { identify: page.startedHere.has(id) && can("operator") });
}

/** Open the result of a sweep (a history row, or the sweep that just ended). */
async function openSweep({ id }, { identify = false } = {}) {
  const ticket = ++page.opening;
  const current = () => ticket === page.opening;
  const status = $("result-status");
  const identifyButton = $("identify-sweep");
  identifyButton.hidden = true;
  try {
    let sweep = await api(`/sweeps/${id}`);
    if (!current()) return;
    if (sweep.status !== "complete") {
      showPending(sweep, `Sweep ${id} ${sweep.status}${sweep.reason ? `: ${sweep.reason}` : ""}; no result.`);
      return;
    }
    let jobId = sweep.latest_job_id;
    for (let look = 0; jobId === null && !identify && look < 10; look += 1) {
      // a sweep another client started (the line's scheduler) gets its job from that client: a moment
      await pause(500);
      sweep = await api(`/sweeps/${id}`);
      if (!current()) return;
      jobId = sweep.latest_job_id;
    }
    if (jobId === null && identify) {
      status.textContent = `identifying sweep ${id}…`;
      jobId = (await api(`/sweeps/${id}/jobs`, { method: "POST", body: {} })).id;
    }
    if (jobId === null) {
      showPending(sweep, `Sweep ${id} is complete and not identified yet.`);
      identifyButton.hidden = !can("operator");
      identifyButton.onclick = () => openSweep({ id }, { identify: true });
      return;
    }
    showPending(sweep, `Identifying sweep ${id}…`);
    for (;;) {
      const job = await api(`/jobs/${jobId}`);
      if (!current()) return;
      if (job.status === "succeeded") {
        sweep = await api(`/sweeps/${id}`);
        status.textContent = `identified by job ${job.id}`;
        showResult(sweep, job);
        $("result").scrollIntoView({ block: "start" });
        return;
      }
      if (job.status === "failed" || job.status === "cancelled") {
        showPending(sweep, `Identification ${job.id} ${job.status}: ${job.error ?? ""}`);
        return;
      }
      const step = job.progress ? ` (${Math.round(100 * (job.progress.fraction ?? 0))}%)` : "";
      status.textContent = `identification ${job.id}: ${job.status}${step}`;
      await pause(500);
    }
  } catch (error) {
    if (current()) status.textContent = `sweep ${id}: ${error.message}`;
  }
}

// ---- start -----------------------------------------------------------------------------------------------

function init() {
  $("login-form").addEventListener("submit", (event) => {
    event.preventDefault();
    $("login-error").textContent = "";
    $("login-key").removeAttribute("aria-invalid");
    signIn($("login-key").value.trim());
  });
  $("logout").addEventListener("click", () => signOut());
  $("emergency-stop").addEventListener("click", emergencyStop);
  $("abort-sweep").addEventListener("click", abortSweep);
  initStartForm(sweepStarted);
  initHistory(openSweep);
  if (storedKey()) signIn(storedKey());
  else $("login-key").focus();
}

init();
