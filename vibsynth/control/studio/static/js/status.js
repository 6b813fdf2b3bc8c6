// Status panel: output state, device, rate, underflows, load, OSC/MIDI counters, last errors, MIDI learn.

const $ = (id) => document.getElementById(id);

function pct(v) {
  return typeof v === "number" && v >= 0 ? `${(100 * v).toFixed(1)} %` : "?";
}

function known(v) {
  return v === null || v === undefined || v === -1 ? "?" : String(v);
}

export function mountStatus(studio) {
  const state = $("status-state");
  const note = $("learn-note");

  studio.on("status", (s) => {
    state.textContent = s.state_reason ? `${s.state}: ${s.state_reason}` : s.state;
    state.dataset.state = s.state;
    $("status-device").textContent = s.device || "?";
    $("status-rate").textContent = `${known(s.rate)} Hz, block ${known(s.block_size)}`;
    $("status-underflows").textContent = known(s.underflows);
    $("status-load").textContent = `${pct(s.load)} (peak ${pct(s.load_peak)})`;
    $("status-osc").textContent = s.osc
      ? `messages ${known(s.osc.messages)}, fast path ${known(s.osc.fast_path)}, malformed ${known(s.osc.malformed)}, ` +
        `denied ${known(s.osc.denied)}, errors ${known(s.osc.errors)}`
      : `not running; errors (all inputs) ${known(s.errors_total)}`;
    $("status-midi").textContent = s.midi.length
      ? s.midi.map((m) => {
          const counts = Object.entries(m.counts).map(([k, v]) => `${k} ${v}`).join(", ") || "no messages yet";
          return `${m.port}: ${counts}${m.learning ? ` (learning ${m.learning})` : ""}`;
        }).join("; ")
      : "no MIDI input";
    const refused = Object.entries(s.studio.refused).map(([k, v]) => `${k} ${v}`).join(", ");
    $("status-studio").textContent = `${s.studio.pages} page(s) open; refused ${s.studio.refused_total}` +
      (refused ? ` (${refused})` : "");
    const learning = s.midi.map((m) => m.learning).filter(Boolean);
    for (const knob of ["intensity", "balance"]) {
      $(`learn-${knob}`).setAttribute("aria-pressed", String(learning.includes(knob)));
    }
    $("status-errors").replaceChildren(...s.errors.slice().reverse().map((e) => {
      const li = document.createElement("li");
      li.textContent = `${new Date(e.time * 1000).toLocaleTimeString()} ${e.text}`;
      return li;
    }));
  });

  for (const knob of ["intensity", "balance"]) {
    $(`learn-${knob}`).addEventListener("click", () => {
      note.textContent = `move a MIDI controller to bind it to ${knob}…`;
      studio.send({ type: "learn", knob, id: `learn-${knob}` });
    });
  }
  studio.on("error", (m) => {
    if (typeof m.id === "string" && m.id.startsWith("learn-")) note.textContent = m.message;
  });
}
