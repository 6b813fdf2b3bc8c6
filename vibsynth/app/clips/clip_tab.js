// The studio's clip lane (docs/clips.md, "The studio"): the clip list, the two knob curves over
// time with draggable breakpoints, transients as markers, play / loop / stop on the page's
// channel, save, and import of AHAP / .haptic files (file picker or drop).
//
// The clip being edited is plain data, exactly what its YAML file holds:
// {name, description, tags, duration_ms, loop: {start_ms, end_ms} | null,
//  keyframes: [{t_ms, intensity, balance, interp?}], transients: [{t_ms, intensity, balance, decay_ms}]}

const BASE = "/ext/clips/";
const W = 800;            // SVG user units
const PAD = 36;
const LANE = 140;         // height of each curve's lane
const GAP = 28;
const TOP = 14;
const H = TOP + 2 * LANE + GAP + 24;
const SAMPLES = 400;
const POLL_MS = 100;
const SVG = "http://www.w3.org/2000/svg";
const INTERPS = ["linear", "hold", "smooth"];

const STYLE = `
.clip-lane { display: grid; grid-template-columns: 220px 1fr; gap: 1rem; align-items: start; }
.clip-lane.dropping { outline: 3px dashed var(--accent, #1f6feb); outline-offset: 4px; }
.clip-list ul { list-style: none; margin: 0 0 0.75rem; padding: 0; }
.clip-list button { width: 100%; text-align: left; font: inherit; padding: 0.3rem 0.5rem; margin: 1px 0;
  border: 1px solid transparent; border-radius: 4px; background: transparent; cursor: pointer; }
.clip-list button[aria-current=true] { background: var(--panel, #fff); border-color: var(--line, #d5d9e0); }
.clip-list small { color: var(--muted, #5a6272); display: block; }
.clip-editor { background: var(--panel, #fff); border: 1px solid var(--line, #d5d9e0); border-radius: 6px; padding: 0.75rem; }
.clip-toolbar { display: flex; flex-wrap: wrap; gap: 0.5rem; align-items: center; margin-bottom: 0.5rem; }
.clip-toolbar input[type=number] { width: 6rem; }
.clip-canvas { width: 100%; height: auto; display: block; user-select: none; touch-action: none; }
.clip-canvas .lane-bg { fill: #f7f8fa; stroke: var(--line, #d5d9e0); }
.clip-canvas .curve { fill: none; stroke-width: 2; }
.clip-canvas .curve.intensity { stroke: var(--accent, #1f6feb); }
.clip-canvas .curve.balance { stroke: #d9480f; }
.clip-canvas .point { stroke: #fff; stroke-width: 1.5; cursor: grab; }
.clip-canvas .point.intensity { fill: var(--accent, #1f6feb); }
.clip-canvas .point.balance { fill: #d9480f; }
.clip-canvas .point.selected { stroke: var(--focus, #ffb000); stroke-width: 3; }
.clip-canvas .transient line { stroke: #6b3fa0; stroke-width: 2; }
.clip-canvas .transient path { fill: #6b3fa0; }
.clip-canvas .loop { fill: rgba(46, 160, 67, 0.12); }
.clip-canvas .playhead { stroke: var(--ink, #1d2330); stroke-width: 1.5; }
.clip-canvas text { font-size: 11px; fill: var(--muted, #5a6272); }
.clip-error { color: var(--danger, #b42318); min-height: 1.2em; margin: 0.4rem 0 0; }
.clip-status { color: var(--muted, #5a6272); margin: 0.2rem 0 0; min-height: 1.2em; }
.clip-selected { display: flex; gap: 0.5rem; align-items: center; flex-wrap: wrap; margin-top: 0.4rem; }
`;

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v);
  }
  node.append(...children);
  return node;
}

function svg(tag, attrs = {}) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  return node;
}

/** The curve (intensity, balance) at a time: the same rule as Clip.value_at in Python. */
export function valueAt(clip, t) {
  const keys = clip.keyframes;
  let i = -1;
  while (i + 1 < keys.length && keys[i + 1].t_ms <= t) i += 1;
  if (i < 0) return [keys[0].intensity, keys[0].balance];
  if (i >= keys.length - 1) return [keys[i].intensity, keys[i].balance];
  const a = keys[i], b = keys[i + 1];
  const u = (t - a.t_ms) / (b.t_ms - a.t_ms);
  const interp = a.interp || "linear";
  const w = interp === "hold" ? 0 : interp === "smooth" ? 0.5 - 0.5 * Math.cos(Math.PI * u) : u;
  return [a.intensity + w * (b.intensity - a.intensity), a.balance + w * (b.balance - a.balance)];
}

export async function mount(panel, studio) {
  panel.append(el("style", { text: STYLE }));
  const limits = (studio.hello && studio.hello.limits) || { balance_min: -3.5, balance_max: 3.5 };
  const bmin = limits.balance_min, bmax = limits.balance_max;

  let clip = null;          // the clip being edited
  let origin = "";          // "shipped", "user" or "" (imported, not saved)
  let dirty = false;
  let selected = -1;        // index of the selected keyframe
  let poll = null;

  // ------------------------------------------------------------------ layout
  const list = el("ul", { "aria-label": "clips" });
  const importInput = el("input", { type: "file", accept: ".ahap,.haptic", "data-testid": "clip-import-file" });
  const aside = el("aside", { class: "clip-list" },
    el("h3", { text: "Clips" }), list,
    el("label", { class: "clip-import" }, "Import AHAP / .haptic ", importInput),
    el("p", { class: "help", text: "or drop a file on the lane" }));
  const nameInput = el("input", { type: "text", "data-testid": "clip-name", "aria-label": "clip name", autocomplete: "off" });
  const durationInput = el("input", { type: "number", min: "1", step: "1", "data-testid": "clip-duration", "aria-label": "duration (ms)" });
  const loopBox = el("input", { type: "checkbox", "data-testid": "clip-loop" });
  const playButton = el("button", { type: "button", "data-testid": "clip-play", text: "Play" });
  const stopButton = el("button", { type: "button", "data-testid": "clip-stop", text: "Stop" });
  const saveButton = el("button", { type: "button", "data-testid": "clip-save", text: "Save" });
  const toolbar = el("div", { class: "clip-toolbar" },
    el("label", {}, "Name ", nameInput), el("label", {}, "Duration ", durationInput, " ms"),
    playButton, stopButton, el("label", {}, loopBox, " Loop"), saveButton);
  const canvas = svg("svg", { viewBox: `0 0 ${W} ${H}`, class: "clip-canvas", "data-testid": "clip-canvas",
    role: "img", "aria-label": "intensity and balance over time" });
  const interpSelect = el("select", { "data-testid": "clip-interp", "aria-label": "interpolation" },
    ...INTERPS.map((k) => el("option", { value: k, text: k })));
  const deleteButton = el("button", { type: "button", "data-testid": "clip-delete-key", text: "Delete keyframe" });
  const selectedInfo = el("span", { "data-testid": "clip-selected" });
  const selectedBar = el("div", { class: "clip-selected" }, selectedInfo, el("label", {}, "Segment ", interpSelect), deleteButton);
  const errorLine = el("p", { class: "clip-error", role: "alert", "data-testid": "clip-error" });
  const statusLine = el("p", { class: "clip-status", "data-testid": "clip-status" });
  const editor = el("div", { class: "clip-editor" }, toolbar, canvas, selectedBar,
    el("p", { class: "help", text: "Drag a point; double-click a lane to add a keyframe; Delete removes the selected one." }),
    errorLine, statusLine);
  const lane = el("div", { class: "clip-lane" }, aside, editor);
  panel.append(lane);

  function showError(message) { errorLine.textContent = message || ""; }
  function showStatus(message) { statusLine.textContent = message || ""; }
  function setDirty(on) { dirty = on; saveButton.textContent = on ? "Save *" : "Save"; }

  // ------------------------------------------------------------------ geometry
  const x = (t) => PAD + (t / clip.duration_ms) * (W - 2 * PAD);
  const tOf = (px) => ((px - PAD) / (W - 2 * PAD)) * clip.duration_ms;
  const lanes = {
    intensity: { top: TOP, y: (v) => TOP + (1 - v) * LANE, v: (py) => 1 - (py - TOP) / LANE, lo: 0, hi: 1 },
    balance: {
      top: TOP + LANE + GAP,
      y: (v) => TOP + LANE + GAP + (1 - (Math.min(Math.max(v, bmin), bmax) - bmin) / (bmax - bmin)) * LANE,
      v: (py) => bmin + (1 - (py - (TOP + LANE + GAP)) / LANE) * (bmax - bmin),
      lo: bmin, hi: bmax,
    },
  };

  function toSvg(event) {
    const point = canvas.createSVGPoint();
    point.x = event.clientX;
    point.y = event.clientY;
    return point.matrixTransform(canvas.getScreenCTM().inverse());
  }

  // ------------------------------------------------------------------ drawing
  function draw() {
    canvas.replaceChildren();
    if (!clip) return;
    if (clip.loop) {
      canvas.append(svg("rect", { class: "loop", x: x(clip.loop.start_ms), y: TOP,
        width: Math.max(0, x(clip.loop.end_ms) - x(clip.loop.start_ms)), height: 2 * LANE + GAP }));
    }
    for (const [kind, spec] of Object.entries(lanes)) {
      canvas.append(svg("rect", { class: "lane-bg", "data-lane": kind, x: PAD, y: spec.top, width: W - 2 * PAD, height: LANE }));
      const label = svg("text", { x: PAD + 4, y: spec.top + 12 });
      label.textContent = kind === "intensity" ? "intensity 0..1" : `balance ${bmin}..${bmax}`;
      canvas.append(label);
      const d = [];
      for (let k = 0; k <= SAMPLES; k += 1) {
        const t = (k / SAMPLES) * clip.duration_ms;
        const v = valueAt(clip, t)[kind === "intensity" ? 0 : 1];
        d.push(`${k ? "L" : "M"}${x(t).toFixed(2)},${spec.y(v).toFixed(2)}`);
      }
      canvas.append(svg("path", { class: `curve ${kind}`, d: d.join(" ") }));
    }
    const axis = svg("text", { x: W - PAD, y: H - 6, "text-anchor": "end" });
    axis.textContent = `${clip.duration_ms} ms`;
    canvas.append(axis);
    clip.transients.forEach((tr, i) => {
      const g = svg("g", { class: "transient", "data-testid": "clip-transient", "data-index": i });
      const base = lanes.intensity.y(0), top = lanes.intensity.y(tr.intensity);
      g.append(svg("line", { x1: x(tr.t_ms), x2: x(tr.t_ms), y1: base, y2: top }));
      g.append(svg("path", { d: `M${x(tr.t_ms) - 5},${top - 8} L${x(tr.t_ms) + 5},${top - 8} L${x(tr.t_ms)},${top} Z` }));
      const title = svg("title");
      title.textContent = `transient at ${tr.t_ms} ms: intensity ${tr.intensity}, balance ${tr.balance}, decay ${tr.decay_ms} ms`;
      g.append(title);
      canvas.append(g);
    });
    clip.keyframes.forEach((key, i) => {
      for (const [kind, spec] of Object.entries(lanes)) {
        const dot = svg("circle", { class: `point ${kind}${i === selected ? " selected" : ""}`,
          cx: x(key.t_ms), cy: spec.y(key[kind]), r: 6, "data-testid": "clip-point", "data-kind": kind, "data-index": i });
        dot.addEventListener("pointerdown", (event) => startDrag(event, i, kind));
        canvas.append(dot);
      }
    });
    canvas.append(svg("line", { class: "playhead", "data-testid": "clip-playhead", x1: -10, x2: -10, y1: TOP, y2: TOP + 2 * LANE + GAP }));
    showSelected();
  }

  function showSelected() {
    const key = clip && clip.keyframes[selected];
    selectedBar.hidden = !key;
    if (!key) return;
    selectedInfo.textContent = `keyframe ${selected + 1}: ${key.t_ms.toFixed(1)} ms, intensity ${key.intensity.toFixed(3)}, balance ${key.balance.toFixed(3)}`;
    interpSelect.value = key.interp || "linear";
    deleteButton.disabled = clip.keyframes.length <= 1;
  }

  // ------------------------------------------------------------------ editing
  // The whole drawing is redrawn while dragging, so the drag follows the pointer on the canvas
  // (captured there), not on the point's element, which is replaced.
  function startDrag(event, index, kind) {
    event.preventDefault();
    event.stopPropagation();
    selected = index;
    canvas.setPointerCapture(event.pointerId);
    const keys = clip.keyframes;
    const spec = lanes[kind];
    const move = (ev) => {
      const p = toSvg(ev);
      const lo = index > 0 ? keys[index - 1].t_ms + 0.5 : 0;
      const hi = index < keys.length - 1 ? keys[index + 1].t_ms - 0.5 : clip.duration_ms;
      const t = Math.min(Math.max(tOf(p.x), lo), hi);
      const v = Math.min(Math.max(spec.v(p.y), spec.lo), spec.hi);
      keys[index] = { ...keys[index], t_ms: Math.round(t * 10) / 10, [kind]: Math.round(v * 1000) / 1000 };
      setDirty(true);
      draw();
    };
    const up = (ev) => {
      canvas.removeEventListener("pointermove", move);
      canvas.removeEventListener("pointerup", up);
      canvas.removeEventListener("pointercancel", up);
      if (canvas.hasPointerCapture(ev.pointerId)) canvas.releasePointerCapture(ev.pointerId);
      draw();
    };
    canvas.addEventListener("pointermove", move);
    canvas.addEventListener("pointerup", up);
    canvas.addEventListener("pointercancel", up);
    draw();
  }

  canvas.addEventListener("dblclick", (event) => {
    if (!clip) return;
    const p = toSvg(event);
    const t = Math.round(Math.min(Math.max(tOf(p.x), 0), clip.duration_ms) * 10) / 10;
    if (clip.keyframes.some((k) => Math.abs(k.t_ms - t) < 0.5)) return;
    const [intensity, balance] = valueAt(clip, t);
    const at = clip.keyframes.findIndex((k) => k.t_ms > t);
    const index = at < 0 ? clip.keyframes.length : at;
    const before = clip.keyframes[index - 1];
    clip.keyframes.splice(index, 0, { t_ms: t, intensity: Math.round(intensity * 1000) / 1000,
      balance: Math.round(balance * 1000) / 1000, interp: before ? before.interp || "linear" : "linear" });
    selected = index;
    setDirty(true);
    draw();
  });

  interpSelect.addEventListener("change", () => {
    if (!clip || selected < 0) return;
    clip.keyframes[selected] = { ...clip.keyframes[selected], interp: interpSelect.value };
    setDirty(true);
    draw();
  });

  function deleteSelected() {
    if (!clip || selected < 0 || clip.keyframes.length <= 1) return;
    clip.keyframes.splice(selected, 1);
    selected = Math.min(selected, clip.keyframes.length - 1);
    setDirty(true);
    draw();
  }
  deleteButton.addEventListener("click", deleteSelected);
  panel.addEventListener("keydown", (event) => {
    if ((event.key === "Delete" || event.key === "Backspace") && event.target.tagName !== "INPUT") deleteSelected();
  });

  durationInput.addEventListener("change", () => {
    const value = Number(durationInput.value);
    if (!clip || !(value > 0)) return;
    clip.duration_ms = value;
    setDirty(true);
    draw();
  });

  // ------------------------------------------------------------------ loading, saving
  function load(data, from) {
    clip = { description: "", tags: [], loop: null, transients: [], ...data };
    clip.keyframes = clip.keyframes.map((k) => ({ interp: "linear", ...k }));
    origin = from;
    selected = -1;
    nameInput.value = clip.name;
    durationInput.value = String(clip.duration_ms);
    loopBox.checked = Boolean(clip.loop);
    for (const item of list.querySelectorAll("[data-testid=clip-item]")) {
      item.setAttribute("aria-current", String(item.dataset.name === clip.name));
    }
    setDirty(from === "");
    draw();
  }

  async function refreshList() {
    const data = await studio.fetchJSON(`${BASE}list`);
    list.replaceChildren(...data.clips.map((c) => el("li", {},
      el("button", { type: "button", "data-testid": "clip-item", "data-name": c.name,
        "aria-current": String(Boolean(clip && clip.name === c.name)), onclick: () => open(c.name) },
        c.name, el("small", { text: `${c.duration_ms} ms · ${c.origin}${c.loop ? " · loop" : ""}` })))));
    if (!data.playing) showStatus("no clip player runs in this service: play is unavailable");
    const broken = Object.values(data.errors || {});
    if (broken.length) showError(broken[0]);
    return data;
  }

  async function open(name) {
    if (dirty && clip && !window.confirm(`Discard the unsaved changes to ${clip.name}?`)) return;
    try {
      const data = await studio.fetchJSON(`${BASE}clip/${encodeURIComponent(name)}`);
      showError("");
      load(data.clip, data.origin);
      showStatus(`${data.origin} clip: ${data.path}`);
    } catch (error) {
      showError(error.message);
    }
  }

  function current() {
    const name = nameInput.value.trim();
    return { ...clip, name };
  }

  saveButton.addEventListener("click", async () => {
    if (!clip) return;
    const data = current();
    try {
      const saved = await studio.fetchJSON(`${BASE}clip/${encodeURIComponent(data.name)}`, {
        method: "PUT", headers: { "Content-Type": "application/json" }, body: JSON.stringify(data),
      });
      showError("");
      load(saved.clip, "user");
      setDirty(false);
      showStatus(`saved ${saved.saved}`);
      await refreshList();
    } catch (error) {
      showError(error.message);
    }
  });

  async function importFile(file) {
    try {
      const text = await file.text();
      const data = await studio.fetchJSON(`${BASE}import?file=${encodeURIComponent(file.name)}`, {
        method: "POST", headers: { "Content-Type": "text/plain" }, body: text,
      });
      showError("");
      load(data.clip, "");
      showStatus(`imported ${file.name} (not saved yet)${data.ignored.length ? `; ignored: ${data.ignored.join("; ")}` : ""}`);
    } catch (error) {
      showError(error.message);
    }
  }
  importInput.addEventListener("change", () => {
    if (importInput.files.length) importFile(importInput.files[0]);
    importInput.value = "";
  });
  lane.addEventListener("dragover", (event) => { event.preventDefault(); lane.classList.add("dropping"); });
  lane.addEventListener("dragleave", () => lane.classList.remove("dropping"));
  lane.addEventListener("drop", (event) => {
    event.preventDefault();
    lane.classList.remove("dropping");
    const file = event.dataTransfer && event.dataTransfer.files[0];
    if (file) importFile(file);
  });

  // ------------------------------------------------------------------ playing
  function playhead(ms) {
    const line = canvas.querySelector("[data-testid=clip-playhead]");
    if (!line || !clip) return;
    const px = ms === null ? -10 : x(Math.min(ms, clip.duration_ms));
    line.setAttribute("x1", px);
    line.setAttribute("x2", px);
  }

  function stopPolling() {
    if (poll !== null) clearInterval(poll);
    poll = null;
  }

  function startPolling(channel) {
    stopPolling();
    poll = setInterval(async () => {
      try {
        const data = await studio.fetchJSON(`${BASE}playing?channel=${channel}`);
        if (!data.playing) {
          playhead(null);
          playButton.dataset.state = "idle";
          stopPolling();
          return;
        }
        playhead(data.playing.position_ms);
      } catch { stopPolling(); }
    }, POLL_MS);
  }

  playButton.addEventListener("click", async () => {
    if (!clip) return;
    const channel = studio.channel();
    const data = current();
    try {
      await studio.fetchJSON(`${BASE}play`, {
        method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ name: data.name, channel, loop: loopBox.checked, clip: data }),
      });
      showError("");
      playButton.dataset.state = "playing";
      showStatus(`playing ${data.name} on channel ${channel}${loopBox.checked ? " (looped)" : ""}`);
      startPolling(channel);
    } catch (error) {
      showError(error.message);
    }
  });

  stopButton.addEventListener("click", async () => {
    const channel = studio.channel();
    try {
      await studio.fetchJSON(`${BASE}stop`, {
        method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify({ channel }),
      });
      showError("");
      playButton.dataset.state = "idle";
      showStatus(`stopped channel ${channel}`);
    } catch (error) {
      showError(error.message);
    }
  });

  // ------------------------------------------------------------------ start
  try {
    const data = await refreshList();
    if (data.clips.length) await open(data.clips[0].name);
  } catch (error) {
    showError(error.message);
  }
}
