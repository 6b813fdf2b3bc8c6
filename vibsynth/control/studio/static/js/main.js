// The studio page: one WebSocket to the service, the tab bar, and the panels.
// Each panel is an ES module with mount(studio); extension tabs are imported on first open
// and their mount(panel, studio) is called (docs/studio.md, "Extensions").

import { mountKnobs } from "./knobs.js";
import { mountSpectrum } from "./spectrum.js";
import { mountPresets } from "./presets.js";
import { mountRecording } from "./recording.js";
import { mountStatus } from "./status.js";
import { mountFollow } from "./follow.js";

const RECONNECT_MIN_MS = 250;
const RECONNECT_MAX_MS = 5000;

class Studio {
  constructor() {
    this.handlers = new Map();       // message type -> [fn]
    this.extensionHandlers = new Map(); // extension name -> [fn]
    this.hello = null;
    this.ws = null;
    this.nextId = 1;
    this.retryMs = RECONNECT_MIN_MS;
    this.connection = document.getElementById("connection");
  }

  /**
   * Call fn(message) for every pushed message of this type ("hello", "knob", "status", ...), and
   * for the panels' local events ("knobs-shown": the knobs of the channel shown, after any change).
   */
  on(type, fn) {
    if (!this.handlers.has(type)) this.handlers.set(type, []);
    this.handlers.get(type).push(fn);
  }

  /** Call fn(key, data) for every message an extension publishes (StudioHost.publish). */
  onExtension(name, fn) {
    if (!this.extensionHandlers.has(name)) this.extensionHandlers.set(name, []);
    this.extensionHandlers.get(name).push(fn);
  }

  /** Send a message (an object with a type); returns false while disconnected. */
  send(message) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    this.ws.send(JSON.stringify(message));
    return true;
  }

  /** The channel the page shows (1-based). */
  channel() {
    return Number(document.getElementById("channel").value || 1);
  }

  /** fetch() returning parsed JSON; throws Error(message) with the server's error text. */
  async fetchJSON(url, options = {}) {
    const response = await fetch(url, { credentials: "same-origin", ...options });
    const text = await response.text();
    let data = null;
    try { data = text ? JSON.parse(text) : null; } catch { data = null; }
    if (!response.ok) {
      const error = new Error((data && data.message) || text.trim() || `HTTP ${response.status}`);
      error.status = response.status;
      error.data = data;
      throw error;
    }
    return data;
  }

  dispatch(message) {
    if (message.type === "batch") {
      for (const inner of message.messages) this.dispatch(inner);
      return;
    }
    if (message.type === "hello") this.hello = message;
    if (message.type === "ext") {
      for (const fn of this.extensionHandlers.get(message.extension) || []) fn(message.key, message.data);
      return;
    }
    for (const fn of this.handlers.get(message.type) || []) {
      try { fn(message); } catch (error) { console.error(error); }
    }
  }

  setConnection(state, text) {
    this.connection.dataset.state = state;
    this.connection.textContent = text;
  }

  connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    this.ws = ws;
    ws.addEventListener("open", () => {
      this.retryMs = RECONNECT_MIN_MS;
      this.setConnection("open", "connected");
    });
    ws.addEventListener("message", (event) => {
      let message;
      try { message = JSON.parse(event.data); } catch { return; }
      this.dispatch(message);
    });
    ws.addEventListener("close", async (event) => {
      this.ws = null;
      if (event.code === 1001) {
        this.setConnection("closed", "vibsynth stopped; reconnecting…");
      } else {
        this.setConnection("closed", "disconnected; reconnecting…");
      }
      // A studio restarted with a new token refuses our cookie: say so instead of retrying forever.
      try {
        const response = await fetch("/api/state", { credentials: "same-origin" });
        if (response.status === 403) {
          this.setConnection("refused", "refused: the studio's token changed; open the URL vibsynth serve printed");
          return;
        }
      } catch { /* not reachable yet */ }
      setTimeout(() => this.connect(), this.retryMs);
      this.retryMs = Math.min(RECONNECT_MAX_MS, this.retryMs * 2);
    });
  }
}

function mountTabs(studio) {
  const tabs = document.getElementById("tabs");
  const main = document.querySelector("main");
  const loaded = new Set();

  function select(name) {
    for (const tab of tabs.querySelectorAll("[role=tab]")) {
      const on = tab.dataset.tab === name;
      tab.setAttribute("aria-selected", String(on));
      tab.tabIndex = on ? 0 : -1;
      document.getElementById(tab.getAttribute("aria-controls")).hidden = !on;
    }
  }

  async function open(ext) {
    select(ext.name);
    if (loaded.has(ext.name)) return;
    loaded.add(ext.name);
    const panel = document.getElementById(`panel-${ext.name}`);
    try {
      const module = await import(ext.script);
      await module.mount(panel, studio);
    } catch (error) {
      panel.textContent = `The ${ext.title} tab failed to load: ${error.message}`;
    }
  }

  tabs.addEventListener("keydown", (event) => {
    const all = [...tabs.querySelectorAll("[role=tab]")];
    const at = all.indexOf(document.activeElement);
    if (at < 0) return;
    const step = event.key === "ArrowRight" ? 1 : event.key === "ArrowLeft" ? -1 : 0;
    if (!step) return;
    const next = all[(at + step + all.length) % all.length];
    next.focus();
    next.click();
    event.preventDefault();
  });
  document.getElementById("tab-studio").addEventListener("click", () => select("studio"));

  studio.on("hello", (hello) => {
    for (const ext of hello.extensions) {
      if (document.getElementById(`tab-${ext.name}`)) continue;
      const tab = document.createElement("button");
      tab.setAttribute("role", "tab");
      tab.id = `tab-${ext.name}`;
      tab.dataset.tab = ext.name;
      tab.setAttribute("aria-controls", `panel-${ext.name}`);
      tab.setAttribute("aria-selected", "false");
      tab.tabIndex = -1;
      tab.textContent = ext.title;
      tab.addEventListener("click", () => open(ext));
      tabs.appendChild(tab);
      const panel = document.createElement("section");
      panel.id = `panel-${ext.name}`;
      panel.setAttribute("role", "tabpanel");
      panel.setAttribute("aria-labelledby", tab.id);
      panel.className = "workspace extension";
      panel.hidden = true;
      main.appendChild(panel);
      if (location.hash === `#${ext.name}`) open(ext); // a link to one tab (vibsynth lab opens #lab)
    }
  });
}

const studio = new Studio();
window.studio = studio; // for scripts and tests in the browser console
mountTabs(studio);
mountKnobs(studio);
mountSpectrum(studio);
mountPresets(studio);
mountRecording(studio);
mountStatus(studio);
mountFollow(studio);
studio.connect();
