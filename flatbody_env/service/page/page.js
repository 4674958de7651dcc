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
  else if (d.minExcl !== undefined && !(x > Number(d.minExcl))) errors.push([id, `${label}: must be > ${d.minExcl}, got ${fmt(x)}`]);
  else if (d.min !== undefined && x < Number(d.min)) errors.push([id, `${label}: must be at least ${fmt(Number(d.min))}, got ${fmt(x)}`]);
  else if (d.max !== undefined && x > Number(d.max)) errors.push([id, `${label}: must be at most ${fmt(Number(d.max))}, got ${fmt(x)}`]);
  else if (input.min !== "" && x < Number(input.min)) errors.push([id, `${label}: must be at least ${input.min}, got ${fmt(x)}`]);
  else if (input.max !== "" && x > Number(input.max)) errors.push([id, `${label}: must be at most ${input.max}, got ${fmt(x)}`]);
  return x;
}

function clearFieldErrors(scope) {
  (scope || document).querySelectorAll("label.bad").forEach((l) => {
    l.classList.remove("bad");
    const m = l.querySelector(".msg");
    if (m) m.remove();
    const i = l.querySelector("input, select");
    if (i) i.removeAttribute("aria-invalid");
  });
}

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
 * focused), and a one-line summary next to the button that was pressed (`boxId`). */
function showErrors(errors, boxId) {
  for (const [id, msg] of errors) setFieldError(id, msg);
  const box = boxId ? $(boxId) : null;
  if (box) {
    const first = errors[0];
    const where = first[0] && !$(boxId).closest("form").contains($(first[0])) ? " (the field is marked above)" : "";
    box.textContent = (errors.length > 1 ? `${errors.length} fields to fix: ` : "") + first[1] + where;
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

/** An API error in the form's words: the field's label instead of the request's path. */
function formMessage(err, id) {
  let detail = err.data.detail || err.message;
  const field = err.data.field;
  if (field && detail.startsWith(field)) detail = detail.slice(field.length).replace(/^:\s*/, "");
  detail = detail.replace(/must lie in \(allowed range \[([^,\]]+), ([^\]]+)\]\)/, "must lie between $1 and $2")
    .replace(/\bstart\b/g, "from").replace(/\bstop\b/g, "to").replace(/, got ([-0-9.e+]+)/, (m, v) => `, got ${fmt(Number(v))}`);
  return id ? `${labelOf(id)}: ${detail}` : detail;
}

/** Show an API error next to its field when it names one of the form's fields, else next to the button. */
function showApiError(err, boxId) {
  if (!(err instanceof ApiError)) err = new ApiError(0, { detail: `the page failed: ${err.message}` });
  const id = fieldFor(err.data.field);
  if (id) {
    showErrors([[id, formMessage(err, id)]], boxId);
  } else if (boxId) {
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
    ell.solutions.forEach((e, i) => {
      const s = stab.solutions[i] || {};
      const cls = s.classification === "elliptic" ? "stable" : s.classification === "hyperbolic" ? "unstable" : "";
      const tr = document.createElement("tr");
      for (const v of [i, fmt(e.state.lambda), fmt(e.state.mu), fmt(e.state.rho), fmt(e.omega3), fmt(e.theta_dot), fmt(e.energy, 8)]) {
        tr.append(el("td", { text: String(v) }));
      }
      tr.append(el("td", { class: `text ${cls}`, text: s.classification || "?" }), el("td", { text: fmt(s.max_real_part, 3) }));
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
  "record": [["recording.rrd", "recording (.rrd)"]],
  "family": [["family.png", "chart (PNG)"], ["family.csv", "table (CSV)"]],
  "stability-map": [["stability-map.png", "map (PNG)"], ["stability-map.csv", "table (CSV)"]],
  "evaluate": [["evaluation.json", "report (JSON)"]],
};
const ROWS = new Map();   // job id → its row in the jobs table

const artifactUrl = (id, name) => `/jobs/${id}/artifact?name=${encodeURIComponent(name)}`;

function sceneName(scene) { return typeof scene === "string" ? `scene “${scene}”` : `a custom body (${describeBody(scene)})`; }

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
  if (job.error) status.append(el("div", { class: "note err", text: job.error }));
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
    tr.dataset.status = "cancelled";
    tr.querySelector(".status").textContent = "cancelled and deleted";
    tr.querySelector(".act").innerHTML = "";
    tr.classList.add("gone");
  }
  document.querySelectorAll(`[data-job="${id}"]`).forEach((node) => node.remove());
}

async function startJob(kind, params, boxId) {
  showError("");
  try {
    const { id } = await api("POST", "/jobs", { kind, params });
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
    cell.append(el("a", { href: artifactUrl(job.id, name), download: name, text: label }), " ");
  }
  if (document.querySelector(`[data-job="${job.id}"]`)) return;
  if (job.kind === "record") {
    cell.append(el("div", { class: "note" }, "open it with: ", el("code", { class: "cmd", text: `rerun ${job.result.recording}` })));
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
       el("a", { href: artifactUrl(job.id, png), download: png, text: "PNG" }), " · ",
       el("a", { href: artifactUrl(job.id, csv), download: csv, text: "CSV table" })));
  fig.dataset.created = job.created;
  insertByCreated($("pictures"), fig);
}

function zoom(src, caption) {
  const dlg = $("zoom");
  dlg.querySelector("img").src = src;
  dlg.querySelector("img").alt = caption;
  dlg.querySelector("p").textContent = caption;
  if (typeof dlg.showModal === "function") dlg.showModal(); else window.open(src, "_blank");
}

// ---------------------------------------------------------------------------------------------
// a recording: what to run, and the file
// ---------------------------------------------------------------------------------------------
function showRecording(job) {
  const r = job.result;
  const card = el("article", { class: "card", "data-job": job.id, "data-kind": "record" },
    el("h3", { text: `Recording ready: ${r.recording}` }),
    el("p", { class: "note", text: `${describeJob(job)} — ${r.samples} samples to t = ${fmt(r.t_end)}, integrated with ${r.method} (${r.model} chart).` }),
    el("p", {}, el("a", { class: "button", href: artifactUrl(job.id, r.recording), download: r.recording, text: `Download ${r.recording}` })),
    el("p", {}, "Then open it with the rerun viewer (0.41, the SDK's version): ",
       el("code", { class: "cmd", text: r.open_with || `rerun ${r.recording}` })));
  card.dataset.created = job.created;
  insertByCreated($("runs"), card);
}

// ---------------------------------------------------------------------------------------------
// a trajectory: λ, μ, ϱ, s₃ and H against t, and the ellipse (plain SVG)
// ---------------------------------------------------------------------------------------------
function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  return node;
}

/** About `n` round tick values covering [lo, hi]. */
function ticks(lo, hi, n = 5) {
  const span = hi - lo;
  if (!(span > 0)) return [lo];
  const raw = span / n, mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => span / s <= n) || 10 * mag;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
  return out;
}

/** The colour of a variable (`lambda`, `mu`, `rho`, `s3`, `energy`, …): the CSS property --color-NAME that the service
 *  sets from the recordings' palette (flatbody_env.env.rendering.COLORS), so the page, the rerun views and the
 *  rgb_array frames draw each variable in one colour. */
function varColor(name) {
  return getComputedStyle(document.documentElement).getPropertyValue(`--color-${name}`).trim() || "#444";
}

/** A line chart of series [{name, values, color}] (color: a variable's name, see varColor) against t, with axes, ticks, a legend and a time marker. */
function lineChart(t, series, { title, ylabel, note }) {
  const W = 640, H = 230, L = 64, R = 12, T = 28, B = 40;
  let lo = Infinity, hi = -Infinity;
  for (const s of series) for (const v of s.values) { if (v < lo) lo = v; if (v > hi) hi = v; }
  const mid = (lo + hi) / 2;
  if (!(hi - lo > 1e-9 * Math.max(1, Math.abs(mid)))) {   // constant within round-off: a flat line, not magnified noise
    const pad = Math.max(1e-3 * Math.abs(mid), 1e-3);
    lo = mid - pad; hi = mid + pad;
  } else {
    const pad = 0.05 * (hi - lo); lo -= pad; hi += pad;
  }
  const t0 = t[0], t1 = t[t.length - 1] > t0 ? t[t.length - 1] : t0 + 1;
  const x = (v) => L + (W - L - R) * (v - t0) / (t1 - t0);
  const y = (v) => T + (H - T - B) * (1 - (v - lo) / (hi - lo));
  const root = svg("svg", { viewBox: `0 0 ${W} ${H}`, class: "chart", role: "img", "aria-label": title });
  root.append(svg("text", { x: L, y: 16, class: "title" }, title));
  for (const v of ticks(lo, hi)) {
    root.append(svg("line", { x1: L, x2: W - R, y1: y(v), y2: y(v), class: "grid" }));
    root.append(svg("text", { x: L - 6, y: y(v) + 4, class: "tick", "text-anchor": "end" }, fmt(v, 5)));
  }
  for (const v of ticks(t0, t1, 8)) {
    root.append(svg("line", { x1: x(v), x2: x(v), y1: T, y2: H - B, class: "grid" }));
    root.append(svg("text", { x: x(v), y: H - B + 16, class: "tick", "text-anchor": "middle" }, fmt(v, 5)));
  }
  root.append(svg("rect", { x: L, y: T, width: W - L - R, height: H - T - B, class: "frame" }));
  root.append(svg("text", { x: (L + W - R) / 2, y: H - 6, class: "axis", "text-anchor": "middle" }, "t (model time unit)"));
  root.append(svg("text", { x: 14, y: (T + H - B) / 2, class: "axis", "text-anchor": "middle", transform: `rotate(-90 14 ${(T + H - B) / 2})` }, ylabel));
  series.forEach((s, k) => {
    const step = Math.max(1, Math.floor(t.length / 2000));
    let d = "";
    for (let i = 0; i < t.length; i += step) d += `${i ? "L" : "M"}${x(t[i]).toFixed(1)},${y(s.values[i]).toFixed(1)}`;
    root.append(svg("path", { d, class: "line", stroke: varColor(s.color), "data-name": s.name }));
    if (series.length > 1) {
      const lx = W - R - 70 * (series.length - k);
      root.append(svg("line", { x1: lx, x2: lx + 18, y1: 14, y2: 14, stroke: varColor(s.color), "stroke-width": 2.5 }));
      root.append(svg("text", { x: lx + 22, y: 18, class: "legend" }, s.name));
    }
  });
  const marker = svg("line", { x1: x(t0), x2: x(t0), y1: T, y2: H - B, class: "marker" });
  root.append(marker);
  const box = el("figure", { class: "plot" }, root);
  if (note) box.append(el("figcaption", { class: "note", text: note }));
  return { node: box, mark: (v) => { marker.setAttribute("x1", x(v)); marker.setAttribute("x2", x(v)); } };
}

/** The ellipse of the body's shape at sample i: semi-axes λ, μ turned by the material angle θ (R not shown). */
function ellipseView(traj) {
  const S = 260, C = S / 2;
  const lam = traj.state.lambda, mu = traj.state.mu, th = traj.state.theta;
  let r = 0;
  for (let i = 0; i < lam.length; i++) r = Math.max(r, lam[i], mu[i]);
  const scale = (C - 16) / r;
  const root = svg("svg", { viewBox: `0 0 ${S} ${S}`, class: "ellipse", role: "img", "aria-label": "the ellipse" });
  root.append(svg("line", { x1: 8, x2: S - 8, y1: C, y2: C, class: "grid" }), svg("line", { x1: C, x2: C, y1: 8, y2: S - 8, class: "grid" }));
  const deg = (a) => -a * 180 / Math.PI;
  root.append(svg("ellipse", { cx: C, cy: C, rx: lam[0] * scale, ry: mu[0] * scale, transform: `rotate(${deg(th[0])} ${C} ${C})`, class: "start" }));
  const now = svg("ellipse", { cx: C, cy: C, class: "now" });
  const axis = svg("line", { x1: C, y1: C, class: "axis-line" });
  root.append(now, axis);
  const draw = (i) => {
    now.setAttribute("rx", lam[i] * scale);
    now.setAttribute("ry", mu[i] * scale);
    now.setAttribute("transform", `rotate(${deg(th[i])} ${C} ${C})`);
    axis.setAttribute("x2", C + lam[i] * scale * Math.cos(th[i]));
    axis.setAttribute("y2", C - lam[i] * scale * Math.sin(th[i]));
  };
  return { node: root, draw };
}

function showTrajectory(job) {
  const traj = job.result;
  const t = traj.t, st = traj.state;
  const H0 = traj.energy.length ? traj.energy[0] : 0;
  let drift = 0;
  for (const h of traj.energy) drift = Math.max(drift, Math.abs(h - H0));
  const charts = [
    lineChart(t, [{ name: "λ", values: st.lambda, color: "lambda" }, { name: "μ", values: st.mu, color: "mu" }, { name: "ϱ", values: st.rho, color: "rho" }],
              { title: "shape: the stretches λ, μ and the thickness ϱ", ylabel: "λ, μ, ϱ (dimensionless)" }),
    lineChart(t, [{ name: "s₃", values: st.s3, color: "s3" }], { title: "spin s₃", ylabel: "s₃ (dimensionless)" }),
    lineChart(t, [{ name: "H", values: traj.energy, color: "energy" }],
              { title: "energy H", ylabel: "H (dimensionless)", note: `H(0) = ${fmt(H0, 10)}; largest |H(t) − H(0)| = ${fmt(drift, 3)}` +
                (drift < ZERO_TOL ? " (within round-off)" : "") }),
  ];
  const ell = ellipseView(traj);
  const slider = el("input", { type: "range", min: "0", max: String(t.length - 1), value: "0", "aria-label": "time" });
  const readout = el("p", { class: "note readout" });
  const show = (i) => {
    ell.draw(i);
    for (const c of charts) c.mark(t[i]);
    readout.textContent = `t = ${fmt(t[i], 5)}: λ = ${fmt(st.lambda[i])}, μ = ${fmt(st.mu[i])}, ϱ = ${fmt(st.rho[i])}, ` +
      `θ = ${fmt(st.theta[i], 4)} rad, s₃ = ${fmt(st.s3[i])}, H = ${fmt(traj.energy[i], 10)} (all dimensionless)`;
  };
  slider.addEventListener("input", () => show(Number(slider.value)));
  const meta = traj.meta || {};
  const card = el("article", { class: "card trajectory", "data-job": job.id, "data-kind": "simulate" },
    el("h3", { text: `Simulation of ${sceneName(job.params.scene)}` }),
    el("p", { class: "note", text: `${t.length} samples, t = ${fmt(t[0])} … ${fmt(t[t.length - 1])}; ${meta.method || "?"} in the ` +
      `${meta.model || "?"} chart, ${meta.nfev !== undefined ? `${meta.nfev} right-hand-side evaluations, ` : ""}` +
      `${fmtDuration(meta.wall_time)} of integration. ` }, el("a", { href: artifactUrl(job.id, "trajectory.json"), download: "trajectory.json", text: "trajectory (JSON)" })),
    el("div", { class: "plots" },
      el("div", { class: "series" }, ...charts.map((c) => c.node)),
      el("figure", { class: "shape" }, ell.node,
         el("figcaption", { class: "note", text: "the ellipse at the time chosen below (solid) and at t = 0 (dashed): semi-axes λ, μ, turned by the material angle θ; the rotation R is not drawn" }),
         slider, readout)));
  card.dataset.created = job.created;
  show(0);
  insertByCreated($("runs"), card);
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
    else if (!["s3", "p_theta"].includes(vary) && !(params.from > 0)) {
      errors.push(["vary-from", `from: the constant ${SYMBOL[vary]} must stay > 0, got ${fmt(params.from)}`]);
    }
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
  document.querySelectorAll("input").forEach((node) => node.addEventListener("input", () => {
    const l = node.closest("label.bad");
    if (l) { l.classList.remove("bad"); const m = l.querySelector(".msg"); if (m) m.remove(); node.removeAttribute("aria-invalid"); }
  }));
  $("scene").addEventListener("change", () => { fillFromScene($("scene").value); markEllipsesStale(); });
  $("zoom").addEventListener("click", (e) => { if (e.target === $("zoom")) $("zoom").close(); });
  try {
    const h = await api("GET", "/health");
    $("health").textContent = `service ${h.status}, version ${h.version}`;
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
