// The studio's Calibrate tab: per channel, a profile's measured response, the lab's iso-intensity
// curve (in acceleration), the band they derive, and "apply to channel" (writes it into the profile).
import { el, fmt, SVG_NS } from "/ext/lab/tab.js";

export async function mount(panel, studio) {
  const error = el("p", { class: "error", role: "alert", "data-testid": "calibrate-error" });
  const status = el("p", { class: "note", role: "status", "aria-live": "polite", "data-testid": "calibrate-status" });
  const channel = el("select", { id: "calibrate-channel", "data-testid": "calibrate-channel" });
  const profile = el("select", { id: "calibrate-profile", "data-testid": "calibrate-profile" });
  const sessions = el("ul", { class: "lab-sessions", "aria-label": "Iso-intensity sessions", "data-testid": "calibrate-sessions" });
  const show = el("button", { type: "button", "data-testid": "calibrate-show", text: "Show" });
  const apply = el("button", { type: "button", "data-testid": "calibrate-apply", text: "Apply to channel" });
  const band = el("p", { "data-testid": "calibrate-band" });
  const figure = el("div", { "data-testid": "calibrate-plot" });
  panel.append(el("section", { class: "lab-box", "aria-labelledby": "calibrate-title" },
    el("h2", { id: "calibrate-title", text: "Calibrate" }),
    el("div", { class: "field" }, el("label", { for: "calibrate-channel", text: "Channel" }), channel),
    el("div", { class: "field" }, el("label", { for: "calibrate-profile", text: "Profile (measured response)" }), profile),
    el("p", { class: "help", text: "Iso-intensity sessions (the Lab tab's sines) whose mean curve to use:" }), sessions,
    el("div", { class: "actions" }, show, apply), error, status, band, figure));

  async function call(path, body) {
    error.textContent = "";
    try {
      const options = body === undefined ? {} : {
        method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) };
      return await studio.fetchJSON(`/ext/calibrate/${path}`, options);
    } catch (failure) {
      error.textContent = failure.message;
      return null;
    }
  }

  const chosen = () => [...sessions.querySelectorAll("input:checked")].map((box) => box.dataset.folder);

  function plot(view) {
    const svg = document.createElementNS(SVG_NS, "svg");
    svg.setAttribute("viewBox", "0 0 400 220");
    svg.setAttribute("style", "width: 100%; max-width: 640px");
    svg.setAttribute("role", "img");
    svg.setAttribute("aria-label", "Response and iso-intensity curve, dB over log frequency");
    const series = [[view.response.map(([f, v]) => [f, v]), "C0", "calibrate-response"]];
    if (view.iso) series.push([view.iso.frequency_hz.map((f, k) => [f, view.iso.acceleration_db[k]]), "C3", "calibrate-iso"]);
    const all = series.flatMap(([pts]) => pts.map(([, v]) => v));
    const lo = Math.min(...all) - 3, hi = Math.max(...all) + 3;
    const x = (f) => 20 + 360 * Math.log(Math.min(Math.max(f, 10), 1000) / 10) / Math.log(100);
    const y = (v) => 210 - 200 * (v - lo) / (hi - lo);
    if (view.band_hz || view.model_band_hz) {
      const [a, b] = view.band_hz || view.model_band_hz;
      const rect = document.createElementNS(SVG_NS, "rect");
      Object.entries({ x: x(a), y: 10, width: x(b) - x(a), height: 200, fill: "rgba(120,120,120,0.15)" })
        .forEach(([k, v]) => rect.setAttribute(k, v));
      svg.append(rect);
    }
    for (const [pts, colour, testid] of series) {
      const line = document.createElementNS(SVG_NS, "polyline");
      line.setAttribute("points", pts.map(([f, v]) => `${x(f).toFixed(1)},${y(v).toFixed(1)}`).join(" "));
      line.setAttribute("fill", "none");
      line.setAttribute("stroke", colour === "C0" ? "#1f77b4" : "#d62728");
      line.setAttribute("stroke-width", "2");
      line.setAttribute("data-testid", testid);
      svg.append(line);
    }
    figure.replaceChildren(svg, el("p", { class: "help",
      text: "Blue: the response (dB per unit drive); red: the iso-intensity curve in acceleration (dB re the reference); grey: the band. 10–1000 Hz, log." }));
  }

  show.addEventListener("click", async () => {
    const view = await call("view", { profile: profile.value, sessions: chosen() });
    if (!view) return;
    const derived = view.band_hz ? `${fmt(view.band_hz[0], 1)}–${fmt(view.band_hz[1], 1)} Hz` : "–";
    band.textContent = `Band from the measured curve: ${derived}; with the model curve: ` +
      `${fmt(view.model_band_hz[0], 1)}–${fmt(view.model_band_hz[1], 1)} Hz.`;
    band.dataset.band = view.band_hz ? view.band_hz.join(",") : "";
    plot(view);
  });
  apply.addEventListener("click", async () => {
    const done = await call("apply", { channel: Number(channel.value), profile: profile.value, sessions: chosen() });
    if (done) status.textContent = `Channel ${done.channel}: ${done.profile} now has the band ${fmt(done.band_hz[0], 1)}–${fmt(done.band_hz[1], 1)} Hz (${done.file}).` +
      (done.applied ? ` The channel plays it now: ${done.trim}.` : "") +
      (done.saved ? ` Kept in ${done.saved}: ${done.config}` :
        ` Not saved${done.save_error ? ` (${done.save_error})` : ""}; to keep it after a restart, add: ${done.config}`);
  });

  const setup = await call("setup");
  if (!setup) return;
  for (let c = 1; c <= setup.channels; c++) channel.append(el("option", { value: String(c), text: String(c) }));
  for (const name of setup.profiles) profile.append(el("option", { value: name, text: name, selected: name === setup.profile }));
  setup.sessions.forEach((s, k) => sessions.append(el("li", {},
    el("input", { type: "checkbox", id: `calibrate-s${k}`, "data-testid": "calibrate-session", dataset: { folder: s.folder } }),
    el("label", { for: `calibrate-s${k}`, text: `${s.participant}: ${s.set} (${s.done}/${s.total})` }))));
  if (!setup.sessions.length) sessions.append(el("li", { class: "help", text: "none yet (the Lab tab, stimuli: Sines)" }));
}
