"""The page at ``GET /``: one HTML file with its script and style, no build step (kept in Python so that it is
installed with the package). It talks to the same REST API as any client: upload or paste, settings, progress,
summary, plot, downloads, cancel, and the run on the simulated robot."""

# ruff: noqa: E501
PAGE = r"""<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>planner: path jobs</title>
<link rel="stylesheet" href="/view3d/view.css">
<script type="importmap">{"imports": {"three": "/view3d/vendor/three.module.min.js"}}</script>
<style>
  :root { --fg: #1d2330; --muted: #5b6475; --line: #d5d9e0; --accent: #2457c5; --bad: #b3261e; --ok: #1e7b34; }
  * { box-sizing: border-box; }
  body { font: 14px/1.45 system-ui, sans-serif; color: var(--fg); margin: 0; background: #f5f6f8; }
  header { background: #fff; border-bottom: 1px solid var(--line); padding: 10px 20px; display: flex; gap: 16px;
           align-items: center; }
  header h1 { font-size: 18px; margin: 0; flex: 1; }
  main { display: grid; grid-template-columns: 380px 1fr; gap: 16px; padding: 16px 20px; }
  section { background: #fff; border: 1px solid var(--line); border-radius: 6px; padding: 12px 14px; }
  h2 { font-size: 15px; margin: 0 0 8px; }
  label { display: block; margin: 6px 0 2px; color: var(--muted); font-size: 12px; }
  input, select, textarea { width: 100%; font: inherit; padding: 4px 6px; border: 1px solid var(--line);
                            border-radius: 4px; }
  textarea { height: 110px; font-family: ui-monospace, monospace; font-size: 12px; }
  .row { display: grid; grid-template-columns: 1fr 1fr; gap: 8px; }
  .tabs button { border: 1px solid var(--line); background: #fff; padding: 4px 10px; cursor: pointer; }
  .tabs button.on { background: var(--accent); color: #fff; border-color: var(--accent); }
  button.primary { margin-top: 10px; background: var(--accent); color: #fff; border: 0; padding: 7px 14px;
                   border-radius: 4px; cursor: pointer; font: inherit; }
  button:disabled { opacity: .5; cursor: default; }
  #error { color: var(--bad); white-space: pre-wrap; margin-top: 8px; }
  progress { width: 100%; height: 14px; }
  pre { background: #f7f8fa; border: 1px solid var(--line); padding: 8px; overflow-x: auto; font-size: 12px;
        white-space: pre-wrap; }
  #plot { max-width: 100%; border: 1px solid var(--line); display: none; margin-top: 8px; }
  table { border-collapse: collapse; width: 100%; font-size: 12px; }
  td, th { border-bottom: 1px solid var(--line); padding: 3px 4px; text-align: left; }
  tr.job { cursor: pointer; } tr.job:hover { background: #eef2fb; }
  .state-done { color: var(--ok); } .state-failed { color: var(--bad); } .state-cancelled { color: var(--muted); }
  #downloads a { margin-right: 12px; }
  .hidden { display: none; }
</style>
</head>
<body>
<header>
  <h1>planner: robot path jobs</h1>
  <span id="mode"></span>
  <input id="apikey" type="password" placeholder="API key (pk_...)" style="width: 280px">
</header>
<main>
  <div>
    <section>
      <h2>New job</h2>
      <div class="tabs"><button id="tab-file" class="on" type="button">Upload a toolpath</button><button
        id="tab-points" type="button">Paste waypoints</button></div>
      <div id="pane-file">
        <label for="file">APT/CLSF, 5-axis G-code, CSV or JSON file</label>
        <input id="file" type="file">
        <div class="row">
          <div><label for="units">units of a CSV/JSON file</label>
            <select id="units"><option value="">default (mm)</option><option>mm</option><option>m</option>
              <option>inch</option></select></div>
          <div><label for="machine">machine (5-axis G-code)</label><input id="machine" placeholder="haas-umc-750"></div>
        </div>
      </div>
      <div id="pane-points" class="hidden">
        <label for="points">waypoints x, y, z in mm, one per line (or a JSON list)</label>
        <textarea id="points" placeholder="0, 0, 0&#10;100, 20, 0&#10;200, 0, 10"></textarea>
      </div>
      <div class="row">
        <div><label for="path">path model</label><select id="path"><option>auto</option><option>interpolate</option>
          <option>cam</option></select></div>
        <div><label for="axes">tool axis</label><select id="axes"><option>auto</option><option>file</option>
          <option>approach</option><option>fixed</option><option>path</option></select></div>
        <div><label for="frame">frame method</label><select id="frame"><option>rmf</option><option>grm</option>
          <option>juttler</option><option>er</option><option>double-reflection</option></select></div>
        <div><label for="tolerance">tolerance, mm</label><input id="tolerance" type="number" step="any" value="0.01"></div>
        <div><label for="corner">corner angle, deg</label><input id="corner" type="number" step="any" value="60"></div>
        <div><label for="feed">feed, mm/s</label><input id="feed" type="number" step="any" value="50"></div>
        <div><label for="rate">rate, Hz</label><input id="rate" type="number" step="any" value="500"></div>
        <div><label for="robot">robot</label><select id="robot"><option value="">none</option><option>ur3e</option>
          <option>ur5e</option><option>ur10e</option><option>ur16e</option><option>ur20</option></select></div>
        <div><label for="passes">passes (K,K or longest)</label><input id="passes" placeholder="all"></div>
        <div><label for="partframe">part frame x,y,z (mm), rx,ry,rz (deg), or auto</label><input id="partframe"
          placeholder="400, 996.5, -100, 0, 0, 0"></div>
      </div>
      <button id="submit" class="primary" type="button">Plan</button>
      <div id="error"></div>
    </section>
    <section style="margin-top: 16px">
      <h2>My jobs</h2>
      <table><thead><tr><th>created</th><th>input</th><th>state</th></tr></thead><tbody id="jobs"></tbody></table>
    </section>
  </div>
  <section id="job">
    <h2>Job <span id="job-id"></span></h2>
    <div id="job-empty">Submit a job or pick one from the list.</div>
    <div id="job-body" class="hidden">
      <div>state: <b id="job-state"></b> <span id="job-stage"></span>
        <button id="cancel" type="button" class="hidden">Cancel</button></div>
      <progress id="job-progress" max="1" value="0"></progress>
      <div id="job-error" style="color: var(--bad)"></div>
      <div id="downloads"></div>
      <pre id="summary" class="hidden"></pre>
      <div id="run" class="hidden">
        <div id="run-reason" style="color: var(--bad)"></div>
        <div class="row" style="grid-template-columns: 1fr 1fr auto auto; align-items: end">
          <div><label for="exec-robot">robot</label><select id="exec-robot"><option>sim</option></select></div>
          <div><label for="exec-mode">mode</label><select id="exec-mode"><option value="program">program (URScript)</option>
            <option value="stream">stream (servoJ)</option></select></div>
          <button id="execute" type="button">Run on the robot</button>
          <button id="exec-stop" type="button" class="hidden">Stop</button>
        </div>
        <div>execution: <b id="exec-state"></b> <span id="exec-stage"></span></div>
        <progress id="exec-progress" max="1" value="0"></progress>
        <div id="execute-result" style="color: var(--bad)"></div>
        <pre id="exec-report" class="hidden"></pre>
        <img id="exec-plot" alt="plot of the run over the planned job" class="hidden" style="max-width: 100%; border: 1px solid var(--line); margin-top: 8px">
      </div>
      <img id="plot" alt="plot of the planned job">
      <div id="view3d"></div>
    </div>
  </section>
</main>
<script>
"use strict";
const $ = (id) => document.getElementById(id);
let current = null, timer = null, devMode = false, execution = null, execTimer = null, modeChosen = false,
    execLost = false;
$("apikey").value = localStorage.getItem("planner-key") || "";
$("apikey").addEventListener("change", () => { localStorage.setItem("planner-key", $("apikey").value); listJobs(); });

function headers(extra) {
  const h = Object.assign({}, extra || {});
  const key = $("apikey").value.trim();
  if (key) h["X-API-Key"] = key;
  return h;
}
async function api(path, options) {
  const o = Object.assign({}, options || {});
  o.headers = headers(o.headers);
  const r = await fetch(path, o);
  if (!r.ok) {
    let msg = r.status + " " + r.statusText;
    try {
      const body = await r.json();
      msg = Array.isArray(body.detail)
        ? body.detail.map((d) => (d.loc || []).slice(1).join(".") + ": " + d.msg).join("\n")
        : (body.detail || msg);
    } catch (e) { /* not JSON */ }
    throw Object.assign(new Error(msg), {status: r.status});
  }
  return r;
}
function tab(which) {
  $("tab-file").classList.toggle("on", which === "file");
  $("tab-points").classList.toggle("on", which === "points");
  $("pane-file").classList.toggle("hidden", which !== "file");
  $("pane-points").classList.toggle("hidden", which !== "points");
}
$("tab-file").onclick = () => tab("file");
$("tab-points").onclick = () => tab("points");

// a part frame as typed: x, y, z in mm and rx, ry, rz in deg (or each with its unit, as on the command line: 0.4m,
// 1.5708rad) -> the API's metres and radians; "auto" as it is
const LENGTH_UNITS = {mm: 1e-3, cm: 1e-2, m: 1, in: 0.0254}, ANGLE_UNITS = {deg: Math.PI / 180, rad: 1};
function partFrame(text) {
  if (text.toLowerCase() === "auto") return "auto";
  const parts = text.split(/[\s,;]+/).filter((p) => p), names = ["x", "y", "z", "rx", "ry", "rz"];
  const usage = "six values x, y, z in mm and rx, ry, rz in deg (or each with its unit: 0.4m, 1.5708rad), or auto";
  if (parts.length !== 6) throw new Error(`part frame ${text}: must be ${usage}, got ${parts.length} values`);
  const si = [], typed = [];
  parts.forEach((p, i) => {
    const m = /^([-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?)([a-z]*)$/i.exec(p);
    if (!m) throw new Error(`part frame ${text}: ${names[i]} = ${p} is not a number (must be ${usage})`);
    const units = i < 3 ? LENGTH_UNITS : ANGLE_UNITS, unit = m[2].toLowerCase() || (i < 3 ? "mm" : "deg");
    if (!Object.hasOwn(units, unit))
      throw new Error(`part frame ${text}: ${names[i]} = ${p}: unknown unit "${m[2]}" (${i < 3 ? "a length" : "an angle"} takes ${Object.keys(units).join(", ")})`);
    const x = parseFloat(m[1]);
    if (!Number.isFinite(x)) throw new Error(`part frame ${text}: ${names[i]} = ${p} is not a finite number`);
    if (i < 3 && !m[2] && x !== 0) typed.push(x);
    si.push(x * units[unit]);
  });
  // metres typed where millimetres are expected: every position value given without a unit under 5 mm
  if (typed.length && typed.every((x) => Math.abs(x) < 5)) {
    const mm = parts.slice(0, 3).map((p) => (/[a-z]$/i.test(p) ? p : String(+(parseFloat(p) * 1000).toPrecision(12))));
    throw new Error(`part frame ${text}: x, y, z are in mm and all under 5 mm: did you type m where mm is expected? ` +
                    `In mm that is ${mm.join(", ")}; give a value its unit (${parts[0]}mm) if millimetres are meant`);
  }
  return si;
}
function num(id, scale) { const v = parseFloat($(id).value); return Number.isFinite(v) ? v * (scale || 1) : undefined; }
function settings() {
  const s = {path: $("path").value, axes: $("axes").value, frame: $("frame").value};
  const put = (k, v) => { if (v !== undefined) s[k] = v; };
  put("tolerance", num("tolerance", 1e-3)); put("corner_deg", num("corner")); put("feed", num("feed", 1e-3));
  put("rate", num("rate"));
  if ($("robot").value) s.robot = $("robot").value;
  const pf = $("partframe").value.trim();
  if (pf) s.part_frame = partFrame(pf);
  const p = $("passes").value.trim();
  if (p === "longest") s.passes = "longest";
  else if (p && p !== "all") s.passes = p.split(/[ ,]+/).map((x) => parseInt(x, 10));
  return s;
}
function parsePoints(text) {
  text = text.trim();
  let rows;
  if (text.startsWith("[")) rows = JSON.parse(text);
  else rows = text.split(/\n+/).filter((l) => l.trim() && !l.trim().startsWith("#"))
    .map((l) => l.trim().split(/[ ,;\t]+/).map(Number));
  return rows.map((r) => r.map((x) => x / 1000));
}
$("submit").onclick = async () => {
  $("error").textContent = "";
  $("submit").disabled = true;
  try {
    let r;
    if (!$("pane-file").classList.contains("hidden")) {
      const f = $("file").files[0];
      if (!f) throw new Error("choose a toolpath file");
      const form = new FormData();
      form.append("file", f);
      form.append("settings", JSON.stringify(settings()));
      const ro = {};
      if ($("units").value) ro.units = $("units").value;
      if ($("machine").value.trim()) ro.machine = $("machine").value.trim();
      form.append("read_options", JSON.stringify(ro));
      r = await api("/v1/jobs", {method: "POST", body: form});
    } else {
      const body = {waypoints: parsePoints($("points").value), settings: settings()};
      r = await api("/v1/jobs", {method: "POST", body: JSON.stringify(body),
                                 headers: {"Content-Type": "application/json"}});
    }
    const created = await r.json();
    show(created.id);
    listJobs();
  } catch (e) {
    $("error").textContent = e.message;
  } finally {
    $("submit").disabled = false;
  }
};
async function download(url, name) {
  const r = await api(url);
  const blob = await r.blob();
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob); a.download = name; a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 5000);
}
function show(id) {
  current = id;
  $("job-empty").classList.add("hidden");
  $("job-body").classList.remove("hidden");
  $("job-id").textContent = id;
  $("plot").style.display = "none"; $("plot").removeAttribute("src");
  $("summary").classList.add("hidden"); $("downloads").innerHTML = ""; $("job-error").textContent = "";
  $("run").classList.add("hidden"); $("execute-result").textContent = ""; $("exec-report").classList.add("hidden");
  $("exec-state").textContent = ""; $("exec-stage").textContent = ""; $("exec-progress").value = 0;
  $("exec-stop").classList.add("hidden"); execution = null; if (execTimer) clearTimeout(execTimer);
  $("exec-plot").classList.add("hidden"); $("exec-plot").removeAttribute("src"); $("run-reason").textContent = "";
  $("execute").disabled = false;
  if (timer) clearTimeout(timer);
  poll();
}
async function poll() {
  const id = current;
  let v;
  try { v = await (await api("/v1/jobs/" + id)).json(); } catch (e) { $("job-error").textContent = e.message; return; }
  if (id !== current) return;
  $("job-state").textContent = v.state;
  $("job-state").className = "state-" + v.state;
  $("job-stage").textContent = v.progress.text ? `(${v.progress.text})` : "";
  $("job-progress").value = v.state === "done" ? 1 : (v.progress.total ? v.progress.done / v.progress.total : 0);
  $("cancel").classList.toggle("hidden", !(v.state === "queued" || v.state === "running"));
  if (v.state === "queued" || v.state === "running") { timer = setTimeout(poll, 500); return; }
  listJobs();
  if (v.error) $("job-error").textContent = v.error.message;
  if (v.state !== "done") return;
  $("summary").textContent = (v.describe || []).join("\n");
  $("summary").classList.remove("hidden");
  const stem = v.input.name.replace(/\.[^.]*$/, "").replace(/[<>]/g, "") || "job";
  const links = [["csv", "trajectory CSV"], ["json", "trajectory JSON"]].concat(v.links.script ? [["script", "URScript program"]] : []);
  $("downloads").innerHTML = "";
  for (const [fmt, text] of links) {
    const a = document.createElement("a");
    a.href = "#"; a.textContent = text; a.id = "download-" + fmt;
    a.onclick = (ev) => { ev.preventDefault(); download(v.links[fmt], `${stem}.${fmt}`).catch((e) => { $("job-error").textContent = e.message; }); };
    $("downloads").appendChild(a);
  }
  $("run").classList.remove("hidden");
  const reason = notRunnable(v.summary || {});
  $("execute").disabled = reason !== "";
  $("run-reason").textContent = reason ? "Run is disabled: " + reason : "";
  listRobots();
  if (window.view3d) window.view3d.show(id).catch((e) => { $("job-error").textContent = "3D view: " + e.message; });
  try {
    const blob = await (await api(v.links.plot)).blob();
    if (id !== current) return;
    $("plot").src = URL.createObjectURL(blob);
    $("plot").style.display = "block";
  } catch (e) { $("job-error").textContent = "plot: " + e.message; }
}
function notRunnable(s) {
  if (!s.robot) return "the job was planned without a robot model; plan it for a robot to run it";
  if (s.executable === false) return s.not_executable || "the job cannot run on its robot";
  return "";
}
$("cancel").onclick = async () => {
  try { await api("/v1/jobs/" + current, {method: "DELETE"}); } catch (e) { $("job-error").textContent = e.message; }
  poll();
};
async function listRobots() {
  try {
    const robots = (await (await api("/v1/robots")).json()).robots;
    const sel = $("exec-robot"), keep = sel.value;
    sel.innerHTML = "";
    for (const r of robots) {
      const o = document.createElement("option");
      o.value = r.name; o.textContent = r.name + (r.simulated ? " (simulated)" : " (" + r.model + ")") + (r.busy ? ", busy" : "");
      sel.appendChild(o);
    }
    if (robots.some((r) => r.name === keep)) sel.value = keep;
    const robot = robots.find((r) => r.name === sel.value);
    if (robot && !modeChosen) $("exec-mode").value = robot.mode_default;  // the service's default mode
  } catch (e) { /* no key yet */ }
}
$("exec-mode").addEventListener("change", () => { modeChosen = true; });
$("execute").onclick = async () => {
  $("execute-result").textContent = ""; $("exec-report").classList.add("hidden");
  try {
    const r = await api(`/v1/jobs/${current}/executions`, {method: "POST",
      body: JSON.stringify({robot: $("exec-robot").value, mode: $("exec-mode").value}),
      headers: {"Content-Type": "application/json"}});
    execution = (await r.json()).id;
    if (window.view3d) window.view3d.watch(execution);
    pollExecution();
  } catch (e) { $("execute-result").textContent = e.message; }
};
$("exec-stop").onclick = async () => {
  try { await api("/v1/executions/" + execution, {method: "DELETE"}); } catch (e) { $("execute-result").textContent = e.message; }
};
async function pollExecution() {
  const id = execution;
  if (!id) return;
  let v;
  try { v = await (await api("/v1/executions/" + id)).json(); } catch (e) {
    $("execute-result").textContent = e.message;
    execLost = !e.status || e.status >= 500;  // the service away (restarting): asked again
    if (execLost) execTimer = setTimeout(pollExecution, 1000);
    return;
  }
  if (execLost) { $("execute-result").textContent = ""; execLost = false; }
  if (id !== execution) return;
  const active = ["starting", "running", "stopping"].includes(v.state);
  $("exec-state").textContent = v.state;
  $("exec-state").className = "state-" + v.state;
  $("exec-stage").textContent = `(${v.progress.text})`;
  $("exec-progress").value = v.state === "done" ? 1 : (v.progress.total ? v.progress.done / v.progress.total : 0);
  $("exec-stop").classList.toggle("hidden", !active);
  $("execute").disabled = active;
  if (active) { execTimer = setTimeout(pollExecution, 300); return; }
  if (v.error) {
    const e = v.error, where = [];
    if (e.t !== null) where.push(`t = ${e.t.toFixed(3)} s`);
    if (e.line !== null) where.push(`source line ${e.line}`);
    if (e.pose) where.push("pose p[" + e.pose.map((x) => x.toFixed(4)).join(", ") + "]");
    $("execute-result").textContent = `${e.kind}: ${e.reason}` + (where.length ? ` (${where.join(", ")})` : "");
  }
  if (v.report) { $("exec-report").textContent = v.report.describe.join("\n"); $("exec-report").classList.remove("hidden"); }
  listRobots();
  if (v.links.plot) {
    try {
      const blob = await (await api(v.links.plot)).blob();
      if (id !== execution) return;
      $("exec-plot").src = URL.createObjectURL(blob);
      $("exec-plot").classList.remove("hidden");
    } catch (e) { $("execute-result").textContent = "run plot: " + e.message; }
  }
}
async function listJobs() {
  try {
    const page = await (await api("/v1/jobs?limit=20")).json();
    const body = $("jobs");
    body.innerHTML = "";
    for (const j of page.jobs) {
      const tr = document.createElement("tr");
      tr.className = "job"; tr.onclick = () => show(j.id);
      const cells = [new Date(j.created_at * 1000).toLocaleTimeString(), j.input.name, j.state];
      for (const c of cells) { const td = document.createElement("td"); td.textContent = c; tr.appendChild(td); }
      tr.lastChild.className = "state-" + j.state;
      body.appendChild(tr);
    }
  } catch (e) { /* no key yet */ }
}
fetch("/healthz").then((r) => r.json()).then((h) => {
  devMode = h.dev_no_auth;
  $("mode").textContent = devMode ? "development mode (no keys)" : "";
  $("apikey").classList.toggle("hidden", devMode);
  listJobs();
});
</script>
<script type="module">
import { mount } from "/view3d/view.js";
mount(document.getElementById("view3d"), api);
</script>
</body>
</html>
"""
