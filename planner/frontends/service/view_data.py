"""The data of the page's 3D view of a planned job: the trajectory decimated within a tolerance, the arm's model,
the I/O stations and the problems placed in time.

The whole trajectory is read once at the job's rate (chunk by chunk: bounded memory) and reduced to a *fine* path
(:data:`FINE_TOLERANCE`); a request then thins that to its own tolerance (the size of a pixel at the page's zoom),
for the whole job or for a window of time (detail on demand). The tolerance bounds what the page shows at ANY time,
not only at the kept samples: between two kept samples the page interpolates linearly in time, and a sample is
dropped only if the TCP position (m) and the joints scaled by the arm's reach (rad x m) differ from that
interpolation by less than the tolerance. So the drawn path and the arm posed by the time slider are both within the
tolerance of the plan.

Arrays go to the page as base64 of little-endian typed arrays (t float64, the rest float32 / int32 / uint8).
"""

from __future__ import annotations

import base64
import io
import math
import re
import zipfile
from dataclasses import dataclass
from typing import Any

import numpy as np

from planner.errors import PlannerError

#: Tolerance of the fine path kept per job, m (the finest detail a request gets).
FINE_TOLERANCE = 1e-5
#: Coarsest tolerance a request may ask for, m.
MAX_TOLERANCE = 0.1
#: The kinds of move, in the order of their index (``ViewPath.kind``).
KINDS = ("cut", "rapid", "reorientation", "reconfiguration", "dwell")
#: Levels of the thinning at most (each splits every interval still beyond the tolerance at its worst sample).
MAX_LEVELS = 64
_LINE = re.compile(r"\blines? (\d+)")
#: The stored fine path's format (:meth:`ViewPath.to_bytes`).
FORMAT = "planner-view 1"
#: The arrays of a :class:`ViewPath`, in order.
FIELDS = ("t", "xyz", "axis", "q", "line", "pass_index", "kind", "io", "feed")
#: Their types as stored (what the page gets: float32 is 0.1 um at 1 m, 1e-7 rad), little-endian.
STORED = {"t": "<f8", "xyz": "<f4", "axis": "<f4", "q": "<f4", "line": "<i4", "pass_index": "<i4", "kind": "u1",
          "io": "<i4", "feed": "<f4"}


@dataclass(frozen=True, eq=False)
class ViewPath:
    """Samples of a trajectory kept for the view.

    t (n,) job time s; xyz (n, 3) TCP position m (robot base frame, or the part's when planned without a robot);
    axis (n, 3) tool z axis (unit); q (n, 6) joints rad (NaN rows where unreachable) or None; line (n,) source line;
    pass_index (n,) pass (-1 outside cuts); kind (n,) index into :data:`KINDS`; io (n,) output bits; feed (n,) TCP
    speed m/s."""

    t: np.ndarray
    xyz: np.ndarray
    axis: np.ndarray
    q: np.ndarray | None
    line: np.ndarray
    pass_index: np.ndarray
    kind: np.ndarray
    io: np.ndarray
    feed: np.ndarray

    def __len__(self) -> int:
        return int(self.t.size)

    def take(self, idx: np.ndarray) -> ViewPath:
        return ViewPath(self.t[idx], self.xyz[idx], self.axis[idx], None if self.q is None else self.q[idx],
                        self.line[idx], self.pass_index[idx], self.kind[idx], self.io[idx], self.feed[idx])

    @staticmethod
    def concat(parts: list[ViewPath]) -> ViewPath:
        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(p, name) for p in parts])

        q = None if parts[0].q is None else cat("q")
        return ViewPath(cat("t"), cat("xyz"), cat("axis"), q, cat("line"), cat("pass_index"), cat("kind"), cat("io"),
                        cat("feed"))

    def to_bytes(self) -> bytes:
        """The samples as stored with the job (an ``.npz`` of plain arrays of the types of :data:`STORED`,
        :data:`FORMAT`; no pickle): about 70 bytes a sample before compression."""
        buf = io.BytesIO()
        arrays: dict[str, Any] = {name: np.asarray(getattr(self, name), dtype=STORED[name]) for name in FIELDS
                                  if getattr(self, name) is not None}
        np.savez_compressed(buf, format=np.array(FORMAT), fine_tolerance=np.float64(FINE_TOLERANCE), **arrays)
        return buf.getvalue()

    @staticmethod
    def from_bytes(data: bytes) -> ViewPath:
        """Samples stored by :meth:`to_bytes`; PlannerError if they are not (or of another format)."""
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                version = str(z["format"])
                arrays = {name: z[name].astype(np.float64) if z[name].dtype.kind == "f" else z[name].astype(np.int64)
                          for name in FIELDS if name in z.files}
            if version == FORMAT:
                return ViewPath(q=arrays.pop("q", None), **arrays)
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise PlannerError(f"the stored view data cannot be read: {exc}") from None
        raise PlannerError(f"stored view data of format {version!r}; this version reads {FORMAT!r}")

    def features(self, reach: float) -> np.ndarray:
        """(n, 3) or (n, 9): position m, and the joints times ``reach`` m (NaN as 0)."""
        if self.q is None:
            return self.xyz
        return np.hstack((self.xyz, np.nan_to_num(self.q) * reach))


def thin(t: np.ndarray, f: np.ndarray, tolerance: float, keep: np.ndarray | None = None) -> np.ndarray:
    """Indices of the samples to keep so that the linear interpolation in time between kept samples is within
    ``tolerance`` of every feature row (max norm over the row's distance): a Douglas-Peucker split on time, all
    intervals of a level at once, each level looking only at the intervals still beyond the tolerance.

    t (n,) increasing s; f (n, k) features; keep (n,) bool: samples kept whatever their error (first and last
    always). Returns (m,) increasing indices."""
    n = t.size
    kept = np.zeros(n, dtype=bool) if keep is None else keep.copy()
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    kept[0] = kept[-1] = True
    s = np.arange(n)  # the samples of intervals that may still be beyond the tolerance
    for _ in range(MAX_LEVELS):
        s = s[~kept[s]]
        if not s.size:
            break
        idx = np.flatnonzero(kept)
        seg = np.searchsorted(idx, s, side="right") - 1
        a, b = idx[seg], idx[seg + 1]
        span = t[b] - t[a]
        w = np.divide(t[s] - t[a], span, out=np.zeros(s.size), where=span > 0)
        err = np.linalg.norm(f[s] - (f[a] + w[:, None] * (f[b] - f[a])), axis=1)
        starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
        worst = np.maximum.reduceat(err, starts)  # per interval
        over = worst > tolerance
        if not over.any():
            s = s[:0]
            break
        group = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, s.size]))
        hit = np.flatnonzero((err == worst[group]) & over[group])
        _, first = np.unique(group[hit], return_index=True)
        kept[s[hit[first]]] = True
        s = s[over[group]]
    else:  # (a pathological path: the rest kept whole where still beyond the tolerance)
        kept[s] = True
    return np.flatnonzero(kept)


def fine_path(job, rate: float | None = None, tolerance: float = FINE_TOLERANCE) -> ViewPath:
    """The job's trajectory at ``rate`` (default the job's) reduced within ``tolerance`` m (:func:`thin`) chunk by
    chunk; every move's first and last sample and every output switch (and the sample before it) are kept.

    The joints are solved only where they are kept: each chunk's poses are thinned first on the TCP position and
    the tool frame (its x and z axes times the arm's reach: a frame within the tolerance at the reach), the
    inverse kinematics is then solved at the kept samples on the job's branch (:func:`~planner.kinematics.
    inverse_path`, from the previous chunk's joints, as :func:`planner.trajectory.track_joints` does) and checked
    by :func:`_refined`. A chunk that carries its joints (a change of configuration, a joint move) is thinned on
    position and joints. The whole NX job (12.9 million poses) needs the inverse kinematics of about one pose in
    twenty instead of every one."""
    from planner.kinematics.poses import pose_to_matrix

    traj = job.trajectory(rate)
    reach = _reach(job)
    robot, tcp = job.settings.robot, job.settings.tcp
    q_prev = getattr(job, "start_joints", None)
    q_prev = None if q_prev is None else np.asarray(q_prev, dtype=float)
    parts: list[ViewPath] = []
    for c in traj.chunks(joints=False):
        n = c.times.size
        if n == 0:
            continue
        xyz = c.poses[:, :3]
        R = pose_to_matrix(c.poses)[:, :3, :3]
        axis = R[:, :, 2]
        speed = np.zeros(n)
        if n > 1:
            speed[1:] = np.linalg.norm(np.diff(xyz, axis=0), axis=1) / np.diff(c.times)
            speed[0] = speed[1]
        keep = np.zeros(n, dtype=bool)
        switch = np.flatnonzero(np.diff(c.io) != 0)
        keep[switch] = keep[np.minimum(switch + 1, n - 1)] = True
        whole = ViewPath(c.times, xyz, axis, c.joints, c.lines, np.full(n, c.pass_index),
                         np.full(n, KINDS.index(c.kind) if c.kind in KINDS else 0), c.io, speed)
        if robot is None or c.joints is not None:  # no joints, or the chunk's own (a joint move)
            if c.joints is not None:
                q_prev = c.joints[-1]
            parts.append(whole.take(thin(c.times, whole.features(reach), tolerance, keep)))
            continue
        frame = np.hstack((xyz, R[:, :, 0] * reach, axis * reach))
        idx = thin(c.times, frame, tolerance, keep)
        idx, q = _refined(robot, tcp, c.times, c.poses, idx, q_prev, reach, tolerance)
        ok = np.flatnonzero(np.isfinite(q).all(axis=1))
        if ok.size:
            q_prev = q[ok[-1]]
        part = whole.take(idx)
        parts.append(ViewPath(part.t, part.xyz, part.axis, q, part.line, part.pass_index, part.kind, part.io,
                              part.feed))
    if not parts:
        raise PlannerError(f"job {job.source}: the trajectory has no sample to show")
    return ViewPath.concat(parts)


def _refined(robot: str, tcp, t: np.ndarray, poses: np.ndarray, idx: np.ndarray, q_prev: np.ndarray | None,
             reach: float, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The kept samples ``idx`` (m,) of one chunk and their joints (m, 6) rad, with samples added until the joints'
    linear interpolation in time is within ``tolerance`` / ``reach`` rad of a solution of the planned pose at the
    quarter points of every interval between kept samples (the worst of an interval that is not added, as
    :func:`thin` does), and every change of reachability seen at the kept or checked samples lies between
    neighbouring samples (bisected).

    t (n,) s and poses (n, 6) are the chunk's; the joints of the kept samples are tracked on one branch from
    ``q_prev`` (:func:`~planner.kinematics.inverse_path`), an added sample's are the solution nearest to the
    interpolation (or, next to an unreachable sample, to its reachable neighbour)."""
    from planner.kinematics import inverse_batch, inverse_path

    q = inverse_path(robot, poses[idx], q_prev, tcp=tcp, allow_unreachable=True)
    for _ in range(MAX_LEVELS):
        a, b = idx[:-1], idx[1:]
        gap = b - a
        open_ = np.flatnonzero(gap > 1)
        if not open_.size:
            break
        k = np.repeat(open_, 3)  # the interval of each check
        quarter = np.tile([1, 2, 3], open_.size)
        c = np.clip(a[k] + (gap[k] * quarter) // 4, a[k] + 1, b[k] - 1)
        w = ((t[c] - t[a[k]]) / (t[b[k]] - t[a[k]]))[:, None]
        qa, qb = q[k], q[k + 1]
        qi = qa + w * (qb - qa)
        ref = np.where(np.isfinite(qi), qi, np.where(np.isfinite(qa), qa, qb))  # NaN: both ends unreachable
        sol = inverse_batch(robot, poses[c], tcp=tcp, q6_ref=np.nan_to_num(ref[:, 5]))
        d = sol.q - np.nan_to_num(ref)[:, None, :]
        d = (d + np.pi) % (2.0 * np.pi) - np.pi  # a solution's joints shifted by whole turns next to the reference
        dist = np.where(sol.valid, np.linalg.norm(d, axis=2), np.inf)
        best = np.argmin(dist, axis=1)
        reachable = sol.valid.any(axis=1)
        q_new = np.nan_to_num(ref) + d[np.arange(c.size), best]
        q_new[~reachable] = np.nan
        err = dist[np.arange(c.size), best] * reach
        interpolated = np.isfinite(qi).all(axis=1)
        err[interpolated != reachable] = np.inf  # reachability changes inside the interval
        err[~interpolated & ~reachable] = 0.0
        mixed = np.isfinite(qa).all(axis=1) != np.isfinite(qb).all(axis=1)
        err[mixed & (quarter == 2)] = np.inf  # bisected until the change lies between neighbours
        worst = np.full(gap.size, -1.0)
        np.maximum.at(worst, k, err)
        over = worst[k] > tolerance
        pick = np.flatnonzero(over & (err == worst[k]))
        if not pick.size:
            break
        _, first = np.unique(k[pick], return_index=True)
        add = pick[first]
        order = np.argsort(np.r_[idx, c[add]], kind="stable")
        idx = np.r_[idx, c[add]][order]
        q = np.vstack((q, q_new[add]))[order]
    return idx, q


def window(path: ViewPath, tolerance: float, t0: float | None = None, t1: float | None = None,
           reach: float = 1.0) -> ViewPath:
    """``path`` between job times t0 and t1 (with the samples on either side) thinned to ``tolerance`` m; the
    output switches and unreachable edges the fine path keeps stay."""
    lo = 0 if t0 is None else max(int(np.searchsorted(path.t, t0, side="right")) - 1, 0)
    hi = len(path) if t1 is None else min(int(np.searchsorted(path.t, t1, side="left")) + 1, len(path))
    part = path.take(np.arange(lo, hi))
    keep = np.zeros(len(part), dtype=bool)
    switch = np.flatnonzero(np.diff(part.io) != 0)
    keep[switch] = keep[np.minimum(switch + 1, len(part) - 1)] = True
    if part.q is not None:
        bad = ~np.isfinite(part.q).all(axis=1)
        edge = np.flatnonzero(np.diff(bad.astype(np.int8)) != 0)
        keep[edge] = keep[np.minimum(edge + 1, len(part) - 1)] = True
    if len(part) and tolerance > FINE_TOLERANCE:
        return part.take(thin(part.t, part.features(reach), tolerance, keep))
    return part


def _reach(job) -> float:
    if job.settings.robot is None:
        return 1.0
    from planner.kinematics.ur_models import get_model

    return float(get_model(job.settings.robot).reach)


def _b64(a: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=np.dtype(dtype).newbyteorder("<")).tobytes()).decode()


def path_json(path: ViewPath, tolerance: float) -> dict:
    """The samples as the page reads them (base64 arrays, see the module doc)."""
    return {"n": len(path), "tolerance": tolerance, "t": _b64(path.t, "f8"), "xyz": _b64(path.xyz, "f4"),
            "axis": _b64(path.axis, "f4"), "q": None if path.q is None else _b64(path.q, "f4"),
            "line": _b64(path.line, "i4"), "pass": _b64(path.pass_index, "i4"), "kind": _b64(path.kind, "u1"),
            "io": _b64(path.io, "i4"), "feed": _b64(path.feed, "f4")}


def robot_json(job) -> dict | None:
    """The arm for the page: standard DH (d, a, alpha per joint, m and rad), the TCP in the flange frame, the joint
    limits, rad."""
    if job.settings.robot is None:
        return None
    from planner.kinematics.ur_models import DH_ALPHA, get_model

    m = get_model(job.settings.robot)
    tcp = job.settings.tcp
    return {"model": m.name, "d": m.d.tolist(), "a": m.a.tolist(), "alpha": list(DH_ALPHA),
            "tcp": [0.0] * 6 if tcp is None else [float(v) for v in tcp], "q_min": list(m.q_min),
            "q_max": list(m.q_max), "reach": m.reach}


def stations(path: ViewPath) -> list[dict]:
    """The output switches: job time s, TCP position m, bits that changed, the word after."""
    if len(path) < 2:
        return []
    k = np.flatnonzero(np.diff(path.io) != 0) + 1
    return [{"t": float(path.t[i]), "xyz": path.xyz[i].tolist(), "changed": int(path.io[i] ^ path.io[i - 1]),
             "io": int(path.io[i])} for i in k]


def problems(job, path: ViewPath) -> list[dict]:
    """The summary's problems placed on the path: reachability problems and lowered feeds (at the first sample of
    the source line they name), changes of the arm configuration (at their move's start), unreachable stretches
    (where the joints are missing). Each: kind, text, t s (None when not placed), xyz m."""
    out: list[dict] = []

    def at_line(text: str) -> int | None:
        m = _LINE.search(text)
        if not m:
            return None
        hit = np.flatnonzero(path.line == int(m.group(1)))
        return int(hit[0]) if hit.size else None

    def add(kind: str, text: str, i: int | None) -> None:
        out.append({"kind": kind, "text": text, "t": None if i is None else float(path.t[i]),
                    "xyz": None if i is None else path.xyz[i].tolist()})

    for text in job.problems:
        add("unreachable", str(text), at_line(str(text)))
    for text in job.slowed:
        add("slowed", str(text), at_line(str(text)))
    recon = np.flatnonzero(np.diff((path.kind == KINDS.index("reconfiguration")).astype(np.int8)) == 1) + 1
    lines = job.reconfiguration_lines() if hasattr(job, "reconfiguration_lines") else []
    for j, i in enumerate(recon):
        add("reconfiguration", str(lines[j]) if j < len(lines) else "change of the arm configuration", int(i))
    if path.q is not None:
        bad = ~np.isfinite(path.q).all(axis=1)
        starts = np.flatnonzero(np.diff(np.r_[0, bad.astype(np.int8)]) == 1)
        for i in starts[:50]:
            add("no-ik", f"no joint solution from t = {path.t[i]:.3f} s (source line {path.line[i]})", int(i))
    return out


def scene_json(job, path: ViewPath, overview: ViewPath, tolerance: float) -> dict:
    """Everything the page draws of a job: the arm, the part frame, the path (``overview``, thinned to
    ``tolerance``), the stations and the problems (placed on the fine ``path``)."""
    from planner.kinematics.poses import as_transform

    frame = as_transform(job.settings.part_frame, "part_frame")
    return {"source": job.source, "duration_s": float(path.t[-1]), "rate": float(job.settings.rate),
            "n_samples": int(job.trajectory().n_samples), "fine_samples": len(path), "fine_tolerance": FINE_TOLERANCE,
            "kinds": list(KINDS), "passes": len(job.passes), "robot": robot_json(job),
            "part_frame": frame.tolist(), "stations": stations(path), "problems": problems(job, path),
            "bounds": [path.xyz.min(axis=0).tolist(), path.xyz.max(axis=0).tolist()],
            "path": path_json(overview, tolerance)}


def scene(job, fine: ViewPath, reach: float, tolerance: float | None = None, pixels: int = 1000) -> dict:
    """``GET /v1/jobs/{id}/view``: :func:`scene_json` with the path thinned to ``tolerance`` m (default: one pixel of
    a ``pixels``-wide view of the whole path, the diagonal of its bounding box)."""
    if tolerance is None:
        diag = float(np.linalg.norm(fine.xyz.max(axis=0) - fine.xyz.min(axis=0)))
        tolerance = min(max(diag / pixels, FINE_TOLERANCE), MAX_TOLERANCE)
    checked_window(tolerance, None, None)
    return scene_json(job, fine, window(fine, tolerance, reach=reach), tolerance)


def detail(fine: ViewPath, reach: float, t0: float, t1: float, tolerance: float = FINE_TOLERANCE) -> dict:
    """``GET /v1/jobs/{id}/view/path``: the path between job times t0 and t1 s within ``tolerance`` m."""
    checked_window(tolerance, t0, t1)
    return {"t0": t0, "t1": t1, "path": path_json(window(fine, tolerance, t0, t1, reach=reach), tolerance)}


def checked_window(tolerance: float, t0: float | None, t1: float | None) -> None:
    """One-line errors for a request's tolerance (m) and time window (s)."""
    if not (math.isfinite(tolerance) and FINE_TOLERANCE <= tolerance <= MAX_TOLERANCE):
        raise PlannerError(f"tolerance must be in [{FINE_TOLERANCE:g}, {MAX_TOLERANCE:g}] m, got {tolerance!r}")
    for name, v in (("t0", t0), ("t1", t1)):
        if v is not None and not math.isfinite(v):
            raise PlannerError(f"{name} must be a finite time in s, got {v!r}")
    if t0 is not None and t1 is not None and not t0 < t1:
        raise PlannerError(f"the window needs t0 < t1, got t0 = {t0!r} s, t1 = {t1!r} s")
