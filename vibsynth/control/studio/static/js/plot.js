// A small SVG plotter for 30-band spectra: dB over log frequency 10-1000 Hz.

const NS = "http://www.w3.org/2000/svg";
const F_MIN = 10;
const F_MAX = 1000;
const F_TICKS = [10, 20, 50, 100, 200, 500, 1000];

function el(name, attrs = {}, text = "") {
  const node = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text) node.textContent = text;
  return node;
}

/**
 * Draw curves into an SVG element (its viewBox gives the size).
 * curves: [{values: [dB or null] (one per centre), className}]
 * band: [lowHz, highHz] shaded; yRange: [low, high] dB (null = from the data).
 */
export function drawSpectrum(svg, { centres, curves, band = null, yRange = null, title = "" }) {
  const [, , width, height] = svg.getAttribute("viewBox").split(" ").map(Number);
  const m = { left: 56, right: 12, top: 14, bottom: 40 };
  const w = width - m.left - m.right;
  const h = height - m.top - m.bottom;
  let [low, high] = yRange || [Infinity, -Infinity];
  if (!yRange) {
    for (const c of curves) for (const v of c.values || []) if (v !== null) { low = Math.min(low, v); high = Math.max(high, v); }
    if (!Number.isFinite(low)) { low = -100; high = 0; }
    low = 10 * Math.floor((low - 3) / 10);
    high = 10 * Math.ceil((high + 3) / 10);
    if (high - low < 30) low = high - 30;
  }
  const x = (f) => m.left + (w * Math.log10(f / F_MIN)) / Math.log10(F_MAX / F_MIN);
  const y = (db) => m.top + (h * (high - Math.max(low, Math.min(high, db)))) / (high - low);

  const keep = [...svg.children].filter((n) => n.tagName === "desc" || n.tagName === "title");
  svg.replaceChildren(...keep);
  if (band) svg.appendChild(el("rect", { class: "band", x: x(band[0]), y: m.top, width: x(band[1]) - x(band[0]), height: h }));

  const grid = el("g", { class: "grid" });
  const axes = el("g", { class: "axis" });
  const step = high - low > 80 ? 20 : 10;
  for (let db = Math.ceil(low / step) * step; db <= high; db += step) {
    grid.appendChild(el("line", { x1: m.left, x2: m.left + w, y1: y(db), y2: y(db) }));
    axes.appendChild(el("text", { x: m.left - 6, y: y(db) + 4, "text-anchor": "end" }, String(db)));
  }
  for (const f of F_TICKS) {
    grid.appendChild(el("line", { x1: x(f), x2: x(f), y1: m.top, y2: m.top + h }));
    axes.appendChild(el("text", { x: x(f), y: m.top + h + 15, "text-anchor": "middle" }, String(f)));
  }
  axes.appendChild(el("path", { d: `M${m.left},${m.top}V${m.top + h}H${m.left + w}`, fill: "none" }));
  svg.append(grid, axes);
  svg.appendChild(el("text", { class: "axis-title", x: m.left + w / 2, y: height - 6, "text-anchor": "middle" },
    "frequency (Hz, log scale)"));
  svg.appendChild(el("text", { class: "axis-title", x: 14, y: m.top + h / 2, "text-anchor": "middle",
    transform: `rotate(-90 14 ${m.top + h / 2})` }, title || "band level (dB re unit RMS)"));

  for (const curve of curves) {
    if (!curve.values) continue;
    let points = [];
    const flush = () => {
      if (points.length > 1) svg.appendChild(el("polyline", { class: `curve ${curve.className}`, points: points.join(" ") }));
      points = [];
    };
    curve.values.forEach((v, i) => {
      if (v === null) { flush(); return; }
      points.push(`${x(centres[i]).toFixed(1)},${y(v).toFixed(1)}`);
    });
    flush();
  }
}
