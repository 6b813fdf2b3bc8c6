// Follow panel: the live follower's input (picker), its level (meter), gain, gate, range, focus,
// on/off per channel, and a canvas trace of the tracked intensity and balance over the input's level.
// State comes from GET /api/follow (with the whole trace) and the {"type": "follow"} pushes (the
// last second of trace, merged by time); changes go to POST /api/follow, one per request, through
// the follower's setters (the ranges are the typed settings', in state.limits). The sliders take the
// studio's keyboard steps (keysteps.js). The canvas carries the newest values as data-* attributes
// for scripts and tests.

import { keySteps } from "./keysteps.js";

const $ = (id) => document.getElementById(id);
const HOLD_MS = 400;       // a control the user just moved ignores pushes this long
const SEND_EVERY_MS = 50;  // a dragged slider sends at most this often (and its last value)
const TRACE_S = 10;        // seconds of trace drawn
const MAX_POINTS = 600;    // points kept per route
const LEVEL_RANGE = [-120, 0];

const SLIDERS = {
  gain_db: { id: "follow-gain", format: (v) => `${v >= 0 ? "+" : ""}${v.toFixed(1)} dB` },
  gate_db: { id: "follow-gate", format: (v) => `${v.toFixed(1)} dB` },
  range_db: { id: "follow-range", format: (v) => `${v.toFixed(1)} dB` },
};

export function mountFollow(studio) {
  const panel = $("follow-panel");
  const hint = $("follow-hint");
  const picker = $("follow-input");
  const inputState = $("follow-input-state");
  const meter = $("follow-meter");
  const meterText = $("follow-meter-value");
  const focus = $("follow-focus");
  const canvas = $("follow-trace");
  const routesBox = $("follow-routes");
  const error = $("follow-error");
  const gateState = $("follow-gate-state");
  const mode = $("follow-mode");

  let state = null;                 // the last message (snapshot, limits)
  const traces = new Map();         // route label -> [[t, level, intensity, balance, gate], ...]
  const heldUntil = {};
  const timers = {};
  const lastSent = {};
  let devices = [];
  let switching = false;

  function showError(text) { error.textContent = text || ""; }

  async function change(body) {
    try {
      const answer = await studio.fetchJSON("/api/follow", {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body),
      });
      showError("");
      if (answer) apply(answer);
      return true;
    } catch (failure) {
      showError(failure.message);
      return false;
    }
  }

  // ------------------------------------------------------------------ sliders and focus
  for (const [key, spec] of Object.entries(SLIDERS)) {
    const input = $(spec.id);
    const text = $(`${spec.id}-value`);
    keySteps(input);
    const send = () => {
      lastSent[key] = performance.now();
      timers[key] = null;
      change({ [key]: Number(input.value) });
    };
    input.addEventListener("input", () => {
      heldUntil[key] = performance.now() + HOLD_MS;
      text.textContent = spec.format(Number(input.value));
      if (timers[key]) return;
      const wait = SEND_EVERY_MS - (performance.now() - (lastSent[key] || 0));
      if (wait <= 0) send();
      else timers[key] = setTimeout(send, wait);
    });
  }
  focus.addEventListener("change", () => {
    heldUntil.focus = performance.now() + HOLD_MS;
    change({ focus: focus.value });
  });

  // ------------------------------------------------------------------ the input picker
  function fillPicker() {
    const snapshot = state && state.snapshot;
    const current = snapshot ? snapshot.device : "";
    const options = [];
    const first = document.createElement("option");
    first.value = "";
    first.textContent = snapshot ? `${current || "default input"} (following)` : "choose an input to follow…";
    options.push(first);
    for (const d of devices) {
      const option = document.createElement("option");
      option.value = d.name;
      option.textContent = `${d.name} (${d.channels} in${d.host_api ? `, ${d.host_api}` : ""})`;
      options.push(option);
    }
    picker.replaceChildren(...options);
    picker.value = "";
    picker.disabled = switching || !(state && state.can_start) && !snapshot;
  }

  async function loadDevices() {
    try {
      const answer = await studio.fetchJSON("/api/follow/devices");
      devices = answer.devices || [];
      if (answer.message) inputState.textContent = answer.message;
    } catch (failure) {
      devices = [];
      inputState.textContent = failure.message;
    }
    fillPicker();
  }

  picker.addEventListener("change", async () => {
    const device = picker.value;
    if (!device) return;
    if (state && !state.can_start) {
      showError("this studio cannot switch follow inputs");
      picker.value = "";
      return;
    }
    switching = true;
    inputState.textContent = `opening ${device}…`;
    picker.disabled = true;
    const ok = await change({ device });
    switching = false;
    inputState.textContent = ok ? `following ${device}` : "";
    if (ok) traces.clear();
    fillPicker();
  });
  $("follow-refresh").addEventListener("click", loadDevices);

  // ------------------------------------------------------------------ per-channel on/off
  function renderRoutes(routes) {
    const known = new Map([...routesBox.children].map((b) => [b.dataset.label, b]));
    const wanted = [];
    for (const route of routes) {
      let button = known.get(route.label);
      if (!button) {
        button = document.createElement("button");
        button.type = "button";
        button.dataset.label = route.label;
        if (route.kind === "channel") {
          button.dataset.testid = "follow-toggle";
          button.dataset.channel = String(route.index + 1);
          button.addEventListener("click", () => {
            const on = button.getAttribute("aria-pressed") !== "true";
            heldUntil[route.label] = performance.now() + HOLD_MS;
            button.setAttribute("aria-pressed", String(on));
            change({ channel: route.index + 1, on });
          });
        } else {
          button.disabled = true; // a touch source's route: on/off is per output channel
        }
        button.textContent = route.kind === "channel" ? `ch ${route.index + 1}` : `source ${route.index + 1}`;
      }
      if (!(performance.now() < (heldUntil[route.label] || 0))) {
        button.setAttribute("aria-pressed", String(route.on));
      }
      button.title = route.on ? "follows the input (click: the knobs take over)" : "the knobs play (click: follow)";
      wanted.push(button);
    }
    routesBox.replaceChildren(...wanted);
  }

  // ------------------------------------------------------------------ the trace
  function merge(trace, full) {
    if (full) traces.clear();
    for (const [label, points] of Object.entries(trace || {})) {
      const kept = traces.get(label) || [];
      const last = kept.length ? kept[kept.length - 1][0] : -Infinity;
      if (points.length && points[points.length - 1][0] < last - 1) kept.length = 0; // the input restarted
      const newest = kept.length ? kept[kept.length - 1][0] : -Infinity;
      for (const p of points) if (p[0] > newest) kept.push(p);
      if (kept.length > MAX_POINTS) kept.splice(0, kept.length - MAX_POINTS);
      traces.set(label, kept);
    }
  }

  function shownRoute() {
    const routes = (state && state.snapshot && state.snapshot.routes) || [];
    const label = `ch${studio.channel()}`;
    return routes.find((r) => r.label === label) || routes[0] || null;
  }

  function draw() {
    const ctx = canvas.getContext("2d");
    const { width, height } = canvas;
    const m = { left: 40, right: 40, top: 10, bottom: 22 };
    const w = width - m.left - m.right;
    const h = height - m.top - m.bottom;
    ctx.clearRect(0, 0, width, height);
    const route = shownRoute();
    const points = route ? traces.get(route.label) || [] : [];
    const limits = (state && state.snapshot) ? state.snapshot : null;
    const bmin = studio.hello ? studio.hello.limits.balance_min : -3.5;
    const bmax = studio.hello ? studio.hello.limits.balance_max : 3.5;
    const end = points.length ? points[points.length - 1][0] : 0;
    const x = (t) => m.left + w * (1 - (end - t) / TRACE_S);
    const yLevel = (db) => m.top + h * (LEVEL_RANGE[1] - Math.max(LEVEL_RANGE[0], Math.min(LEVEL_RANGE[1], db))) /
      (LEVEL_RANGE[1] - LEVEL_RANGE[0]);
    const yUnit = (v) => m.top + h * (1 - Math.max(0, Math.min(1, v)));
    const yBalance = (b) => yUnit((b - bmin) / (bmax - bmin));

    // grid and axes: dB on the left, intensity on the right, seconds below
    ctx.font = "11px system-ui, sans-serif";
    ctx.fillStyle = "#5a6272";
    ctx.strokeStyle = "#e7eaef";
    ctx.lineWidth = 1;
    for (let db = LEVEL_RANGE[0]; db <= LEVEL_RANGE[1]; db += 20) {
      const y = Math.round(yLevel(db)) + 0.5;
      ctx.beginPath(); ctx.moveTo(m.left, y); ctx.lineTo(m.left + w, y); ctx.stroke();
      ctx.textAlign = "right"; ctx.fillText(String(db), m.left - 4, y + 4);
    }
    ctx.textAlign = "left";
    for (const v of [0, 0.5, 1]) ctx.fillText(v.toFixed(1), m.left + w + 4, yUnit(v) + 4);
    ctx.textAlign = "center";
    for (let s = 0; s <= TRACE_S; s += 2) ctx.fillText(s ? `−${s} s` : "now", x(end - s), height - 6);

    if (points.length > 1) {
      // input level: a grey area
      ctx.fillStyle = "#c9ced6";
      ctx.beginPath();
      ctx.moveTo(x(points[0][0]), yLevel(LEVEL_RANGE[0]));
      for (const p of points) if (p[0] >= end - TRACE_S) ctx.lineTo(x(p[0]), yLevel(p[1]));
      ctx.lineTo(x(end), yLevel(LEVEL_RANGE[0]));
      ctx.closePath();
      ctx.fill();
      const line = (value, color) => {
        ctx.strokeStyle = color;
        ctx.lineWidth = 2;
        ctx.beginPath();
        let started = false;
        for (const p of points) {
          if (p[0] < end - TRACE_S) continue;
          const y = value(p);
          if (started) ctx.lineTo(x(p[0]), y); else { ctx.moveTo(x(p[0]), y); started = true; }
        }
        ctx.stroke();
      };
      line((p) => yBalance(p[3]), "#d9480f");
      line((p) => yUnit(p[2]), "#1f6feb");
    }
    if (limits) {
      ctx.strokeStyle = "#b42318";
      ctx.setLineDash([5, 4]);
      ctx.lineWidth = 1;
      const y = Math.round(yLevel(limits.gate_db)) + 0.5;
      ctx.beginPath(); ctx.moveTo(m.left, y); ctx.lineTo(m.left + w, y); ctx.stroke();
      ctx.setLineDash([]);
    }
    ctx.strokeStyle = "#9aa3b2";
    ctx.strokeRect(m.left + 0.5, m.top + 0.5, w, h);

    const last = points[points.length - 1];
    canvas.dataset.points = String(points.length);
    canvas.dataset.route = route ? route.label : "";
    canvas.dataset.t = last ? String(last[0]) : "";
    canvas.dataset.levelDb = last ? String(last[1]) : "";
    canvas.dataset.intensity = last ? String(last[2]) : "";
    canvas.dataset.balance = last ? String(last[3]) : "";
  }

  // ------------------------------------------------------------------ applying a state
  function apply(message) {
    if (message.limits) {
      for (const [key, spec] of Object.entries(SLIDERS)) {
        const input = $(spec.id);
        const [low, high] = message.limits[key];
        input.min = String(low);
        input.max = String(high);
      }
      if (focus.options.length !== message.limits.focus.length) {
        focus.replaceChildren(...message.limits.focus.map((f) => {
          const option = document.createElement("option");
          option.value = f;
          option.textContent = f;
          return option;
        }));
      }
    }
    const wasRunning = state && state.running;
    state = message;
    panel.dataset.running = String(Boolean(message.running));
    hint.textContent = message.running ? "" : message.hint;
    if (!message.running) {
      for (const spec of Object.values(SLIDERS)) $(spec.id).disabled = true;
      focus.disabled = true;
      routesBox.replaceChildren();
      meter.value = LEVEL_RANGE[0];
      meterText.textContent = "–";
      if (wasRunning || !picker.options.length) fillPicker();
      draw();
      return;
    }
    const s = message.snapshot;
    for (const [key, spec] of Object.entries(SLIDERS)) {
      const input = $(spec.id);
      input.disabled = false;
      if (performance.now() < (heldUntil[key] || 0) || timers[key]) continue;
      input.value = String(s[key]);
      $(`${spec.id}-value`).textContent = spec.format(Number(s[key]));
    }
    focus.disabled = false;
    if (!(performance.now() < (heldUntil.focus || 0))) focus.value = s.focus;
    const peak = Math.max(LEVEL_RANGE[0], Math.min(LEVEL_RANGE[1], Number(s.peak_db)));
    meter.value = peak;
    meter.dataset.levelDb = String(s.peak_db);
    meterText.textContent = s.peak_db > LEVEL_RANGE[0] ? `${s.peak_db.toFixed(1)} dB` : "silent";
    gateState.textContent = s.gate ? "open" : "closed";
    gateState.dataset.open = String(Boolean(s.gate));
    mode.textContent = `${s.mode} mode`;
    const stateText = s.state === "open" ? "" : `${s.state}${s.reason ? `: ${s.reason}` : ""}`;
    if (!switching) inputState.textContent = stateText;
    if (!wasRunning || (picker.options.length && !picker.options[0].textContent.startsWith(s.device || "default"))) {
      fillPicker();
    }
    if (message.error && !error.textContent) showError(message.error);
    renderRoutes(s.routes);
    if (message.trace) merge(message.trace, message.full);
    draw();
  }

  studio.on("follow", apply);
  studio.on("hello", async () => {
    try {
      apply(await studio.fetchJSON("/api/follow"));
    } catch (failure) {
      showError(failure.message);
    }
    loadDevices();
  });
  $("channel").addEventListener("change", draw);
}
