// The Depict viewer: load a frame (kept on the server), tune a pipeline, compare, take it away.
// Every request goes to this page's own origin; the API key travels in the Authorization header.
import { el, stepForm } from "./forms.js";
import { CompareView } from "./view.js";

const $ = (id) => document.getElementById(id);
const BUILTIN = {
  "Radiance Scaling": [{ op: "radiance_scaling" }],
  "Radiance Scaling (paper)": [{ op: "radiance_scaling", params: { preset: "paper" } }],
  "Light Alignment": [{ op: "light_alignment" }],
  "Unsharp masking": [{ op: "unsharp_masking" }],
  "Radiance Scaling + unsharp masking": [{ op: "radiance_scaling" }, { op: "unsharp_masking" }],
  "Apparent Relief": [{ op: "apparent_relief" }],
};
const SAVED = "depict.presets";

const state = { ops: {}, frame: null, steps: [], latest: null, previewMs: null, layer: "beauty" };
const view = new CompareView($("compare"));

function setStatus(text, kind = "") {
  $("status").textContent = text;
  $("status").className = `status ${kind}`;
}

function headers(extra = {}) {
  const key = sessionStorage.getItem("depict.key");
  return key ? { ...extra, Authorization: `Bearer ${key}` } : extra;
}

// A problem answer as an Error with the HTTP status (429 "busy" is not an error to the user).
async function api(path, options = {}) {
  const response = await fetch(path, { ...options, headers: headers(options.headers) });
  if (!response.ok) {
    let detail = response.statusText;
    try { detail = (await response.json()).detail || detail; } catch { /* not JSON */ }
    const error = new Error(detail);
    error.status = response.status;
    error.retryAfter = Number(response.headers.get("Retry-After") || 1);
    throw error;
  }
  return response;
}

function pipeline() {
  return { steps: state.steps.map((s) => (Object.keys(s.params).length ? { op: s.op, params: s.params } : { op: s.op })) };
}

// ---- loading and inspecting --------------------------------------------------------------

async function loadFrame(request, label) {
  setStatus(`loading ${label}…`, "busy");
  $("progress").hidden = false;
  try {
    const answer = await (await api(request.path, request.options)).json();
    state.frame = answer;
    showInfo(answer.info);
    fillMasks(answer.info);
    fillLayers(answer.info.layers);
    setStatus(`${answer.name} loaded`);
    await showLayer();
    schedulePreview(0);
  } catch (error) {
    setStatus(error.status === 429 ? "busy: try again in a moment" : error.message, error.status === 429 ? "busy" : "error");
  } finally {
    $("progress").hidden = true;
  }
}

function upload(file) {
  const form = new FormData();
  form.append("file", file, file.name);
  form.append("preset", $("read-preset").value);
  // (the height of the first previews: their copy is made from the upload's inspection)
  loadFrame({ path: "/v1/frames?height=" + $("height").value, options: { method: "POST", body: form } }, file.name);
}

function cameraText(info) {
  const cam = info.camera;
  if (!cam) return "none";
  const lens = cam.fov_y_deg ? `fov ${cam.fov_y_deg.toFixed(1)}°` : cam.ortho_height ? `ortho ${cam.ortho_height}` : "";
  return `${cam.projection || "perspective"} ${lens}`;
}

function showInfo(info) {
  const rows = [
    ["file", `${info.file} (${info.size[0]}×${info.size[1]})`],
    ["preset", `${info.preset}: ${info.preset_reason}`],
    ["buffers", Object.entries(info.buffers).map(([k, v]) => `${k} ← ${v.source}`).join("\n")],
    ["camera", cameraText(info)],
    ["camera from", info.camera_source || "—"],
    ["colour space", info.colour_space || "unknown"],
  ];
  for (const layer of info.cryptomatte || []) rows.push([layer.name, Object.keys(layer.names).join(", ")]);
  const blocked = Object.entries(info.operators.not_runnable).map(([k, v]) => `${k} (needs ${v.join(", ")})`);
  if (blocked.length) rows.push(["cannot run", blocked.join("; ")]);
  for (const line of [...info.problems, ...info.warnings]) rows.push(["note", line]);
  const cell = (k, v) => (k === "buffers"
    ? el("details", {}, el("summary", {}, `${Object.keys(info.buffers).length} buffers: ${Object.keys(info.buffers).join(", ")}`), v)
    : v);
  $("info").replaceChildren(...rows.flatMap(([k, v]) => [el("dt", {}, k), el("dd", {}, cell(k, v))]));
}

// What a step's `mask` may name in this frame: its one-channel buffers and its Cryptomatte names.
function fillMasks(info) {
  const one = Object.entries(info.buffers).filter(([, b]) => b.shape.length === 2).map(([k]) => k);
  const crypto = (info.cryptomatte || []).flatMap((layer, i) => {
    const prefix = i === 0 ? "cryptomatte" : `cryptomatte/${layer.name.split(".").pop()}`;
    return Object.keys(layer.names).map((n) => `${prefix}:${n}`);
  });
  $("suggest-mask").replaceChildren(...[...crypto, ...one].map((v) => el("option", { value: v })));
}

function fillLayers(layers) {
  $("layer").replaceChildren(...layers.map((l) => el("option", { value: l }, l)));
  state.layer = layers.includes("beauty") ? "beauty" : layers[0];
  $("layer").value = state.layer;
}

async function showLayer() {
  if (!state.frame) return;
  const height = previewHeight();
  const blob = await (await api(`/v1/frames/${state.frame.id}/layers/${state.layer}.png?height=${height}`)).blob();
  view.show("before", URL.createObjectURL(blob));
  const bitmap = await createImageBitmap(blob);
  view.setSize(bitmap.width, bitmap.height);
  showAfter();
}

function previewHeight() {
  return Math.min(Number($("height").value), state.frame ? state.frame.info.size[1] : 1e9);
}

// ---- previews: one in flight; what changed meanwhile is asked for as soon as it is back ----
// (no delay before the first: a slider shows its effect while it moves, at the worker's pace)

let timer = null;
let running = null;  // the preview in flight
let again = false;  // something changed since it was asked for

function schedulePreview(delay = 0) {
  clearTimeout(timer);
  timer = setTimeout(nextPreview, delay);
  updateCommands();
}

function nextPreview() {
  if (running) {
    again = true;
    return;
  }
  again = false;
  running = preview().finally(() => {
    running = null;
    if (again) nextPreview();
  });
}

function b64blob(b64) {
  const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  return new Blob([bytes], { type: "image/png" });
}

async function preview() {
  if (!state.frame || !state.steps.length) return;
  const frame = state.frame;
  const started = performance.now();
  setStatus("computing preview…", "busy");
  $("progress").hidden = false;
  try {
    const body = JSON.stringify({
      pipeline: pipeline(), height: previewHeight(), exposure: Number($("exposure").value) || 0,
      score_map: state.layer === "score_map",
    });
    const response = await api(`/v1/frames/${frame.id}/preview`, {
      method: "POST", body, headers: { "Content-Type": "application/json" },
    });
    const answer = await response.json();
    if (frame !== state.frame) return;  // another frame was loaded meanwhile
    state.latest = answer;
    state.previewMs = performance.now() - started;
    showAfter();
    const score = answer.score;
    $("scores").textContent = score ? `congruence ${score.before.toFixed(3)} → ${score.after.toFixed(3)}` : "no score (no depth)";
    const said = answer.warnings.length ? ` (${answer.warnings.join("; ")})` : "";
    setStatus(`preview ${answer.size[0]}×${answer.size[1]} in ${Math.round(state.previewMs)} ms${said}`, said ? "warning" : "");
    document.body.dataset.previews = String(Number(document.body.dataset.previews || 0) + 1);
  } catch (error) {
    if (error.status === 409) return;  // (another client's newer preview of this frame)
    if (error.status === 429) {
      setStatus(`busy: retrying in ${error.retryAfter} s`, "busy");
      again = false;  // (the retry asks for the latest settings, after Retry-After)
      schedulePreview(1000 * error.retryAfter);
      return;
    }
    setStatus(error.message, "error");
  } finally {
    if (!again) $("progress").hidden = true;
  }
}

function showAfter() {
  const answer = state.latest;
  if (!answer) return;
  const b64 = state.layer === "score_map" ? answer.score_map : answer.image;
  if (b64) view.show("after", URL.createObjectURL(b64blob(b64)));
}

// ---- the pipeline's steps ----------------------------------------------------------------

function renderSteps() {
  $("steps").replaceChildren(...state.steps.map((step, i) => {
    const op = state.ops[step.op];
    const move = (d) => () => {
      const [s] = state.steps.splice(i, 1);
      state.steps.splice(Math.max(0, Math.min(state.steps.length, i + d)), 0, s);
      renderSteps(); schedulePreview();
    };
    const fold = () => { step.folded = !step.folded; renderSteps(); };
    const head = el("div", { class: "step-head" },
      el("button", { type: "button", class: "fold", title: "show or hide the parameters", onclick: fold }, step.folded ? "▸" : "▾"),
      el("span", { class: "grow", title: op.summary }, step.op),
      el("button", { type: "button", title: "up", onclick: move(-1) }, "↑"),
      el("button", { type: "button", title: "down", onclick: move(1) }, "↓"),
      el("button", { type: "button", title: "defaults", onclick: () => { step.params = {}; renderSteps(); schedulePreview(); } }, "reset"),
      el("button", { type: "button", title: "remove", onclick: () => { state.steps.splice(i, 1); renderSteps(); schedulePreview(); } }, "✕"));
    const form = step.folded ? null : stepForm(op, step.params, () => schedulePreview(), { mask: true });
    return el("li", { "data-op": step.op }, head, form);
  }));
}

function setSteps(steps) {
  state.steps = steps.filter((s) => state.ops[s.op]).map((s) => ({ op: s.op, params: structuredClone(s.params || {}) }));
  renderSteps();
  schedulePreview();
}

function savedPresets() {
  try { return JSON.parse(localStorage.getItem(SAVED) || "{}"); } catch { return {}; }
}

function fillPresets() {
  const saved = savedPresets();
  const options = [el("option", { value: "" }, "presets…"),
    ...Object.keys(BUILTIN).map((n) => el("option", { value: `b:${n}` }, n)),
    ...Object.keys(saved).map((n) => el("option", { value: `s:${n}` }, `★ ${n}`))];
  $("presets").replaceChildren(...options);
}

// ---- taking it away -----------------------------------------------------------------------

function download(blob, name) {
  const a = el("a", { href: URL.createObjectURL(blob), download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

const quote = (s) => `'${s.replaceAll("'", "'\\''")}'`;

function updateCommands() {
  const name = state.frame ? state.frame.name : "frame.exr";
  const stem = name.replace(/\.exr$/i, "");
  const text = JSON.stringify(pipeline());
  const preset = $("read-preset").value !== "auto" ? ` --preset ${$("read-preset").value}` : "";
  const presetField = $("read-preset").value !== "auto" ? ` -F preset=${$("read-preset").value}` : "";
  const key = sessionStorage.getItem("depict.key") ? ` -H "Authorization: Bearer $DEPICT_API_KEY"` : "";
  $("commands").value = [
    `# the pipeline, saved as pipeline.json:`,
    `depict enhance ${quote(name)} -o ${quote(`${stem}_depict.exr`)} --pipeline pipeline.json${preset}`,
    ``,
    `curl -sf${key} -F file=@${quote(name)}${presetField} -F pipeline=${quote(text)} \\`,
    `  -o ${quote(`${stem}_depict.exr`)} ${location.origin}/v1/enhance`,
  ].join("\n");
}

async function downloadExr() {
  if (!state.frame) return;
  setStatus("computing the full-resolution EXR…", "busy");
  $("progress").hidden = false;
  try {
    const query = encodeURIComponent(JSON.stringify(pipeline()));
    const blob = await (await api(`/v1/frames/${state.frame.id}/enhanced.exr?pipeline=${query}`)).blob();
    download(blob, `${state.frame.name.replace(/\.exr$/i, "")}_depict.exr`);
    setStatus(`full-resolution EXR ready (${(blob.size / 2 ** 20).toFixed(1)} MiB)`);
  } catch (error) {
    setStatus(error.status === 429 ? "busy: try again in a moment" : error.message, error.status === 429 ? "busy" : "error");
  } finally {
    $("progress").hidden = true;
  }
}

// ---- wiring -------------------------------------------------------------------------------

function wire() {
  $("key").value = sessionStorage.getItem("depict.key") || "";
  $("key").addEventListener("change", () => { sessionStorage.setItem("depict.key", $("key").value.trim()); init(); });
  $("file").addEventListener("change", () => $("file").files[0] && upload($("file").files[0]));
  $("example").addEventListener("click", () => loadFrame({ path: "/v1/frames/example?height=" + $("height").value, options: { method: "POST" } }, "the example"));
  const drop = $("drop");
  drop.addEventListener("dragover", (e) => { e.preventDefault(); drop.classList.add("over"); });
  drop.addEventListener("dragleave", () => drop.classList.remove("over"));
  drop.addEventListener("drop", (e) => {
    e.preventDefault(); drop.classList.remove("over");
    if (e.dataTransfer.files[0]) upload(e.dataTransfer.files[0]);
  });
  $("add-step").addEventListener("click", () => {
    for (const s of state.steps) s.folded = true; // the new step's form in view
    state.steps.push({ op: $("add-op").value, params: {} });
    renderSteps(); schedulePreview();
  });
  $("presets").addEventListener("change", () => {
    const [kind, name] = [$("presets").value.slice(0, 1), $("presets").value.slice(2)];
    if (kind === "b") setSteps(BUILTIN[name]);
    if (kind === "s") setSteps(savedPresets()[name].steps);
    $("presets").value = "";
  });
  $("save-preset").addEventListener("click", () => {
    const name = $("preset-name").value.trim();
    if (!name) return;
    localStorage.setItem(SAVED, JSON.stringify({ ...savedPresets(), [name]: pipeline() }));
    fillPresets();
  });
  $("layer").addEventListener("change", () => {
    const mapBefore = state.layer === "score_map";
    state.layer = $("layer").value;
    showLayer().then(() => { if (mapBefore !== (state.layer === "score_map")) schedulePreview(0); })
      .catch((e) => setStatus(e.message, "error"));
  });
  for (const b of document.querySelectorAll(".modes button")) {
    b.addEventListener("click", () => setMode(b.dataset.mode));
  }
  $("toggle").addEventListener("click", () => setMode(view.mode === "after" ? "before" : "after"));
  document.addEventListener("keydown", (e) => { if (e.key === "t" && e.target.tagName !== "INPUT") $("toggle").click(); });
  $("fit").addEventListener("click", () => view.setZoom(null));
  $("actual").addEventListener("click", () => view.setZoom(1));
  $("height").addEventListener("change", () => showLayer().then(() => schedulePreview(0)));
  $("exposure").addEventListener("change", () => schedulePreview(0));
  $("read-preset").addEventListener("change", updateCommands);
  $("download-exr").addEventListener("click", downloadExr);
  $("download-pipeline").addEventListener("click", () => download(new Blob([JSON.stringify(pipeline(), null, 2)], { type: "application/json" }), "pipeline.json"));
}

function setMode(mode) {
  view.setMode(mode);
  for (const b of document.querySelectorAll(".modes button")) b.classList.toggle("on", b.dataset.mode === mode);
}

async function init() {
  try {
    const ops = await (await api("/v1/operators")).json();
    state.ops = Object.fromEntries(ops.map((o) => [o.name, o]));
    $("add-op").replaceChildren(...ops.map((o) => el("option", { value: o.name, title: o.summary }, o.name)));
    const names = await (await api("/v1/presets")).json();
    $("read-preset").replaceChildren(...["auto", ...names].map((n) => el("option", { value: n }, n)));
    if (!state.steps.length) setSteps(BUILTIN["Radiance Scaling"]);
    setStatus(state.frame ? state.frame.name : "no frame: drop an EXR or load the example");
  } catch (error) {
    setStatus(error.status === 401 ? "this server needs an API key (top right)" : error.message, "error");
  }
}

wire();
fillPresets();
updateCommands();
init();
