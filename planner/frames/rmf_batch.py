"""The exact RMF angle of many PH segments at once (the path-level fast path of :mod:`planner.frames.rmf`).

Same mathematics as :class:`planner.frames.rmf.RMFAngle` (psi' = -2 (A* A')_i / |A|^2 integrated by
Gauss-Legendre quadrature), vectorized over segments and samples: panel counts from the complex roots
of every segment's speed polynomial (batched companion-matrix eigenvalues), per-segment totals, and
angles at sorted samples integrated between neighbouring samples.
"""

from __future__ import annotations

from math import comb

import numpy as np

from planner import quaternion as qt
from planner.curves.ph_core import batch_sigma
from planner.frames.rmf import RMFAngle

_X16, _W16 = np.polynomial.legendre.leggauss(16)
#: Neighbouring samples of one segment are chained (integrated from one to the next) with a Gauss-Legendre
#: rule whose size grows with their distance in panel widths: the rate's poles lie >= ~1.5 panel widths
#: away (batch_panels), so over w panels the rule converges like rho^-2q with rho = 3/w + sqrt(9/w^2 + 1):
#: 6 points up to a quarter panel (24^-12), 8 up to half (12^-16), 12 up to a whole panel (6.2^-24).
_CHAIN_RULES = tuple((w, *np.polynomial.legendre.leggauss(q)) for w, q in ((0.25, 6), (0.5, 8), (1.0, 12)))


def rate_coefficients(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Power-basis coefficients (lowest first) of q = (A* A')_i (N, 2m-2) and sigma = |A|^2 (N, 2m-1).

    psi' = -2 q / sigma. Computed once per segment so that evaluating the rate is two scalar Horner
    schemes per node.
    """
    m = A.shape[1]
    M = np.zeros((m, m))  # Bernstein -> power for the quaternion polynomial
    for k in range(m):
        for j in range(k + 1):
            M[k, j] = comb(m - 1, k) * comb(k, j) * (-1) ** (k - j)
    P = np.einsum("kj,njc->nkc", M, A)  # A(t) = sum_k P_k t^k
    q = np.zeros((A.shape[0], max(2 * m - 2, 1)))
    sig = np.zeros((A.shape[0], 2 * m - 1))
    for j in range(m):
        for k in range(m):
            sig[:, j + k] += np.einsum("nc,nc->n", P[:, j], P[:, k])
            if k >= 1:  # (conj(P_j) k P_k t^(j+k-1))_i
                q[:, j + k - 1] += k * qt.mul(qt.conj(P[:, j]), P[:, k])[:, 1]
    return q, sig


def _horner(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Polynomials with per-row coefficients c (n, d+1) (lowest first) at x (n, q)."""
    r = np.broadcast_to(c[:, -1:], x.shape).copy()
    for j in range(c.shape[1] - 2, -1, -1):
        r *= x
        r += c[:, j : j + 1]
    return r


def batch_rate(A: np.ndarray | None, nodes: np.ndarray, coeffs=None) -> np.ndarray:
    """psi'(t) at nodes (n, q) of segments with coefficients A (n, m, 4) (one segment per row); A may be None
    when ``coeffs`` (from :func:`rate_coefficients`) are given."""
    if coeffs is None:
        if A is None:
            raise TypeError("batch_rate needs the coefficients A or their rate_coefficients")
        coeffs = rate_coefficients(A)
    q, sig = coeffs
    return -2.0 * _horner(q, nodes) / _horner(sig, nodes)


def batch_panels(A: np.ndarray) -> np.ndarray:
    """Gauss-Legendre panels (N,) per segment: about 1.5 / (distance of sigma's roots to [0, 1])."""
    sig = batch_sigma(A)  # (N, d + 1) Bernstein
    d = sig.shape[1] - 1
    M = np.zeros((d + 1, d + 1))  # Bernstein -> power
    for k in range(d + 1):
        for j in range(k + 1):
            M[k, j] = comb(d, k) * comb(k, j) * (-1) ** (k - j)
    c = sig @ M.T  # power coefficients, lowest first
    lead = c[:, -1]
    ok = np.abs(lead) > 1e-12 * np.abs(c).max(axis=1)
    out = np.full(A.shape[0], 2, dtype=int)
    if ok.any():
        comp = np.zeros((int(ok.sum()), d, d))
        comp[:, 1:, :-1] = np.eye(d - 1)
        comp[:, :, -1] = -c[ok, :-1] / lead[ok, None]
        r = np.linalg.eigvals(comp)
        dist = np.where(r.real < 0, np.abs(r), np.where(r.real > 1, np.abs(r - 1), np.abs(r.imag))).min(axis=1)
        out[ok] = np.clip(np.ceil(1.5 / np.maximum(dist, 1e-6)), 2, 4096).astype(int)
    for i in np.flatnonzero(~ok):  # degenerate leading coefficient: the scalar routine handles it
        out[i] = RMFAngle.of(A[i]).edges.size - 1
    return out


def panel_angles(A: np.ndarray, panels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative angle at every panel edge of every segment, flattened.

    Returns ``(cum, offsets)``: segment k's edges j = 0..M_k hold cum[offsets[k] + j], with
    cum[offsets[k]] = 0 and cum[offsets[k] + M_k] = psi(1) - psi(0).
    """
    offsets = np.concatenate(([0], np.cumsum(panels + 1)))
    cum = np.zeros(offsets[-1])
    coeffs = rate_coefficients(A)
    for M in np.unique(panels):  # few distinct panel counts: one vectorized pass each
        idx = np.flatnonzero(panels == M)
        nodes = (np.arange(M)[:, None] + 0.5 * (1.0 + _X16)) / M  # (M, 16)
        rate = batch_rate(None, np.broadcast_to(nodes.ravel(), (idx.size, nodes.size)),
                          (coeffs[0][idx], coeffs[1][idx]))
        per_panel = (rate.reshape(idx.size, M, 16) @ _W16) * (0.5 / M)
        pos = offsets[idx][:, None] + np.arange(1, M + 1)
        cum[pos] = np.cumsum(per_panel, axis=1)
    return cum, offsets


class PathRMFAngles:
    """psi(t) - psi(0) of every segment of a path, evaluable at any (segment, t) samples at once."""

    def __init__(self, A: np.ndarray):
        self.panels = batch_panels(A)
        self.cum, self.offsets = panel_angles(A, self.panels)
        self.q, self.sig = rate_coefficients(A)
        self._qT, self._sT = np.ascontiguousarray(self.q.T), np.ascontiguousarray(self.sig.T)

    def to_state(self) -> dict:
        """The tables, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"panels": self.panels, "cum": self.cum, "offsets": self.offsets, "q": self.q, "sig": self.sig}

    @classmethod
    def from_state(cls, state: dict) -> PathRMFAngles:
        """The tables of :meth:`to_state` read back, without integrating again."""
        out = cls.__new__(cls)
        out.panels, out.cum, out.offsets = state["panels"], state["cum"], state["offsets"]
        out.q, out.sig = state["q"], state["sig"]
        out._qT, out._sT = np.ascontiguousarray(out.q.T), np.ascontiguousarray(out.sig.T)
        return out

    @property
    def totals(self) -> np.ndarray:
        return self.cum[self.offsets[1:] - 1]

    def _rate(self, k: np.ndarray, x: np.ndarray) -> np.ndarray:
        """psi'(x) at nodes x (q, n) (node-major) of the samples' segments k (n,): per-sample coefficients
        gathered once, then Horner on contiguous rows."""
        num = self._qT[-1][k] * x
        for c in self._qT[-2:0:-1]:
            num += c[k]
            num *= x
        num += self._qT[0][k]
        den = self._sT[-1][k] * x
        for c in self._sT[-2:0:-1]:
            den += c[k]
            den *= x
        den += self._sT[0][k]
        return -2.0 * num / den

    def direct(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        """From the segment's panel edge below t: 16-point Gauss-Legendre (any order of samples)."""
        M = self.panels[k]
        j = np.clip((t * M).astype(int), 0, M - 1)
        a = j / M
        half = 0.5 * (t - a)
        return self.cum[self.offsets[k] + j] + (_W16 @ self._rate(k, a + half * (1.0 + _X16[:, None]))) * half

    def __call__(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Angles at samples (k, t). Runs of samples of one segment, sorted along the path, are chained:
        each sample adds the integral from its predecessor (6 to 12 rate evaluations, by distance, instead
        of 16; at the controller rate nearly every sample is chained); the first of a run is evaluated
        directly."""
        n = t.size
        prev_t = np.concatenate(([0.0], t[:-1]))
        width = t - prev_t
        span = np.full(n, np.inf)  # distance to the predecessor in panel widths; inf: start a new run
        same = np.flatnonzero((k[1:] == k[:-1]) & (width[1:] >= 0)) + 1
        span[same] = width[same] * self.panels[k[same]]
        out = np.empty(n)
        anchors = np.flatnonzero(span > _CHAIN_RULES[-1][0])
        out[anchors] = self.direct(k[anchors], t[anchors])
        if anchors.size < n:
            inc = np.zeros(n)
            lower = -1.0
            for w, x, wts in _CHAIN_RULES:
                idx = np.flatnonzero((span > lower) & (span <= w))
                lower = w
                if idx.size:
                    half = 0.5 * width[idx]
                    inc[idx] = (wts @ self._rate(k[idx], prev_t[idx] + half * (1.0 + x[:, None]))) * half
            inc[anchors] = out[anchors]
            total = np.cumsum(inc)
            run = np.repeat(anchors, np.diff(np.append(anchors, n)))  # the anchor of each sample's run
            out = total - total[run] + out[run]
        return out
