"""Jüttler's rational rotation-minimizing frame of one spatial PH cubic (seed section 7.1).

A PH cubic has the hodograph h(t) = A(t) i A*(t) with a linear quaternion polynomial
A(t) = (1 - t) A0 + t A1 = S(t) A0, where S(t) = (1 - t) + t A1 A0^-1 stays in the plane spanned by 1 and
one unit vector u. So its unit tangent z(t) = h / |h| turns about the fixed axis u: the tangent
indicatrix is a circular arc, traced with the rational quadratic parameterization of weights
|h0| = |A0|^2, h0.h1/|h0| = <A0, A1> = |A0||A1| cos(phi/2), |h2| = |A1|^2. That is exactly the
parameterization of R1 in seed eq. (13) with w0 = |A0|, w1 = |A1| (eqs. 16, 17), so Jüttler's motion
with these weights puts the frame's first column on the curve's unit tangent at every t.
"""

from __future__ import annotations

import numpy as np

from planner.frames import validation as val
from planner.frames.juttler import RationalArcMotion
from planner.frames.piecewise_motion import PiecewiseArcMotion, chain_arc_motion
from planner.frames.spherical_arc import SphericalArcs, arcs_from_tangent
from planner.frames.validation import FrameDataError

#: Relative residual of the PH conditions on (h0, h1, h2) above which the data is rejected.
PH_TOL = 1e-9


def tangent_arcs(hodographs) -> tuple[SphericalArcs, np.ndarray, np.ndarray]:
    """Tangent indicatrix arcs and weights of m PH cubics from their hodograph control vectors.

    Parameters
    ----------
    hodographs : array (m, 3, 3)
        hodographs[k] = (h0, h1, h2) of segment k (rows).

    Returns
    -------
    arcs : SphericalArcs (m,)
        Arc k starts at h0/|h0|, turns about its axis by phi_k in [0, 2 pi) and ends at h2/|h2|.
    w0, w1 : ndarray (m,)
        sqrt|h0|, sqrt|h2| = |A0|, |A1|: with these weights R1 (seed eq. 13) traces the arc with the
        curve's own parameterization.

    Raises
    ------
    FrameDataError
        Naming the segment: non-finite data, zero end derivative, not PH, hodograph vanishing inside.
    """
    h = np.asarray(hodographs, dtype=float)
    if h.ndim != 3 or h.shape[1:] != (3, 3) or h.shape[0] == 0:
        raise FrameDataError(f"expected shape (m, 3, 3) = (segments, (h0, h1, h2), xyz), got {h.shape}",
                             "hodographs")
    if not np.isfinite(h).all():
        k = int(np.argmax(~np.isfinite(h).all(axis=(1, 2))))
        raise FrameDataError(f"is not finite ({h[k].tolist()})", "hodographs", k)
    h0, h1, h2 = h[:, 0], h[:, 1], h[:, 2]
    n0, n1, n2 = (np.linalg.norm(v, axis=1) for v in (h0, h1, h2))
    scale = (n0 + n1 + n2) ** 2
    for bad, what in ((n0 <= 1e-13 * np.sqrt(scale), "h0 is zero: the tangent is undefined at t = 0"),
                      (n2 <= 1e-13 * np.sqrt(scale), "h2 is zero: the tangent is undefined at t = 1")):
        if bad.any():
            raise FrameDataError(what, "hodographs", int(np.argmax(bad)))
    # |h(t)|^2 = sigma(t)^2 coefficient by coefficient, sigma = (n0, sigma1, n2) in Bernstein form
    sigma1 = np.einsum("ij,ij->i", h0, h1) / n0
    # degree-4 Bernstein coefficients 3 and 2 (0, 1, 4 hold by the choice of sigma)
    res = np.maximum(np.abs(np.einsum("ij,ij->i", h1, h2) - sigma1 * n2),
                     np.abs(2 * n1 * n1 + np.einsum("ij,ij->i", h0, h2) - 2 * sigma1**2 - n0 * n2))
    bad = res > PH_TOL * scale
    if bad.any():
        k = int(np.argmax(bad))
        raise FrameDataError(f"(h0, h1, h2) is not the hodograph of a PH cubic: |h(t)| is not a polynomial "
                             f"(relative residual {res[k] / scale[k]:.3g})", "hodographs", k)
    bad = sigma1 <= -(1.0 - 1e-12) * np.sqrt(n0 * n2)
    if bad.any():
        raise FrameDataError("the hodograph vanishes inside the segment (A0 and A1 opposite): cusp",
                             "hodographs", int(np.argmax(bad)))
    z0, z2 = h0 / n0[:, None], h2 / n2[:, None]
    tan0 = h1 - np.einsum("ij,ij->i", h1, z0)[:, None] * z0  # direction of z'(0)
    nt = np.linalg.norm(tan0, axis=1)
    straight = nt <= 1e-12 * n1  # the tangent does not turn: a point arc on any great circle
    other = np.where((np.abs(z0[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    tan0 = np.where(straight[:, None], np.cross(z0, other), tan0)
    tan0 /= np.linalg.norm(tan0, axis=1, keepdims=True)
    arcs = arcs_from_tangent(z0, tan0, np.where(straight[:, None], z0, z2))
    return arcs, np.sqrt(n0), np.sqrt(n2)


def _vector(v, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,):
        raise FrameDataError(f"expected a vector of shape (3,), got shape {a.shape}", name)
    if not np.isfinite(a).all():
        raise FrameDataError(f"is not finite ({a})", name)
    return a


def ph_cubic_rmm(h0, h1, h2, start=None, *, sign_reference=None,
                 r2_weights: str = "reparameterized") -> RationalArcMotion:
    """Rational RMF (Jüttler 1998, sec. 7.1) of the PH cubic with quadratic hodograph h0, h1, h2.

    Parameters
    ----------
    h0, h1, h2 : array (3,)
        Bernstein control vectors of the hodograph r'(t) (m per unit t) of a spatial PH cubic:
        h0 = A0 i A0*, h1 = (A0 i A1* + A1 i A0*)/2, h2 = A1 i A1*.
    start : array (3, 3), optional
        Frame at t = 0, right-handed orthonormal with column 0 equal to the unit tangent h0/|h0|.
        Default: the shortest-arc rotation taking e1 to the tangent.
    sign_reference : array (4,), optional
        Sign of the quaternion at t = 0 (positive inner product with this), for continuity along a spline.
    r2_weights : str
        Free parameter of R2 (seed sec. 6). Default ``"reparameterized"``: the weights |A0| != |A1|
        of a PH cubic make the seed's heuristic (``"paper"``) twist more; see
        :func:`~planner.frames.juttler.rational_coefficients`.

    Returns
    -------
    RationalArcMotion
        ``frames(t)`` (n, 3, 3): column 0 the unit tangent h(t)/|h(t)| (exactly, to round-off),
        columns 1, 2 the rational rotation-minimizing normal-plane vectors (degree 6 rational);
        ``quaternion(t)`` the cubic quaternion polynomial; ``.exact()`` the exact RMF of the segment
        with the same start frame, evaluated at the same curve parameter t.

    Raises
    ------
    FrameDataError
        If an h is not finite, h0 or h2 is zero, the data is not the hodograph of a PH cubic, the
        hodograph vanishes inside the segment, or ``start`` is not a valid frame on the tangent.
    """
    hod = np.stack([_vector(v, name) for v, name in ((h0, "h0"), (h1, "h1"), (h2, "h2"))])
    try:
        arcs, w0, w1 = tangent_arcs(hod[None])
    except FrameDataError as exc:  # one segment: name the hodograph, not segment 0
        raise FrameDataError(str(exc).split(": ", 1)[1], "h0, h1, h2") from None
    z0 = arcs.start[0]
    f0 = val.default_frame(z0, 0) if start is None else val.frame(start, "start", z0, 0)
    motion = chain_arc_motion(arcs, start_frame=f0, axis_column=0, w0=w0, w1=w1, sign_reference=sign_reference,
                              r2_weights=r2_weights).segment(0)
    assert isinstance(motion, RationalArcMotion)  # chain_arc_motion is rational unless told otherwise
    return motion


def ph_cubic_spline_rmm(hodographs, knots=None, start=None, *, sign_reference=None, rational: bool = True,
                        r2_weights: str = "reparameterized") -> PiecewiseArcMotion:
    """Jüttler's rational RMF of a G1 PH cubic spline (seed sec. 7.1), all segments at once.

    Parameters
    ----------
    hodographs : array (m, 3, 3)
        Hodograph control vectors (h0, h1, h2) of each segment (local parameter in [0, 1]).
    knots : array (m + 1,), optional
        Global parameters of the segment ends (default 0, 1, ..., m).
    start : array (3, 3), optional
        Frame at the start, column 0 = the unit tangent there (default: shortest arc from e1).
    sign_reference : array (4,), optional
        Sign of the first quaternion.
    rational : bool
        Jüttler's rational motion (True) or the exact RMF (False).
    r2_weights : str
        Free parameter of each R2, as in :func:`ph_cubic_rmm`.

    Returns
    -------
    PiecewiseArcMotion
        Frames (column 0 = unit tangent) C0 at the joints, each segment starting from the end frame
        of the previous one; quaternion signs continuous.

    Raises
    ------
    FrameDataError
        As :func:`tangent_arcs`, and where the unit tangents of neighbouring segments differ (the spline
        is not G1 there: split the path at corners).
    """
    arcs, w0, w1 = tangent_arcs(hodographs)
    z0 = arcs.start[0]
    f0 = val.default_frame(z0, 0) if start is None else val.frame(start, "start", z0, 0)
    return chain_arc_motion(arcs, knots, start_frame=f0, axis_column=0, w0=w0, w1=w1,
                            sign_reference=sign_reference, rational=rational, r2_weights=r2_weights)
