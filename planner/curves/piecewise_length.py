"""Arc-length bookkeeping of a piecewise PH path: the one implementation the PH splines share.

A PH piece's speed sigma(t) = |dr/dt| is a polynomial in its local parameter t in [0, 1] (Bernstein coefficients
``sigma_coeffs``, degree d), so its arc length s(t) is the polynomial of degree d + 1 whose Bernstein coefficients
are the cumulative sums of sigma's divided by d + 1 (:func:`planner.curves.ph_core.arc_length_coeffs`): piece
lengths, the lengths at the piece ends, the arc length at a parameter and its inverse are exact to round-off.
:class:`planner.curves.spline.PHSpline` (PH quintic and cubic pieces) and
:class:`planner.curves.planar_ph_spline.PlanarPHSpline` (planar PH cubic pieces) take them from here.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from planner import bernstein
from planner.curves.ph_core import arc_length_coeffs, invert_arc_length
from planner.validation import check_arc_lengths


class PiecewiseLength:
    """Arc length of a path of PH pieces; a base class of the spline dataclasses.

    A subclass provides ``sigma_coeffs`` (m, d + 1) (each piece's speed in its local parameter t), ``locate(u)``
    (piece indices (n,) and local parameters t (n,) of global parameters u (n,)) and ``piece_bounds`` (m + 1,)
    (the global parameter at the ends of the pieces).
    """

    @property
    def sigma_coeffs(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def piece_bounds(self) -> np.ndarray:
        raise NotImplementedError

    def locate(self, u) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    @cached_property
    def segment_lengths(self) -> np.ndarray:
        """Exact arc length of every piece (m,), metres."""
        return self.sigma_coeffs.sum(axis=1) / self.sigma_coeffs.shape[1]

    @cached_property
    def cumulative_lengths(self) -> np.ndarray:
        """Arc length at the end of every piece (m + 1,), starting at 0."""
        return np.concatenate(([0.0], np.cumsum(self.segment_lengths)))

    @property
    def length(self) -> float:
        """Total arc length (metres), exact."""
        return float(self.cumulative_lengths[-1])

    def arc_length(self, u) -> np.ndarray:
        """Exact arc length from the start to u, shape (n,)."""
        k, t = self.locate(u)
        S = arc_length_coeffs(self.sigma_coeffs[k])
        return self.cumulative_lengths[k] + np.einsum("nk,nk->n", bernstein.basis(S.shape[1] - 1, t), S)

    def parameter_at_length(self, s) -> np.ndarray:
        """Global parameters u (n,) at arc lengths s (n,) in [0, length]; exact to round-off.

        Safeguarded Newton iteration on each piece's arc-length polynomial (monotone in t),
        :func:`planner.curves.ph_core.invert_arc_length`.
        """
        s = check_arc_lengths(s, self.length)
        cum = self.cumulative_lengths
        k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, self.segment_lengths.size - 1)
        t = invert_arc_length(self.sigma_coeffs[k], s - cum[k])
        b = self.piece_bounds
        return b[k] + t * (b[k + 1] - b[k])
