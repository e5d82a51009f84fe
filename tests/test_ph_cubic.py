"""PH cubics and their G1 Hermite interpolation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings

from planner.curves.ph_cubic import PHCubic
from planner.errors import NoSolutionError, PlannerError
from tests.conftest import quaternions


@given(quaternions(), quaternions())
@settings(max_examples=50, deadline=None)
def test_ph_property_and_exact_length(A0, A1):
    c = PHCubic.from_quaternions(A0, A1)
    t = np.linspace(0, 1, 33)
    assert np.allclose(np.linalg.norm(c.derivative(t), axis=1), c.speed(t), rtol=1e-13, atol=1e-14)
    # Simpson's rule is exact for the quadratic speed
    assert c.length == pytest.approx((c.speed(0)[0] + 4 * c.speed(0.5)[0] + c.speed(1)[0]) / 6, rel=1e-13)
    s = np.linspace(0, c.length, 17)
    assert np.abs(c.arc_length(0, c.parameter_at_length(s)) - s).max() < 1e-13 * max(1, c.length)


@given(quaternions(), quaternions())
@settings(max_examples=60, deadline=None)
def test_g1_hermite_recovers_the_curve_that_made_the_data(A0, A1):
    c = PHCubic.from_quaternions(A0, A1)
    # straight lines admit a whole family of PH cubic parametrizations: not a G1 Hermite problem
    assume(np.linalg.norm(c.hodograph_coeffs[1] - c.hodograph_coeffs[1] @ c.tangent(0.0)[0] * c.tangent(0.0)[0])
           > 1e-6 * np.abs(c.hodograph_coeffs).max())
    p1 = c.points(1.0)[0]
    t0, t1 = c.tangent([0.0, 1.0])
    sols = PHCubic.hermite_all(np.zeros(3), p1, t0, t1)
    t = np.linspace(0, 1, 9)
    scale = max(1.0, np.abs(c.control_points).max())
    assert any(np.abs(s.points(t) - c.points(t)).max() < 1e-9 * scale for s in sols)
    for s in sols:  # every solution meets the G1 data
        assert np.abs(s.points([0, 1]) - [np.zeros(3), p1]).max() < 1e-12 * scale
        assert np.abs(s.tangent([0, 1]) - [t0, t1]).max() < 1e-10
    assert len(sols) <= 2


def test_unit_tangent_of_a_ph_cubic_is_a_circular_arc():
    c = PHCubic.from_quaternions((1, 0.2, -0.3, 0.5), (0.4, 1.0, 0.7, -0.2))
    z = c.tangent(np.linspace(0, 1, 50))
    # points of a circle on the sphere lie in one plane: z . n = const
    centred = z - z.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    assert sv[-1] < 1e-12 * sv[0]


def test_planar_g1_data_gives_planar_solutions():
    sols = PHCubic.hermite_all([0, 0, 0], [1, 0, 0], [1, 1, 0], [1, -1, 0])
    assert len(sols) == 2
    for s in sols:
        assert np.abs(s.control_points[:, 2]).max() < 1e-12


def test_no_ph_cubic_raises_clear_error():
    # tangents turned against each other across the chord: a PH cubic cannot do it
    with pytest.raises(NoSolutionError, match="no PH cubic joins"):
        PHCubic.hermite([0, 0, 0], [1, 0, 0], [-1, 0.1, 0], [-1, -0.1, 0.05])


@pytest.mark.parametrize(
    "args, match",
    [
        (([0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]), "p0 and p1 coincide"),
        (([0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0]), "t0 must not be the zero vector"),
        (([0, 0, 0], [1, 0, np.nan], [1, 0, 0], [1, 0, 0]), "p1 must be finite"),
    ],
)
def test_bad_input(args, match):
    with pytest.raises(PlannerError, match=match):
        PHCubic.hermite_all(*args)
