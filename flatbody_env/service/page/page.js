// The flatbody service page: plain JS over the service's own JSON API (no build step).
"use strict";

const $ = (id) => document.getElementById(id);
let SCENES = {};

function showError(text) {
  const box = $("error");
  box.textContent = text;
  box.hidden = !text;
}

async function api(method, path, body) {
  const opts = { method, headers: {} };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  const r = await fetch(path, opts);
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) {
    const detail = data && data.detail ? data.detail : `HTTP ${r.status}`;
    throw new Error(`${method} ${path}: ${detail}`);
  }
  return data;
}

const num = (id) => Number($(id).value);
const fmt = (x, d = 6) => (x === null || x === undefined ? "—" : Number(x).toPrecision(d));

function bodySpec() {
  const name = $("potential").value;
  const consts = { V1: ["k"], V2: ["c", "d"], V3: ["kappa"] }[name];
  const potential = { name };
  for (const c of consts) potential[c] = num(c);
  return { params: { J: num("J"), J3: num("J3") }, potential, thickness: { a: num("a"), b: num("b") } };
}

function showPotentialFields() {
  const name = $("potential").value;
  document.querySelectorAll(".pot").forEach((el) => el.classList.toggle("shown", el.classList.contains(name)));
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
  if (sc.t_end) $("t_end").value = Math.min(sc.t_end, 200);
  showPotentialFields();
}

async function findEllipses() {
  showError("");
  const req = { body: bodySpec(), s3: num("s3"), p_theta: num("p_theta") };
  $("ellipses-status").textContent = "computing…";
  try {
    const [ell, stab] = await Promise.all([api("POST", "/ellipses", req), api("POST", "/stability", req)]);
    const tbody = $("ellipses-table").querySelector("tbody");
    tbody.innerHTML = "";
    ell.solutions.forEach((e, i) => {
      const s = stab.solutions[i] || {};
      const cls = s.classification === "elliptic" ? "stable" : s.classification === "hyperbolic" ? "unstable" : "";
      const tr = document.createElement("tr");
      tr.innerHTML = `<td>${i}</td><td>${fmt(e.state.lambda)}</td><td>${fmt(e.state.mu)}</td><td>${fmt(e.state.rho)}</td>` +
        `<td>${fmt(e.omega3)}</td><td>${fmt(e.theta_dot)}</td><td>${fmt(e.energy, 8)}</td>` +
        `<td class="text ${cls}">${s.classification || "?"}</td><td>${fmt(s.max_real_part, 3)}</td>`;
      tbody.appendChild(tr);
    });
    $("ellipses-table").hidden = ell.solutions.length === 0;
    $("ellipses-status").textContent = `${ell.solutions.length} stationary ellipse(s) for s3 = ${req.s3}, p_θ = ${req.p_theta}`;
  } catch (err) {
    $("ellipses-status").textContent = "";
    showError(err.message);
  }
}

function sceneForRun() {
  const name = $("scene").value;
  if (name) return name;
  const base = SCENES["default"];
  const state = Object.assign({}, base.state, { s3: num("s3"), p_theta: num("p_theta") });
  return Object.assign({ name: "custom" }, bodySpec(), { state });
}

const files = {
  "simulate": [["trajectory.json", "trajectory (JSON)"]],
  "record": [["recording.rrd", "recording (.rrd)"]],
  "family": [["family.png", "chart (PNG)"], ["family.csv", "table (CSV)"]],
  "stability-map": [["stability-map.png", "map (PNG)"], ["stability-map.csv", "table (CSV)"]],
};

async function startJob(kind, params) {
  showError("");
  try {
    const { id } = await api("POST", "/jobs", { kind, params });
    const tr = document.createElement("tr");
    tr.id = `job-${id}`;
    tr.dataset.kind = kind;
    tr.innerHTML = `<td class="text">${kind}</td><td class="text status">queued</td>` +
      `<td><progress max="1" value="0"></progress></td><td class="text files"></td>`;
    $("jobs").querySelector("tbody").prepend(tr);
    watch(id, tr);
  } catch (err) {
    showError(err.message);
  }
}

async function watch(id, tr) {
  let job;
  try {
    job = await api("GET", `/jobs/${id}`);
  } catch (err) {
    showError(err.message);
    return;
  }
  tr.dataset.status = job.status;
  tr.querySelector(".status").textContent = job.status + (job.error ? `: ${job.error}` : "");
  tr.querySelector("progress").value = job.progress;
  if (job.status === "queued" || job.status === "running") {
    setTimeout(() => watch(id, tr), 400);
    return;
  }
  if (job.status !== "done") return;
  const cell = tr.querySelector(".files");
  for (const [name, label] of files[job.kind] || []) {
    const a = document.createElement("a");
    a.href = `/jobs/${id}/artifact?name=${encodeURIComponent(name)}`;
    a.download = name;
    a.textContent = label;
    cell.appendChild(a);
    cell.appendChild(document.createTextNode(" "));
  }
  if (job.kind === "record") {
    const hint = document.createElement("div");
    hint.className = "note";
    hint.innerHTML = `open it with: <code class="cmd">rerun ${job.result.recording}</code>`;
    cell.appendChild(hint);
  }
  if (job.kind === "family" || job.kind === "stability-map") {
    const png = files[job.kind][0][0];
    const fig = document.createElement("figure");
    fig.innerHTML = `<img alt="${job.kind} chart" src="/jobs/${id}/artifact?name=${png}"><figcaption class="note">${job.kind}</figcaption>`;
    $("pictures").prepend(fig);
  }
}

async function init() {
  showPotentialFields();
  $("potential").addEventListener("change", showPotentialFields);
  $("find-ellipses").addEventListener("click", findEllipses);
  $("scene").addEventListener("change", () => fillFromScene($("scene").value));
  $("start-family").addEventListener("click", () => {
    const params = { body: bodySpec(), vary: $("vary").value, from: num("vary-from"), to: num("vary-to") };
    if ($("vary").value !== "s3") params.s3 = num("s3");
    if ($("vary").value !== "p_theta") params.p_theta = num("p_theta");
    startJob("family", params);
  });
  $("start-map").addEventListener("click", () => startJob("stability-map", { body: bodySpec(), grid: num("map-grid") }));
  const runParams = () => ({ scene: sceneForRun(), t_end: num("t_end"), method: $("method").value });
  $("start-simulate").addEventListener("click", () => startJob("simulate", Object.assign(runParams(), { samples: num("samples") })));
  $("start-record").addEventListener("click", () => startJob("record", Object.assign(runParams(), { samples: num("samples") })));
  try {
    const h = await api("GET", "/health");
    $("health").textContent = `service ${h.status}, version ${h.version}`;
    SCENES = await api("GET", "/scenes");
    for (const name of Object.keys(SCENES)) {
      const opt = document.createElement("option");
      opt.value = opt.textContent = name;
      $("scene").appendChild(opt);
    }
    const methods = await api("GET", "/methods");
    for (const m of methods.filter((m) => m.adaptive)) {
      const opt = document.createElement("option");
      opt.value = opt.textContent = m.name;
      if (m.name === "DOP853") opt.selected = true;
      $("method").appendChild(opt);
    }
    document.body.dataset.ready = "yes";
  } catch (err) {
    showError(err.message);
  }
}

init();
