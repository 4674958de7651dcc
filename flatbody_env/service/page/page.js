// The flatbody service page: plain JS over the service's own JSON API (no build step, nothing from
// elsewhere: the charts are SVG drawn here).
"use strict";

const $ = (id) => document.getElementById(id);
const SVG_NS = "http://www.w3.org/2000/svg";
let SCENES = {};
const ZERO_TOL = 1e-12;      // |x| below this is round-off, shown as 0 (said on the page)
const POLL_MS = 300;         // how often a running job is asked for its progress

// ---------------------------------------------------------------------------------------------
// numbers and times
// ---------------------------------------------------------------------------------------------
const SUPERSCRIPT = { "-": "⁻", "0": "⁰", "1": "¹", "2": "²", "3": "³", "4": "⁴", "5": "⁵", "6": "⁶", "7": "⁷", "8": "⁸", "9": "⁹" };

/** A number for people: `digits` significant digits, no trailing zeros, 1.5×10⁻⁷ for the very small or large,
 * and 0 for |x| < ZERO_TOL (round-off). */
function fmt(x, digits = 6) {
  if (x === null || x === undefined || x === "") return "—";
  x = Number(x);
  if (Number.isNaN(x)) return "—";
  if (!Number.isFinite(x)) return x > 0 ? "∞" : "-∞";
  if (Math.abs(x) < ZERO_TOL) return "0";
  const a = Math.abs(x);
  if (a >= 1e-4 && a < 1e6) return String(Number(x.toPrecision(digits)));
  const [m, e] = x.toExponential(digits - 1).split("e");
  const mant = m.includes(".") ? m.replace(/\.?0+$/, "") : m;
  return `${mant}×10${String(Number(e)).split("").map((c) => SUPERSCRIPT[c] || c).join("")}`;
}

/** A tick label: `v` (a multiple of the axis' `step`) in the format of `fmt`, "0" only where it is 0 on the axis (a
 * drift of 10⁻¹³ keeps its ticks instead of collapsing to round-off). */
function fmtTick(v, step) {
  if (Math.abs(v) < Math.abs(step) * 1e-9) return "0";
  const a = Math.abs(v);
  if (a >= 1e-4 && a < 1e6) return String(Number(v.toPrecision(6)));
  const [m, e] = v.toExponential(5).split("e");
  const mant = m.includes(".") ? m.replace(/\.?0+$/, "") : m;
  return `${mant}×10${String(Number(e)).split("").map((c) => SUPERSCRIPT[c] || c).join("")}`;
}

// a number as Python writes it in a message (1e+06, -2.5, 9.9e-07): not inside a name such as J3, s3, V3 or t_end
const NUMBER_IN_TEXT = /(^|[\s(\[,=<>≤≥:])(-?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?)(?=$|[\s)\],;:]|\.(?:\s|$))/gi;

/** A message's numbers in the page's one format (`fmt`: 1×10⁶, not 1e+06 beside 1×10³⁰⁰), and the library's range
 * wording in plain words. */
function tidyMessage(text) {
  return String(text)
    .replace(/must lie in \(allowed range \[([^,\]]+), ([^\]]+)\]\)/g, "must lie between $1 and $2")
    .replace(/ \(allowed range \(0, ([^\]]+)\]\)/g, " and at most $1")
    .replace(/ \(allowed range \(0, inf\)\)/g, "")
    .replace(/must be <= /g, "must be at most ").replace(/must be >= /g, "must be at least ")
    .replace(NUMBER_IN_TEXT, (m, pre, num) => pre + fmt(Number(num)));
}

/** Seconds as "0.4 s", "12 s", "3 min 05 s", "1 h 02 min". */
function fmtDuration(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "—";
  if (s < 10) return `${s.toFixed(1)} s`;
  if (s < 60) return `${Math.round(s)} s`;
  const m = Math.floor(s / 60), sec = Math.round(s - 60 * m);
  if (m < 60) return `${m} min ${String(sec).padStart(2, "0")} s`;
  return `${Math.floor(m / 60)} h ${String(m % 60).padStart(2, "0")} min`;
}

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c);
  return node;
}

// ---------------------------------------------------------------------------------------------
// the API
// ---------------------------------------------------------------------------------------------
class ApiError extends Error {
  constructor(status, data) {
    super((data && data.detail) || `the service answered HTTP ${status}`);
    this.status = status;
    this.data = data || {};
  }
}

async function api(method, path, body) {
  const opts = { method, headers: {} };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  let r;
  try {
    r = await fetch(path, opts);
  } catch (e) {
    throw new ApiError(0, { detail: "the service cannot be reached (is flatbody serve still running?)" });
  }
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) throw new ApiError(r.status, data);
  return data;
}

/** The page-wide message (errors that belong to no field): a bar fixed at the top of the window. */
function showError(text) {
  const box = $("error");
  box.textContent = text;
  box.hidden = !text;
}

// ---------------------------------------------------------------------------------------------
// fields: reading, checking before sending, and errors next to the field at fault
// ---------------------------------------------------------------------------------------------
const labelOf = (id) => { const l = $(id).closest("label"); return (l && l.dataset.label) || id; };

/** The number in field `id`, or an error pushed to `errors` ([id, message]) in the form's words. */
function readNumber(id, errors) {
  const input = $(id);
  const label = labelOf(id);
  const text = input.value.trim();
  if (input.validity && input.validity.badInput) {
    errors.push([id, `${label}: not a number yet (finish typing it, e.g. 1e-3)`]);
    return NaN;
  }
  if (text === "") {
    errors.push([id, `${label}: enter a number`]);
    return NaN;
  }
  const x = Number(text);
  if (!Number.isFinite(x)) {
    errors.push([id, `${label}: not a number: ${text}`]);
    return NaN;
  }
  const d = input.dataset;
  if (d.integer && !Number.isInteger(x)) errors.push([id, `${label}: must be a whole number, got ${fmt(x)}`]);
  else if (d.minExcl !== undefined && !(x > Number(d.minExcl))) errors.push([id, `${label}: must be > ${fmt(Number(d.minExcl))}, got ${fmt(x)}`]);
  else if (d.min !== undefined && x < Number(d.min)) errors.push([id, `${label}: must be at least ${fmt(Number(d.min))}, got ${fmt(x)}`]);
  else if (d.max !== undefined && x > Number(d.max)) errors.push([id, `${label}: must be at most ${fmt(Number(d.max))}, got ${fmt(x)}`]);
  else if (input.min !== "" && x < Number(input.min)) errors.push([id, `${label}: must be at least ${fmt(Number(input.min))}, got ${fmt(x)}`]);
  else if (input.max !== "" && x > Number(input.max)) errors.push([id, `${label}: must be at most ${fmt(Number(input.max))}, got ${fmt(x)}`]);
  return x;
}

/** Remove the error of the field `node` (an input or select): its mark, its message, and its name from every summary
 * that lists it (a summary whose fields are all fixed goes). */
function clearFieldError(node) {
  const l = node.closest("label.bad");
  if (l) {
    l.classList.remove("bad");
    const m = l.querySelector(".msg");
    if (m) m.remove();
  }
  node.removeAttribute("aria-invalid");
  document.querySelectorAll(".action-error[data-fields]").forEach((box) => {
    const left = box.dataset.fields.split(" ").filter((f) => f && f !== node.id);
    box.dataset.fields = left.join(" ");
    if (!left.length) { box.hidden = true; box.textContent = ""; }
  });
}

function clearFieldErrors(scope) {
  (scope || document).querySelectorAll("label.bad input, label.bad select").forEach(clearFieldError);
}

/** The message of a field: a bubble under it that covers what lies below instead of pushing the row apart. */
function setFieldError(id, message) {
  const input = $(id);
  const label = input.closest("label");
  label.classList.add("bad");
  input.setAttribute("aria-invalid", "true");
  let m = label.querySelector(".msg");
  if (!m) { m = el("span", { class: "msg", role: "alert" }); label.append(m); }
  m.textContent = message;
}

function inView(node) {
  const r = node.getBoundingClientRect();
  return r.top >= 0 && r.bottom <= window.innerHeight;
}

/** Show errors ([id, message] pairs): each next to its field (the first one scrolled into view and
 * focused), and a one-line summary next to the button that was pressed (`boxId`), which goes once every field it
 * names is changed. */
function showErrors(errors, boxId) {
  for (const [id, msg] of errors) setFieldError(id, msg);
  const box = boxId ? $(boxId) : null;
  if (box) {
    const first = errors[0];
    const where = first[0] && !$(boxId).closest("form").contains($(first[0])) ? " (the field is marked above)" : "";
    box.className = "action-error";
    box.textContent = (errors.length > 1 ? `${errors.length} fields to fix: ` : "") + first[1] + where;
    box.dataset.fields = [...new Set(errors.map(([id]) => id))].join(" ");
    box.hidden = false;
  }
  const input = $(errors[0][0]);
  if (!inView(input)) input.scrollIntoView({ block: "center" });
  input.focus({ preventScroll: true });
  if (box && !inView(box) && inView(input) === false) box.scrollIntoView({ block: "nearest" });
}

function clearAction(boxId) {
  const box = $(boxId);
  box.className = "action-error";
  box.textContent = "";
  delete box.dataset.fields;
  box.hidden = true;
}

// the request's field names (the API's error `field`) → the form's inputs
const FIELD_IDS = { J: "J", J1: "J", J2: "J", J3: "J3", k: "k", c: "c", d: "d", kappa: "kappa", a: "a", b: "b", s3: "s3",
  p_theta: "p_theta", potential: "potential", from: "vary-from", to: "vary-to", start: "vary-from", stop: "vary-to",
  vary: "vary", grid: "map-grid", t_end: "t_end", samples: "samples", method: "method", scene: "scene", name: "potential" };

function fieldFor(path) {
  if (!path) return null;
  const parts = String(path).split(".");
  for (let i = parts.length - 1; i >= 0; i--) {
    const id = FIELD_IDS[parts[i]];
    if (id && $(id)) return id;
  }
  return null;
}

/** An API error in the form's words: the field's label instead of the request's path, numbers as the page writes
 * them (`tidyMessage`). */
function formMessage(err, id) {
  let detail = err.data.detail || err.message;
  const field = err.data.field;
  if (field && detail.startsWith(field)) detail = detail.slice(field.length).replace(/^:\s*/, "");
  detail = tidyMessage(detail.replace(/\bstart\b/g, "from").replace(/\bstop\b/g, "to"));
  return id ? `${labelOf(id)}: ${detail}` : detail;
}

/** Show an API error next to its field when it names one of the form's fields, else next to the button. */
function showApiError(err, boxId) {
  if (!(err instanceof ApiError)) err = new ApiError(0, { detail: `the page failed: ${err.message}` });
  const id = fieldFor(err.data.field);
  if (id) {
    showErrors([[id, formMessage(err, id)]], boxId);
  } else if (boxId) {
    $(boxId).className = "action-error";
    $(boxId).textContent = formMessage(err, null);
    $(boxId).hidden = false;
    if (!inView($(boxId))) $(boxId).scrollIntoView({ block: "center" });
  } else {
    showError(formMessage(err, null));
  }
}

// ---------------------------------------------------------------------------------------------
// the body form
// ---------------------------------------------------------------------------------------------
const CONSTS = { V1: ["k"], V2: ["c", "d"], V3: ["kappa"] };
const SYMBOL = { kappa: "κ", p_theta: "p_θ", s3: "s3", k: "k", c: "c", d: "d", a: "a", b: "b", J: "J", J3: "J3" };

function bodySpec(errors) {
  const name = $("potential").value;
  const potential = { name };
  for (const c of CONSTS[name]) potential[c] = readNumber(c, errors);
  return { params: { J: readNumber("J", errors), J3: readNumber("J3", errors) }, potential,
           thickness: { a: readNumber("a", errors), b: readNumber("b", errors) } };
}

function describeBody(body) {
  const p = body.potential;
  const consts = CONSTS[p.name].filter((c) => p[c] !== undefined).map((c) => `${SYMBOL[c]} = ${fmt(p[c])}`).join(", ");
  const th = body.thickness ? `, a = ${fmt(body.thickness.a)}, b = ${fmt(body.thickness.b)}` : "";
  const J = body.params.J !== undefined ? body.params.J : body.params.J1;
  return `${p.name} (${consts}), J = ${fmt(J)}, J3 = ${fmt(body.params.J3)}${th}`;
}

function showPotentialFields() {
  const name = $("potential").value;
  document.querySelectorAll(".pot").forEach((node) => node.classList.toggle("shown", node.classList.contains(name)));
}

function fillFromScene(name) {
  const sc = SCENES[name];
  $("scene-description").textContent = sc ? sc.description || "" : "";
  if (!sc) return;
  const p = sc.params || {};
  $("J").value = p.J !== undefined ? p.J : p.J1;
  $("J3").value = p.J3;
  $("potential").value = sc.potential.name;
  for (const c of ["k", "c", "d", "kappa"]) if (sc.potential[c] !== undefined) $(c).value = sc.potential[c];
  if (sc.thickness) { $("a").value = sc.thickness.a; $("b").value = sc.thickness.b; }
  $("s3").value = sc.state.s3;
  $("p_theta").value = sc.state.p_theta;
  if (sc.t_end) $("t_end").value = Math.min(sc.t_end, 10000);
  showPotentialFields();
  clearFieldErrors($("body-panel"));
}

// the request the ellipse table answers; when the body form no longer matches it, the table is
// greyed out and the status says so (the numbers are never shown as if they were the form's)
let ellipsesRequest = null;

function markEllipsesStale() {
  if (ellipsesRequest === null) return;
  const errors = [];
  const now = JSON.stringify({ body: bodySpec(errors), s3: readNumber("s3", errors), p_theta: readNumber("p_theta", errors) });
  const stale = errors.length > 0 || now !== ellipsesRequest;
  $("ellipses-table").classList.toggle("stale", stale);
  const status = $("ellipses-status");
  const note = " (the form has changed since: press Find again)";
  if (stale && !status.textContent.endsWith(note)) status.textContent += note;
  if (!stale && status.textContent.endsWith(note)) status.textContent = status.textContent.slice(0, -note.length);
}

async function findEllipses() {
  showError("");
  clearFieldErrors($("body-form"));
  clearAction("ellipses-error");
  const errors = [];
  const req = { body: bodySpec(errors), s3: readNumber("s3", errors), p_theta: readNumber("p_theta", errors) };
  if (errors.length) { showErrors(errors, "ellipses-error"); return; }
  $("ellipses-status").textContent = "computing…";
  try {
    const [ell, stab] = await Promise.all([api("POST", "/ellipses", req), api("POST", "/stability", req)]);
    const tbody = $("ellipses-table").querySelector("tbody");
    tbody.innerHTML = "";
    const biggest = Math.max(...ell.solutions.map((e) => Math.max(e.state.lambda, e.state.mu)), 1);
    ell.solutions.forEach((e, i) => {
      const s = stab.solutions[i] || {};
      const cls = s.classification === "elliptic" ? "stable" : s.classification === "hyperbolic" ? "unstable" : "";
      const tr = el("tr", { "data-index": String(i) });
      tr.append(el("td", { text: String(i) }), el("td", { class: "shape" }, ellipseIcon(e.state.lambda, e.state.mu, biggest)));
      for (const v of [fmt(e.state.lambda), fmt(e.state.mu), fmt(e.state.rho), fmt(e.omega3), fmt(e.theta_dot), fmt(e.energy, 8)]) {
        tr.append(el("td", { text: String(v) }));
      }
      tr.append(el("td", { class: `text ${cls}`, text: s.classification || "?" }), el("td", { text: fmt(s.max_real_part, 3) }));
      const label = `ellipse ${i} (λ = ${fmt(e.state.lambda, 4)}, μ = ${fmt(e.state.mu, 4)})`;
      tr.append(el("td", { class: "text act" },
        el("button", { type: "button", class: "from-here", title: `a simulation job that starts on ${label}, with t_end, samples and method of 4.`,
                       text: "simulate from here", onclick: () => simulateFrom(req, e, i) }),
        el("button", { type: "button", class: "as-target", title: `draw ${label} as the target of the next simulations and recordings`,
                       text: "use as target", onclick: () => useAsTarget(e, i) })));
      tbody.appendChild(tr);
    });
    $("ellipses-table").hidden = ell.solutions.length === 0;
    $("ellipses-status").textContent = `${ell.solutions.length} stationary ellipse(s) for ${req.body.potential.name}, ` +
      `s3 = ${fmt(req.s3)}, p_θ = ${fmt(req.p_theta)}`;
    ellipsesRequest = JSON.stringify(req);
    $("ellipses-table").classList.remove("stale");
  } catch (err) {
    $("ellipses-status").textContent = "";
    showApiError(err, "ellipses-error");
  }
}

/** A small drawing of an ellipse with semi-axes λ, μ (to the scale of the largest in the table). */
function ellipseIcon(lam, mu, biggest) {
  const S = 34, C = S / 2, k = (C - 2) / biggest;
  const root = svg("svg", { viewBox: `0 0 ${S} ${S}`, width: S, height: S, class: "ellipse-icon", role: "img", "aria-label": `λ = ${fmt(lam, 4)}, μ = ${fmt(mu, 4)}` });
  root.append(svg("ellipse", { cx: C, cy: C, rx: lam * k, ry: mu * k, class: "now" }),
              svg("line", { x1: C, y1: C, x2: C + lam * k, y2: C, class: "axis-line" }));
  return root;
}

/** A simulation job that starts on stationary ellipse `e` of the table's request `req` (its body and state), with
 * the run form's t_end, samples and method: an elliptic one stays put, a hyperbolic one leaves. */
function simulateFrom(req, e, i) {
  clearFieldErrors($("run-form"));
  clearAction("run-error");
  const errors = [];
  const params = { scene: Object.assign({ name: `ellipse ${i}` }, JSON.parse(JSON.stringify(req.body)), { state: e.state }),
                   t_end: readNumber("t_end", errors), samples: readNumber("samples", errors), method: $("method").value };
  if (errors.length) { showErrors(errors, "run-error"); return; }
  startJob("simulate", params, "run-error");
  $("run-error").scrollIntoView({ block: "nearest" });
}

let TARGET = null;   // the stationary ellipse chosen as the target: drawn in the next simulations and recordings

function useAsTarget(e, i) {
  TARGET = { lambda: e.state.lambda, mu: e.state.mu, rho: e.state.rho, index: i };
  document.querySelectorAll("#ellipses-table tbody tr").forEach((tr) => tr.classList.toggle("target", tr.dataset.index === String(i)));
  $("target-note").replaceChildren(`Target: ellipse ${i}, λ* = ${fmt(TARGET.lambda)}, μ* = ${fmt(TARGET.mu)}, ϱ* = ${fmt(TARGET.rho)} — drawn in magenta and as faint bands in the next simulations and recordings. `,
    el("button", { type: "button", text: "no target", onclick: () => { TARGET = null; $("target-note").textContent = "";
      document.querySelectorAll("#ellipses-table tbody tr.target").forEach((tr) => tr.classList.remove("target")); } }));
}

/** The target a job was started with (kept in this browser: the service has no target). */
function targetOf(id) {
  try { return JSON.parse(localStorage.getItem(`flatbody-target-${id}`) || "null"); } catch (e) { return null; }
}

function sceneForRun(errors) {
  const name = $("scene").value;
  if (name) return name;
  const base = SCENES["default"];
  const state = Object.assign({}, base.state, { s3: readNumber("s3", errors), p_theta: readNumber("p_theta", errors) });
  return Object.assign({ name: "custom" }, bodySpec(errors), { state });
}

// ---------------------------------------------------------------------------------------------
// jobs: start, watch (real progress from the worker), cancel, and what each shows when done
// ---------------------------------------------------------------------------------------------
const FILES = {
  "simulate": [["trajectory.json", "trajectory (JSON)"]],
  "record": [["recording.rrd", "recording (.rrd)"], ["preview.png", "preview (PNG)"], ["trajectory.json", "trajectory (JSON)"]],
  "family": [["family.png", "chart (PNG)"], ["family.csv", "table (CSV)"]],
  "stability-map": [["stability-map.png", "map (PNG)"], ["stability-map.csv", "table (CSV)"]],
  "evaluate": [["evaluation.json", "report (JSON)"]],
};
const ROWS = new Map();   // job id → its row in the jobs table

const artifactUrl = (id, name) => `/jobs/${id}/artifact?name=${encodeURIComponent(name)}`;

function sceneName(scene) {
  if (typeof scene === "string") return `scene “${scene}”`;
  const named = scene.name && scene.name !== "custom" ? `${scene.name} of ` : "";
  return `${named}a custom body (${describeBody(scene)})`;
}

/** What a job computes, in words, from its parameters (the caption of its picture or plots). */
function describeJob(job) {
  const p = job.params || {};
  switch (job.kind) {
    case "family": {
      const held = [p.vary !== "s3" ? `s3 = ${fmt(p.s3 === null || p.s3 === undefined ? 2 : p.s3)}` : null,
                    p.vary !== "p_theta" ? `p_θ = ${fmt(p.p_theta === null || p.p_theta === undefined ? 0.5 : p.p_theta)}` : null]
        .filter(Boolean).join(", ");
      return `Family of stationary ellipses over ${SYMBOL[p.vary] || p.vary} from ${fmt(p.from)} to ${fmt(p.to)}` +
        `${held ? ` (${held})` : ""}; body ${describeBody(p.body)}`;
    }
    case "stability-map":
      return `Stability map of ${p.grid} × ${p.grid} shapes, λ ∈ [${fmt((p.lam_range || [1.02])[0])}, ${fmt((p.lam_range || [0, 3])[1])}], ` +
        `μ ∈ [${fmt((p.mu_range || [0.3])[0])}, ${fmt((p.mu_range || [0, 3])[1])}]; body ${describeBody(p.body)}`;
    case "simulate":
    case "record": {
      const what = job.kind === "simulate" ? "Simulation" : "Recording";
      const tEnd = p.t_end ? `t = 0 … ${fmt(p.t_end)}` : "the scene's t_end";
      return `${what} of ${sceneName(p.scene)}, ${tEnd}, ${p.samples || (job.kind === "record" ? 401 : 101)} samples, method ${p.method || "auto"}`;
    }
    case "evaluate":
      return `Evaluation of the shipped agent, ${p.episodes} episodes`;
    default:
      return job.kind;
  }
}

function progressText(job) {
  const pct = `${Math.floor(100 * job.progress)} %`;
  if (job.status === "queued") return "waiting for a free worker";
  if (job.status === "running") {
    const parts = [pct, `${fmtDuration(job.elapsed)} elapsed`];
    if (job.remaining !== null && job.remaining !== undefined) parts.push(`about ${fmtDuration(job.remaining)} left`);
    return parts.join(" · ");
  }
  if (job.status === "done") return `took ${fmtDuration(job.elapsed)}`;
  return job.elapsed !== null && job.elapsed !== undefined ? `stopped after ${fmtDuration(job.elapsed)}` : "";
}

function jobRow(job) {
  let tr = ROWS.get(job.id);
  if (tr) return tr;
  tr = el("tr", { id: `job-${job.id}` });
  tr.dataset.kind = job.kind;
  tr.dataset.created = job.created;
  tr.append(
    el("td", { class: "text what" }, el("strong", { text: job.kind }), el("div", { class: "note", text: describeJob(job) })),
    el("td", { class: "text status" }),
    el("td", { class: "text prog" }, el("progress", { max: "1", value: "0" }), el("span", { class: "pct" }), el("div", { class: "note stage" })),
    el("td", { class: "text files" }),
    el("td", { class: "text act" }),
  );
  insertByCreated($("jobs").querySelector("tbody"), tr);
  ROWS.set(job.id, tr);
  $("no-jobs").hidden = true;
  return tr;
}

/** Newest first: put `node` (with data-created) before the first older sibling. */
function insertByCreated(parent, node) {
  const created = Number(node.dataset.created || 0);
  for (const child of parent.children) {
    if (Number(child.dataset.created || 0) < created) { parent.insertBefore(node, child); return; }
  }
  parent.append(node);
}

function updateRow(job) {
  const tr = jobRow(job);
  tr.dataset.status = job.status;
  const status = tr.querySelector(".status");
  status.textContent = job.status;
  status.className = `text status ${job.status}`;
  if (job.error) status.append(el("div", { class: "note err", text: tidyMessage(job.error) }));
  const bar = tr.querySelector("progress");
  bar.value = job.progress;
  bar.dataset.value = String(job.progress);
  tr.querySelector(".pct").textContent = progressText(job);
  tr.querySelector(".stage").textContent = job.status === "running" && job.stage ? job.stage : "";
  const act = tr.querySelector(".act");
  act.innerHTML = "";
  if (job.status === "queued" || job.status === "running") {
    act.append(el("button", { type: "button", class: "cancel", text: "cancel", title: "stop the job and delete it (DELETE /jobs/{id})",
                              onclick: () => cancelJob(job.id) }));
  } else {
    act.append(el("button", { type: "button", class: "delete", text: "delete", title: "delete the job and its files",
                              onclick: () => { if (confirm("Delete this job and its files?")) cancelJob(job.id); } }));
  }
}

async function cancelJob(id) {
  try {
    await api("DELETE", `/jobs/${id}`);
  } catch (err) {
    if (err.status !== 404) { showError(err.message); return; }
  }
  const tr = ROWS.get(id);
  if (tr) {
    const was = tr.dataset.status;
    tr.dataset.status = "cancelled";
    tr.querySelector(".status").textContent = was === "queued" || was === "running" ? "cancelled and deleted" : "deleted";
    tr.querySelector(".act").innerHTML = "";
    tr.querySelector(".pct").textContent = "";      // no estimate of a job that no longer runs
    tr.querySelector(".stage").textContent = "";
    tr.querySelector("progress").remove();
    tr.querySelector(".files").innerHTML = "";
    tr.classList.add("gone");
  }
  document.querySelectorAll(`[data-job="${id}"]`).forEach((node) => node.remove());
}

async function startJob(kind, params, boxId) {
  showError("");
  try {
    const { id } = await api("POST", "/jobs", { kind, params });
    if (TARGET && (kind === "simulate" || kind === "record")) {
      try { localStorage.setItem(`flatbody-target-${id}`, JSON.stringify(TARGET)); } catch (e) { /* private mode: not kept */ }
    }
    let job = { id, kind, params, status: "queued", progress: 0, created: Date.now() / 1000 };
    try { job = await api("GET", `/jobs/${id}`); } catch (e) { /* shown as sent; watch() fetches it again */ }
    updateRow(job);
    watch(id);
    const box = $(boxId);
    box.className = "action-note";
    box.replaceChildren(`${kind} job started: `, el("a", { href: `#job-${id}`, text: "its progress is in Jobs below" }));
    box.hidden = false;
  } catch (err) {
    showApiError(err, boxId);
  }
}

async function watch(id) {
  let job;
  try {
    job = await api("GET", `/jobs/${id}`);
  } catch (err) {
    if (err.status === 404) return;   // deleted meanwhile
    setTimeout(() => watch(id), 2000);
    return;
  }
  if (!ROWS.has(id) || ROWS.get(id).dataset.status === "cancelled") return;
  updateRow(job);
  if (job.status === "queued" || job.status === "running") {
    setTimeout(() => watch(id), POLL_MS);
    return;
  }
  if (job.status === "done") showResult(job);
}

function showResult(job) {
  const tr = jobRow(job);
  const cell = tr.querySelector(".files");
  cell.innerHTML = "";
  for (const [name, label] of FILES[job.kind] || []) {
    if (job.artifacts && !job.artifacts.includes(name)) continue;
    cell.append(el("a", { href: artifactUrl(job.id, name), download: "", text: label }), " ");
  }
  if (document.querySelector(`[data-job="${job.id}"]`)) return;
  if (job.kind === "record") {
    showRecording(job);
  } else if (job.kind === "family" || job.kind === "stability-map") {
    showPicture(job);
  } else if (job.kind === "simulate") {
    showTrajectory(job);
  }
}

// ---------------------------------------------------------------------------------------------
// pictures (family, stability map): full width, captioned with their parameters, click to enlarge
// ---------------------------------------------------------------------------------------------
function showPicture(job) {
  const [png, csv] = FILES[job.kind].map((f) => f[0]);
  const caption = describeJob(job);
  const img = el("img", { alt: caption, src: artifactUrl(job.id, png), title: "click to enlarge" });
  img.addEventListener("click", () => zoom(img.src, caption));
  const fig = el("figure", { "data-job": job.id, "data-kind": job.kind },
    img,
    el("figcaption", {}, el("span", { class: "cap", text: caption }), " — ",
       el("a", { href: artifactUrl(job.id, png), download: "", text: "PNG" }), " · ",
       el("a", { href: artifactUrl(job.id, csv), download: "", text: "CSV table" })));
  if (job.kind === "family" && job.result) fig.append(familyEnds(job));
  fig.dataset.created = job.created;
  insertByCreated($("pictures"), fig);
}

/** Where and why each branch of a family ends, and the seeds where nothing was found (a family is never cut short
 * without a word). */
function familyEnds(job) {
  const r = job.result, sym = SYMBOL[r.param] || r.param;
  const list = el("ul", { class: "note ends" });
  const ends = r.ends || [];
  const branches = [...new Set(ends.map((e) => e.branch))];
  for (const bi of branches) {
    const [lo, hi] = ends.filter((e) => e.branch === bi);
    const end = (e) => `${sym} = ${fmt(e.param, 4)}` + (e.reason === "range" ? " (the range's end)" : ` (λ = ${fmt(e.lambda, 4)}, μ = ${fmt(e.mu, 4)}: ${e.detail})`);
    list.append(el("li", { "data-branch": String(bi), text: `branch ${bi}: from ${end(lo)} to ${end(hi)}` }));
  }
  if (!branches.length) list.append(el("li", { text: "no stationary ellipse in the search box anywhere in the range" }));
  if ((r.empty_seeds || []).length) {
    list.append(el("li", { text: `no stationary ellipse in the search box at ${r.empty_seeds.map((v) => `${sym} = ${fmt(v, 4)}`).join(", ")}` }));
  }
  if (r.scale && r.scale !== "linear") {
    list.append(el("li", { text: `the range spans decades: followed in ${r.scale === "log" ? "ln" : "asinh"} ${sym}, with seeds spread evenly over the decades` }));
  }
  return el("div", { class: "family-ends" }, el("span", { class: "note", text: "Where the branches end:" }), list);
}

function zoom(src, caption) {
  const dlg = $("zoom");
  dlg.querySelector("img").src = src;
  dlg.querySelector("img").alt = caption;
  dlg.querySelector("p").textContent = caption;
  if (typeof dlg.showModal === "function") dlg.showModal(); else window.open(src, "_blank");
}

// ---------------------------------------------------------------------------------------------
// a recording: a preview (the body at four times, the plots of its trajectory), the file, and what to run
// ---------------------------------------------------------------------------------------------
function showRecording(job) {
  const r = job.result;
  const name = r.download || r.recording;
  const card = el("article", { class: "card recording", "data-job": job.id, "data-kind": "record" },
    el("h3", { text: `Recording ready: ${name}` }),
    el("p", { class: "note", text: `${describeJob(job)} — ${r.samples} samples to t = ${fmt(r.t_end)}, integrated with ${r.method} (${r.model} chart).` }),
    el("p", { class: "get" }, el("a", { class: "button", href: artifactUrl(job.id, r.recording), download: "", text: `Download ${name}` }),
       " then open it with the rerun viewer (0.41, the SDK's version): ", el("code", { class: "cmd", text: r.open_with || `rerun ${name}` })));
  if ((job.artifacts || []).includes("preview.png")) {
    const src = artifactUrl(job.id, "preview.png");
    const img = el("img", { class: "preview", src, alt: `the plate seen from +z at four times of the recording`, title: "click to enlarge" });
    img.addEventListener("click", () => zoom(src, "the plate seen from +z (the env's rgb_array frame) at four times, first and last included"));
    card.append(el("figure", { class: "preview" }, img,
      el("figcaption", { class: "note", text: "Preview: the plate seen from +z at four times of the recording (first and last included), as the env's rgb_array frame draws it; below, the recorded trajectory." })));
  }
  card.dataset.created = job.created;
  insertByCreated($("runs"), card);
  if ((job.artifacts || []).includes("trajectory.json")) {
    api("GET", artifactUrl(job.id, "trajectory.json")).then((traj) => trajectoryPlots(card, traj, { target: targetOf(job.id) }))
      .catch(() => card.append(el("p", { class: "note", text: "(the recorded trajectory could not be read back for its plots)" })));
  }
}

// ---------------------------------------------------------------------------------------------
// a trajectory: λ, μ, ϱ, s₃, H and the energy drift against t, and the ellipse (plain SVG)
// ---------------------------------------------------------------------------------------------
function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  return node;
}

/** About `n` round tick values covering [lo, hi], and their step. */
function ticks(lo, hi, n = 5) {
  const span = hi - lo;
  if (!(span > 0)) return { values: [lo], step: 1 };
  const raw = span / n, mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => span / s <= n) || 10 * mag;
  const values = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) values.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return { values, step };
}

/** The colour of a variable (`lambda`, `mu`, `rho`, `s3`, `energy`, …): the CSS property --color-NAME that the service
 *  sets from the recordings' palette (flatbody_env.env.rendering.COLORS), so the page, the rerun views and the
 *  rgb_array frames draw each variable in one colour. */
function varColor(name) {
  return getComputedStyle(document.documentElement).getPropertyValue(`--color-${name}`).trim() || "#444";
}

/** The first index i with t[i] ≥ v (t increasing). */
function lowerIndex(t, v) {
  let lo = 0, hi = t.length;
  while (lo < hi) { const mid = (lo + hi) >> 1; if (t[mid] < v) lo = mid + 1; else hi = mid; }
  return lo;
}

/** The samples of `values` on [i0, i1] as the screen can show them, `columns` pixel columns wide: every sample when
 * there are few, else per column the mean, min and max (a series that oscillates faster than a pixel is a band of its
 * range around its mean, never the aliasing pattern of every k-th sample). */
function columns(t, values, i0, i1, x, columns) {
  const n = i1 - i0 + 1;
  if (n <= 2 * columns) {
    const pts = [];
    for (let i = i0; i <= i1; i++) pts.push([x(t[i]), values[i], values[i], values[i]]);
    return { pts, banded: false };
  }
  const pts = [];
  const x0 = x(t[i0]), w = x(t[i1]) - x0;
  let col = -1, sum = 0, cnt = 0, mn = Infinity, mx = -Infinity;
  const flush = () => { if (cnt) pts.push([x0 + (col + 0.5) * w / columns, sum / cnt, mn, mx]); };
  for (let i = i0; i <= i1; i++) {
    const c = Math.min(columns - 1, Math.floor((x(t[i]) - x0) / w * columns));
    if (c !== col) { flush(); col = c; sum = 0; cnt = 0; mn = Infinity; mx = -Infinity; }
    const v = values[i];
    sum += v; cnt++; if (v < mn) mn = v; if (v > mx) mx = v;
  }
  flush();
  return { pts, banded: true };
}

const CHART_FONT = { title: 13, tick: 11, axis: 12 };   // px on screen, at every width (the SVG is drawn at its width)

/** A line chart of series [{name, values, color, target?}] against t on the window [a, b] of t, `width` px wide:
 * axes, ticks (the last one inside the frame), a legend, a time marker, and a band per series where it oscillates
 * faster than the screen shows. `flat`: a spread below this (relative to the values' size) is drawn flat. Returns
 * {node, mark(t), x(t) → px, inverse(px) → t}. */
function lineChart(t, series, { title, ylabel, width, window: win, flat = 1e-9, flatPad = null, targets = [] }) {
  const W = Math.max(300, Math.round(width)), narrow = W < 520;
  const R = 16, B = 40, CHAR = 7.4;   // CHAR: the width of a 12–13 px character, about
  // the title on one line, or two where it is long; the legend beside it, or on a row of its own when they do not fit
  const legendW = series.length > 1 ? (narrow ? 44 : 60) * series.length : 0;
  const lines = [""];
  for (const word of title.split(" ")) {   // word-wrapped to the chart's width
    const last = lines[lines.length - 1];
    if (last && (last.length + 1 + word.length) * CHAR > W - 16) lines.push(word);
    else lines[lines.length - 1] = last ? `${last} ${word}` : word;
  }
  const legendRow = legendW > 0 && (lines.length > 1 || lines[0].length * CHAR + legendW + 24 > W);
  const T = 12 + 16 * lines.length + (legendRow ? 18 : 0) + 4;
  const H = (narrow ? 170 : 200) + T - 30;
  const [a, b] = win;
  const i0 = Math.max(0, lowerIndex(t, a) - 1), i1 = Math.min(t.length - 1, lowerIndex(t, b));
  let lo = Infinity, hi = -Infinity;
  for (const s of series) for (let i = i0; i <= i1; i++) { const v = s.values[i]; if (v < lo) lo = v; if (v > hi) hi = v; }
  for (const v of targets.map((g) => g.value)) { if (v < lo) lo = v; if (v > hi) hi = v; }
  const mid = (lo + hi) / 2;
  let isFlat = false;
  if (!(hi - lo > flat * Math.max(1, Math.abs(mid)))) {   // constant within round-off: a flat line, not magnified noise
    const pad = flatPad !== null ? flatPad : Math.max(1e-3 * Math.abs(mid), 1e-3);
    lo = mid - pad; hi = mid + pad; isFlat = true;
  } else {
    const pad = 0.05 * (hi - lo); lo -= pad; hi += pad;
  }
  const yt = ticks(lo, hi, narrow ? 4 : 5);
  const L = Math.min(96, Math.max(50, 24 + 6.6 * Math.max(...yt.values.map((v) => fmtTick(v, yt.step).length))));
  const x = (v) => L + (W - L - R) * (v - a) / (b - a);
  const y = (v) => T + (H - T - B) * (1 - (v - lo) / (hi - lo));
  const root = svg("svg", { viewBox: `0 0 ${W} ${H}`, width: W, height: H, class: "chart", role: "img", "aria-label": title });
  const tx = lines.every((l) => l.length * CHAR + L + (legendRow ? 0 : legendW) < W) ? L : 8;
  lines.forEach((line, k) => root.append(svg("text", { x: tx, y: 17 + 16 * k, class: "title" }, line)));
  const legendY = legendRow ? 17 + 16 * lines.length : 13;
  for (const v of yt.values) {
    root.append(svg("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), class: "grid" }));
    root.append(svg("text", { x: L - 6, y: y(v) + 4, class: "tick", "text-anchor": "end" }, fmtTick(v, yt.step)));
  }
  const xt = ticks(a, b, narrow ? 4 : 8);
  for (const v of xt.values) {
    root.append(svg("line", { x1: x(v), x2: x(v), y1: T, y2: H - B, class: "grid" }));
    const label = fmtTick(v, xt.step);
    const px = x(v), half = 3.3 * label.length;   // the label stays inside the chart: no "1000(" at the right edge
    const anchor = px + half > W - 2 ? "end" : px - half < L - 20 ? "start" : "middle";
    root.append(svg("text", { x: anchor === "end" ? W - 2 : px, y: H - B + 16, class: "tick", "text-anchor": anchor }, label));
  }
  root.append(svg("rect", { x: L, y: T, width: W - L - R, height: H - T - B, class: "frame" }));
  root.append(svg("text", { x: (L + W - R) / 2, y: H - 6, class: "axis", "text-anchor": "middle" }, "t (model time unit)"));
  root.append(svg("text", { x: 14, y: (T + H - B) / 2, class: "axis", "text-anchor": "middle", transform: `rotate(-90 14 ${(T + H - B) / 2})` }, ylabel));
  const clipId = `clip-${Math.random().toString(36).slice(2)}`;
  root.append(svg("clipPath", { id: clipId }, undefined));
  root.lastChild.append(svg("rect", { x: L, y: T, width: W - L - R, height: H - T - B }));
  const plot = svg("g", { "clip-path": `url(#${clipId})` });
  root.append(plot);
  for (const g of targets) {   // a target value: a wide faint band in the variable's colour (as in the recordings)
    plot.append(svg("line", { x1: L, x2: W - R, y1: y(g.value), y2: y(g.value), class: "target", stroke: varColor(g.color), "data-name": g.name }));
  }
  let banded = false;
  series.forEach((s, k) => {
    const { pts, banded: band } = columns(t, s.values, i0, i1, x, W - L - R);
    banded = banded || band;
    if (band) {
      let d = "";
      pts.forEach((p, j) => { d += `${j ? "L" : "M"}${p[0].toFixed(1)},${y(p[3]).toFixed(1)}`; });
      for (let j = pts.length - 1; j >= 0; j--) d += `L${pts[j][0].toFixed(1)},${y(pts[j][2]).toFixed(1)}`;
      plot.append(svg("path", { d: d + "Z", class: "band", fill: varColor(s.color), "data-name": s.name }));
    }
    let d = "";
    pts.forEach((p, j) => { d += `${j ? "L" : "M"}${p[0].toFixed(1)},${y(p[1]).toFixed(1)}`; });
    plot.append(svg("path", { d, class: "line", stroke: varColor(s.color), "data-name": s.name }));
    if (series.length > 1) {
      const lx = legendRow ? L + (narrow ? 44 : 60) * k : W - R - (narrow ? 44 : 60) * (series.length - k);
      root.append(svg("line", { x1: lx, x2: lx + 16, y1: legendY - 4, y2: legendY - 4, stroke: varColor(s.color), "stroke-width": 2.5 }));
      root.append(svg("text", { x: lx + 20, y: legendY, class: "legend" }, s.name));
    }
  });
  const marker = svg("line", { x1: x(a), x2: x(a), y1: T, y2: H - B, class: "marker" });
  root.append(marker);
  const sel = svg("rect", { x: L, y: T, width: 0, height: H - T - B, class: "zoom-sel" });
  root.append(sel);
  const inverse = (px) => a + (b - a) * (px - L) / (W - L - R);
  return {
    node: root, banded, flat: isFlat, x, inverse, sel, plotLeft: L, plotRight: W - R,
    mark: (v) => { const px = Math.min(Math.max(x(v), L), W - R); marker.setAttribute("x1", px); marker.setAttribute("x2", px); },
  };
}

/** The ellipse of the body's shape at sample i: semi-axes λ, μ turned by the material angle θ (R not shown); a target
 * ellipse (λ*, μ*) in magenta when one was chosen in the table of stationary ellipses. */
function ellipseView(traj, target) {
  const S = 260, C = S / 2;
  const lam = traj.state.lambda, mu = traj.state.mu, th = traj.state.theta;
  let r = target ? Math.max(target.lambda, target.mu) : 0;
  for (let i = 0; i < lam.length; i++) r = Math.max(r, lam[i], mu[i]);
  const scale = (C - 16) / r;
  const root = svg("svg", { viewBox: `0 0 ${S} ${S}`, class: "ellipse", role: "img", "aria-label": "the ellipse" });
  root.append(svg("line", { x1: 8, x2: S - 8, y1: C, y2: C, class: "grid" }), svg("line", { x1: C, x2: C, y1: 8, y2: S - 8, class: "grid" }));
  const deg = (a) => -a * 180 / Math.PI;
  root.append(svg("ellipse", { cx: C, cy: C, rx: lam[0] * scale, ry: mu[0] * scale, transform: `rotate(${deg(th[0])} ${C} ${C})`, class: "start" }));
  const now = svg("ellipse", { cx: C, cy: C, class: "now" });
  const axis = svg("line", { x1: C, y1: C, class: "axis-line" });
  root.append(now, axis);
  let goal = null;
  if (target) {   // the target's shape, along the body's current axes (the table gives λ*, μ*, not an orientation)
    goal = svg("ellipse", { cx: C, cy: C, rx: target.lambda * scale, ry: target.mu * scale, class: "target-shape" });
    root.append(goal);
  }
  const draw = (i) => {
    now.setAttribute("rx", lam[i] * scale);
    now.setAttribute("ry", mu[i] * scale);
    now.setAttribute("transform", `rotate(${deg(th[i])} ${C} ${C})`);
    if (goal) goal.setAttribute("transform", `rotate(${deg(th[i])} ${C} ${C})`);
    axis.setAttribute("x2", C + lam[i] * scale * Math.cos(th[i]));
    axis.setAttribute("y2", C - lam[i] * scale * Math.sin(th[i]));
  };
  return { node: root, draw };
}

/** The plots of a trajectory in `host`: λ, μ, ϱ; s₃; H; the energy drift H − H₀ on its own scale; the ellipse at a
 * time picked with a slider. Drag across a plot to zoom every plot to that time window; "whole run" goes back. The
 * plots are drawn at the width they are shown at (the text stays readable on a phone) and again when it changes. */
function trajectoryPlots(host, traj, { target = null } = {}) {
  const t = traj.t, st = traj.state;
  const H0 = traj.energy.length ? traj.energy[0] : 0;
  const dH = traj.energy.map((h) => h - H0);
  let drift = 0;
  for (const v of dH) drift = Math.max(drift, Math.abs(v));
  const rel = Math.abs(H0) > 0 ? drift / Math.abs(H0) : NaN;
  const tg = target ? [{ name: "λ*", value: target.lambda, color: "lambda" }, { name: "μ*", value: target.mu, color: "mu" },
                       { name: "ϱ*", value: target.rho, color: "rho" }] : [];
  const specs = [
    { series: [{ name: "λ", values: st.lambda, color: "lambda" }, { name: "μ", values: st.mu, color: "mu" }, { name: "ϱ", values: st.rho, color: "rho" }],
      title: "shape: the stretches λ, μ and the thickness ϱ" + (target ? " (targets: faint bands)" : ""), ylabel: "λ, μ, ϱ", targets: tg },
    { series: [{ name: "s₃", values: st.s3, color: "s3" }], title: "spin s₃", ylabel: "s₃" },
    { series: [{ name: "H", values: traj.energy, color: "energy" }], title: `energy H (H₀ = ${fmt(H0, 10)})`, ylabel: "H" },
    { series: [{ name: "H − H₀", values: dH, color: "energy" }], ylabel: "H − H₀", flat: 1e-14 * Math.max(1, Math.abs(H0)),
      flatPad: 1e-12 * Math.max(1, Math.abs(H0)),
      title: "energy drift H − H₀: " + (drift < ZERO_TOL ? "below 10⁻¹² everywhere (round-off: H is conserved)" :
        `largest |H − H₀| = ${fmt(drift, 3)}` + (Number.isFinite(rel) ? ` (${fmt(rel, 3)} of |H₀|)` : "")) },
  ];
  const series = el("div", { class: "series" });
  const tools = el("p", { class: "note zoom-tools" });
  const whole = el("button", { type: "button", class: "whole-run", text: "whole run" });
  const ell = ellipseView(traj, target);
  const slider = el("input", { type: "range", min: "0", max: String(t.length - 1), value: "0", "aria-label": "time" });
  const readout = el("p", { class: "note readout" });
  const view = { a: t[0], b: t[t.length - 1] > t[0] ? t[t.length - 1] : t[0] + 1, i: 0 };
  let charts = [];
  const show = (i) => {
    view.i = i;
    ell.draw(i);
    for (const c of charts) c.mark(t[i]);
    readout.textContent = `t = ${fmt(t[i], 5)}: λ = ${fmt(st.lambda[i])}, μ = ${fmt(st.mu[i])}, ϱ = ${fmt(st.rho[i])}, ` +
      `θ = ${fmt(st.theta[i], 4)} rad, s₃ = ${fmt(st.s3[i])}, H = ${fmt(traj.energy[i], 10)} (all dimensionless)`;
  };
  const draw = () => {
    const width = series.clientWidth || host.clientWidth || 640;
    series.replaceChildren();
    charts = specs.map((sp) => lineChart(t, sp.series, { ...sp, width, window: [view.a, view.b] }));
    for (const [k, c] of charts.entries()) {
      const fig = el("figure", { class: "plot", "data-chart": String(k) }, c.node);
      series.append(fig);
      zoomable(c, (a, b) => { view.a = a; view.b = b; draw(); });
    }
    const whole_ = view.a <= t[0] && view.b >= t[t.length - 1];
    const banded = charts.some((c) => c.banded);
    tools.replaceChildren(
      whole_ ? `whole run, t = ${fmt(t[0])} … ${fmt(t[t.length - 1])}` : `t = ${fmt(view.a, 5)} … ${fmt(view.b, 5)} of ${fmt(t[0])} … ${fmt(t[t.length - 1])}`,
      " — drag across a plot to zoom in. ",
      ...(whole_ ? [] : [whole]),
      banded ? " Shaded: the range of the samples behind each pixel, around their mean (the motion is faster than the plot's pixels)." : "",
    );
    show(view.i);
  };
  whole.addEventListener("click", () => { view.a = t[0]; view.b = t[t.length - 1]; draw(); });
  slider.addEventListener("input", () => show(Number(slider.value)));
  host.append(el("div", { class: "plots" },
    el("div", { class: "series-col" }, tools, series),
    el("figure", { class: "shape" }, ell.node,
       el("figcaption", { class: "note", text: "the ellipse at the time chosen below (solid) and at t = 0 (dashed): semi-axes λ, μ, turned by the material angle θ; the rotation R is not drawn" +
         (target ? `; magenta: the target λ* = ${fmt(target.lambda)}, μ* = ${fmt(target.mu)}, drawn along the body's current axes` : "") }),
       slider, readout)));
  requestAnimationFrame(draw);
  let last = 0;
  new ResizeObserver(() => { const w = series.clientWidth; if (w && Math.abs(w - last) > 8) { last = w; draw(); } }).observe(series);
  return { drift, rel };
}

/** Drag across chart `c` to pick a time window: `done(a, b)` with the window (at least 1 % of the shown one). */
function zoomable(c, done) {
  const svgNode = c.node;
  let start = null;
  const px = (e) => {
    const r = svgNode.getBoundingClientRect();
    const k = svgNode.viewBox.baseVal.width / r.width;
    return Math.min(Math.max((e.clientX - r.left) * k, c.plotLeft), c.plotRight);
  };
  svgNode.addEventListener("pointerdown", (e) => { start = px(e); svgNode.setPointerCapture(e.pointerId); });
  svgNode.addEventListener("pointermove", (e) => {
    if (start === null) return;
    const p = px(e);
    c.sel.setAttribute("x", Math.min(p, start));
    c.sel.setAttribute("width", Math.abs(p - start));
  });
  svgNode.addEventListener("pointerup", (e) => {
    if (start === null) return;
    const p = px(e), s0 = start;
    start = null;
    c.sel.setAttribute("width", 0);
    if (Math.abs(p - s0) < 6) return;   // a click, not a drag
    const a = c.inverse(Math.min(p, s0)), b = c.inverse(Math.max(p, s0));
    if (b > a) done(a, b);
  });
}

function showTrajectory(job) {
  const traj = job.result;
  const t = traj.t;
  const meta = traj.meta || {};
  const card = el("article", { class: "card trajectory", "data-job": job.id, "data-kind": "simulate" },
    el("h3", { text: `Simulation of ${sceneName(job.params.scene)}` }),
    el("p", { class: "note", text: `${t.length} samples, t = ${fmt(t[0])} … ${fmt(t[t.length - 1])}; ${meta.method || "?"} in the ` +
      `${meta.model || "?"} chart, ${meta.nfev !== undefined ? `${meta.nfev} right-hand-side evaluations, ` : ""}` +
      `${fmtDuration(meta.wall_time)} of integration. ` }, el("a", { href: artifactUrl(job.id, "trajectory.json"), download: "", text: "trajectory (JSON)" })));
  card.dataset.created = job.created;
  insertByCreated($("runs"), card);
  trajectoryPlots(card, traj, { target: targetOf(job.id) });
}

// ---------------------------------------------------------------------------------------------
// start
// ---------------------------------------------------------------------------------------------
function runParams(errors) {
  const params = { scene: sceneForRun(errors), t_end: readNumber("t_end", errors), samples: readNumber("samples", errors), method: $("method").value };
  return params;
}

function submitRun(kind) {
  clearFieldErrors();
  clearAction("run-error");
  const errors = [];
  const params = runParams(errors);
  if (errors.length) { showErrors(errors, "run-error"); return; }
  startJob(kind, params, "run-error");
}

const PARAM_RANGE = [1e-6, 1e6];   // a constant of the body (J, J3, k, c, d, κ, a, b): the service's bounds
const MOMENTUM_MAX = 1e6;          // a spin (s3, p_θ)

/** The family's from/to fields take the range of what is varied: a constant of the body within [10⁻⁶, 10⁶], a spin
 * within ±10⁶ (the service refuses the rest; the page says so before sending). */
function varyBounds() {
  const body = !["s3", "p_theta"].includes($("vary").value);
  for (const id of ["vary-from", "vary-to"]) {
    const d = $(id).dataset;
    d.min = String(body ? PARAM_RANGE[0] : -MOMENTUM_MAX);
    d.max = String(body ? PARAM_RANGE[1] : MOMENTUM_MAX);
    const unit = $(id).closest("label").querySelector(".unit");
    unit.textContent = (body ? "dimensionless, 10⁻⁶ … 10⁶" : "dimensionless, −10⁶ … 10⁶") + (id === "vary-to" ? ", > from" : "");
  }
}

function submitFamily() {
  clearFieldErrors();
  clearAction("family-error");
  const errors = [];
  const vary = $("vary").value;
  const params = { body: bodySpec(errors), vary, from: readNumber("vary-from", errors), to: readNumber("vary-to", errors) };
  if (vary !== "s3") params.s3 = readNumber("s3", errors);
  if (vary !== "p_theta") params.p_theta = readNumber("p_theta", errors);
  if (!errors.some(([id]) => id === "vary-from" || id === "vary-to")) {
    if (!(params.to > params.from)) errors.push(["vary-to", `to: must be greater than from (${fmt(params.from)}), got ${fmt(params.to)}`]);
  }
  if (errors.length) { showErrors(errors, "family-error"); return; }
  startJob("family", params, "family-error");
}

function submitMap() {
  clearFieldErrors();
  clearAction("map-error");
  const errors = [];
  const params = { body: bodySpec(errors), grid: readNumber("map-grid", errors) };
  if (errors.length) { showErrors(errors, "map-error"); return; }
  startJob("stability-map", params, "map-error");
}

/** The jobs the service holds (GET /jobs): their rows, and the results of the finished ones. */
async function loadJobs() {
  const { jobs } = await api("GET", "/jobs?limit=50");
  for (const job of jobs) updateRow(job);
  for (const job of jobs) {
    if (job.status === "queued" || job.status === "running") watch(job.id);
    else if (job.status === "done") {
      api("GET", `/jobs/${job.id}`).then(showResult).catch(() => {});
    }
  }
}

const HEALTH_MS = 5000;   // how often the header asks the service whether it is still there

/** The header's word on the service, asked again every HEALTH_MS: "service ok" only while it answers. */
async function checkHealth() {
  const node = $("health");
  try {
    const h = await api("GET", "/health");
    node.textContent = `service ${h.status}, version ${h.version}`;
    node.className = "";
  } catch (err) {
    node.textContent = "service unreachable — stopped? (retrying)";
    node.className = "down";
  }
  setTimeout(checkHealth, HEALTH_MS);
}

async function init() {
  showPotentialFields();
  $("potential").addEventListener("change", showPotentialFields);
  $("body-form").addEventListener("submit", (e) => { e.preventDefault(); findEllipses(); });
  $("family-form").addEventListener("submit", (e) => { e.preventDefault(); submitFamily(); });
  $("map-form").addEventListener("submit", (e) => { e.preventDefault(); submitMap(); });
  $("run-form").addEventListener("submit", (e) => { e.preventDefault(); submitRun("simulate"); });
  $("start-record").addEventListener("click", () => submitRun("record"));
  document.querySelectorAll("#body-panel input, #body-panel select").forEach((node) => {
    node.addEventListener("input", markEllipsesStale);
    node.addEventListener("change", markEllipsesStale);
  });
  document.querySelectorAll("input, select").forEach((node) => {
    node.addEventListener("input", () => clearFieldError(node));
    node.addEventListener("change", () => clearFieldError(node));
  });
  $("vary").addEventListener("change", varyBounds);
  varyBounds();
  $("scene").addEventListener("change", () => { fillFromScene($("scene").value); markEllipsesStale(); });
  $("zoom").addEventListener("click", (e) => { if (e.target === $("zoom")) $("zoom").close(); });
  try {
    const h = await api("GET", "/health");
    $("health").textContent = `service ${h.status}, version ${h.version}`;
    setTimeout(checkHealth, HEALTH_MS);
    SCENES = await api("GET", "/scenes");
    for (const name of Object.keys(SCENES)) $("scene").append(el("option", { value: name, text: name }));
    const methods = await api("GET", "/methods");
    for (const m of methods.filter((m) => m.adaptive)) {
      $("method").append(el("option", { value: m.name, text: `${m.name} (adaptive, order ${m.order}, ${m.chart} chart)` }));
    }
    await loadJobs();
    document.body.dataset.ready = "yes";
  } catch (err) {
    showError(err.message);
  }
}

init();
