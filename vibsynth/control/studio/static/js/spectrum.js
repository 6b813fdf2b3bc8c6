// Spectrum panel: target M + t·V1 at the current knobs, mean M, and the measured output,
// for the channel the page shows. data-target-db / data-mean-db / data-measured-db hold the
// 30 band levels (JSON; null = silent band) for scripts and tests.

import { drawSpectrum } from "./plot.js";

export function mountSpectrum(studio) {
  const svg = document.getElementById("spectrum");
  const note = document.getElementById("spectrum-note");
  let last = null;
  let measured = null;

  function draw() {
    if (!last) return;
    svg.dataset.targetDb = JSON.stringify(last.target_db || []);
    svg.dataset.meanDb = JSON.stringify(last.mean_db || []);
    svg.dataset.measuredDb = JSON.stringify(measured || []);
    svg.dataset.intensity = String(last.intensity);
    svg.dataset.balance = String(last.balance);
    drawSpectrum(svg, {
      centres: last.centres_hz,
      band: last.intensity_band_hz,
      yRange: last.y_range_db,
      curves: [
        { values: last.mean_db, className: "mean" },
        { values: last.target_db, className: "target" },
        { values: measured, className: "measured" },
      ],
    });
    const notes = [];
    if (!last.target_db) notes.push("intensity 0: the target is silence");
    if (last.muted) notes.push("muted: the output fades to silence");
    if (!last.tap) notes.push("measured: this engine has no output tap");
    note.textContent = notes.join("; ");
  }

  studio.on("spectrum", (m) => {
    if (m.channel !== studio.channel()) return;
    last = m;
    if ("measured_db" in m) measured = m.measured_db;
    draw();
  });
  document.getElementById("channel").addEventListener("change", () => { last = null; measured = null; });
}
