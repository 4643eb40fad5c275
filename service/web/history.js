// History of tests (sweeps), newest first, filterable by vehicle id, each row opening its result; and the
// inspection line's schedules for admins: list, add, cancel.

import { api } from "./api.js";
import { sweepBody } from "./form.js";
import { can } from "./roles.js";

const $ = (id) => document.getElementById(id);

function when(iso) {
  return iso ? new Date(iso).toLocaleString() : "—";
}

function cell(row, text) {
  row.insertCell().textContent = text ?? "—";
}

/** Load the history into its table; `onOpen(sweep)` when a row is opened (click, Enter or Space). */
export async function loadHistory(onOpen) {
  const filter = $("history-filter").value.trim();
  const query = filter ? `?vehicle_id=${encodeURIComponent(filter)}&limit=50` : "?limit=50";
  const status = $("history-status");
  try {
    const { sweeps, total } = await api(`/sweeps${query}`);
    const body = $("history-body");
    body.replaceChildren();
    for (const sweep of sweeps) {
      const row = body.insertRow();
      row.setAttribute("data-testid", "history-row");
      row.tabIndex = 0;
      row.setAttribute("aria-label", `open the result of sweep ${sweep.id}`);
      cell(row, String(sweep.id));
      cell(row, when(sweep.created_at));
      cell(row, sweep.lane || null);
      cell(row, sweep.test?.vehicle_id);
      cell(row, sweep.test?.operator_name);
      cell(row, sweep.status + (sweep.reason ? ` (${sweep.reason})` : ""));
      row.addEventListener("click", () => onOpen(sweep));
      row.addEventListener("keydown", (event) => {
        if (event.key === "Enter" || event.key === " ") {
          event.preventDefault();
          onOpen(sweep);
        }
      });
    }
    status.textContent = sweeps.length
      ? `${sweeps.length} of ${total} test(s), newest first`
      : filter ? `no test for vehicle ${filter}` : "no test yet";
  } catch (error) {
    status.textContent = `history: ${error.message}`;
  }
}

/** Load the schedules (admins only). */
export async function loadSchedules() {
  if (!can("admin")) return;
  const status = $("schedule-status");
  try {
    const { tests } = await api("/schedules?limit=50");
    const body = $("schedule-body");
    body.replaceChildren();
    for (const test of tests) {
      const row = body.insertRow();
      cell(row, String(test.id));
      cell(row, test.run_at ? when(test.run_at) : "when the bench is free");
      cell(row, test.status + (test.reason ? ` (${test.reason})` : ""));
      cell(row, test.sweep_id ? String(test.sweep_id) : null);
      const actions = row.insertCell();
      if (test.status === "waiting") {
        const button = document.createElement("button");
        button.type = "button";
        button.textContent = `Cancel test ${test.id}`;
        button.addEventListener("click", async () => {
          try {
            await api(test.links.cancel, { method: "POST" });
            status.textContent = `test ${test.id} cancelled`;
          } catch (error) {
            status.textContent = `cancel ${test.id}: ${error.message}`;
          }
          loadSchedules();
        });
        actions.append(button);
      }
    }
    if (!tests.length) status.textContent = "nothing scheduled";
  } catch (error) {
    status.textContent = `schedules: ${error.message}`;
  }
}

/** Schedule the test described in the start form at the chosen time (or when the bench is free). */
async function addSchedule(event) {
  event.preventDefault();
  const status = $("schedule-status");
  const at = $("schedule-at").value;
  const body = sweepBody();
  if (at) body.run_at = new Date(at).toISOString();
  try {
    const test = await api("/schedules", { method: "POST", body });
    status.textContent = `test ${test.id} scheduled`;
  } catch (error) {
    status.textContent = `${error.field ? error.field + ": " : ""}${error.message}`;
  }
  loadSchedules();
}

export function initHistory(onOpen) {
  $("history-form").addEventListener("submit", (event) => {
    event.preventDefault();
    loadHistory(onOpen);
  });
  $("schedule-form").addEventListener("submit", addSchedule);
  $("schedule-refresh").addEventListener("click", loadSchedules);
}
