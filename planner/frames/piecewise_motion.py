"""Chains of circular-arc RMMs (Jüttler 1998, sections 5 and 7): C0 frames at the joints.

The RMM of a C0 chain of circular arcs on the unit sphere is the chain of the arcs' RMMs, each arc
starting from the end frame of the previous one (seed sec. 5: "collecting the individual segments").
The exact RMM of an arc maps its start frame to its end frame by a rotation T that does not depend on
the spin (seed eq. 10: a change of rho is a constant right factor), so all start frames follow at once
from a cumulative product of the T's, and every quantity here is vectorized over arcs and samples.
Jüttler's rational motion of an arc meets the exact one at both ends (seed eq. 18), so the rational
chain has the same joint frames as the exact chain.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from planner import bernstein
from planner import quaternion as quat
from planner.frames import validation as val
from planner.frames.juttler import (
    R2_WEIGHTS,
    ExactArcMotion,
    RationalArcMotion,
    arc_q1,
    arc_transport,
    place_arcs,
    rational_coefficients,
    spin_for_start,
)
from planner.frames.quaternion_scan import cumulative_left_product
from planner.frames.spherical_arc import SphericalArcs
from planner.frames.validation import FrameDataError
from planner.rotations import matrix_to_quaternion, quaternion_to_matrix
from planner.validation import finite_floats

#: Largest gap (rad) accepted between the end of one arc and the start of the next.
JOINT_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class PiecewiseArcMotion:
    """A chain of m arc RMMs (rational, seed eqs. 13-15, or exact, eq. 10) over knots t_0 < ... < t_m.

    On [t_k, t_k+1] the motion is segment k evaluated at u = (t - t_k) / (t_k+1 - t_k).

    Attributes
    ----------
    knots : ndarray (m + 1,)
        Increasing parameter values of the joints.
    phi, psi, rho, w0, w1 : ndarray (m,)
        Per-arc angle, angular radius, spin (rad) and weights, as in :func:`~planner.frames.juttler.rmm_arc`.
    left : ndarray (m, 4)
        Per-arc placing quaternions; ``right`` (4,) the common column permutation.
    axis_column : int
        Column of the frames holding the moving axis.
    rational : bool
        True for Jüttler's rational motion, False for the exact RMM of the same arcs.
    r2_weights : str
        Free parameter of each R2, see :func:`~planner.frames.juttler.rational_coefficients`.
    """

    knots: np.ndarray
    phi: np.ndarray
    psi: np.ndarray
    rho: np.ndarray
    w0: np.ndarray
    w1: np.ndarray
    left: np.ndarray
    right: np.ndarray
    axis_column: int
    rational: bool = True
    r2_weights: str = "paper"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"knots": self.knots, "phi": self.phi, "psi": self.psi, "rho": self.rho, "w0": self.w0, "w1": self.w1,
                "left": self.left, "right": self.right, "axis_column": self.axis_column, "rational": self.rational,
                "r2_weights": self.r2_weights}

    @classmethod
    def from_state(cls, state: dict) -> PiecewiseArcMotion:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    def __len__(self) -> int:
        return self.phi.shape[0]

    @cached_property
    def coeffs(self) -> np.ndarray:
        """Bernstein coefficients (m, 4, 4) of the cubic quaternion polynomials R_k(u) (seed sec. 6)."""
        r1, r2 = rational_coefficients(self.phi, self.psi, self.w0, self.w1, self.rho, self.r2_weights)
        return quat.mul(quat.mul(self.left[:, None, :], bernstein.quaternion_product(r1, r2)), self.right)

    @cached_property
    def _stack(self) -> dict:
        if self.rational:
            return {"c": self.coeffs, "dc": 3.0 * np.diff(self.coeffs, axis=1)}
        m = len(self)
        return {"phi": self.phi, "psi": self.psi, "rho": self.rho, "w0": self.w0, "w1": self.w1,
                "uniform": np.zeros(m), "left": self.left, "right": np.broadcast_to(self.right, (m, 4))}

    def segment(self, k: int) -> RationalArcMotion | ExactArcMotion:
        """Segment k as a one-arc motion in its local parameter u in [0, 1]."""
        args = (float(self.phi[k]), float(self.psi[k]))
        if not self.rational:
            return ExactArcMotion(*args, float(self.rho[k]), float(self.w0[k]), float(self.w1[k]), False,
                                  self.left[k], self.right, self.axis_column)
        r1, r2 = rational_coefficients(*args, self.w0[k], self.w1[k], self.rho[k], self.r2_weights)
        return RationalArcMotion(*args, float(self.w0[k]), float(self.w1[k]), float(self.rho[k]),
                                 self.left[k], self.right, self.axis_column, r1, r2, self.coeffs[k],
                                 self.r2_weights)

    def exact(self) -> PiecewiseArcMotion:
        """The exact RMM of the same arcs with the same start frame and parameterization."""
        return replace(self, rational=False)

    def locate(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Segment indices (n,) and local parameters u (n,) in [0, 1] of parameter values t (n,)."""
        t = np.atleast_1d(finite_floats(t, "t"))
        lo, hi = self.knots[0], self.knots[-1]
        slack = 1e-12 * max(1.0, abs(lo), abs(hi))
        bad = ~np.isfinite(t) | (t < lo - slack) | (t > hi + slack)
        if bad.any():
            i = int(np.argmax(bad))
            raise FrameDataError(f"= {t[i]!r} is outside the parameter range [{lo}, {hi}]", "t", i)
        idx = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self) - 1)
        u = np.clip((t - self.knots[idx]) / (self.knots[idx + 1] - self.knots[idx]), 0.0, 1.0)
        return idx, u

    def _eval(self, t):
        idx, u = self.locate(t)
        kind = RationalArcMotion if self.rational else ExactArcMotion
        q, omega = kind._eval(self._stack, idx, u)
        return q, omega / np.diff(self.knots)[idx][:, None]

    def quaternion(self, t) -> np.ndarray:
        """Unit quaternions (n, 4) of the frames at t (n,); signs continuous across the joints."""
        q = self._eval(t)[0]
        return q / np.sqrt(quat.norm2(q))[:, None]

    def frames(self, t) -> np.ndarray:
        """Frames (n, 3, 3) at t (n,); column ``axis_column`` is the moving axis."""
        return quaternion_to_matrix(self._eval(t)[0])

    def angular_velocity(self, t) -> np.ndarray:
        """Angular velocity (n, 3) in rad per unit of t (one-sided at the joints: the right segment)."""
        return self._eval(t)[1]

    def axis(self, t) -> np.ndarray:
        """The moving axis (n, 3) at t (n,)."""
        return self.frames(t)[:, :, self.axis_column]

    @property
    def joint_quaternions(self) -> np.ndarray:
        """Unit quaternions (m + 1, 4) of the frames at the knots (identical for rational and exact)."""
        return self.quaternion(self.knots)


def chain_arc_motion(arcs: SphericalArcs, knots=None, *, start_frame=None, axis_column: int = 2, w0=None,
                     w1=None, sign_reference=None, rational: bool = True,
                     r2_weights: str = "paper") -> PiecewiseArcMotion:
    """The RMM of a C0 chain of arcs, each starting from the end frame of the previous one.

    Parameters
    ----------
    arcs : SphericalArcs
        m arcs; arc k + 1 must start where arc k ends (to ``JOINT_TOL`` rad).
    knots : array (m + 1,), optional
        Increasing joint parameters (default 0, 1, ..., m).
    start_frame : array (3, 3), optional
        Frame at the first knot, right-handed orthonormal, column ``axis_column`` = arcs.start[0].
        Default: rho = 0 in the standard coordinates of the first arc.
    axis_column : int
        Column holding the moving axis (2: tool frames, 0: path frames with the unit tangent first).
    w0, w1 : array (m,), optional
        Weights of each R1 (seed eq. 13) (default 1; with 1 the quaternion polynomials also join C0).
    sign_reference : array (4,), optional
        The first quaternion gets the sign of positive inner product with this one.
    rational : bool
        Jüttler's rational motion (True) or the exact RMM of the arcs (False).
    r2_weights : str
        Free parameter of each R2 (matters only for unequal weights), see
        :func:`~planner.frames.juttler.rational_coefficients`.

    Returns
    -------
    PiecewiseArcMotion
    """
    m = len(arcs)
    if m == 0:
        raise FrameDataError("is empty", "arcs")
    knots = np.arange(m + 1, dtype=float) if knots is None else np.asarray(knots, dtype=float)
    if knots.shape != (m + 1,):
        raise FrameDataError(f"must have {m + 1} entries (one more than the arcs), got shape {knots.shape}",
                             "knots")
    bad = ~np.isfinite(knots[1:]) | ~(np.diff(knots) > 0)
    if not np.isfinite(knots[0]) or bad.any():
        i = 0 if not np.isfinite(knots[0]) else int(np.argmax(bad)) + 1
        raise FrameDataError("knots must be finite and strictly increasing", "knots", i)
    start = val.unit_vectors(arcs.start, "arcs.start")
    axis = val.unit_vectors(arcs.axis, "arcs.axis")
    gap = np.linalg.norm(arcs.end[:-1] - start[1:], axis=1)
    if (gap > JOINT_TOL).any():
        i = int(np.argmax(gap > JOINT_TOL)) + 1
        raise FrameDataError(f"starts {gap[i - 1]:.3g} rad away from the end of arc {i - 1}", "arcs", i)
    phi = np.asarray(arcs.angle, dtype=float)
    w0 = np.ones(m) if w0 is None else np.broadcast_to(np.asarray(w0, dtype=float), (m,))
    w1 = np.ones(m) if w1 is None else np.broadcast_to(np.asarray(w1, dtype=float), (m,))
    bad = ~(np.abs(phi) < 2 * np.pi) | ~(w0 > 0) | ~(w1 > 0) | ~np.isfinite(w0 * w1)
    if bad.any():
        k = int(np.argmax(bad))
        raise FrameDataError(f"needs |angle| < 2 pi and finite weights > 0, got angle {phi[k]!r}, "
                             f"w0 {w0[k]!r}, w1 {w1[k]!r}", "arcs", k)
    right = matrix_to_quaternion(val.cyclic_permutation(axis_column))
    psi, left = place_arcs(start, axis)
    if start_frame is None:
        f0 = quat.mul(quat.mul(left[0], arc_q1(np.float64(0.0), psi[0])), right)
    else:
        f0 = matrix_to_quaternion(val.frame(start_frame, "start_frame", start[0], axis_column))
    if sign_reference is not None and quat.dot(f0, sign_reference) < 0:
        f0 = -f0
    f = cumulative_left_product(arc_transport(phi[:-1], psi[:-1], left[:-1]), f0)  # frames at the joints
    rho = spin_for_start(f, psi, left, right)
    if r2_weights not in R2_WEIGHTS:
        raise FrameDataError(f"must be one of {R2_WEIGHTS}, got {r2_weights!r}", "r2_weights")
    return PiecewiseArcMotion(knots, phi, psi, rho, np.array(w0), np.array(w1), left, right, axis_column,
                              rational, r2_weights)
