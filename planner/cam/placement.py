"""Where to put the part: ``part_frame="auto"`` places a planned job in front of the robot.

The part frame is searched among a translation and a rotation about the base z axis (the part stays level:
its z axis is the base's), ``p[x, y, z, 0, 0, theta]``. A UR arm turns about its base axis (joint 1, +-2 pi),
so only three numbers change what the arm does: the horizontal distance ``r`` of the part's centre from the
base axis, the height ``h`` of the centre and the part's turn ``theta`` about its centre; the centre is put
on the base +x axis.

Every candidate is rated on a decimated set of the job's poses (at most :data:`SAMPLES`: each move's ends,
points spread evenly along the job, and the extreme points along x, y, z), on each of the arm's eight
inverse-kinematics branches (one configuration for the whole job):

- every pose must have a solution on the branch, and the tool must stay :data:`BASE_CLEARANCE` from the
  base axis (the robot's foot);
- the **singularity margin** is the smallest over the poses of ``|sin q3|`` (elbow: the arm stretched out),
  ``|sin q5|`` (wrist: tool axis parallel to the shoulder axis) and ``|a2 cos q2 + a3 cos(q2 + q3) + d5
  sin(q2 + q3 + q4)| / (|a2| + |a3|)`` (shoulder: the wrist over the base axis): the Jacobian's determinant of a
  UR arm is ``a2 a3 sin q3 sin q5 (a2 cos q2 + a3 cos(q2 + q3) + d5 sin(q2 + q3 + q4))``;
- the **joint-limit margin** is the smallest distance (rad) of any joint from its limits over the poses, the
  joints followed continuously from pose to pose and shifted by whole turns to centre them in their range.

The rating of a branch is ``min(singularity margin, joint-limit margin / pi)``, of a candidate its best
branch's; where no branch reaches every pose, minus the smallest fraction of poses out of reach (so the search
climbs towards reach). A coarse grid over (r, h, theta) is rated in a few vectorized batches, then the best
grid points are refined with Nelder-Mead (scipy.optimize) within a bounded number of ratings.
:func:`place_part` raises PlannerError when no candidate reaches every sampled pose.

The planner then checks the whole job at the found frame as for any frame (its report names what is left).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from planner.errors import PlannerError
from planner.kinematics import get_model, inverse_batch
from planner.motion import poses_at_length, tool_orientation
from planner.rotations import matrix_to_rotvec
from planner.wording import pose_option

#: Poses of the job rated per candidate, at most (plus the extremes along x, y, z).
SAMPLES = 400
#: Smallest horizontal distance (m) of the tool from the base axis: the robot's foot is there.
BASE_CLEARANCE = 0.1
#: Grid of the coarse search: distances, heights, turns.
GRID = (10, 8, 8)
#: Refinement: grid points refined, ratings per refinement at most.
REFINE_STARTS, REFINE_RATINGS = 3, 80


@dataclass(frozen=True)
class Placement:
    """A part frame found by :func:`place_part`.

    Attributes
    ----------
    part_frame : tuple (6,)
        ``(x, y, z, 0, 0, theta)`` (m, rotation vector): the part frame in the robot base frame.
    singularity_margin : float
        Smallest of |sin q3|, |sin q5| and the shoulder factor over the rated poses (0..1, larger is safer).
    joint_margin : float
        Smallest distance of any joint from its limits over the rated poses, rad.
    factors : tuple (3,)
        The smallest elbow, wrist and shoulder factors separately.
    branch : int
        The inverse-kinematics branch rated (``IKSolutions``: 4 * shoulder + 2 * wrist + elbow).
    poses : int
        Poses rated per candidate.
    ratings : int
        Candidates rated.
    seconds : float
        Wall time of the search, s.
    """

    part_frame: tuple
    singularity_margin: float
    joint_margin: float
    factors: tuple
    branch: int
    poses: int
    ratings: int
    seconds: float

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"part_frame": self.part_frame, "singularity_margin": self.singularity_margin,
                "joint_margin": self.joint_margin, "factors": self.factors, "branch": self.branch, "poses": self.poses,
                "ratings": self.ratings, "seconds": self.seconds}

    @classmethod
    def from_state(cls, state: dict) -> Placement:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def option(self) -> str:
        """The frame as the CLI's ``--part-frame`` value (mm and deg to 4 decimals)."""
        return pose_option(self.part_frame)

    def describe(self) -> str:
        """One line for a person."""
        e, w, s = self.factors
        return (f"part frame placed for the robot (part_frame='auto'): --part-frame {self.option}; singularity "
                f"margin {self.singularity_margin:.3f} (|sin q3| {e:.3f}, |sin q5| {w:.3f}, shoulder {s:.3f}), "
                f"joint-limit margin {math.degrees(self.joint_margin):.1f} deg, over {self.poses} poses "
                f"({self.ratings} placements rated in {self.seconds:.2f} s)")


def job_samples(moves, count: int = SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Decimated tool poses of planned moves in the part frame: positions (n, 3) and frames (n, 3, 3), in job
    order: every move's ends (known without evaluating its path), points every ``length / count`` along the
    moves longer than that, then at most ``count`` of them spread evenly and the extremes along x, y, z."""
    moving = [m for m in moves if m.kind == "dwell" or (m.kind in ("cut", "rapid", "reorientation")
                                                        and m.profile is not None)]
    if not moving:
        raise PlannerError("part_frame='auto': the job has no motion to place")
    length = sum(float(m.path.length) for m in moving if m.kind in ("cut", "rapid"))
    step = max(length / max(count, 1), 1e-6)
    P, R = [], []
    for m in moving:
        start = np.asarray(m.point, float)
        if m.kind == "cut":
            end = m.item.points[-1]
        elif m.kind == "rapid":
            end = m.item.end
        else:
            end = start
        P.append(start[None])
        R.append(m.start_frame[None])
        if m.kind in ("cut", "rapid") and float(m.path.length) > step:
            L = float(m.path.length)
            x = np.linspace(0.0, L, math.ceil(L / step) + 1)[1:-1]
            p, F, _ = poses_at_length(m.path, tool_orientation(m.frames), x)
            P.append(np.asarray(p, float))
            R.append(np.asarray(F, float))
        if m.kind != "dwell":
            P.append(np.asarray(end, float)[None])
            R.append(m.end_frame[None])
    pos, frames = np.concatenate(P), np.concatenate(R)
    if len(pos) > count:
        keep = np.union1d(np.linspace(0, len(pos) - 1, count).round().astype(np.int64),
                          np.concatenate((pos.argmin(axis=0), pos.argmax(axis=0))))
        pos, frames = pos[keep], frames[keep]
    return pos, frames


class _Rater:
    """Rates candidate placements (r, h, theta) of fixed part-frame poses for one robot."""

    def __init__(self, robot: str, tcp, pos: np.ndarray, frames: np.ndarray):
        self.model = get_model(robot)
        self.robot, self.tcp = robot, tcp
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        self.centre = 0.5 * (lo + hi)
        self.pos = pos - self.centre  # about the part's centre
        self.frames = frames
        self.size = hi - lo
        self.ratings = 0

    def frame(self, r: float, h: float, theta: float) -> tuple:
        """The part frame (6,) that puts the part's centre at (r, 0, h), turned by theta about it."""
        c, s = math.cos(theta), math.sin(theta)
        cx, cy, cz = self.centre
        t = (r - (c * cx - s * cy), -(s * cx + c * cy), h - cz)
        th = math.atan2(s, c)
        return tuple(float(v) for v in (t[0], t[1], t[2], 0.0, 0.0, th))  # plain floats (JSON, reprs)

    def rate(self, cands, detail: bool = False):
        """Ratings (C,) of candidates (C, 3) = (r, h, theta); with ``detail`` also the best branch (C,), its
        singularity margin (C,), joint-limit margin (C,) and elbow, wrist, shoulder factors (C, 3)."""
        cands = np.atleast_2d(np.asarray(cands, dtype=float))
        C, n = len(cands), len(self.pos)
        self.ratings += C
        th = cands[:, 2]
        c, s = np.cos(th), np.sin(th)
        Rz = np.zeros((C, 3, 3))
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
        p = np.einsum("cij,nj->cni", Rz, self.pos)
        p[..., 0] += cands[:, None, 0]
        p[..., 2] += cands[:, None, 1]
        rot = matrix_to_rotvec(np.einsum("cij,njk->cnik", Rz, self.frames).reshape(-1, 3, 3))
        sol = inverse_batch(self.robot, np.hstack((p.reshape(-1, 3), rot)), tcp=self.tcp)
        q = sol.q.reshape(C, n, 8, 6)
        ok = sol.valid.reshape(C, n, 8) & (np.hypot(p[..., 0], p[..., 1]) >= BASE_CLEARANCE)[..., None]
        m = self.model
        qz = np.where(ok[..., None], q, 0.0)
        elbow = np.abs(np.sin(qz[..., 2]))
        wrist = np.abs(np.sin(qz[..., 4]))
        shoulder = np.abs(m.a2 * np.cos(qz[..., 1]) + m.a3 * np.cos(qz[..., 1] + qz[..., 2])
                          + m.d5 * np.sin(qz[..., 1] + qz[..., 2] + qz[..., 3])) / (abs(m.a2) + abs(m.a3))
        factors = np.stack([np.where(ok, f, np.inf).min(axis=1) for f in (elbow, wrist, shoulder)], axis=-1)
        sing = factors.min(axis=-1)  # (C, 8)
        u = np.unwrap(qz, axis=1)  # joints followed from pose to pose (where the branch reaches every pose)
        lo_q, hi_q = u.min(axis=1), u.max(axis=1)  # (C, 8, 6)
        two_pi = 2.0 * math.pi
        k0 = np.round(-(lo_q + hi_q) / 2.0 / two_pi)
        best = np.full(lo_q.shape, -np.inf)
        for dk in (-1.0, 0.0, 1.0):
            k = (k0 + dk) * two_pi
            best = np.maximum(best, np.minimum(m.upper - (hi_q + k), (lo_q + k) - m.lower))
        joint = best.min(axis=-1)  # (C, 8)
        full = ok.all(axis=1)
        score = np.where(full, np.minimum(sing, joint / math.pi), -(1.0 - ok.mean(axis=1)))
        b = score.argmax(axis=1)
        rows = np.arange(C)
        out = score[rows, b]
        if not detail:
            return out
        return out, b, sing[rows, b], joint[rows, b], factors[rows, b]


def place_part(moves, robot: str, tcp=None, *, source: str = "the job") -> Placement:
    """The part frame (translation and turn about the base z) with the largest singularity and joint-limit
    margin over the job's decimated poses (see the module doc).

    Parameters
    ----------
    moves : sequence of PlannedMove
        The job's moves, planned in the part frame.
    robot : str
        UR model.
    tcp : tuple (6,) or None
        The tool centre point in the flange frame.

    Raises
    ------
    PlannerError
        When no candidate reaches every sampled pose (the message gives the job's size and the arm's reach).
    """
    tic = time.perf_counter()
    pos, frames = job_samples(moves)
    rater = _Rater(robot, tcp, pos, frames)
    reach = rater.model.reach
    d1 = rater.model.d1
    half = 0.5 * float(np.hypot(rater.size[0], rater.size[1]))
    nr, nh, nt = GRID
    r_lo, r_hi = BASE_CLEARANCE, reach + half
    h_lo, h_hi = d1 - 0.8 * reach, d1 + 0.8 * reach
    rs, hs = np.linspace(r_lo, r_hi, nr), np.linspace(h_lo, h_hi, nh)
    ts = np.linspace(-math.pi, math.pi, nt, endpoint=False)
    grid = np.stack(np.meshgrid(rs, hs, ts, indexing="ij"), axis=-1).reshape(-1, 3)
    # batches of about 40,000 poses (memory: the eight branches of every pose)
    per = max(1, 40_000 // len(pos))
    scores = np.concatenate([rater.rate(grid[a:a + per]) for a in range(0, len(grid), per)])
    order = np.argsort(-scores)[:REFINE_STARTS]
    scale = np.array([(r_hi - r_lo) / nr, (h_hi - h_lo) / nh, 2.0 * math.pi / nt])

    def cost(z):
        r = min(max(z[0], r_lo), r_hi)
        h = min(max(z[1], h_lo), h_hi)
        return -float(rater.rate([[r, h, z[2]]])[0])

    found = [(float(scores[i]), grid[i]) for i in order]
    for i in order:
        x0 = grid[i]
        simplex = np.vstack((x0, x0 + np.diag(scale)))
        res = minimize(cost, x0, method="Nelder-Mead",
                       options={"initial_simplex": simplex, "maxfev": REFINE_RATINGS, "xatol": 1e-4, "fatol": 1e-5})
        z = np.array([min(max(res.x[0], r_lo), r_hi), min(max(res.x[1], h_lo), h_hi), res.x[2]])
        found.append((-float(res.fun), z))
    score, z = max(found, key=lambda f: f[0])
    if score <= 0.0:
        raise PlannerError(
            f"{source}: part_frame='auto' found no placement where the {robot} reaches every pose on one arm "
            f"configuration: the best (--part-frame {pose_option(rater.frame(*z))}) leaves {-100 * score:.1f} % of "
            f"{len(pos)} sampled poses out of reach or within {BASE_CLEARANCE:g} m of the base axis; the job spans "
            f"{rater.size[0]:.3f} x {rater.size[1]:.3f} x {rater.size[2]:.3f} m and the {robot} reaches about "
            f"{reach:.2f} m from its shoulder (give --part-frame yourself, a smaller job or another robot)")
    _, b, sing, joint, factors = rater.rate([z], detail=True)
    return Placement(rater.frame(*z), float(sing[0]), float(joint[0]), tuple(float(f) for f in factors[0]),
                     int(b[0]), len(pos), rater.ratings, time.perf_counter() - tic)


