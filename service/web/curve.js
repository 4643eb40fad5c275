// The force-velocity curve as SVG: the identified points, their 95% confidence band and the tanh fit
// F(v) = c_s·v + kappa·(tanh(mu·v + beta) − tanh(beta)). One chart per curve (left and right for an axle).

import { ticks } from "./axes.js";

const SVG = "http://www.w3.org/2000/svg";
const WIDTH = 560;
const HEIGHT = 360;
const PAD = { left: 64, right: 14, top: 28, bottom: 44 };

function el(name, attributes = {}, text) {
  const node = document.createElementNS(SVG, name);
  for (const [key, value] of Object.entries(attributes)) node.setAttribute(key, String(value));
  if (text !== undefined) node.textContent = text;
  return node;
}

/** The tanh model's force (N) at velocity v (m/s). */
export function tanhForce({ c_s, kappa, mu, beta }, v) {
  return c_s * v + kappa * (Math.tanh(mu * v + beta) - Math.tanh(beta));
}

const CORNER_TITLE = { single: "Damper", left: "Left damper", right: "Right damper" };

/** An <svg> of one identified curve (a CurveOut of the result). */
export function curveSvg(curve) {
  const v = curve.velocity_m_s;
  const f = curve.force_N;
  const low = curve.force_N_low;
  const high = curve.force_N_high;
  const fit = [];
  const [v0, v1] = [Math.min(...v), Math.max(...v)];
  for (let i = 0; i <= 120; i += 1) {
    const speed = v0 + ((v1 - v0) * i) / 120;
    fit.push([speed, tanhForce(curve.tanh, speed)]);
  }
  const forces = [...f, ...(low ?? []), ...(high ?? []), ...fit.map((p) => p[1])].filter(Number.isFinite);
  const [f0, f1] = [Math.min(...forces), Math.max(...forces)];
  const plotW = WIDTH - PAD.left - PAD.right;
  const plotH = HEIGHT - PAD.top - PAD.bottom;
  const x = (speed) => PAD.left + ((speed - v0) / (v1 - v0 || 1)) * plotW;
  const y = (force) => PAD.top + (1 - (force - f0) / (f1 - f0 || 1)) * plotH;
  const title = CORNER_TITLE[curve.corner] ?? curve.corner;
  const svg = el("svg", {
    viewBox: `0 0 ${WIDTH} ${HEIGHT}`,
    role: "img",
    "aria-label": `${title}: force against velocity, ${v.length} points, 95% band and tanh fit`,
    class: "curve",
  });
  svg.append(el("text", { x: PAD.left, y: 18, class: "chart-title" }, title));
  const grid = el("g", { class: "grid" });
  for (const speed of ticks(v0, v1, 6)) {
    grid.append(el("line", { x1: x(speed), x2: x(speed), y1: PAD.top, y2: PAD.top + plotH }));
    grid.append(el("text", { x: x(speed), y: HEIGHT - 26, "text-anchor": "middle" }, String(speed)));
  }
  for (const force of ticks(f0, f1, 6)) {
    grid.append(el("line", { x1: PAD.left, x2: PAD.left + plotW, y1: y(force), y2: y(force) }));
    grid.append(el("text", { x: PAD.left - 6, y: y(force) + 4, "text-anchor": "end" }, String(force)));
  }
  grid.append(
    el("text", { x: PAD.left + plotW / 2, y: HEIGHT - 6, "text-anchor": "middle" }, "velocity (m/s)"),
  );
  grid.append(
    el("text", { x: 14, y: PAD.top + plotH / 2, transform: `rotate(-90 14 ${PAD.top + plotH / 2})`,
      "text-anchor": "middle" }, "force (N)"),
  );
  svg.append(grid);
  if (low && high) {
    const upper = v.map((speed, i) => `${x(speed)},${y(high[i])}`);
    const lower = v.map((speed, i) => `${x(speed)},${y(low[i])}`).reverse();
    svg.append(el("polygon", { points: [...upper, ...lower].join(" "), class: "band" }));
  }
  svg.append(
    el("polyline", { points: fit.map(([s, force]) => `${x(s)},${y(force)}`).join(" "), class: "fit" }),
  );
  const outliers = new Set(curve.outliers ?? []);
  const points = el("g", { class: "points" });
  v.forEach((speed, i) => {
    points.append(el("circle", { cx: x(speed), cy: y(f[i]), r: 3.2, class: outliers.has(i) ? "outlier" : "" }));
  });
  svg.append(points);
  const legend = el("g", { class: "legend", transform: `translate(${PAD.left + 10} ${PAD.top + 8})` });
  legend.append(el("rect", { x: 0, y: 0, width: 14, height: 10, class: "band" }));
  legend.append(el("text", { x: 20, y: 9 }, "95% band"));
  legend.append(el("line", { x1: 90, x2: 110, y1: 5, y2: 5, class: "fit" }));
  legend.append(el("text", { x: 116, y: 9 }, "tanh fit"));
  legend.append(el("circle", { cx: 180, cy: 5, r: 3.2 }));
  legend.append(el("text", { x: 188, y: 9 }, "identified points"));
  svg.append(legend);
  return svg;
}
