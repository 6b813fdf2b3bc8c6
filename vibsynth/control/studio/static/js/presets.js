// Presets panel: the library (filter by name or tag, click to audition), a form with every
// field and its range, save as a user preset (errors beside the fields), delete user presets.
// The list follows the library live (hot reload, the command line, other pages).
// Until a preset is picked, intensity and balance follow the knobs of the channel shown, so that
// Save as saves the sound that plays; they are then left out of the request and the service fills
// them from that channel's knobs as they are when it saves (docs/studio.md, "Presets").

const $ = (id) => document.getElementById(id);
const CONFIRM_MS = 5000;
const FOLLOWED = ["intensity", "balance"]; // the fields that can follow the channel's knobs

function el(tag, attrs = {}, text = "") {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v !== null && v !== undefined) node.setAttribute(k, String(v));
  }
  if (text) node.textContent = text;
  return node;
}

export function mountPresets(studio) {
  const list = $("preset-list");
  const filter = $("preset-filter");
  const form = $("preset-form");
  const fieldsBox = $("preset-fields");
  const saveName = $("preset-save-name");
  const saveButton = $("preset-save");
  const deleteButton = $("preset-delete");
  const error = $("preset-error");
  const note = $("preset-note");
  const nameHelp = $("preset-name-help");

  let presets = [];
  let schema = null;
  let selected = null;        // name of the preset the form started from
  let dirty = false;          // the form was edited since it was loaded
  let replaceName = null;     // the name the user was asked to confirm replacing
  let deleteArmed = null;     // [name, timer] after the first click on delete
  const following = new Set(FOLLOWED); // fields showing the channel's knobs (none typed in, no preset picked)
  let followNote = null;
  const inputs = {};

  // ------------------------------------------------------------------ the form
  function buildForm() {
    fieldsBox.replaceChildren();
    for (const field of schema) {
      if (field.key === "name") {
        nameHelp.textContent = `the user preset's name (its file name): ${field.allowed}`;
        saveName.maxLength = 64;
        continue;
      }
      const id = `preset-field-${field.key}`;
      const label = el("label", { for: id }, field.key.replace("_ms", " (ms)").replace("_", " "));
      let input;
      if (field.key === "description") {
        input = el("textarea", { id, maxlength: field.maxLength, rows: 2 });
      } else if (field.key === "tags") {
        input = el("input", { id, type: "text", autocomplete: "off", placeholder: "comma-separated" });
      } else {
        const step = field.type === "integer" ? 1 : field.key === "glide_ms" ? 1 : 0.001;
        input = el("input", { id, type: "number", min: field.minimum, max: field.maximum, step, inputmode: "decimal" });
      }
      const help = el("p", { class: "field-help", id: `${id}-help` }, field.allowed);
      const problem = el("p", { class: "field-error", id: `${id}-error`, role: "alert" });
      input.setAttribute("aria-describedby", `${id}-help ${id}-error`);
      if (field.required) input.required = true;
      input.addEventListener("input", () => {
        dirty = true;
        clearProblem(field.key);
        if (following.delete(field.key)) follow();
      });
      inputs[field.key] = { input, problem, field };
      fieldsBox.append(label, input, help, problem);
    }
    const take = el("button", { type: "button", id: "preset-take-knobs" }, "Take the knobs");
    take.title = "Intensity and balance from the channel shown in the Knobs panel, following it " +
      "until you type in them or pick a preset";
    take.addEventListener("click", () => {
      for (const key of FOLLOWED) {
        following.add(key);
        clearProblem(key);
      }
      dirty = true;
      follow();
    });
    followNote = el("p", { class: "note follow", id: "preset-follow", "data-testid": "preset-follow" });
    fieldsBox.append(el("span"), take, followNote);
    follow();
  }

  /** Show the channel's knobs in the fields that follow them (knobs: the Knobs panel's channel). */
  function follow(knobs = studio.currentKnobs && studio.currentKnobs()) {
    if (!followNote) return;
    for (const key of FOLLOWED) {
      const on = following.has(key);
      inputs[key].input.classList.toggle("following", on);
      if (on && knobs) inputs[key].input.value = String(Number(Number(knobs[key]).toFixed(4)));
    }
    followNote.textContent = following.size && knobs
      ? `${[...following].join(" and ")} follow the knobs of channel ${knobs.channel}: Save saves what plays`
      : "";
  }

  function clearProblem(key) {
    const entry = inputs[key];
    if (!entry) return;
    entry.problem.textContent = "";
    entry.input.removeAttribute("aria-invalid");
  }

  function clearProblems() {
    for (const key of Object.keys(inputs)) clearProblem(key);
    saveName.removeAttribute("aria-invalid");
    error.textContent = "";
  }

  function load(preset) {
    for (const [key, { input }] of Object.entries(inputs)) {
      const value = preset[key];
      input.value = value === undefined || value === null ? "" : key === "tags" ? value.join(", ") : String(value);
    }
    saveName.value = preset.name;
    selected = preset.name;
    following.clear();
    follow();
    dirty = false;
    replaceName = null;
    clearProblems();
    renderButtons();
  }

  function values() {
    const body = {};
    for (const [key, { input, field }] of Object.entries(inputs)) {
      const text = input.value.trim();
      if (text === "" || following.has(key)) continue; // the service fills these from the channel's knobs
      if (key === "tags") body.tags = text.split(",").map((t) => t.trim()).filter(Boolean);
      else if (key === "description") body.description = input.value;
      else if (field.type === "integer") body[key] = Number.isInteger(Number(text)) ? Number(text) : text;
      else body[key] = Number.isFinite(Number(text)) ? Number(text) : text;
    }
    return body;
  }

  // ------------------------------------------------------------------ the list
  function matches(preset, text) {
    if (!text) return true;
    const t = text.toLowerCase();
    return preset.name.toLowerCase().includes(t) || (preset.tags || []).some((tag) => tag.toLowerCase().includes(t));
  }

  function renderList() {
    const text = filter.value.trim();
    const items = presets.filter((p) => matches(p, text)).map((p) => {
      const button = el("button", { type: "button", "data-testid": "preset-item", "data-name": p.name,
        "aria-current": String(p.name === selected) });
      button.append(el("strong", {}, p.name), el("span", { class: "tags" }, (p.tags || []).join(", ")),
        el("span", { class: "origin" }, p.origin));
      button.title = `${p.description || ""} (intensity ${p.intensity}, balance ${p.balance})`.trim();
      button.addEventListener("click", () => {
        load(p);
        renderList();
        studio.send({ type: "preset", channel: studio.channel(), name: p.name, id: `audition-${p.name}` });
        note.textContent = `auditioning ${p.name} on channel ${studio.channel()}`;
      });
      return el("li", {}, "").appendChild(button).parentNode;
    });
    list.replaceChildren(...items);
    if (!items.length) list.append(el("li", { class: "note" }, presets.length ? "no preset matches" : "no presets"));
  }

  function renderButtons() {
    const current = presets.find((p) => p.name === saveName.value.trim());
    deleteButton.disabled = !current || current.read_only;
    deleteButton.title = current && current.read_only ? "shipped presets are read-only" : "";
    if (!deleteArmed) deleteButton.textContent = "Delete";
    saveButton.textContent = replaceName && replaceName === saveName.value.trim() ? `Replace ${replaceName}` : "Save";
  }

  // ------------------------------------------------------------------ pushes
  studio.on("presets", (m) => {
    if (!schema && m.schema) {
      schema = m.schema;
      buildForm();
    }
    if (!m.available) {
      note.textContent = "no preset library is loaded";
      return;
    }
    presets = m.presets;
    const shown = presets.find((p) => p.name === selected);
    if (shown && !dirty && !following.size) load(shown); // a hot-reloaded change of the preset being looked at
    renderList();
    renderButtons();
    const broken = m.errors.map((e) => e.message);
    if (broken.length) note.textContent = `${broken.length} preset file(s) could not be read: ${broken[0]}`;
  });

  studio.on("error", (m) => {
    if (typeof m.id === "string" && m.id.startsWith("audition-")) error.textContent = m.message;
  });

  studio.on("knobs-shown", (knobs) => { if (following.size) follow(knobs); });

  // ------------------------------------------------------------------ actions
  filter.addEventListener("input", renderList);
  saveName.addEventListener("input", () => { saveName.removeAttribute("aria-invalid"); renderButtons(); });

  form.addEventListener("submit", async (event) => {
    event.preventDefault();
    clearProblems();
    note.textContent = "";
    const name = saveName.value.trim();
    const existing = presets.find((p) => p.name === name);
    const editingInPlace = existing && existing.origin === "user" && selected === name;
    const body = {
      ...values(), name, channel: studio.channel(), like: selected,
      overwrite: Boolean(editingInPlace || replaceName === name),
    };
    try {
      const result = await studio.fetchJSON("/api/presets", {
        method: "POST",
        headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body),
      });
      note.textContent = result.note;
      selected = name;
      dirty = false;
      replaceName = null;
      renderButtons();
    } catch (failure) {
      error.textContent = failure.message;
      const data = failure.data || {};
      if (data.exists) replaceName = name;
      for (const problem of data.problems || []) {
        const key = problem.key.split(/[.[]/)[0];
        if (key === "name") saveName.setAttribute("aria-invalid", "true");
        const entry = inputs[key];
        if (!entry) continue;
        entry.problem.textContent = problem.message;
        entry.input.setAttribute("aria-invalid", "true");
      }
      renderButtons();
    }
  });

  deleteButton.addEventListener("click", async () => {
    const name = saveName.value.trim();
    if (!deleteArmed || deleteArmed[0] !== name) {
      if (deleteArmed) clearTimeout(deleteArmed[1]);
      deleteArmed = [name, setTimeout(() => { deleteArmed = null; renderButtons(); }, CONFIRM_MS)];
      deleteButton.textContent = `Delete ${name}? Click again`;
      return;
    }
    clearTimeout(deleteArmed[1]);
    deleteArmed = null;
    clearProblems();
    try {
      const result = await studio.fetchJSON(`/api/presets/${encodeURIComponent(name)}`, { method: "DELETE" });
      note.textContent = result.note;
      if (selected === name) selected = null;
    } catch (failure) {
      error.textContent = failure.message;
    }
    renderButtons();
  });
}
