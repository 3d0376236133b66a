// Forms generated from the operators' JSON schemas (GET /v1/operators): one control per
// parameter. A step's params hold only what the user changed from the defaults, so the
// pipeline JSON stays what a person would write, and an operator's `preset` keeps working.

const el = (tag, attrs = {}, ...children) => {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v !== undefined && v !== null && v !== false) node.setAttribute(k, v === true ? "" : v);
  }
  for (const child of children.flat()) if (child !== null && child !== undefined) node.append(child);
  return node;
};
export { el };

// The alternatives of a schema: {number, nullable, auto, enums, type}.
function kinds(schema) {
  const alts = schema.anyOf || [schema];
  const out = { nullable: false, auto: null, number: null, enums: null, other: null };
  for (const alt of alts) {
    if (alt.type === "null") out.nullable = true;
    else if (alt.const !== undefined) out.auto = alt.const;
    else if (alt.type === "number" || alt.type === "integer") out.number = alt;
    else if (alt.enum) out.enums = alt.enum;
    else out.other = alt;
  }
  return out;
}

// A slider's mapping t in [0, 1] <-> value: logarithmic for wide positive ranges.
function sliderScale(num, dflt) {
  let lo = num.minimum ?? num.exclusiveMinimum ?? -1e3;
  let hi = num.maximum ?? num.exclusiveMaximum ?? 1e3;
  const ref = typeof dflt === "number" && dflt > 0 ? dflt : null;
  if (lo >= 0 && ref !== null && hi / ref > 50) {
    const a = Math.max(lo > 0 ? lo : ref / 30, ref / 30);
    const b = Math.min(hi, ref * 30);
    return { log: true, to: (t) => a * Math.pow(b / a, t), from: (v) => Math.log(v / a) / Math.log(b / a) };
  }
  if (num.exclusiveMinimum !== undefined) lo += (hi - lo) * 1e-3;
  if (num.exclusiveMaximum !== undefined) hi -= (hi - lo) * 1e-3;
  return { log: false, to: (t) => lo + t * (hi - lo), from: (v) => (v - lo) / (hi - lo) };
}

const round = (v, integer) => (integer ? Math.round(v) : Number(v.toPrecision(3)));

// A number: slider + box; `auto`/null alternatives as a checkbox that leaves it unset.
function numberControl(name, schema, value, set) {
  const k = kinds(schema);
  const num = k.number;
  const integer = num.type === "integer";
  const dflt = schema.default;
  const shown = typeof value === "number" ? value : typeof dflt === "number" ? dflt : (num.minimum ?? 0);
  const scale = sliderScale(num, typeof dflt === "number" ? dflt : shown);
  const slider = el("input", { type: "range", min: 0, max: 1000, step: 1, "aria-label": name });
  const box = el("input", { type: "number", step: "any", class: "num", "aria-label": `${name} value` });
  const place = (v) => {
    slider.value = String(Math.round(1000 * Math.min(1, Math.max(0, scale.from(v)))));
    box.value = String(v);
  };
  place(shown);
  const optional = k.nullable || k.auto !== null;
  const unsetLabel = k.auto !== null ? String(k.auto) : "default";
  const unset = optional ? el("input", { type: "checkbox", "aria-label": `${name} ${unsetLabel}` }) : null;
  const enable = (on) => { slider.disabled = !on; box.disabled = !on; };
  if (unset) {
    unset.checked = typeof value !== "number";
    enable(!unset.checked);
    unset.addEventListener("change", () => {
      enable(!unset.checked);
      set(unset.checked ? undefined : Number(box.value));
    });
  }
  slider.addEventListener("input", () => {
    const v = round(scale.to(Number(slider.value) / 1000), integer);
    box.value = String(v);
    set(v);
  });
  box.addEventListener("change", () => {
    const v = Number(box.value);
    if (Number.isFinite(v)) { place(v); set(v); }
  });
  const parts = [slider, box];
  if (unset) parts.push(el("label", { class: "unset" }, unset, unsetLabel));
  return el("span", { class: "number" }, parts);
}

// A direction on the unit hemisphere facing the camera, dragged on a shaded disc.
const DIRECTION = /^(dir:)?\s*(-?[\d.eE+-]+)\s*,\s*(-?[\d.eE+-]+)\s*,\s*(-?[\d.eE+-]+)(.*)$/;

function sphereWidget(text, onPick) {
  const size = 84;
  const canvas = el("canvas", { width: size, height: size, class: "sphere", title: "drag to aim the light" });
  const ctx = canvas.getContext("2d");
  const draw = (x, y, z) => {
    const img = ctx.createImageData(size, size);
    for (let j = 0; j < size; j++) {
      for (let i = 0; i < size; i++) {
        const u = (2 * (i + 0.5)) / size - 1, v = 1 - (2 * (j + 0.5)) / size;
        const r2 = u * u + v * v, o = 4 * (j * size + i);
        if (r2 > 1) { img.data[o + 3] = 0; continue; }
        const w = Math.sqrt(1 - r2);
        const shade = Math.max(0, u * x + v * y + w * z);
        const g = Math.round(40 + 200 * shade);
        img.data[o] = g; img.data[o + 1] = g; img.data[o + 2] = Math.min(255, g + 10); img.data[o + 3] = 255;
      }
    }
    ctx.putImageData(img, 0, 0);
    ctx.beginPath();
    ctx.arc(((x + 1) / 2) * size, ((1 - y) / 2) * size, 4, 0, 2 * Math.PI);
    ctx.fillStyle = "#f5a623"; ctx.fill();
  };
  const show = (t) => {
    const m = DIRECTION.exec(t || "");
    if (!m) { draw(-0.4, 0.6, 0.7); return; }
    const [x, y, z] = [Number(m[2]), Number(m[3]), Number(m[4])];
    const n = Math.hypot(x, y, z) || 1;
    draw(x / n, y / n, z / n);
  };
  const pick = (event) => {
    const box = canvas.getBoundingClientRect();
    let u = (2 * (event.clientX - box.left)) / box.width - 1;
    let v = 1 - (2 * (event.clientY - box.top)) / box.height;
    const r = Math.hypot(u, v);
    if (r > 0.999) { u /= r / 0.999; v /= r / 0.999; }
    const w = Math.sqrt(Math.max(0, 1 - u * u - v * v));
    const dir = [u, v, w].map((c) => c.toFixed(3)).join(",");
    draw(u, v, w);
    onPick(dir);
  };
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    pick(e);
    const move = (m) => pick(m);
    canvas.addEventListener("pointermove", move);
    canvas.addEventListener("pointerup", () => canvas.removeEventListener("pointermove", move), { once: true });
  });
  show(text);
  return { canvas, show };
}

// A light (string) or lights (array of strings): the sphere aims the first one, the text
// field holds them all (separated by ';').
function lightControl(name, schema, value, set) {
  const isList = schema.type === "array";
  const dflt = schema.default;
  const asText = (v) => (Array.isArray(v) ? v.join("; ") : v ?? "");
  const input = el("input", { type: "text", class: "text", "aria-label": name, placeholder: asText(dflt) || "the operator's default" });
  input.value = asText(value);
  const parse = (t) => {
    const items = t.split(";").map((s) => s.trim()).filter(Boolean);
    if (!items.length) return undefined;
    return isList ? items : items[0];
  };
  const sphere = sphereWidget(input.value || asText(dflt), (dir) => {
    const items = (input.value || "").split(";").map((s) => s.trim()).filter(Boolean);
    const m = DIRECTION.exec(items[0] || "");
    items[0] = dir + (m ? m[5] : "");
    input.value = items.join("; ");
    set(parse(input.value));
  });
  input.addEventListener("change", () => { sphere.show(input.value || asText(dflt)); set(parse(input.value)); });
  return el("span", { class: "light" }, sphere.canvas, input);
}

function choiceControl(name, options, value, dflt, set) {
  const select = el("select", { "aria-label": name }, options.map((o) => el("option", { value: o }, String(o))));
  select.value = String(value ?? dflt ?? options[0]);
  select.addEventListener("change", () => set(select.value));
  return select;
}

function listControl(name, schema, value, set) {
  const items = schema.items || {};
  if (items.enum) {
    const unknown = value === undefined && schema.default === undefined; // the operator decides
    const chosen = new Set(value ?? schema.default ?? []);
    return el("span", { class: "checks", title: unknown ? "the operator's default" : "" }, items.enum.map((o) => {
      const box = el("input", { type: "checkbox", "aria-label": `${name} ${o}` });
      box.checked = chosen.has(o);
      box.indeterminate = unknown;
      box.addEventListener("change", () => {
        box.checked ? chosen.add(o) : chosen.delete(o);
        set(items.enum.filter((x) => chosen.has(x)));
      });
      return el("label", {}, box, o);
    }));
  }
  const numeric = items.type === "number" || items.type === "integer";
  const placeholder = schema.default ? schema.default.join(", ") : "the operator's default";
  const input = el("input", { type: "text", class: "text", "aria-label": name, placeholder });
  input.value = (value || []).join(", ");
  input.addEventListener("change", () => {
    const parts = input.value.split(",").map((s) => s.trim()).filter(Boolean);
    set(parts.length ? parts.map((s) => (numeric ? Number(s) : s)) : undefined);
  });
  return input;
}

// A number or a word (`auto`) without bounds: a text field, empty for the default.
function autoControl(name, schema, value, set) {
  const input = el("input", { type: "text", class: "text", "aria-label": name, placeholder: String(schema.default ?? "") });
  input.value = value === undefined ? "" : String(value);
  input.addEventListener("change", () => {
    const text = input.value.trim();
    set(text === "" ? undefined : Number.isFinite(Number(text)) ? Number(text) : text);
  });
  return input;
}

function jsonControl(name, value, set) {
  const input = el("input", { type: "text", class: "text", "aria-label": name, placeholder: "JSON" });
  input.value = value === undefined ? "" : JSON.stringify(value);
  input.addEventListener("change", () => {
    try { set(input.value.trim() ? JSON.parse(input.value) : undefined); input.classList.remove("bad"); }
    catch { input.classList.add("bad"); }
  });
  return input;
}

function control(name, schema, value, set, suggestions) {
  const k = kinds(schema);
  const listSchema = schema.type === "array" ? schema : k.other && k.other.type === "array" ? k.other : null;
  if (name === "light" || name === "lights") return lightControl(name, listSchema || schema, value, set);
  if (schema.type === "boolean") {
    const box = el("input", { type: "checkbox", "aria-label": name });
    box.checked = value ?? schema.default ?? false;
    box.addEventListener("change", () => set(box.checked));
    return el("label", { class: "toggle" }, box);
  }
  if (schema.enum || k.enums) return choiceControl(name, schema.enum || k.enums, value, schema.default, set);
  if (k.number && (k.number.maximum !== undefined || k.number.exclusiveMaximum !== undefined)) {
    return numberControl(name, schema, value, set);
  }
  if (listSchema) return listControl(name, listSchema, value, set);
  if (k.number && k.auto !== null) return autoControl(name, schema, value, set);
  if (schema.type === "string" || (k.other && k.other.type === "string")) {
    const list = suggestions[name] ? "suggest-" + name : undefined;
    const input = el("input", { type: "text", class: "text", "aria-label": name, placeholder: schema.default ?? "", list });
    input.value = value ?? "";
    input.addEventListener("change", () => set(input.value || undefined));
    return input;
  }
  return jsonControl(name, value, set);
}

// The form of one step: a row per parameter; `changed(params)` after every edit.
// `suggestions`: parameter name -> values offered in a list (a datalist of that id must exist).
export function stepForm(op, params, changed, suggestions = {}) {
  const props = op.params.properties || {};
  const rows = Object.entries(props).map(([name, schema]) => {
    const set = (v) => {
      if (v === undefined || JSON.stringify(v) === JSON.stringify(schema.default)) delete params[name];
      else params[name] = v;
      changed(params);
    };
    const label = el("label", { class: "pname", title: schema.description || "" }, name);
    return el("div", { class: "param", "data-param": name }, label, control(name, schema, params[name], set, suggestions));
  });
  return el("div", { class: "params" }, rows);
}
