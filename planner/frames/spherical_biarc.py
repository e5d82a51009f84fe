"""Spherical biarc approximation of a curve on the unit sphere (Jüttler 1998, section 5).

A spherical curve z(t) is replaced by a C1 chain of circular arcs: at the knots with even index the
chain interpolates z and the direction of z' (G1 Hermite data), and each pair of neighbouring
Hermite data is joined by a biarc, two arcs with a common tangent at their junction. The biarc is
built in the plane of a stereographic projection, which maps circles to circles and preserves angles
(seed sec. 5): the planar biarc with equal tangent lengths is projected back. Knots are refined
(bisection, vectorized over all open intervals at each level) until every biarc lies within the
tolerance of the curve. The RMM of z is then approximated by the chain of the arcs' rational RMMs
(seed sec. 6), with frames C0 at the joints.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from planner.errors import ConvergenceError
from planner.frames import validation as val
from planner.frames.piecewise_motion import PiecewiseArcMotion, chain_arc_motion
from planner.frames.spherical_arc import SphericalArcs, arcs_from_tangent, geodesic_distance
from planner.frames.validation import FrameDataError

#: Interior samples of z per interval at which a biarc is checked (callable input).
CHECK_SAMPLES = 15
#: A biarc longer than LENGTH_FACTOR times the sampled curve (plus 4 tol) is rejected as a detour.
LENGTH_FACTOR = 1.5
#: Biarcs are accepted when the checked error is below SAFETY * tol (margin for the error between samples).
SAFETY = 0.9
#: Intervals of a callable z are not bisected below MIN_INTERVAL times its parameter range.
MIN_INTERVAL = 1e-6


@dataclass(frozen=True, eq=False)
class SphericalBiarcSpline:
    """A C1 chain of 2b circular arcs on the unit sphere approximating z(t).

    Attributes
    ----------
    knots : ndarray (2b + 1,)
        Joint parameters; ``knots[::2]`` are the Hermite points where the chain meets z(t) and the
        direction of z'(t); ``knots[1::2]`` are the biarc junctions (callable z: the parameter of
        the point of z nearest to the junction; samples: where the sampled curve has covered the first
        arc's share of the biarc length).
    arcs : SphericalArcs
        The 2b arcs; on [knots[k], knots[k+1]] arc k is traced with the rational parameterization of
        Jüttler's R1 with weights ``weights[k]`` (seed eqs. 13, 16).
    weights : ndarray (2b, 2)
        Weights (w0, w1) = (1, sqrt(|z'| at start / |z'| at end)) of each arc, so that the chain moves
        about as fast as z at its knots; with the junction parameters this keeps the chain point at t
        within about tol of z(t) (measured: below 2.5 tol for tol down to 1e-8 on a callable z).
    tol : float
        Requested tolerance (rad, great-circle distance).
    max_error : float
        Largest great-circle distance (rad) from the checked samples of z to the chain.
    """

    knots: np.ndarray
    arcs: SphericalArcs
    weights: np.ndarray
    tol: float
    max_error: float

    @property
    def hermite_knots(self) -> np.ndarray:
        """Parameters (b + 1,) where the chain interpolates z and its tangent direction."""
        return self.knots[::2]

    @cached_property
    def _motion(self) -> PiecewiseArcMotion:
        return self.rmm()

    def points(self, t) -> np.ndarray:
        """Points (n, 3) of the chain at t (n,), the axis of ``rmm()`` at the same t."""
        return self._motion.axis(t)

    def rmm(self, start=None, axis_column: int = 2, exact: bool = False,
            sign_reference=None) -> PiecewiseArcMotion:
        """The piecewise RMM along the chain: frames C0 at the joints, quaternion signs continuous.

        Parameters
        ----------
        start : array (3, 3), optional
            Frame at the first knot with column ``axis_column`` = z at the first knot.
        axis_column : int
            Column of the frames holding the moving axis (2 for tool frames).
        exact : bool
            False: Jüttler's rational motion (seed eqs. 13-15); True: the exact RMM of the arcs (eq. 10).
        sign_reference : array (4,), optional
            Sign of the first quaternion.
        """
        return chain_arc_motion(self.arcs, self.knots, start_frame=start, axis_column=axis_column,
                                w0=self.weights[:, 0], w1=self.weights[:, 1], sign_reference=sign_reference,
                                rational=not exact, r2_weights="reparameterized")


# --------------------------------------------------------------------------------------------------
# Biarcs
# --------------------------------------------------------------------------------------------------
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def biarcs(p0, t0, p1, t1) -> tuple[SphericalArcs, SphericalArcs, np.ndarray]:
    """Spherical biarcs (k,) from (p0, t0) to (p1, t1): unit points and unit tangents, each (k, 3).

    Stereographic projection from -c, c = (p0 + p1)/|p0 + p1|, onto the plane normal to c (conformal;
    seed sec. 5); there the biarc with equal tangent lengths a: |v - a (t0 + t1)| = 2 a with v = q1 - q0,
    a = v.v / (v.(t0 + t1) + sqrt((v.(t0 + t1))^2 + 2 (1 - t0.t1) v.v)), junction
    (q0 + a t0 + q1 - a t1)/2; the junction is mapped back and both arcs are built on the sphere.

    Returns
    -------
    first, second : SphericalArcs
        The two arcs of each biarc.
    ok : ndarray (k,) of bool
        False where the construction failed (antipodal ends or tangents that admit no biarc).
    """
    c = p0 + p1
    nc = np.linalg.norm(c, axis=1)
    ok = nc > 1e-6
    c = np.where(ok[:, None], c, [0.0, 0.0, 1.0]) / np.where(ok, nc, 1.0)[:, None]
    e1 = p0 - _dot(p0, c)[:, None] * c
    other = np.where((np.abs(c[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.where((np.linalg.norm(e1, axis=1) < 1e-150)[:, None], np.cross(c, other), e1)
    e1 = _unit(e1)
    e2 = np.cross(c, e1)

    def stereo(x):
        return np.stack((_dot(x, e1), _dot(x, e2)), -1) / (1.0 + _dot(x, c))[:, None]

    def dstereo(x, v):
        s = 1.0 + _dot(x, c)
        vp = np.stack((_dot(v, e1), _dot(v, e2)), -1)
        xp = np.stack((_dot(x, e1), _dot(x, e2)), -1)
        return vp / s[:, None] - xp * (_dot(v, c) / s**2)[:, None]

    q0, q1 = stereo(p0), stereo(p1)
    d0, d1 = dstereo(p0, t0), dstereo(p1, t1)
    n0, n1 = np.linalg.norm(d0, axis=1), np.linalg.norm(d1, axis=1)
    ok &= (n0 > 0) & (n1 > 0)
    d0 = d0 / np.where(n0 > 0, n0, 1.0)[:, None]
    d1 = d1 / np.where(n1 > 0, n1, 1.0)[:, None]
    v = q1 - q0
    vv = _dot(v, v)
    vt = _dot(v, d0 + d1)
    den = vt + np.sqrt(np.maximum(vt * vt + 2.0 * (1.0 - _dot(d0, d1)) * vv, 0.0))
    ok &= (den > 1e-12 * np.sqrt(vv)) | (vv == 0)
    a = np.where(den > 0, vv / np.where(den > 0, den, 1.0), 0.0)
    j = 0.5 * (q0 + a[:, None] * d0 + q1 - a[:, None] * d1)
    y = j[:, :1] * e1 + j[:, 1:] * e2
    yy = _dot(y, y)[:, None]
    m = (2.0 * y + (1.0 - yy) * c) / (1.0 + yy)
    m = _unit(m)
    first = arcs_from_tangent(p0, t0, m)
    tm = first.tangent(np.arange(len(first)), first.angle)
    tm = np.where((np.linalg.norm(tm, axis=1) > 0.5)[:, None], tm, t0)
    second = arcs_from_tangent(m, tm, p1)
    return first, second, ok


# --------------------------------------------------------------------------------------------------
# Input handling
# --------------------------------------------------------------------------------------------------
def _tangent_plane(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    return v - _dot(v, p)[:, None] * p


def sample_tangents(z: np.ndarray) -> np.ndarray:
    """Unit tangent directions (n, 3) at samples z (n, 3) of a spherical curve (zero where undefined).

    At sample i the tangent of the circle through samples i-1, i, i+1 (the first and last three at
    the ends): with n = (z_i - z_i-1) x (z_i+1 - z_i) that circle turns about n, so its tangent at x
    is n x x / |n x x|. Exact for circular arcs, second order otherwise; where three samples are not
    distinct the projected chord is used.
    """
    n = z.shape[0]
    if n == 2:
        d = _tangent_plane(z, np.repeat((z[1] - z[0])[None], 2, axis=0))
    else:
        mid = np.clip(np.arange(n), 1, n - 2)
        a, b, c = z[mid - 1], z[mid], z[mid + 1]
        normal = np.cross(b - a, c - b)
        d = np.cross(normal, z)
        chord = _tangent_plane(z, c - a)
        small = np.linalg.norm(d, axis=1) <= 1e-14 * np.linalg.norm(chord, axis=1) ** 2
        d = np.where(small[:, None], chord, d)
    nd = np.linalg.norm(d, axis=1, keepdims=True)
    return np.divide(d, nd, out=np.zeros_like(d), where=nd > 0)


def _derivative_fd(z: Callable, t: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Second-order finite differences of z at t inside [lo, hi] (one-sided at the ends)."""
    h = 1e-6 * (hi - lo)
    tc = np.clip(t, lo + h, hi - h)  # centre of a stencil that stays inside [lo, hi]
    zm, z0, zp = (val.curve_values(z, tc + s, "z", True) for s in (-h, 0.0, h))
    off = ((t - tc) / h)[:, None]  # -1, 0 or 1: derivative of the interpolating parabola at t
    return ((zp - zm) / 2 + off * (zp - 2 * z0 + zm)) / h


def _directions(p: np.ndarray, d: np.ndarray, scale: float) -> np.ndarray:
    """Unit tangent directions of derivative vectors d at p; zero rows where |d| * scale < 1e-13."""
    d = _tangent_plane(p, d)
    nd = np.linalg.norm(d, axis=1, keepdims=True)
    return np.divide(d, nd, out=np.zeros_like(d), where=nd * scale >= 1e-13)


def _fill_tangents(p0, t0, p1, t1):
    """Replace zero tangents (z' = 0 at a knot) by the chord direction, or any normal if p0 = p1."""
    out = []
    for p, t in ((p0, t0), (p1, t1)):
        chord = _tangent_plane(p, p1 - p0)
        other = np.where((np.abs(p[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        alt = np.where((np.linalg.norm(chord, axis=1) > 0)[:, None], chord, np.cross(p, other))
        out.append(np.where((np.linalg.norm(t, axis=1) < 0.5)[:, None], _unit(alt), t))
    return out


# --------------------------------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------------------------------
def _assess(p0, t0, p1, t1, seg_of_sample, zs, data_length, tol):
    """Build the biarcs of k intervals and measure them.

    zs (s, 3) are the checked samples, seg_of_sample (s,) their interval; data_length (k,) the length
    of the sampled curve per interval. Returns (first, second, error (k,), accepted (k,)).
    """
    t0, t1 = _fill_tangents(p0, t0, p1, t1)
    first, second, ok = biarcs(p0, t0, p1, t1)
    k = p0.shape[0]
    err = np.zeros(k)
    if zs.shape[0]:
        d = np.minimum(first.distance(seg_of_sample, zs), second.distance(seg_of_sample, zs))
        np.maximum.at(err, seg_of_sample, d)
    length = first.length + second.length
    ok &= length <= LENGTH_FACTOR * data_length + 4 * tol
    ok &= np.isfinite(err)
    return first, second, err, ok & (err <= SAFETY * tol)


def _rowwise_interp(x: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """np.interp(x[i], xp[i], fp[i]) for each row i of non-decreasing xp (k, m)."""
    j = np.clip((xp < x[:, None]).sum(axis=1), 1, xp.shape[1] - 1)
    r = np.arange(xp.shape[0])
    x0, x1, f0, f1 = xp[r, j - 1], xp[r, j], fp[r, j - 1], fp[r, j]
    w = np.clip(np.where(x1 > x0, (x - x0) / np.where(x1 > x0, x1 - x0, 1.0), 0.5), 0.0, 1.0)
    return f0 + w * (f1 - f0)


def _junction_fraction(first: SphericalArcs, second: SphericalArcs) -> np.ndarray:
    """Share (k,) of the first arc in the biarc length, kept inside [0.05, 0.95]."""
    l1, tot = first.length, first.length + second.length
    return np.clip(np.where(tot > 0, l1 / np.where(tot > 0, tot, 1.0), 0.5), 0.05, 0.95)


def _arc_weight(speed0: np.ndarray, speed1: np.ndarray) -> np.ndarray:
    """Weight ratio r = w1 / w0 of R1 (seed eq. 13) fitting the curve's speeds at both ends of an arc.

    With weights (1, r) an arc of chord c = 2 sin(psi) sin(phi / 2) spanning ``span`` in t moves at
    r c / span at its start and c / (r span) at its end (rad per unit t). The speeds |z'| at the two
    ends ask for r = speed0 span / c and r = c / (speed1 span); their geometric mean
    r = sqrt(speed0 / speed1) splits the mismatch. Kept in [1/8, 8]; 1 where undefined.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sqrt(speed0 / speed1)
    return np.where(np.isfinite(r) & (r > 0), np.clip(r, 0.125, 8.0), 1.0)


def _assemble(done, tol):
    """Sort the accepted biarcs and set junction parameters and weights.

    ``done`` holds per level (a, b, first, second, err, t_mid, speed_a, speed_b): interval ends,
    arcs, errors, junction parameters and the curve's speed |z'| at the ends.
    """
    a, b, err, mid, sa, sb, sm = (np.concatenate([d[c] for d in done]) for c in (0, 1, 4, 5, 6, 7, 8))
    first = SphericalArcs.concatenate([d[2] for d in done])
    second = SphericalArcs.concatenate([d[3] for d in done])
    order = np.argsort(a)
    a, b, err, mid, sa, sb, sm = (x[order] for x in (a, b, err, mid, sa, sb, sm))
    first, second = first.take(order), second.take(order)
    mid = np.clip(mid, a + 0.05 * (b - a), b - 0.05 * (b - a))
    knots = np.empty(2 * a.shape[0] + 1)
    knots[0:-1:2], knots[1::2], knots[-1] = a, mid, b[-1]
    weights = np.ones((2 * a.shape[0], 2))
    weights[0::2, 1] = _arc_weight(sa, sm)
    weights[1::2, 1] = _arc_weight(sm, sb)
    arcs = SphericalArcs.interleave(first, second)
    return SphericalBiarcSpline(knots, arcs, weights, tol, float(err.max(initial=0.0)))


def _fit_callable(z, dz, tol, lo, hi, max_arcs):
    def derivative(t):
        return val.curve_values(dz, t, "dz", False) if dz is not None else _derivative_fd(z, t, lo, hi)

    edges = np.linspace(lo, hi, 9)
    a, b = edges[:-1], edges[1:]
    done = []
    frac = np.arange(1, CHECK_SAMPLES + 1) / (CHECK_SAMPLES + 1)
    while a.size:
        ends = np.concatenate((a, b))
        pts = val.curve_values(z, ends, "z", True)
        der = _tangent_plane(pts, derivative(ends))
        tan = _directions(pts, der, hi - lo)
        speed = np.linalg.norm(der, axis=1)
        k = a.size
        p0, p1, t0, t1 = pts[:k], pts[k:], tan[:k], tan[k:]
        ts = a[:, None] + (b - a)[:, None] * frac
        zs = val.curve_values(z, ts.ravel(), "z", True)
        seg = np.repeat(np.arange(k), CHECK_SAMPLES)
        poly = np.concatenate((p0[:, None], zs.reshape(k, CHECK_SAMPLES, 3), p1[:, None]), axis=1)
        cum = np.concatenate((np.zeros((k, 1)), np.cumsum(geodesic_distance(poly[:, 1:], poly[:, :-1]), axis=1)),
                             axis=1)
        first, second, err, good = _assess(p0, t0, p1, t1, seg, zs, cum[:, -1], tol)
        # junction parameter: where the sampled curve has covered the first arc's share of the length
        params = np.concatenate((a[:, None], ts, b[:, None]), axis=1)
        mid = _rowwise_interp(_junction_fraction(first.take(good), second.take(good)) * cum[good, -1],
                              cum[good], params[good])
        junction = first.take(good).end
        for _ in range(2):  # Gauss-Newton on (z(t) - m) . z'(t) = 0: the point of z nearest to the junction
            zt, dt = val.curve_values(z, mid, "z", True), derivative(mid)
            step = np.einsum("ij,ij->i", zt - junction, dt) / np.maximum(np.einsum("ij,ij->i", dt, dt), 1e-300)
            mid = np.clip(mid - step, a[good], b[good])
        speed_mid = np.linalg.norm(_tangent_plane(val.curve_values(z, mid, "z", True), derivative(mid)), axis=1)
        done.append((a[good], b[good], first.take(good), second.take(good), err[good], mid,
                     speed[:k][good], speed[k:][good], speed_mid))
        bad = ~good
        if bad.any():
            if (b - a)[bad].min() < MIN_INTERVAL * (hi - lo):
                i = int(np.flatnonzero(bad)[np.argmin((b - a)[bad])])
                raise ConvergenceError(f"spherical biarcs: tolerance {tol} not met near t = {a[i]:.9g} "
                                       f"(error {err[i]:.3g} rad on an interval of length "
                                       f"{b[i] - a[i]:.3g}; z may have a corner there)")
            if 2 * (sum(d[0].size for d in done) + 2 * int(bad.sum())) > max_arcs:
                raise ConvergenceError(f"spherical biarcs: more than {max_arcs} arcs needed for tol = {tol}")
        half = 0.5 * (a[bad] + b[bad])
        a, b = np.concatenate((a[bad], half)), np.concatenate((half, b[bad]))
    return _assemble(done, tol)


def _fit_samples(z, ts, tol, max_arcs):
    n = z.shape[0]
    tan = sample_tangents(z)
    cum = np.concatenate(([0.0], np.cumsum(geodesic_distance(z[1:], z[:-1]))))
    speed = np.gradient(cum, ts, edge_order=2 if n > 2 else 1)  # |z'| from the sampled arc length
    edges = np.unique(np.round(np.linspace(0, n - 1, min(n, 9))).astype(int))
    i, j = edges[:-1], edges[1:]
    done = []
    while i.size:
        counts = j - i - 1
        seg = np.repeat(np.arange(i.size), counts)
        inner = np.arange(seg.size) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(i + 1, counts)
        first, second, err, good = _assess(z[i], tan[i], z[j], tan[j], seg, z[inner], cum[j] - cum[i], tol)
        stuck = ~good & (j - i < 2)
        if stuck.any():
            s = int(i[np.argmax(stuck)])
            raise ConvergenceError(f"spherical biarcs: no acceptable biarc between samples {s} and {s + 1} "
                                   "(the sampled tangents turn back; denser samples may help)")
        ig, jg = i[good], j[good]
        frac = _junction_fraction(first.take(good), second.take(good))
        mid = np.interp(cum[ig] + frac * (cum[jg] - cum[ig]), cum, ts)
        done.append((ts[ig], ts[jg], first.take(good), second.take(good), err[good], mid, speed[ig], speed[jg],
                     np.interp(mid, ts, speed)))
        if 2 * sum(d[0].size for d in done) > max_arcs:
            raise ConvergenceError(f"spherical biarcs: more than {max_arcs} arcs needed for tol = {tol}")
        bad = ~good
        half = (i[bad] + j[bad]) // 2
        i, j = np.concatenate((i[bad], half)), np.concatenate((half, j[bad]))
    return _assemble(done, tol)


def fit_spherical_biarcs(z, tol: float = 1e-4, *, t=None, dz: Callable | None = None,
                         interval: tuple[float, float] = (0.0, 1.0), max_arcs: int = 1 << 16
                         ) -> SphericalBiarcSpline:
    """Approximate a curve z(t) on the unit sphere by a spherical biarc spline within ``tol``.

    Parameters
    ----------
    z : callable or array (n, 3)
        Either a function mapping t (m,) to unit vectors (m, 3), or unit vectors sampled densely along
        the curve (n >= 2).
    tol : float
        Tolerance (rad): largest great-circle distance from the checked samples of z to the chain.
        For a callable, 15 samples per interval are checked; for sampled data, every sample.
    t : array (n,), optional
        Increasing parameters of the samples (default evenly spaced on [0, 1]); sampled input only.
    dz : callable, optional
        Derivative of a callable z (m,) -> (m, 3); default second-order finite differences.
        For samples, tangents come from circles through three neighbouring samples.
    interval : (float, float)
        Parameter interval of a callable z.
    max_arcs : int
        Upper bound on the number of arcs.

    Returns
    -------
    SphericalBiarcSpline

    Raises
    ------
    FrameDataError
        On non-unit or non-finite samples (naming the index or the parameter value), mismatched
        lengths, non-increasing t, or bad ``tol``/``interval``.
    ConvergenceError
        When the tolerance cannot be met (a corner in z, or more than ``max_arcs`` arcs).
    """
    tol = val.positive_scalar(tol, "tol")
    if callable(z):
        if t is not None:
            raise FrameDataError("is for sampled input; for a callable z pass interval=(t0, t1)", "t")
        lo, hi = (val.finite_scalar(v, "interval") for v in interval)
        if not hi > lo:
            raise FrameDataError(f"must satisfy t0 < t1, got {interval}", "interval")
        return _fit_callable(z, dz, tol, lo, hi, max_arcs)
    if dz is not None:
        raise FrameDataError("is for a callable z; sampled tangents are estimated from the samples", "dz")
    zs = val.unit_vectors(z, "z")
    n = zs.shape[0]
    if n < 2:
        raise FrameDataError(f"needs at least 2 samples, got {n}", "z")
    ts = np.linspace(0.0, 1.0, n) if t is None else np.asarray(t, dtype=float)
    if ts.shape != (n,):
        raise FrameDataError(f"must have shape ({n},) like z, got {ts.shape}", "t")
    bad = ~np.isfinite(ts)
    bad[1:] |= ~(np.diff(ts) > 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise FrameDataError(f"= {ts[i]!r}: parameters must be finite and strictly increasing", "t", i)
    return _fit_samples(zs, ts, tol, max_arcs)
