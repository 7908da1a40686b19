// The dashboard page: one page for the simulator (mode "sim") and for the robot's box picker
// (mode "picker", served by box_picker.py); /api/config says which. The box is drawn by BoxCanvas.
import {BoxCanvas} from "./box_canvas.js";

const LIVE_VIEWS = ["wrist_A", "third_A", "wrist_B", "third_B"]; // server.py's LIVE_VIEWS, in order
const $ = (id) => document.getElementById(id);
const fmt = (box) => (box ? "[" + box.map((v) => v.toFixed(3)).join(", ") + "]" : "none");

class ApiError extends Error {
  constructor(message, status) { super(message); this.status = status; }
}

async function api(method, path, body) {
  const init = {method, headers: {}};
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetch(path, init);
  let data = null;
  try { data = await response.json(); } catch { data = null; }
  if (!response.ok) throw new ApiError(data?.error ?? `${response.status} ${response.statusText}`, response.status);
  return data;
}

function showMessage(text, kind = "info") {
  const el = $("message");
  el.textContent = text;
  el.className = `message ${kind}`;
  el.dataset.kind = kind;
}

// ---------------------------------------------------------------- simulator mode
class SimPage {
  constructor(config) {
    this.config = config;
    this.sceneVersion = null;
    this.frameTimes = [];
    this.canvas = new BoxCanvas($("box-canvas"), {
      onBox: (box) => this.request("POST", "/api/target", {box}),
      onClick: (point) => this.request("POST", "/api/target", {point}),
    });
    for (const s of config.settings) $("setting").add(new Option(s, s));
    for (const p of config.policies) {
      $("policy-A").add(new Option(p.label, p.id));
      $("policy-B").add(new Option(p.label, p.id));
    }
    for (const m of config.bbox_modes) $("bbox-mode").add(new Option(m, m));
    $("max-steps").value = config.default_max_steps;
    $("max-steps").max = config.max_steps_limit;
    $("load").onclick = () => this.request("POST", "/api/scene", {
      setting: $("setting").value, seed: Number($("seed").value),
    });
    $("run").onclick = () => this.request("POST", "/api/run", this.runRequest());
    for (const name of ["pause", "resume", "step", "reset"]) {
      $(name).onclick = () => this.request("POST", `/api/${name}`);
    }
    this.connect();
  }

  runRequest() {
    const policies = [];
    for (const slot of ["A", "B"]) {
      const policy = $(`path-${slot}`).value.trim() || $(`policy-${slot}`).value;
      if (policy) policies.push(policy);
    }
    return {
      policies,
      bbox_mode: $("bbox-mode").value,
      realtime: $("realtime").checked,
      max_steps: Number($("max-steps").value),
      start_paused: $("start-paused").checked,
    };
  }

  async request(method, path, body) {
    try {
      const status = await api(method, path, body);
      showMessage(status.message ?? "ok", "info");
      this.apply(status);
    } catch (error) {
      showMessage(error.message, "error");
      // A refused box is not the policy's box: show the one the server holds again.
      if (this.scene) this.canvas.setBoxes(this.scene.box, this.scene.target_box);
    }
  }

  connect() {
    const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/api/ws`);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => { $("connection").textContent = "live"; $("connection").className = "badge ok"; };
    ws.onclose = () => {
      $("connection").textContent = "reconnecting";
      $("connection").className = "badge";
      setTimeout(() => this.connect(), 1000);
    };
    ws.onmessage = (event) => {
      if (typeof event.data === "string") this.apply(JSON.parse(event.data));
      else this.frame(new Uint8Array(event.data));
    };
  }

  frame(bytes) {
    const view = LIVE_VIEWS[bytes[0]];
    const img = $(view.replace("_", "-"));
    if (!img) return;
    const url = URL.createObjectURL(new Blob([bytes.subarray(1)], {type: "image/jpeg"}));
    const old = img.dataset.url;
    img.src = url;
    img.dataset.url = url;
    if (old) URL.revokeObjectURL(old);
    if (view === "wrist_A") this.countFrame();
  }

  countFrame() {
    const now = performance.now();
    this.frameTimes.push(now);
    while (this.frameTimes.length && now - this.frameTimes[0] > 2000) this.frameTimes.shift();
    const n = this.frameTimes.length;
    const fps = n > 1 ? (1000 * (n - 1)) / (now - this.frameTimes[0]) : 0;
    $("fps").textContent = `${fps.toFixed(1)} fps`;
    $("fps").dataset.fps = fps.toFixed(2);
  }

  apply(status) {
    const phase = status.phase;
    $("phase").textContent = phase;
    $("phase").dataset.phase = phase;
    // The dashboard's own message, unless a refused request's error is on show (until the next request).
    if ($("message").dataset.kind !== "error") showMessage(status.message ?? "", "info");
    const scene = status.scene;
    this.scene = scene;
    if (scene) {
      if (scene.version !== this.sceneVersion) {
        this.sceneVersion = scene.version;
        this.canvas.setImage(`/api/frame/scene.jpg?v=${scene.version}`);
        $("setting").value = scene.setting;
        $("seed").value = scene.seed;
      }
      this.canvas.setBoxes(scene.box, scene.target_box);
      $("target-info").textContent =
        `target brick ${scene.target} (${scene.target_color}) by ${scene.target_source}; ` +
        `policy box ${fmt(scene.box)}; brick box ${fmt(scene.target_box)}` +
        (scene.target_iou == null ? "" : `; IoU ${scene.target_iou.toFixed(2)}`);
      $("target-info").dataset.box = JSON.stringify(scene.box);
      $("target-info").dataset.sceneVersion = String(scene.version);
    }
    const idle = ["empty", "ready", "done", "error"].includes(phase);
    $("load").disabled = !idle;
    $("run").disabled = !["ready", "done", "error"].includes(phase);
    $("pause").disabled = phase !== "running";
    $("resume").disabled = phase !== "paused";
    $("step").disabled = phase !== "paused";
    $("reset").disabled = !scene;
    const run = status.run;
    for (const a of [$("download-mp4"), $("download-json")]) a.classList.toggle("disabled", !run);
    $("lane-B").hidden = !(run && run.lanes.length > 1);
    for (const slot of ["A", "B"]) {
      const lane = run?.lanes.find((l) => l.slot === slot);
      const outcome = $(`outcome-${slot}`);
      $(`label-${slot}`).textContent = lane ? lane.label : "-";
      $(`steps-${slot}`).textContent = lane ? `step ${lane.steps}` : "";
      outcome.textContent = lane ? (lane.done ? lane.outcome : phase) : "";
      outcome.className = "outcome " + (lane ? (lane.done ? lane.outcome : "running") : "");
      outcome.dataset.done = lane ? String(lane.done) : "false";
    }
  }
}

// ---------------------------------------------------------------- robot box-picker mode
class PickerPage {
  constructor(config) {
    this.box = null;
    this.canvas = new BoxCanvas($("box-canvas"), {
      onBox: (box) => {
        this.box = box;
        $("send-box").disabled = false;
        $("target-info").textContent = `box ${fmt(box)}: press "Send box to the robot"`;
      },
      onClick: () => showMessage("drag a box around the object to pick", "info"),
    });
    const [w, h] = config.image_size; // keep the frame's aspect ratio: the box is normalised per axis
    const canvas = $("box-canvas");
    canvas.height = Math.round((canvas.width * h) / w);
    canvas.style.height = `${canvas.height}px`;
    this.canvas.setImage(`/api/frame/scene.jpg?v=${config.frame_version}`);
    $("send-box").onclick = () => this.send();
    $("connection").textContent = "robot";
    $("connection").className = "badge ok";
    showMessage("drag a box around the object the robot should pick, then send it", "info");
  }

  async send() {
    try {
      const result = await api("POST", "/api/pick", {box: this.box});
      this.canvas.setBoxes(result.box);
      $("send-box").disabled = true;
      showMessage(`box sent to the robot: ${fmt(result.box)}`, "info");
      $("target-info").dataset.box = JSON.stringify(result.box);
    } catch (error) {
      showMessage(error.message, "error");
    }
  }
}

async function main() {
  try {
    const config = await api("GET", "/api/config");
    document.body.className = `mode-${config.mode}`;
    window.page = config.mode === "picker" ? new PickerPage(config) : new SimPage(config);
    document.body.dataset.ready = "true";
  } catch (error) {
    showMessage(`could not start the page: ${error.message}`, "error");
  }
}

main();
