// The page's 3D view of a planned job, and of its run on a robot as it happens (three.js 0.170.0, vendored; MIT).
// The data: GET /v1/jobs/{id}/view (scene), /view/path (detail of a window of time), /v1/executions/{id}/live
// (Server-Sent Events). Units: m, s, rad inside; mm, deg where a person reads them. The robot's base frame is the
// scene's frame (z up).
import * as THREE from "three";
import { OrbitControls } from "./vendor/OrbitControls.js";

const PLANNED = 0x5b6b86, ACTUAL = 0xe07b00, TCP_MARK = 0xff00ff, CUT = 0x1f5fd6, RAPID = 0xf0a020;
const OTHER = 0x8a8f99, TRACE = 0xd0301f;
const SPEEDS = [1, 10, 100];

function b64(s, Type) {
  if (s === null || s === undefined) return null;
  const bin = atob(s), bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}
function decodePath(p) {
  return {n: p.n, tolerance: p.tolerance, t: b64(p.t, Float64Array), xyz: b64(p.xyz, Float32Array),
          axis: b64(p.axis, Float32Array), q: b64(p.q, Float32Array), line: b64(p.line, Int32Array),
          pass: b64(p.pass, Int32Array), kind: b64(p.kind, Uint8Array), io: b64(p.io, Int32Array),
          feed: b64(p.feed, Float32Array)};
}
// the index i with t[i] <= x < t[i+1] (clamped)
function bisect(t, x) {
  let lo = 0, hi = t.length - 1;
  if (x <= t[0]) return 0;
  if (x >= t[hi]) return Math.max(hi - 1, 0);
  while (hi - lo > 1) { const m = (lo + hi) >> 1; if (t[m] <= x) lo = m; else hi = m; }
  return lo;
}
// joints (6) at time x, linear in time between kept samples (null where unreachable)
function jointsAt(p, x) {
  if (!p || !p.q || p.n === 0) return null;
  const i = bisect(p.t, x), j = Math.min(i + 1, p.n - 1);
  const w = p.t[j] > p.t[i] ? Math.min(Math.max((x - p.t[i]) / (p.t[j] - p.t[i]), 0), 1) : 0;
  const q = [];
  for (let k = 0; k < 6; k++) q.push(p.q[6 * i + k] * (1 - w) + p.q[6 * j + k] * w);
  return q.every(Number.isFinite) ? q : null;
}
function xyzAt(p, x) {
  const i = bisect(p.t, x), j = Math.min(i + 1, p.n - 1);
  const w = p.t[j] > p.t[i] ? Math.min(Math.max((x - p.t[i]) / (p.t[j] - p.t[i]), 0), 1) : 0;
  return [0, 1, 2].map((k) => p.xyz[3 * i + k] * (1 - w) + p.xyz[3 * j + k] * w);
}
// standard DH: T_i = T_{i-1} Rz(q) Tz(d) Tx(a) Rx(alpha); frames 0..6 (base .. flange), then the TCP
function dhFrames(robot, q) {
  const out = [new THREE.Matrix4()];
  let T = new THREE.Matrix4();
  for (let i = 0; i < 6; i++) {
    const ct = Math.cos(q[i]), st = Math.sin(q[i]), ca = Math.cos(robot.alpha[i]), sa = Math.sin(robot.alpha[i]);
    const A = new THREE.Matrix4().set(ct, -st * ca, st * sa, robot.a[i] * ct,
                                      st, ct * ca, -ct * sa, robot.a[i] * st,
                                      0, sa, ca, robot.d[i],
                                      0, 0, 0, 1);
    T = T.clone().multiply(A);
    out.push(T);
  }
  out.push(T.clone().multiply(poseMatrix(robot.tcp)));
  return out;
}
function poseMatrix(p) {
  const r = new THREE.Vector3(p[3], p[4], p[5]), angle = r.length();
  const m = new THREE.Matrix4();
  if (angle > 0) m.makeRotationAxis(r.clone().divideScalar(angle), angle);
  m.setPosition(p[0], p[1], p[2]);
  return m;
}

// An arm drawn from its DH parameters at true dimensions: a cylinder per joint (along its axis), a cylinder per
// d and a length (the links), a cone for the tool up to the TCP, a sphere at the TCP.
class Arm {
  constructor(robot, colour, opacity) {
    this.robot = robot;
    this.group = new THREE.Group();
    const s = robot.reach / 1.15;  // radii scaled from a UR5e's (about 40 mm links, 55 mm joints)
    this.rLink = 0.04 * s; this.rJoint = 0.055 * s;
    const mat = new THREE.MeshLambertMaterial({color: colour, transparent: opacity < 1, opacity});
    const jmat = new THREE.MeshLambertMaterial({color: new THREE.Color(colour).multiplyScalar(0.7),
                                               transparent: opacity < 1, opacity});
    const cyl = new THREE.CylinderGeometry(1, 1, 1, 24);
    this.joints = []; this.links = [];
    for (let i = 0; i < 6; i++) {
      const j = new THREE.Mesh(cyl, jmat); this.group.add(j); this.joints.push(j);
      const a = new THREE.Mesh(cyl, mat), b = new THREE.Mesh(cyl, mat);
      this.group.add(a); this.group.add(b); this.links.push([a, b]);
    }
    this.tool = new THREE.Mesh(new THREE.CylinderGeometry(0.2, 1, 1, 16), jmat);
    this.group.add(this.tool);
    // the TCP: a sphere drawn over everything (always seen, its centre where the TCP is)
    this.tcp = new THREE.Mesh(new THREE.SphereGeometry(1, 16, 12),
                              new THREE.MeshBasicMaterial({color: opacity < 1 ? ACTUAL : TCP_MARK, depthTest: false}));
    this.tcp.renderOrder = 10;
    this.tcp.scale.setScalar(0.008 * s);
    this.group.add(this.tcp);
    this.tcpPosition = null;
  }
  static between(mesh, a, b, r) {
    const d = new THREE.Vector3().subVectors(b, a), len = d.length();
    mesh.visible = len > 1e-6;
    if (!mesh.visible) return;
    mesh.position.copy(a).addScaledVector(d, 0.5);
    mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), d.divideScalar(len));
    mesh.scale.set(r, len, r);
  }
  pose(q) {
    this.group.visible = !!q;
    if (!q) return;
    const F = dhFrames(this.robot, q);
    for (let i = 0; i < 6; i++) {
      const o = new THREE.Vector3().setFromMatrixPosition(F[i]);
      const z = new THREE.Vector3().setFromMatrixColumn(F[i], 2);
      const h = this.rJoint * 2.2;
      Arm.between(this.joints[i], o.clone().addScaledVector(z, -h / 2), o.clone().addScaledVector(z, h / 2),
                  this.rJoint);
      const mid = o.clone().addScaledVector(z, this.robot.d[i]);  // along z_{i-1} by d_i, then along x_i by a_i
      const end = new THREE.Vector3().setFromMatrixPosition(F[i + 1]);
      Arm.between(this.links[i][0], o, mid, this.rLink);
      Arm.between(this.links[i][1], mid, end, this.rLink);
    }
    const flange = new THREE.Vector3().setFromMatrixPosition(F[6]);
    const tcp = new THREE.Vector3().setFromMatrixPosition(F[7]);
    Arm.between(this.tool, tcp, flange, this.rLink * 0.5);
    this.tcp.position.copy(tcp);
    this.tcpPosition = tcp;
  }
}

function passColour(k) {
  return new THREE.Color().setHSL(((k * 0.61803) % 1 + 1) % 1, 0.75, 0.45);
}

export class JobView {
  constructor(root, api) {
    this.root = root; this.api = api;
    root.innerHTML = `
      <div class="v3d-bar">
        <button type="button" data-v="play">Play</button>
        <select data-v="speed">${SPEEDS.map((s) => `<option value="${s}">${s}x</option>`).join("")}</select>
        <input data-v="slider" type="range" min="0" max="1" step="any" value="0">
        <span data-v="time">0.000 s</span>
        <select data-v="colour"><option value="pass">colour by pass</option>
          <option value="motion">colour by cut / rapid</option></select>
      </div>
      <div class="v3d-main"><div data-v="canvas" class="v3d-canvas"></div>
        <div class="v3d-side"><div data-v="info" class="v3d-info">Hover or click the path.</div>
          <div data-v="live" class="v3d-live"></div>
          <b>Problems</b><ol data-v="problems" class="v3d-problems"></ol></div></div>`;
    this.el = (k) => root.querySelector(`[data-v="${k}"]`);
    const box = this.el("canvas");
    this.renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
    this.renderer.setPixelRatio(1);
    this.renderer.setClearColor(0xf4f6f9);
    box.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.005, 50);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(1.6, -1.6, 1.2);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener("change", () => { this.dirty = true; this.scheduleDetail(); });
    this.scene.add(new THREE.AmbientLight(0xffffff, 1.4));
    const sun = new THREE.DirectionalLight(0xffffff, 1.8); sun.position.set(2, -3, 4); this.scene.add(sun);
    const grid = new THREE.GridHelper(2, 20, 0xc0c6d0, 0xdde1e7); grid.rotation.x = Math.PI / 2;
    this.scene.add(grid);
    this.scene.add(new THREE.AxesHelper(0.15));
    this.jobGroup = new THREE.Group(); this.scene.add(this.jobGroup);
    this.t = 0; this.playing = false; this.dirty = true; this.job = null; this.detail = null; this.live = null;
    this.state = {t: 0, q: null, tcp: null, liveT: null, liveQ: null, liveSamples: 0, liveEvents: 0,
                  liveConnects: 0, frames: 0, firstFrameMs: null, bytes: 0};
    this.el("slider").addEventListener("input", () => this.setTime(parseFloat(this.el("slider").value)));
    this.el("play").addEventListener("click", () => this.play(!this.playing));
    this.el("colour").addEventListener("change", () => this.drawPath());
    this.renderer.domElement.addEventListener("mousemove", (e) => this.hover(e, false));
    this.renderer.domElement.addEventListener("click", (e) => this.hover(e, true));
    new ResizeObserver(() => this.resize()).observe(box);
    this.resize();
    let last = performance.now();
    const loop = (now) => {
      const dt = Math.min((now - last) / 1000, 0.1); last = now;
      if (this.playing && this.job) {
        const t = this.t + dt * parseFloat(this.el("speed").value);
        if (t >= this.job.duration_s) { this.setTime(this.job.duration_s); this.play(false); } else this.setTime(t);
      }
      if (this.live) this.liveFrame();
      if (this.dirty) {
        this.renderer.render(this.scene, this.camera); this.dirty = false; this.state.frames++;
        if (this.job && this.state.firstFrameMs === null) this.state.firstFrameMs = performance.now() - this.t0;
      }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }
  resize() {
    const box = this.el("canvas"), w = box.clientWidth || 600, h = box.clientHeight || 480;
    this.renderer.setSize(w, h); this.camera.aspect = w / h; this.camera.updateProjectionMatrix(); this.dirty = true;
  }
  async getJSON(url) {
    const r = await this.api(url);
    const text = await r.text();
    this.state.bytes += text.length;
    return JSON.parse(text);
  }
  // show a done job
  async show(jobId) {
    this.t0 = performance.now(); this.state.firstFrameMs = null; this.state.bytes = 0;
    this.jobId = jobId; this.detail = null; this.stopLive();
    const px = Math.max(this.renderer.domElement.width, 100);
    const job = await this.getJSON(`/v1/jobs/${jobId}/view?pixels=${px}`);
    if (this.jobId !== jobId) return;
    job.path = decodePath(job.path);
    this.job = job;
    this.jobGroup.clear();
    const pf = new THREE.AxesHelper(0.1); pf.matrixAutoUpdate = false;
    pf.matrix.fromArray(job.part_frame.flat()).transpose(); this.jobGroup.add(pf);
    this.pathGroup = new THREE.Group(); this.jobGroup.add(this.pathGroup);
    this.drawPath();
    for (const s of job.stations) {
      const m = new THREE.Mesh(new THREE.SphereGeometry(0.005, 12, 8),
                               new THREE.MeshBasicMaterial({color: s.io & s.changed ? 0x1e9b3a : 0xb3261e}));
      m.position.fromArray(s.xyz); this.jobGroup.add(m);
    }
    const list = this.el("problems"); list.innerHTML = "";
    for (const p of job.problems) {
      const li = document.createElement("li");
      li.textContent = `${p.kind}: ${p.text}` + (p.t === null ? "" : ` (t = ${p.t.toFixed(2)} s)`);
      if (p.t !== null) {
        li.style.cursor = "pointer"; li.onclick = () => this.setTime(p.t);
        const m = new THREE.Mesh(new THREE.OctahedronGeometry(0.01), new THREE.MeshBasicMaterial({color: 0xd0101f}));
        m.position.fromArray(p.xyz); this.jobGroup.add(m);
      }
      list.appendChild(li);
    }
    if (!job.problems.length) list.innerHTML = "<li>none</li>";
    this.arm = job.robot ? new Arm(job.robot, PLANNED, 1) : null;
    if (this.arm) this.jobGroup.add(this.arm.group);
    this.actual = job.robot ? new Arm(job.robot, ACTUAL, 0.55) : null;
    if (this.actual) { this.actual.group.visible = false; this.jobGroup.add(this.actual.group); }
    this.trace = null;
    this.el("slider").max = job.duration_s;
    this.frame();
    this.setTime(0);
  }
  // the camera on the path and the arm's base
  frame() {
    const [lo, hi] = this.job.bounds;
    const box = new THREE.Box3(new THREE.Vector3(...lo), new THREE.Vector3(...hi));
    const q0 = jointsAt(this.job.path, 0);
    if (this.job.robot && q0) {  // the arm at the job's start too
      for (const F of dhFrames(this.job.robot, q0)) box.expandByPoint(new THREE.Vector3().setFromMatrixPosition(F));
    }
    const c = box.getCenter(new THREE.Vector3()), r = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 0.05);
    const dist = r / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 1.05;
    this.controls.target.copy(c);
    this.camera.position.copy(c).add(new THREE.Vector3(0.55, -0.7, 0.45).normalize().multiplyScalar(dist));
    this.camera.near = dist / 200; this.camera.far = dist * 20; this.camera.updateProjectionMatrix();
    this.controls.update(); this.dirty = true;
  }
  lineOf(p) {
    const n = p.n, pos = new Float32Array(Math.max(n - 1, 0) * 6), col = new Float32Array(pos.length);
    const byPass = this.el("colour").value === "pass", c = new THREE.Color();
    for (let i = 0; i + 1 < n; i++) {
      for (let k = 0; k < 3; k++) { pos[6 * i + k] = p.xyz[3 * i + k]; pos[6 * i + 3 + k] = p.xyz[3 * i + 3 + k]; }
      const kind = this.job.kinds[p.kind[i + 1]];
      if (kind === "cut") c.set(byPass ? passColour(p.pass[i + 1]) : new THREE.Color(CUT));
      else c.set(kind === "rapid" ? RAPID : OTHER);
      col.set([c.r, c.g, c.b, c.r, c.g, c.b], 6 * i);
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(pos, 3));
    g.setAttribute("color", new THREE.BufferAttribute(col, 3));
    // drawn over the arm (a path under the tool stays in sight)
    const line = new THREE.LineSegments(g, new THREE.LineBasicMaterial({vertexColors: true, depthTest: false}));
    line.renderOrder = 5;
    return line;
  }
  drawPath() {
    if (!this.job) return;
    this.pathGroup.clear();
    this.pathGroup.add(this.lineOf(this.job.path));
    if (this.detail) this.pathGroup.add(this.lineOf(this.detail.path));
    // tool axes: at most 150, evenly over the kept samples of cuts
    const p = this.job.path, cuts = [];
    for (let i = 0; i < p.n; i++) if (this.job.kinds[p.kind[i]] === "cut") cuts.push(i);
    const step = Math.max(1, Math.ceil(cuts.length / 150)), pos = [];
    const len = Math.max(0.02, 0.03 * (this.job.robot ? this.job.robot.reach : 0.3));
    for (let j = 0; j < cuts.length; j += step) {
      const i = cuts[j];
      pos.push(p.xyz[3 * i], p.xyz[3 * i + 1], p.xyz[3 * i + 2], p.xyz[3 * i] - len * p.axis[3 * i],
               p.xyz[3 * i + 1] - len * p.axis[3 * i + 1], p.xyz[3 * i + 2] - len * p.axis[3 * i + 2]);
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(pos), 3));
    this.pathGroup.add(new THREE.LineSegments(g, new THREE.LineBasicMaterial({color: 0x3a9a5b})));
    this.dirty = true;
  }
  pathAt(t) {  // the finest path loaded holding time t
    const d = this.detail;
    return d && t >= d.t0 && t <= d.t1 ? d.path : this.job.path;
  }
  setTime(t) {
    if (!this.job) return;
    this.t = Math.min(Math.max(t, 0), this.job.duration_s);
    this.el("slider").value = this.t;
    this.el("time").textContent = `${this.t.toFixed(3)} s of ${this.job.duration_s.toFixed(1)} s`;
    const q = jointsAt(this.pathAt(this.t), this.t);
    if (this.arm) this.arm.pose(q);
    this.state.t = this.t; this.state.q = q;
    this.state.tcp = this.arm && this.arm.tcpPosition ? this.arm.tcpPosition.toArray() : xyzAt(this.job.path, this.t);
    this.dirty = true;
  }
  play(on) {
    this.playing = on && !!this.job;
    if (this.playing && this.t >= this.job.duration_s) this.setTime(0);
    this.el("play").textContent = this.playing ? "Pause" : "Play";
  }
  // what the page's camera draws: for tests and tools (column-major 4x4, the canvas's box in CSS px)
  cameraMatrices() {
    this.camera.updateMatrixWorld();
    const r = this.renderer.domElement.getBoundingClientRect();
    return {projection: this.camera.projectionMatrix.toArray(), view: this.camera.matrixWorldInverse.toArray(),
            canvas: {x: r.left, y: r.top, width: r.width, height: r.height}};
  }
  project(xyz) {
    const v = new THREE.Vector3(...xyz).project(this.camera), r = this.renderer.domElement.getBoundingClientRect();
    return [r.left + (v.x + 1) / 2 * r.width, r.top + (1 - v.y) / 2 * r.height];
  }
  // hover: the kept sample nearest the pointer (within 10 px); click: the arm there
  hover(e, click) {
    if (!this.job) return;
    const p = this.pathAt(this.t), r = this.renderer.domElement.getBoundingClientRect();
    const M = new THREE.Matrix4().multiplyMatrices(this.camera.projectionMatrix, this.camera.matrixWorldInverse);
    const v = new THREE.Vector3();
    let best = -1, bestD = 100;
    for (const path of [this.job.path].concat(this.detail ? [this.detail.path] : [])) {
      for (let i = 0; i < path.n; i++) {
        v.set(path.xyz[3 * i], path.xyz[3 * i + 1], path.xyz[3 * i + 2]).applyMatrix4(M);
        const x = (v.x + 1) / 2 * r.width - (e.clientX - r.left), y = (1 - v.y) / 2 * r.height - (e.clientY - r.top);
        const d = x * x + y * y;
        if (d < bestD) { bestD = d; best = i; this.hit = path; }
      }
    }
    if (best < 0) return;
    const h = this.hit, t = h.t[best];
    const q = h.q ? Array.from(h.q.slice(6 * best, 6 * best + 6)) : null;
    const lines = [`t = ${t.toFixed(3)} s`, `pass ${h.pass[best] < 0 ? "-" : h.pass[best]} (${this.job.kinds[h.kind[best]]})`,
                   `source line ${h.line[best]}`, `feed ${(1e3 * h.feed[best]).toFixed(1)} mm/s`];
    if (q && this.job.robot) {
      const R = this.job.robot, deg = (x) => (x * 180 / Math.PI).toFixed(1);
      const margin = Math.min(...q.map((x, k) => Math.min(x - R.q_min[k], R.q_max[k] - x)));
      lines.push("joints " + q.map(deg).join(", ") + " deg",
                 `joint-limit margin ${deg(margin)} deg`, `wrist |sin q5| ${Math.abs(Math.sin(q[4])).toFixed(3)}`,
                 `elbow |sin q3| ${Math.abs(Math.sin(q[2])).toFixed(3)}`);
    }
    this.el("info").textContent = lines.join("\n");
    if (click) this.setTime(t);
    void p;
  }
  // detail on demand: zoomed in beyond the loaded tolerance, the visible stretch of time at a pixel's tolerance
  scheduleDetail() {
    clearTimeout(this.detailTimer);
    this.detailTimer = setTimeout(() => this.loadDetail().catch(() => {}), 250);
  }
  pixelSize() {
    const h = this.renderer.domElement.clientHeight || 480;
    const dist = this.camera.position.distanceTo(this.controls.target);
    return 2 * dist * Math.tan(THREE.MathUtils.degToRad(this.camera.fov / 2)) / h;
  }
  async loadDetail() {
    if (!this.job) return;
    const px = Math.max(this.pixelSize(), this.job.fine_tolerance);
    if (px >= this.job.path.tolerance * 0.8) {  // the whole path is fine enough: no detail
      if (this.detail) { this.detail = null; this.drawPath(); this.setTime(this.t); }
      return;
    }
    const p = this.job.path, M = new THREE.Matrix4().multiplyMatrices(this.camera.projectionMatrix,
                                                                      this.camera.matrixWorldInverse);
    const v = new THREE.Vector3();
    let t0 = Infinity, t1 = -Infinity;
    for (let i = 0; i < p.n; i++) {
      v.set(p.xyz[3 * i], p.xyz[3 * i + 1], p.xyz[3 * i + 2]).applyMatrix4(M);
      if (Math.abs(v.x) <= 1.2 && Math.abs(v.y) <= 1.2 && v.z < 1) {
        t0 = Math.min(t0, p.t[Math.max(i - 1, 0)]); t1 = Math.max(t1, p.t[Math.min(i + 1, p.n - 1)]);
      }
    }
    if (!(t1 > t0)) return;
    const d0 = this.detail;
    if (d0 && d0.t0 <= t0 && d0.t1 >= t1 && d0.path.tolerance <= px * 1.25) return;  // what is loaded will do
    const jobId = this.jobId;
    const d = await this.getJSON(`/v1/jobs/${jobId}/view/path?t0=${t0}&t1=${t1}&tolerance=${px}`);
    if (jobId !== this.jobId) return;
    this.detail = {t0, t1, path: decodePath(d.path)};
    this.drawPath(); this.setTime(this.t);
  }

  // ---- live: an execution's joint states (Server-Sent Events over fetch: the API key goes in a header) ----------
  watch(executionId) {
    this.stopLive();
    if (!this.job || !executionId) return;
    const live = {id: executionId, rows: [], last: 0, ended: false, abort: new AbortController(), clock: null};
    this.live = live;
    this.trace = null;
    this.el("live").textContent = "live: connecting";
    const connect = async () => {
      while (!live.ended && this.live === live) {
        try {
          const r = await this.api(`/v1/executions/${executionId}/live`,
                                   {headers: {"Last-Event-ID": String(live.last)}, signal: live.abort.signal});
          this.state.liveConnects++;
          this.el("live").textContent = "live: connected";
          const reader = r.body.getReader(), dec = new TextDecoder();
          let buf = "";
          for (;;) {
            const {value, done} = await reader.read();
            if (done) break;
            buf += dec.decode(value, {stream: true});
            let k;
            while ((k = buf.indexOf("\n\n")) >= 0) { this.liveEvent(live, buf.slice(0, k)); buf = buf.slice(k + 2); }
          }
        } catch (e) {
          if (live.abort.signal.aborted) return;
        }
        if (!live.ended) { this.el("live").textContent = "live: reconnecting"; await new Promise((f) => setTimeout(f, 1000)); }
      }
    };
    connect();
  }
  stopLive() {
    if (this.live) { this.live.ended = true; this.live.abort.abort(); }
    this.live = null;
    if (this.actual) this.actual.group.visible = false;
  }
  liveEvent(live, text) {
    let event = "message", data = "", id = null;
    for (const line of text.split("\n")) {
      if (line.startsWith("event:")) event = line.slice(6).trim();
      else if (line.startsWith("data:")) data += line.slice(5).trim();
      else if (line.startsWith("id:")) id = parseInt(line.slice(3), 10);
    }
    if (event === "end") {
      live.ended = true;
      live.state = JSON.parse(data || "{}").state || "ended";
      this.el("live").textContent = "live: execution " + live.state;
      this.state.liveT = null;  // the last sample shown again, with the end
      return;
    }
    if (!data) return;
    const rows = JSON.parse(data);
    if (id !== null) live.last = id;
    this.state.liveEvents++; this.state.liveSamples += rows.length;
    for (const r of rows) live.rows.push(r);
    if (live.rows.length > 20000) live.rows.splice(0, live.rows.length - 20000);
    this.addTrace(rows);
  }
  addTrace(rows) {
    if (!this.trace) {
      this.tracePos = new Float32Array(3 * 200000); this.traceN = 0;
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.BufferAttribute(this.tracePos, 3));
      this.trace = new THREE.Line(g, new THREE.LineBasicMaterial({color: TRACE}));
      this.jobGroup.add(this.trace);
    }
    for (const r of rows) {
      if (this.traceN >= 200000) break;
      this.tracePos.set([r[7], r[8], r[9]], 3 * this.traceN++);
    }
    this.trace.geometry.attributes.position.needsUpdate = true;
    this.trace.geometry.setDrawRange(0, this.traceN);
  }
  // shown ~150 ms behind the newest sample (samples arrive in bursts); the planned arm at the same job time
  liveFrame() {
    const live = this.live, rows = live.rows;
    if (!rows.length) return;
    const newest = rows[rows.length - 1][0];
    const now = performance.now() / 1000;
    if (live.clock === null || live.ended || Math.abs(now - live.clock - (newest - 0.15)) > 0.5) live.clock = now - (newest - 0.15);
    const t = live.ended ? newest : Math.min(now - live.clock, newest);
    let i = rows.length - 1;
    while (i > 0 && rows[i][0] > t) i--;
    const r = rows[i];
    const q = r.slice(1, 7);
    if (this.actual) { this.actual.group.visible = true; this.actual.pose(q); }
    if (this.state.liveT !== r[0]) {
      this.state.liveT = r[0]; this.state.liveQ = q; this.state.liveIo = r[10];
      this.el("live").textContent = `live: t = ${r[0].toFixed(2)} s, outputs ${r[10].toString(2)}` +
        (live.ended ? ` (execution ${live.state})` : "");
      if (Math.abs(this.t - r[0]) > 1e-9) this.setTime(r[0]);
      this.dirty = true;
    }
  }
}

export function mount(root, api) {
  const view = new JobView(root, api);
  window.view3d = view;
  return view;
}
