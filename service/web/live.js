// The live bench: the SSE stream GET /api/v1/bench/live read with fetch + ReadableStream (EventSource cannot
// send the Bearer header), and the live chart of plate, wheel and body drawn on a <canvas>.

import { API, ApiFailure, pause, storedKey } from "./api.js";
import { ticks } from "./axes.js";

const RECONNECT_MS = 1000;

/**
 * Split an SSE byte stream into events. `feed(text)` takes the next chunk and calls `onEvent(name, data)`
 * for every complete event (data parsed as JSON); comment lines (":" keep-alives) are skipped.
 */
export class SseParser {
  constructor(onEvent) {
    this.onEvent = onEvent;
    this.buffer = "";
  }

  feed(text) {
    this.buffer += text.replace(/\r\n?/g, "\n");
    let end;
    while ((end = this.buffer.indexOf("\n\n")) >= 0) {
      const block = this.buffer.slice(0, end);
      this.buffer = this.buffer.slice(end + 2);
      let name = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith(":")) continue;
        const colon = line.indexOf(":");
        const field = colon < 0 ? line : line.slice(0, colon);
        const value = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
        if (field === "event") name = value;
        else if (field === "data") data.push(value);
      }
      if (data.length) this.onEvent(name, JSON.parse(data.join("\n")));
    }
  }
}

/**
 * Follow the bench: `onState({busy, sweep_id, progress})` and `onSamples({sweep_id, t_s, channels})`.
 * Reconnects a second after a dropped stream. `stop()` ends it.
 */
export class BenchFeed {
  constructor({ onState, onSamples, onError }) {
    this.onState = onState;
    this.onSamples = onSamples;
    this.onError = onError ?? (() => {});
    this.controller = new AbortController();
    this.run();
  }

  stop() {
    this.controller.abort(new DOMException("stopped", "AbortError"));
  }

  async run() {
    const signal = this.controller.signal;
    while (!signal.aborted) {
      try {
        await this.stream(signal);
      } catch (error) {
        if (signal.aborted) return;
        this.onError(error);
        // a key no longer valid, or no bench: trying again would not help
        if (error instanceof ApiFailure && [401, 403, 503].includes(error.status)) return;
      }
      try {
        await pause(RECONNECT_MS, signal);
      } catch {
        return;
      }
    }
  }

  async stream(signal) {
    const response = await fetch(`${API}/bench/live`, {
      headers: { Authorization: `Bearer ${storedKey()}`, Accept: "text/event-stream" },
      signal,
    });
    if (!response.ok) {
      let message = `${response.status} ${response.statusText}`;
      try {
        message = (await response.json()).error?.message ?? message;
      } catch {
        // not JSON
      }
      throw new ApiFailure(response.status, "live", message, null);
    }
    const parser = new SseParser((name, data) => {
      if (name === "state") this.onState(data);
      else if (name === "samples") this.onSamples(data);
    });
    const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return;
      parser.feed(value);
    }
  }
}

/** Channel name -> [label, colour, dash]: plate, wheel, body; an axle's right side dashed. */
const CHANNELS = {
  x_r: ["plate", "#7cc4ff", []],
  x_t: ["wheel", "#ffb347", []],
  x_s: ["body", "#9be37d", []],
};

/** Plate, wheel, body; left before right: the order of the legend and of drawing. */
function byChannel(a, b) {
  const rank = (name) => Object.keys(CHANNELS).indexOf(name.slice(0, 3)) * 2 + (name.slice(4) === "r" ? 1 : 0);
  return rank(a) - rank(b);
}

function channelStyle(name) {
  const [base, side] = [name.slice(0, 3), name.slice(4)];
  const [label, colour, dash] = CHANNELS[base] ?? [name, "#ddd", []];
  return {
    label: side ? `${label} ${side === "l" ? "left" : "right"}` : label,
    colour,
    dash: side === "r" ? [6, 4] : dash,
  };
}

/**
 * The live chart: the last `windowS` seconds of every channel, in mm against time, redrawn (at most once
 * per animation frame) whenever samples arrive. `canvas.dataset.points` counts the points held and
 * `canvas.dataset.frames` the frames drawn, for tests and for whoever wonders whether it is live.
 */
export class LiveChart {
  constructor(canvas, legend, windowS = 8) {
    this.canvas = canvas;
    this.legend = legend;
    this.windowS = windowS;
    this.frames = 0;
    this.pending = false;
    this.clear();
  }

  clear(sweepId = null) {
    this.sweepId = sweepId;
    this.t = [];
    this.series = {};
    this.legend.replaceChildren();
    this.schedule();
  }

  add({ sweep_id: sweepId, t_s: t, channels }) {
    if (sweepId !== this.sweepId) this.clear(sweepId);
    for (const name of Object.keys(channels).sort(byChannel)) {
      const values = channels[name];
      if (!this.series[name]) {
        this.series[name] = [];
        const { label, colour, dash } = channelStyle(name);
        const item = document.createElement("li");
        const swatch = document.createElement("span");
        swatch.className = "swatch" + (dash.length ? " dashed" : "");
        swatch.style.borderColor = colour;
        item.append(swatch, label);
        this.legend.append(item);
      }
      this.series[name].push(...values);
    }
    this.t.push(...t);
    const first = this.t.findIndex((time) => time >= this.t[this.t.length - 1] - this.windowS);
    if (first > 0) {
      this.t.splice(0, first);
      for (const values of Object.values(this.series)) values.splice(0, first);
    }
    this.schedule();
  }

  schedule() {
    if (this.pending) return;
    this.pending = true;
    requestAnimationFrame(() => {
      this.pending = false;
      this.draw();
    });
  }

  draw() {
    const canvas = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    const g = canvas.getContext("2d");
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.fillStyle = "#10151c";
    g.fillRect(0, 0, width, height);
    const pad = { left: 52, right: 10, top: 10, bottom: 26 };
    const plotW = width - pad.left - pad.right;
    const plotH = height - pad.top - pad.bottom;
    const t = this.t;
    let lo = -1;
    let hi = 1;
    for (const values of Object.values(this.series)) {
      for (const v of values) {
        if (v === null) continue; // a sample the stream could not give (not finite)
        lo = Math.min(lo, v * 1000);
        hi = Math.max(hi, v * 1000);
      }
    }
    const t0 = t.length ? Math.max(t[0], t[t.length - 1] - this.windowS) : 0;
    const t1 = t0 + this.windowS;
    const x = (time) => pad.left + ((time - t0) / this.windowS) * plotW;
    const y = (mm) => pad.top + (1 - (mm - lo) / (hi - lo)) * plotH;
    g.strokeStyle = "#3a4756";
    g.fillStyle = "#c9d4df";
    g.font = "12px system-ui, sans-serif";
    g.lineWidth = 1;
    g.setLineDash([]);
    for (const mm of ticks(lo, hi, 5)) {
      g.beginPath();
      g.moveTo(pad.left, y(mm));
      g.lineTo(width - pad.right, y(mm));
      g.stroke();
      g.fillText(`${mm} mm`, 4, y(mm) + 4);
    }
    for (const s of ticks(t0, t1, 6)) {
      g.fillText(`${s} s`, x(s) - 10, height - 8);
    }
    g.lineWidth = 1.6;
    for (const [name, values] of Object.entries(this.series)) {
      const { colour, dash } = channelStyle(name);
      g.strokeStyle = colour;
      g.setLineDash(dash);
      g.beginPath();
      let gap = true;
      values.forEach((v, i) => {
        if (v === null) {
          gap = true;
          return;
        }
        if (gap) g.moveTo(x(t[i]), y(v * 1000));
        else g.lineTo(x(t[i]), y(v * 1000));
        gap = false;
      });
      g.stroke();
    }
    this.frames += 1;
    canvas.dataset.points = String(t.length);
    canvas.dataset.frames = String(this.frames);
  }
}
