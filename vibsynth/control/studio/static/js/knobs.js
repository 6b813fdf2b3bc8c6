// Knobs panel: channel, intensity and balance sliders, XY pad, glide, mute, panic.
// Local moves are sent at once (one WebSocket message per input event); values pushed by
// the service (OSC, MIDI, presets, other pages) are shown unless the user is moving that
// control right now, and the control catches up when the user lets go. The keys move the sliders
// and the pad by 1 % of the range (10 % with Shift or Page Up/Down): keysteps.js.

import { keySteps, onStepKeys, stepValue } from "./keysteps.js";

const HOLD_MS = 300; // a control the user just touched ignores pushes this long

const $ = (id) => document.getElementById(id);

export function formatIntensity(v) {
  return Number(v).toFixed(3);
}

export function formatBalance(v) {
  const n = Number(v);
  return (n >= 0 ? "+" : "") + n.toFixed(3);
}

export function mountKnobs(studio) {
  const select = $("channel");
  const intensity = $("intensity");
  const balance = $("balance");
  const intensityText = $("intensity-value");
  const balanceText = $("balance-value");
  const pad = $("xy-pad");
  const dot = $("xy-dot");
  const zero = $("xy-zero");
  const glide = $("glide");
  const mute = $("mute");
  const panic = $("panic");
  const plays = $("plays");
  const error = $("knob-error");

  let limits = { balance_min: -3.5, balance_max: 3.5, glide_max_ms: 10000 };
  let channels = [];
  const heldUntil = { intensity: 0, balance: 0, glide: 0 };
  let dragging = null;
  let errorTimer = null;
  let catchUp = null;

  const current = () => channels[Number(select.value) - 1];
  studio.currentKnobs = () => current(); // the channel shown: {channel, intensity, balance, ...}
  // a local event for the other panels (the preset form follows the knobs): never sent to the service
  const announce = () => { const s = current(); if (s) studio.dispatch({ type: "knobs-shown", ...s }); };
  const held = (name) => dragging === name || dragging === "xy" && name !== "glide" || performance.now() < heldUntil[name];

  function hold(...names) {
    const until = performance.now() + HOLD_MS;
    for (const name of names) heldUntil[name] = until;
    clearTimeout(catchUp);
    catchUp = setTimeout(render, HOLD_MS + 20);
  }

  function padPosition(b, i) {
    const x = (200 * (b - limits.balance_min)) / (limits.balance_max - limits.balance_min);
    return [Math.max(0, Math.min(200, x)), 200 - 200 * Math.max(0, Math.min(1, i))];
  }

  function drawDot(b, i) {
    const [x, y] = padPosition(b, i);
    dot.setAttribute("cx", x.toFixed(1));
    dot.setAttribute("cy", y.toFixed(1));
    pad.setAttribute("aria-valuetext", `balance ${formatBalance(b)}, intensity ${formatIntensity(i)}`);
  }

  function render() {
    const s = current();
    if (!s) return;
    if (!held("intensity")) {
      intensity.value = String(s.intensity);
      intensityText.textContent = formatIntensity(s.intensity);
    }
    if (!held("balance")) {
      balance.value = String(s.balance);
      balanceText.textContent = formatBalance(s.balance);
    }
    if (!held("intensity") || !held("balance")) drawDot(Number(balance.value), Number(intensity.value));
    if (!held("glide") && document.activeElement !== glide) glide.value = String(Math.round(s.glide_ms));
    mute.setAttribute("aria-pressed", String(Boolean(s.mute)));
    mute.textContent = s.mute ? "Muted" : "Mute";
    const preset = s.preset ? `preset ${s.preset}` : "no preset";
    const driver = s.driver && s.driver !== "knobs" ? `driven by ${s.driver}` : "driven by these knobs";
    plays.textContent = `plays ${preset} · ${driver}`;
    plays.dataset.driver = s.driver || "knobs";
    announce();
  }

  function showError(text) {
    error.textContent = text;
    clearTimeout(errorTimer);
    errorTimer = setTimeout(() => { error.textContent = ""; }, 6000);
  }

  function sendKnob(name, value) {
    const s = current();
    if (!s) return;
    s[name] = value;
    studio.send({ type: "knob", channel: s.channel, name, value });
    announce();
  }

  function sendTexture(b, i) {
    const s = current();
    if (!s) return;
    s.balance = b;
    s.intensity = i;
    studio.send({ type: "texture", channel: s.channel, intensity: i, balance: b });
    announce();
  }

  // ------------------------------------------------------------------ pushes
  studio.on("hello", (hello) => {
    limits = hello.limits;
    channels = hello.state.map((s) => ({ ...s }));
    const keep = Number(select.value) || 1;
    select.replaceChildren(...channels.map((s) => new Option(`Channel ${s.channel}`, String(s.channel))));
    select.value = String(Math.min(keep, channels.length));
    balance.min = String(limits.balance_min);
    balance.max = String(limits.balance_max);
    glide.max = String(limits.glide_max_ms);
    const [zx] = padPosition(0, 0);
    zero.setAttribute("x1", zx.toFixed(1));
    zero.setAttribute("x2", zx.toFixed(1));
    render();
    studio.send({ type: "watch", channel: Number(select.value) });
  });

  studio.on("knob", (m) => {
    const s = channels[m.channel - 1];
    if (!s) return;
    s[m.name] = m.value;
    if (m.channel === Number(select.value)) {
      render();
      if (window.__studioRecord && m.name === "intensity") {
        window.__studioRecord.push({ value: m.value, t: performance.timeOrigin + performance.now() });
      }
    }
  });

  studio.on("error", (m) => {
    // learn and audition answers are shown by their own panels
    if (typeof m.id === "string" && (m.id.startsWith("learn-") || m.id.startsWith("audition-"))) return;
    showError(m.message);
  });

  // ------------------------------------------------------------------ local input
  select.addEventListener("change", () => {
    render();
    studio.send({ type: "watch", channel: Number(select.value) });
  });

  for (const [input, text, name, format] of [
    [intensity, intensityText, "intensity", formatIntensity],
    [balance, balanceText, "balance", formatBalance],
  ]) {
    keySteps(input);
    input.addEventListener("pointerdown", () => { dragging = name; });
    input.addEventListener("input", () => {
      const value = Number(input.value);
      hold(name);
      text.textContent = format(value);
      drawDot(Number(balance.value), Number(intensity.value));
      sendKnob(name, value);
    });
  }
  window.addEventListener("pointerup", () => {
    if (dragging) hold(dragging === "xy" ? "intensity" : dragging, dragging === "xy" ? "balance" : dragging);
    dragging = null;
  });

  function fromPointer(event) {
    const box = pad.getBoundingClientRect();
    const x = Math.max(0, Math.min(1, (event.clientX - box.left) / box.width));
    const y = Math.max(0, Math.min(1, (event.clientY - box.top) / box.height));
    return [limits.balance_min + x * (limits.balance_max - limits.balance_min), 1 - y];
  }

  function padMove(b, i) {
    const bb = Number(Math.max(limits.balance_min, Math.min(limits.balance_max, b)).toFixed(3));
    const ii = Number(Math.max(0, Math.min(1, i)).toFixed(3));
    hold("intensity", "balance");
    intensity.value = String(ii);
    balance.value = String(bb);
    intensityText.textContent = formatIntensity(ii);
    balanceText.textContent = formatBalance(bb);
    drawDot(bb, ii);
    sendTexture(bb, ii);
  }

  pad.addEventListener("pointerdown", (event) => {
    dragging = "xy";
    pad.setPointerCapture(event.pointerId);
    pad.focus();
    padMove(...fromPointer(event));
  });
  pad.addEventListener("pointermove", (event) => {
    if (dragging === "xy") padMove(...fromPointer(event));
  });
  onStepKeys(pad, (fraction, event) => {
    // left/right move the balance (x), up/down and Page Up/Down the intensity (y)
    const b = Number(balance.value);
    const i = Number(intensity.value);
    if (event.key === "ArrowLeft" || event.key === "ArrowRight") {
      padMove(stepValue(b, fraction, limits.balance_min, limits.balance_max), i);
    } else {
      padMove(b, stepValue(i, fraction, 0, 1));
    }
  });

  glide.addEventListener("change", () => {
    const ms = Number(glide.value);
    if (!Number.isFinite(ms) || ms < 0 || ms > limits.glide_max_ms) {
      showError(`glide must be 0..${limits.glide_max_ms} ms`);
      return;
    }
    hold("glide");
    const s = current();
    if (s) {
      s.glide_ms = ms;
      studio.send({ type: "glide", channel: s.channel, value_ms: ms });
    }
  });

  mute.addEventListener("click", () => {
    const s = current();
    if (s) studio.send({ type: "mute", channel: s.channel, value: !s.mute });
  });

  panic.addEventListener("click", () => studio.send({ type: "panic" }));
}
