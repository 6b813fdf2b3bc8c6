// Recording panel: drop or choose a WAV; its analysis (as `vibsynth analyze` gives it) beside
// the model M + t1·V1; make a preset of it (saved in the user preset folder).

import { drawSpectrum } from "./plot.js";
import { formatBalance, formatIntensity } from "./knobs.js";

const $ = (id) => document.getElementById(id);
const UPLOAD_CAP = 64 * 1024 * 1024;

export function mountRecording(studio) {
  const input = $("recording-file");
  const drop = $("recording-drop");
  const state = $("recording-state");
  const error = $("recording-error");
  const analysis = $("recording-analysis");
  const plot = $("recording-spectrum");
  const make = $("recording-make");
  const nameInput = $("recording-name");
  const makeButton = $("recording-make-preset");
  let current = null;
  let replaceName = null;

  function show(result) {
    current = result;
    analysis.hidden = false;
    plot.removeAttribute("hidden"); // an SVG element has no .hidden property
    make.hidden = false;
    $("recording-legend").hidden = false;
    const outside = result.intensity_in_range ? "" : " (outside 0..1: clamped in a preset)";
    $("recording-intensity").textContent = formatIntensity(result.intensity) + outside;
    $("recording-intensity").dataset.value = String(result.intensity);
    $("recording-balance").textContent =
      formatBalance(result.balance) + (result.outside_database ? " (outside the basis' database)" : "");
    $("recording-balance").dataset.value = String(result.balance);
    $("recording-level").textContent = `${result.level_db.toFixed(1)} dB`;
    $("recording-scores").textContent = result.scores.map((s, i) => `t${i + 1} ${s.toFixed(2)}`).join(", ");
    $("recording-stationary").textContent = result.stationary
      ? `yes (level varies by ${result.non_stationarity_db.toFixed(2)} dB over 100 ms windows)`
      : `no: the level varies by ${result.non_stationarity_db.toFixed(2)} dB over 100 ms windows (over ` +
        `${result.non_stationary_threshold_db} dB); the model describes stationary vibrations`;
    $("recording-stationary").dataset.stationary = String(result.stationary);
    drawSpectrum(plot, {
      centres: result.centres_hz,
      band: [80, 200],
      curves: [
        { values: result.model_db, className: "target" },
        { values: result.band_db, className: "recording" },
      ],
      title: "band level (dB)",
    });
    nameInput.value = result.suggested_name;
    replaceName = null;
    makeButton.textContent = "Make preset";
  }

  async function upload(file) {
    error.textContent = "";
    if (!file) return;
    if (file.size > UPLOAD_CAP) {
      error.textContent = `${file.name} is ${(file.size / 1048576).toFixed(0)} MiB; the limit is 64 MiB`;
      return;
    }
    state.textContent = `analysing ${file.name}…`;
    try {
      const result = await studio.fetchJSON("/api/recording", {
        method: "POST",
        headers: { "Content-Type": "audio/wav", "X-Filename": encodeURIComponent(file.name) },
        body: file,
      });
      state.textContent = `${result.file}: ${result.duration_s.toFixed(2)} s at ${result.fs} Hz`;
      show(result);
    } catch (failure) {
      state.textContent = "";
      error.textContent = failure.message;
    }
  }

  input.addEventListener("change", () => upload(input.files[0]));
  drop.addEventListener("dragover", (event) => { event.preventDefault(); drop.classList.add("over"); });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (event) => {
    event.preventDefault();
    drop.classList.remove("over");
    upload(event.dataTransfer.files[0]);
  });

  nameInput.addEventListener("input", () => {
    makeButton.textContent = replaceName === nameInput.value.trim() ? `Replace ${replaceName}` : "Make preset";
  });

  makeButton.addEventListener("click", async () => {
    if (!current) return;
    error.textContent = "";
    const name = nameInput.value.trim();
    try {
      const result = await studio.fetchJSON(`/api/recording/${current.id}/preset`, {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ name, overwrite: replaceName === name }),
      });
      replaceName = null;
      makeButton.textContent = "Make preset";
      state.textContent = [result.note, ...result.warnings].join("; ");
    } catch (failure) {
      error.textContent = failure.message;
      if (failure.data && failure.data.exists) {
        replaceName = name;
        makeButton.textContent = `Replace ${name}`;
      }
    }
  });
}
