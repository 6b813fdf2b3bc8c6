// The studio's Lab tab: set up a session (experimenter), run it (participant), see its results.
// The server runs the trials and plays the stimuli; this page only shows what the participant may
// see (never a stimulus' name) and sends the answers. docs/lab.md explains the protocols.

import { keySteps } from "/static/js/keysteps.js";

const PROTOCOLS = {
  intensity: {
    label: "Intensity (experiment 1)",
    instructions: "Adjust the slider until the stimulus feels as intense as the reference. " +
      "Play either as often as you like, then press Next.",
  },
  dissimilarity: {
    label: "Dissimilarity (experiment 2)",
    instructions: "You feel two vibrations, one after the other. How different do they feel? " +
      "Set the slider, then press Next.",
  },
  resynthesis: {
    label: "Re-synthesis (experiment 3)",
    instructions: "Compare each version with the reference. Rate how similar it feels; " +
      "set the most similar one to the top (1). Play them as often as you like.",
  },
};
const GAIN_STEP = 0.005; // log10 units: 1.2 % of gain per arrow key
const LIVE_GAIN_MS = 50;

export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value === null || value === undefined || value === false) continue;
    if (key === "text") node.textContent = value;
    else if (key === "dataset") Object.assign(node.dataset, value);
    else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
    else node.setAttribute(key, value === true ? "" : value);
  }
  for (const child of children) if (child) node.append(child);
  return node;
}

export const SVG_NS = "http://www.w3.org/2000/svg";

export function fmt(value, digits = 3) {
  return value === null || value === undefined || Number.isNaN(value) ? "–" : Number(value).toFixed(digits);
}

export async function mount(panel, studio) {
  panel.append(el("link", { rel: "stylesheet", href: "/ext/lab/lab.css" }));
  const root = el("div", { class: "lab" });
  panel.append(root);

  const error = el("p", { class: "error", role: "alert", "data-testid": "lab-error" });
  const note = el("p", { class: "note", role: "status", "aria-live": "polite" });
  root.append(error, note);
  let state = { status: "idle" };
  let setupData = null;

  async function call(path, body) {
    error.textContent = "";
    try {
      const options = body === undefined ? {} : {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body),
      };
      const data = await studio.fetchJSON(`/ext/lab/${path}`, options);
      return data;
    } catch (failure) {
      error.textContent = failure.message;
      return null;
    }
  }

  // ---------------------------------------------------------------- set-up (the experimenter's)
  const setup = el("section", { class: "lab-setup", "aria-labelledby": "lab-setup-title" });
  const protocol = el("select", { id: "lab-protocol", "data-testid": "lab-protocol" });
  for (const [value, p] of Object.entries(PROTOCOLS)) protocol.append(el("option", { value, text: p.label }));
  const stimuli = el("select", { id: "lab-stimuli", "data-testid": "lab-stimuli" });
  const folder = el("input", {
    type: "text", id: "lab-stimuli-folder", "data-testid": "lab-stimuli-folder", autocomplete: "off",
    placeholder: "a folder of WAV files (optional)", "aria-describedby": "lab-folder-help",
  });
  const participant = el("input", {
    type: "text", id: "lab-participant", "data-testid": "lab-participant", autocomplete: "off",
    pattern: "[A-Za-z0-9][A-Za-z0-9_\\-]{0,63}", "aria-describedby": "lab-participant-help",
  });
  const seed = el("input", {
    type: "text", id: "lab-seed", "data-testid": "lab-seed", inputmode: "numeric", autocomplete: "off",
    value: String(Math.floor(Math.random() * 1e9)), "aria-describedby": "lab-seed-help",
  });
  const familiarisation = el("input", {
    type: "number", id: "lab-familiarisation", "data-testid": "lab-familiarisation", min: "0", max: "1000",
    step: "1", value: "30", "aria-describedby": "lab-fam-help",
  });
  const reference = el("input", {
    type: "text", id: "lab-reference", "data-testid": "lab-reference", autocomplete: "off",
    placeholder: "sine:250", "aria-describedby": "lab-reference-help",
  });
  const method = el("select", { id: "lab-method", "data-testid": "lab-method", "aria-describedby": "lab-method-help" },
    el("option", { value: "adjustment", text: "Adjustment (a gain slider)" }),
    el("option", { value: "staircase", text: "Staircase, 1-up/1-down (stronger/weaker)" }),
    el("option", { value: "staircase-2d1u", text: "Staircase, 2-down/1-up (70.7 % point)" }));
  const channel = el("select", { id: "lab-channel" });
  const start = el("button", { type: "submit", "data-testid": "lab-start", text: "Start session" });
  const form = el("form", { class: "lab-form", novalidate: true },
    el("h2", { id: "lab-setup-title", text: "New session" }),
    el("div", { class: "field" }, el("label", { for: "lab-protocol", text: "Protocol" }), protocol),
    el("div", { class: "field" }, el("label", { for: "lab-stimuli", text: "Stimuli" }), stimuli),
    el("div", { class: "field" }, el("label", { for: "lab-stimuli-folder", text: "Folder" }), folder),
    el("p", { class: "help", id: "lab-folder-help", text: "A folder here takes the place of the list above." }),
    el("div", { class: "field" }, el("label", { for: "lab-participant", text: "Participant" }), participant),
    el("p", { class: "help", id: "lab-participant-help", text: "An id, not a name: letters, digits, '_' or '-'." }),
    el("div", { class: "field" }, el("label", { for: "lab-seed", text: "Seed" }), seed),
    el("p", { class: "help", id: "lab-seed-help", text: "The same seed gives the same trial order." }),
    el("div", { class: "field" }, el("label", { for: "lab-familiarisation", text: "Familiarisation pairs" }), familiarisation),
    el("p", { class: "help", id: "lab-fam-help", text: "Dissimilarity only; not saved. The paper: 30. 0 to skip." }),
    el("div", { class: "field" }, el("label", { for: "lab-reference", text: "Reference sine" }), reference),
    el("div", { class: "field" }, el("label", { for: "lab-method", text: "Method (sines)" }), method),
    el("p", { class: "help", id: "lab-method-help", text: "Sines only: adjust a slider, or answer stronger/weaker while a staircase sets the level." }),
    el("p", { class: "help", id: "lab-reference-help",
      text: "Sines (iso-intensity) only: sine:F, default 250 Hz. Type sines:F1,F2,… (8–12, 10–1000 Hz) in Folder for your own frequencies." }),
    el("div", { class: "field" }, el("label", { for: "lab-channel", text: "Actuator" }), channel),
    el("div", { class: "actions" }, start),
  );
  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    start.disabled = true;
    note.textContent = "Preparing the stimuli…";
    const result = await call("start", {
      protocol: protocol.value,
      stimuli: stimuli.value,
      folder: folder.value.trim(),
      participant: participant.value.trim(),
      seed: seed.value.trim(),
      familiarisation: Number(familiarisation.value),
      channel: Number(channel.value),
      reference: reference.value.trim() || null,
      method: method.value,
    });
    start.disabled = false;
    note.textContent = "";
    if (result) render(result);
  });

  const sessionList = el("ul", { class: "lab-sessions", "aria-label": "Sessions that can be resumed" });
  const resumeSession = el("button", { type: "button", "data-testid": "lab-resume", text: "Resume session" });
  resumeSession.addEventListener("click", async () => {
    const chosen = sessionList.querySelector("input[name=lab-session]:checked");
    if (!chosen) { error.textContent = "Choose a session to resume."; return; }
    const result = await call("open", { folder: chosen.dataset.folder, channel: Number(channel.value) });
    if (result) render(result);
  });
  const doneList = el("ul", { class: "lab-sessions", "aria-label": "Sessions to analyse" });
  const analyse = el("button", { type: "button", text: "Analyse selected" });
  const equalise = el("button", { type: "button", text: "Store gains as an equalised set" });
  const results = el("div", { class: "lab-results", "aria-live": "polite" });
  analyse.addEventListener("click", () => analyseFolders(checked(doneList), results));
  equalise.addEventListener("click", async () => {
    const folders = checked(doneList);
    if (!folders.length) { error.textContent = "Choose intensity sessions."; return; }
    const result = await call("equalise", { folders });
    if (result) { note.textContent = `Stored ${result.stimuli} stimuli in ${result.folder}`; loadSetup(); }
  });
  setup.append(
    form,
    el("section", { class: "lab-box", "aria-labelledby": "lab-resume-title" },
      el("h2", { id: "lab-resume-title", text: "Unfinished sessions" }), sessionList,
      el("div", { class: "actions" }, resumeSession)),
    el("section", { class: "lab-box", "aria-labelledby": "lab-results-title" },
      el("h2", { id: "lab-results-title", text: "Results" }),
      el("p", { class: "help", text: "Several participants' sessions of one protocol and stimulus set are analysed together." }),
      doneList, el("div", { class: "actions" }, analyse, equalise), results),
  );

  function checked(list) {
    return [...list.querySelectorAll("input[type=checkbox]:checked")].map((box) => box.dataset.folder);
  }

  function sessionLabel(s) {
    return `${s.participant} · ${s.protocol} · ${s.done} / ${s.total} · ${s.set} · ${s.created.slice(0, 16).replace("T", " ")}`;
  }

  async function loadSetup() {
    const data = await call("setup");
    if (!data) return;
    setupData = data;
    const previous = stimuli.value;
    stimuli.replaceChildren(...data.sets.map((s) => el("option", { value: s.value, text: s.label })));
    if ([...stimuli.options].some((o) => o.value === previous)) stimuli.value = previous;
    if (!familiarisation.dataset.touched) familiarisation.value = String(data.defaults.familiarisation_pairs);
    channel.replaceChildren(el("option", { value: "0", text: "All channels" }));
    for (let c = 1; c <= data.channels; c++) channel.append(el("option", { value: String(c), text: `Channel ${c}` }));
    sessionList.replaceChildren();
    doneList.replaceChildren();
    for (const s of data.sessions.slice().reverse()) {
      const id = `lab-s-${Math.random().toString(36).slice(2)}`;
      if (!s.complete) {
        sessionList.append(el("li", {},
          el("input", { type: "radio", name: "lab-session", id, "data-testid": "lab-session", dataset: { folder: s.folder } }),
          el("label", { for: id, text: sessionLabel(s) })));
      }
      if (s.done > 0) {
        doneList.append(el("li", {},
          el("input", { type: "checkbox", id: `${id}-a`, dataset: { folder: s.folder, protocol: s.protocol } }),
          el("label", { for: `${id}-a`, text: sessionLabel(s) })));
      }
    }
    if (!sessionList.children.length) sessionList.append(el("li", { class: "help", text: "none" }));
    for (const problem of data.problems) note.textContent = problem;
    render(data.state);
  }
  familiarisation.addEventListener("input", () => { familiarisation.dataset.touched = "1"; });

  // ---------------------------------------------------------------- the run (the participant's)
  const run = el("section", { class: "lab-run", hidden: true, "aria-labelledby": "lab-run-title" });
  const progress = el("span", { "data-testid": "lab-progress", class: "progress" });
  const phase = el("span", { "data-testid": "lab-phase", class: "phase" });
  const instructions = el("p", { class: "instructions", id: "lab-instructions" });
  const answers = el("div", { class: "answers" });
  const next = el("button", { type: "button", "data-testid": "lab-next", class: "primary", text: "Next" });
  const pause = el("button", { type: "button", "data-testid": "lab-pause", text: "Pause" });
  const resume = el("button", { type: "button", "data-testid": "lab-resume", text: "Resume", hidden: true });
  const stop = el("button", { type: "button", class: "danger", text: "Stop session (experimenter)" });
  run.append(
    el("div", { class: "run-head" },
      el("h2", { id: "lab-run-title", text: "Trial " }, progress), phase),
    instructions, answers,
    el("div", { class: "actions" }, next, pause, resume, stop),
    el("p", { class: "help", text: "Keys: P plays, R plays the reference, Enter goes on." }),
  );
  next.addEventListener("click", submit);
  pause.addEventListener("click", async () => { const s = await call("pause", {}); if (s) render(s); });
  resume.addEventListener("click", async () => { const s = await call("resume", {}); if (s) render(s); });
  stop.addEventListener("click", async () => {
    const s = await call("stop", {});
    if (s) { render(s); loadSetup(); }
  });
  run.addEventListener("keydown", (event) => {
    if (event.target.tagName === "BUTTON" && event.key === "Enter") return;
    const key = event.key.toLowerCase();
    if (key === "p") { play(null); event.preventDefault(); }
    else if (key === "r" && state.protocol !== "dissimilarity") { playReference(); event.preventDefault(); }
    else if (key === "enter") { submit(); event.preventDefault(); }
  });

  let trialKey = "";
  let touched = false;
  let gainTimer = null;

  // Rating sliders (0..1) step 1 % per arrow key, 10 % with Shift or Page Up/Down (the
  // studio's keyboard steps); the intensity slider keeps its log step per key (GAIN_STEP).
  function slider(attrs, low, high, { steps = true } = {}) {
    const input = el("input", { type: "range", ...attrs });
    if (steps) keySteps(input);
    return el("div", { class: "scale" },
      el("span", { class: "end", text: low }),
      input,
      el("span", { class: "end", text: high }));
  }

  const staircase = () => state.protocol === "intensity" && Boolean(state.method) && state.method !== "adjustment";

  async function judge(judgement) {
    for (const b of answers.querySelectorAll("button")) b.disabled = true;
    const s = await call("answer", { judgement });
    if (s) render(s);
    else for (const b of answers.querySelectorAll("button")) b.disabled = false;
  }

  function buildAnswers() {
    answers.replaceChildren();
    touched = false;
    next.hidden = staircase();
    if (staircase()) {
      // The staircase sets the level; the participant only compares it with the reference.
      answers.append(
        el("div", { class: "buttons" },
          el("button", { type: "button", "data-testid": "lab-play-reference", text: "Play reference", onclick: playReference }),
          el("button", { type: "button", "data-testid": "lab-play", text: "Play stimulus", onclick: () => play(null) })),
        el("p", { id: "lab-judge-help", text: "Compared with the reference, the stimulus feels:" }),
        el("div", { class: "buttons", role: "group", "aria-labelledby": "lab-judge-help" },
          el("button", { type: "button", "data-testid": "lab-weaker", text: "Weaker", onclick: () => judge("weaker") }),
          el("button", { type: "button", "data-testid": "lab-stronger", text: "Stronger", onclick: () => judge("stronger") })));
      next.disabled = true;
    } else if (state.protocol === "dissimilarity") {
      const row = slider({ "data-testid": "lab-answer", min: "0", max: "1", step: "0.001", value: "0.5",
        "aria-label": "Dissimilarity: very similar (0) to very dissimilar (1)" }, "very similar", "very dissimilar");
      row.querySelector("input").addEventListener("input", () => { touched = true; next.disabled = false; });
      answers.append(el("div", { class: "buttons" },
        el("button", { type: "button", "data-testid": "lab-play", text: "Play the pair again", onclick: () => play(null) })), row);
      next.disabled = true;
    } else if (state.protocol === "intensity") {
      const [lo, hi] = state.gain_range.map(Math.log10);
      const row = slider({ "data-testid": "lab-answer", min: String(lo), max: String(hi), step: String(GAIN_STEP),
        value: String(state.start), "aria-label": "Intensity of the stimulus: weaker to stronger" }, "weaker", "stronger",
        { steps: false });
      const input = row.querySelector("input");
      input.addEventListener("input", () => liveGain(Number(input.value)));
      answers.append(el("div", { class: "buttons" },
        el("button", { type: "button", "data-testid": "lab-play", text: "Play stimulus", onclick: () => play(null) }),
        el("button", { type: "button", "data-testid": "lab-play-reference", text: "Play reference", onclick: playReference })),
      row);
      next.disabled = false;
    } else {
      answers.append(el("div", { class: "buttons" },
        el("button", { type: "button", "data-testid": "lab-play-reference", text: "Play reference", onclick: playReference })));
      for (let slot = 1; slot <= state.slots; slot++) {
        const row = slider({ "data-testid": "lab-answer", "data-slot": String(slot), min: "0", max: "1", step: "0.001",
          value: "0", "aria-label": `Version ${slot}: very dissimilar (0) to very similar (1)` }, "very dissimilar", "very similar");
        row.prepend(el("button", { type: "button", "data-testid": "lab-play", "data-slot": String(slot),
          text: `Play ${slot}`, onclick: () => play(slot) }));
        answers.append(row);
      }
      next.disabled = false;
    }
  }

  function liveGain(value) {
    if (gainTimer) return;
    gainTimer = setTimeout(async () => {
      gainTimer = null;
      const input = answers.querySelector("[data-testid=lab-answer]");
      try {
        await studio.fetchJSON("/ext/lab/gain", {
          method: "POST", headers: { "Content-Type": "application/json" },
          body: JSON.stringify({ gain: 10 ** Number(input.value) }),
        });
      } catch { /* a refused live gain changes nothing; Next reports real errors */ }
    }, LIVE_GAIN_MS);
  }

  async function play(slot) {
    const body = {};
    if (slot !== null) body.slot = slot;
    if (state.protocol === "intensity" && !staircase()) body.gain = 10 ** Number(answers.querySelector("[data-testid=lab-answer]").value);
    const s = await call("play", body);
    if (s) render(s);
  }

  async function playReference() {
    const s = await call("play-reference", {});
    if (s) render(s);
  }

  async function submit() {
    if (next.disabled || staircase()) return;
    let body;
    if (state.protocol === "resynthesis") {
      body = { ratings: {} };
      for (const input of answers.querySelectorAll("[data-testid=lab-answer]")) body.ratings[input.dataset.slot] = Number(input.value);
    } else {
      const value = Number(answers.querySelector("[data-testid=lab-answer]").value);
      body = { value: state.protocol === "intensity" ? 10 ** value : value };
    }
    next.disabled = true;
    const s = await call("answer", body);
    if (s) render(s);
    else next.disabled = false;
  }

  // ---------------------------------------------------------------- done
  const done = el("section", { class: "lab-done", hidden: true, "data-testid": "lab-done", "aria-labelledby": "lab-done-title" });
  const doneFolder = el("code", {});
  const doneResults = el("div", { class: "lab-results" });
  const showResults = el("button", { type: "button", text: "Show the results" });
  done.append(
    el("h2", { id: "lab-done-title", text: "Thank you: the session is complete." }),
    el("p", {}, "Saved in ", doneFolder),
    el("details", {}, el("summary", { text: "Results (for the experimenter)" }), showResults, doneResults),
    el("div", { class: "actions" }, el("button", { type: "button", text: "Back to set-up", onclick: async () => {
      state = { status: "idle" };
      await loadSetup();
      show("setup");
    } })),
  );
  showResults.addEventListener("click", () => analyseFolders([done.dataset.folder], doneResults));

  root.append(setup, run, done);

  function show(view) {
    setup.hidden = view !== "setup";
    run.hidden = view !== "run";
    done.hidden = view !== "done";
  }

  function render(next_state) {
    if (!next_state) return;
    state = next_state;
    if (state.error) error.textContent = state.error;
    if (state.status === "preparing") {
      note.textContent = "Preparing the stimuli…";
      start.disabled = true;
      return;
    }
    start.disabled = false;
    if (state.status === "done") {
      done.dataset.folder = state.folder || "";
      doneFolder.textContent = state.folder || "";
      show("done");
      return;
    }
    if (state.status === "idle") {
      if (!run.hidden) loadSetup();
      show("setup");
      return;
    }
    show("run");
    progress.textContent = `${state.progress[0]} / ${state.progress[1]}`;
    phase.textContent = state.phase;
    run.dataset.phase = state.phase;
    instructions.textContent = PROTOCOLS[state.protocol].instructions;
    const key = `${state.protocol}:${state.phase}:${state.progress[0]}:${state.familiarisation[0]}`;
    if (key !== trialKey) {
      trialKey = key;
      buildAnswers();
    }
    const paused = state.status === "paused";
    pause.hidden = paused;
    resume.hidden = !paused;
    for (const control of answers.querySelectorAll("button, input")) control.disabled = paused;
    if (paused) next.disabled = true;
    else if (state.protocol !== "dissimilarity" || touched) next.disabled = false;
  }

  // ---------------------------------------------------------------- results
  async function analyseFolders(folders, into) {
    if (!folders.length) { error.textContent = "Choose sessions to analyse."; return; }
    into.replaceChildren(el("p", { class: "note", text: "Analysing…" }));
    const result = await call("analyze", { folders });
    into.replaceChildren();
    if (!result) return;
    if (result.iso) into.append(...isoResults(result.iso));
    else if (result.protocol === "intensity") into.append(...intensityResults(result));
    else if (result.protocol === "dissimilarity") into.append(...dissimilarityResults(result));
    else into.append(...resynthesisResults(result));
  }

  function table(head, rows) {
    return el("table", {},
      el("thead", {}, el("tr", {}, ...head.map((h) => el("th", { scope: "col", text: h })))),
      el("tbody", {}, ...rows.map((r) => el("tr", {}, ...r.map((c) => el("td", { text: String(c) }))))));
  }

  function intensityResults(r) {
    return [
      el("p", { text: `Intensity model: judged dB = ${fmt(r.slope, 2)} × (80–200 Hz level) ${r.intercept >= 0 ? "+" : ""}${fmt(r.intercept, 2)}, ` +
        `R² = ${fmt(r.r2)} (paper: 0.90); on the 10–1000 Hz level R² = ${fmt(r.r2_broadband)} (paper: 0.07).` }),
      el("p", { text: `80–200 Hz level SD: ${fmt(r.level_sd_before, 2)} dB as played, ${fmt(r.level_sd_after, 2)} dB after equalisation.` }),
      table(["stimulus", "80–200 Hz dB", "mean gain", "equalised dB"],
        r.ids.map((id, k) => [id, fmt(r.level_db[k], 2), fmt(r.mean_gain[k]), fmt(r.equalised_db[k], 2)])),
    ];
  }

  function svgFigure(viewBox, cls, label) {
    const svg = document.createElementNS(SVG_NS, "svg");
    svg.setAttribute("viewBox", viewBox);
    svg.setAttribute("class", cls);
    svg.setAttribute("role", "img");
    svg.setAttribute("aria-label", label);
    return svg;
  }

  // Iso-intensity curve (sines): the drive for equal intensity, dB re the reference sine, per frequency.
  function isoResults(iso) {
    const head = ["Hz", "mean dB", "SD dB", ...iso.participants];
    const rows = iso.frequency_hz.map((f, k) => [fmt(f, 1), fmt(iso.mean_db[k], 2), fmt(iso.sd_db[k], 2),
      ...iso.voltage_db.map((row) => fmt(row[k], 2))]);
    const t = table(head, rows);
    t.dataset.testid = "lab-iso-table";
    return [
      el("p", { text: `Iso-intensity curve: drive for the intensity of the ${fmt(iso.reference_hz, 0)} Hz reference sine, ` +
        `dB re its drive (${iso.participants.length} participant${iso.participants.length === 1 ? "" : "s"}).` }),
      isoPlot(iso), t,
    ];
  }

  function isoPlot(iso) {
    const ns = SVG_NS;
    const svg = svgFigure("0 0 400 200", "iso", "Iso-intensity curve: dB re the reference over log frequency");
    svg.setAttribute("data-testid", "lab-iso-plot");
    const values = iso.mean_db.filter((v) => v !== null);
    const lo = Math.min(...values, 0) - 3, hi = Math.max(...values, 0) + 3;
    const x = (f) => 20 + 360 * Math.log(f / 10) / Math.log(100);
    const y = (v) => 190 - 180 * (v - lo) / (hi - lo);
    const points = iso.frequency_hz.map((f, k) => [f, iso.mean_db[k]]).filter(([, v]) => v !== null);
    const line = document.createElementNS(ns, "polyline");
    line.setAttribute("points", points.map(([f, v]) => `${x(f).toFixed(1)},${y(v).toFixed(1)}`).join(" "));
    line.setAttribute("fill", "none");
    line.setAttribute("stroke", "currentColor");
    line.setAttribute("stroke-width", "2");
    const zero = document.createElementNS(ns, "line");
    Object.entries({ x1: 20, x2: 380, y1: y(0), y2: y(0), stroke: "gray", "stroke-dasharray": "4 3" })
      .forEach(([a, b]) => zero.setAttribute(a, b));
    svg.append(zero, line);
    return el("figure", {}, svg, el("figcaption", { text: "10 Hz … 1000 Hz (log); dashed: the reference's drive." }));
  }

  function dissimilarityResults(r) {
    const out = [el("p", { text: `${r.pairs.length} pairs rated; self-pairs ${fmt(r.self_mean)} (paper: 0.12).` })];
    if (r.fit) {
      out.push(el("p", { text: `Held-out R² = ${fmt(r.fit.r2_mean)} (SD ${fmt(r.fit.r2_sd)}; paper: 0.54) over ${r.fit.n_splits} splits, ${r.fit.cv}-fold CV.` }));
      out.push(table(["component", "weight w_j", "selected"],
        r.fit.weights.map((w, j) => [`T${j + 1}`, fmt(w, 5), `${Math.round(100 * r.fit.selected_fraction[j])} %`])));
    }
    if (r.problem) out.push(el("p", { class: "note", text: r.problem }));
    if (r.mds) out.push(mdsMap(r.mds));
    return out;
  }

  function mdsMap(mds) {
    const ns = SVG_NS;
    const svg = svgFigure("-1.15 -1.15 2.3 2.3", "mds", "MDS map of the ratings (blue) and of the model (red)");
    const all = mds.rated.concat(mds.predicted).flat().map(Math.abs);
    const scale = Math.max(...all, 1e-9);
    // Points inside +-0.8 of the +-1.15 view: room for the names around them.
    const point = (p) => [0.8 * p[0] / scale, -0.8 * p[1] / scale];
    // Neighbours along the first dimension take turns above and below their points.
    const order = mds.rated.map((p, k) => k).sort((a, b) => mds.rated[a][0] - mds.rated[b][0]);
    const below = new Set(order.filter((k, rank) => rank % 2 === 1));
    mds.rated.forEach((p, k) => {
      const [x, y] = point(p);
      const [u, v] = point(mds.predicted[k]);
      const line = document.createElementNS(ns, "line");
      Object.entries({ x1: x, y1: y, x2: u, y2: v, class: "err" }).forEach(([a, b]) => line.setAttribute(a, b));
      const dot = document.createElementNS(ns, "circle");
      Object.entries({ cx: x, cy: y, r: 0.03, class: "rated" }).forEach(([a, b]) => dot.setAttribute(a, b));
      const model = document.createElementNS(ns, "rect");
      Object.entries({ x: u - 0.02, y: v - 0.02, width: 0.04, height: 0.04, class: "model" }).forEach(([a, b]) => model.setAttribute(a, b));
      const label = document.createElementNS(ns, "text");
      // Names on the right half read leftwards from their point, so none runs off the map.
      const right = x > 0.2;
      const dy = below.has(k) ? 0.1 : -0.04;
      Object.entries({ x: right ? x - 0.04 : x + 0.04, y: y + dy, class: "name", "text-anchor": right ? "end" : "start" })
        .forEach(([a, b]) => label.setAttribute(a, b));
      label.textContent = mds.names[k];
      svg.append(line, dot, model, label);
    });
    const r = mds.component_r[0];
    return el("figure", {}, svg, el("figcaption", {
      text: `MDS of the mean ratings (blue) and of the model (red). t1 vs dimension 1: r = ${fmt(r[0], 2)} (paper: 0.94).` }));
  }

  function resynthesisResults(r) {
    return [table(["version", "n", "mean", "SD", "median"],
      r.summary.map((row) => [row.version, row.n, fmt(row.mean), fmt(row.sd), fmt(row.median)]))];
  }

  studio.onExtension("lab", (key, data) => { if (key === "state") render(data); });
  await loadSetup();
}
