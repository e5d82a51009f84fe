"""NX NURBS/ records (KNOT/, CNTRL/ with weights and tool axes): read into exact rational B-splines, sampled
within the linearisation tolerance, and planned within the CAM tolerance of the exact curve (10^4 samples)."""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest
from scipy.spatial import cKDTree

from planner import PlanSettings, plan
from planner.io import InputFileError, InputFileWarning, Nurbs, linearize_arcs, read_apt
from planner.io.toolpath import NURBS_SAMPLING_FRACTION

MM = 1e-3
W = math.sqrt(0.5)
R = 20.0  # mm

#: A 270-degree circular arc of radius 20 mm as a rational quadratic B-spline of 3 spans (weights cos 45 deg at
#: the corners): every point of the exact curve is on the circle, whatever the parameter.
CIRCLE_NURBS = f"""FEDRAT/MMPM,600
GOTO/{R},0,5
NURBS/
KNOT/0.3333333,0.3333333,0.6666667,$
0.6666667,1.0000000
CNTRL/{R},{R},5,{W!r}
CNTRL/0,{R},5,1
CNTRL/{-R},{R},5,{W!r}
CNTRL/{-R},0,5,1
CNTRL/{-R},{-R},5,{W!r}
CNTRL/0,{-R},5,1
PAINT/COLOR,31
GOTO/10,{-R},5
"""

#: A cubic 3-span NURBS with weights and tool axes (CNTRL x,y,z,i,j,k,w), NX's implied-start form.
AXES = [(0, 0, 1), (0, 0.6, 0.8), (0.6, 0, 0.8), (0, -0.6, 0.8), (0, 0, 1), (0, 0, 1)]
CUBIC_NURBS = "FEDRAT/MMPM,300\nGOTO/0,0,0,0,0,1\nNURBS/\nKNOT/0.25,0.7,1.0\n" + "".join(
    f"CNTRL/{x},{y},{z},{a[0]},{a[1]},{a[2]},{w}\n"
    for (x, y, z, w), a in zip([(10, 5, 1, 2.0), (20, -5, 2, 0.5), (30, 8, 0, 1.5), (45, 0, 3, 1.0), (50, 2, 3, 1.0)],
                               AXES[1:], strict=True)
) + "GOTO/60,2,3\n"


def read(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_apt(io.StringIO(text), source="t.apt", **kw)


def distances(q: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """Distance of each point q (n, 3) from the polyline through the dense samples ``curve`` (m, 3)."""
    _, j = cKDTree(curve).query(q)
    best = np.full(len(q), np.inf)
    for lo in (j - 1, j):
        a = curve[np.clip(lo, 0, len(curve) - 2)]
        d = curve[np.clip(lo, 0, len(curve) - 2) + 1] - a
        lam = np.clip(np.einsum("ni,ni->n", q - a, d) / np.einsum("ni,ni->n", d, d), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(q - (a + lam[:, None] * d), axis=1))
    return best


def test_rational_circle_is_read_exactly():
    tp = read(CIRCLE_NURBS)
    (nb,) = tp.nurbs
    assert isinstance(nb, Nurbs) and nb.line == 3 and nb.degree == 2
    assert nb.knots.tolist() == pytest.approx([0, 0, 0, 0.3333333, 0.3333333, 0.6666667, 0.6666667, 1, 1, 1])
    assert nb.weights.tolist() == pytest.approx([1, W, 1, W, 1, W, 1])
    assert (nb.start, nb.index) == (0, 1) and len(tp) == 3 and tp.lines.tolist() == [2, 3, 13]
    u = np.linspace(0.0, 1.0, 10_000)
    pts = nb.evaluate(u) / MM
    radius = np.hypot(pts[:, 0], pts[:, 1])
    assert np.abs(radius - R).max() <= 1e-9 * R and np.abs(pts[:, 2] - 5).max() <= 1e-12
    assert np.allclose(nb.evaluate(np.array([0.0, 1.0])), tp.points[[0, 1]], atol=1e-15)
    angle = np.unwrap(np.arctan2(pts[:, 1], pts[:, 0]))
    assert angle[-1] == pytest.approx(1.5 * math.pi) and (np.diff(angle) > 0).all()  # 270 deg, counter-clockwise
    assert tp.feeds[1] == pytest.approx(600 * MM / 60)


@pytest.mark.parametrize("tol", [1e-5, 1e-6])
def test_linearised_samples_stay_within_the_tolerance(tol):
    tp = linearize_arcs(read(CIRCLE_NURBS), tol)
    (nb,) = tp.nurbs
    pts = tp.points[nb.start : nb.index + 1]
    assert np.abs(np.hypot(pts[:, 0], pts[:, 1]) - R * MM).max() <= 1e-12  # every sample on the circle
    # chord sagitta: the largest distance of the exact curve from the polyline, at 10^4 parameters
    dev = distances(nb.evaluate(np.linspace(0, 1, 10_000)), pts)
    fine = tol * NURBS_SAMPLING_FRACTION  # a NURBS is sampled within a fifth of the linearisation tolerance
    assert dev.max() <= fine
    assert len(pts) <= 2 * math.ceil(1.5 * math.pi / (2 * math.acos(1 - fine / (R * MM)))) + 20  # not oversampled
    assert set(tp.lines[nb.start + 1 : nb.index + 1].tolist()) == {3}


@pytest.mark.parametrize("text", [CIRCLE_NURBS, CUBIC_NURBS], ids=["circle", "cubic-weights-axes"])
def test_planned_path_within_cam_tolerance_of_the_exact_nurbs(text, tmp_path):
    path = tmp_path / "nurbs.cls"
    path.write_text(text)
    settings = PlanSettings(path="cam", tolerance=1e-5)
    job = plan(path, settings)
    (nb,) = job.toolpath.nurbs
    exact = nb.evaluate(np.linspace(*nb.domain, 10_000))
    cut = next(m for m in job.moves if m.kind == "cut")
    k = cut.path.knots
    planned = cut.path.points(np.linspace(k[0], k[-1], 400_001))
    # the part of the planned pass that follows the NURBS: from its start to the NURBS end point
    end = int(np.argmin(np.linalg.norm(planned - exact[-1], axis=1)))
    planned = planned[: end + 1]
    there = distances(exact, planned)  # exact curve -> planned path
    back = distances(planned[::20], exact)  # planned path -> exact curve
    dev = max(there.max(), back.max())
    assert dev <= settings.tolerance, f"planned path {dev * 1e6:.3f} um from the exact NURBS"


def test_cubic_weights_and_tool_axes():
    tp = read(CUBIC_NURBS)
    (nb,) = tp.nurbs
    assert nb.degree == 3 and nb.knots.tolist() == [0, 0, 0, 0, 0.25, 0.7, 1, 1, 1, 1]
    assert nb.weights.tolist() == [1, 2.0, 0.5, 1.5, 1.0, 1.0]
    u = np.linspace(0, 1, 10_001)
    axes = nb.axis_at(u)
    assert np.abs(np.linalg.norm(axes, axis=1) - 1).max() <= 1e-12
    assert np.allclose(axes[[0, -1]], [AXES[0], AXES[-1]], atol=1e-12)
    lin = linearize_arcs(tp, 1e-6)
    (nb2,) = lin.nurbs
    seg = slice(nb2.start, nb2.index + 1)
    assert np.allclose(lin.axes[seg][[0, -1]], [AXES[0], AXES[-1]])
    assert lin.axis_given[nb2.index] and lin.axes[-1] == pytest.approx(AXES[-1])  # the last axis stays modal


def test_nurbs_matches_an_independent_de_boor():
    tp = read(CUBIC_NURBS)
    (nb,) = tp.nurbs
    t, p = nb.knots, nb.degree
    ctrl = np.column_stack((nb.control * nb.weights[:, None], nb.weights))

    def de_boor(x):
        k = min(int(np.searchsorted(t, x, side="right")) - 1, len(t) - p - 2)
        d = [ctrl[j + k - p].copy() for j in range(p + 1)]
        for r in range(1, p + 1):
            for j in range(p, r - 1, -1):
                a = (x - t[j + k - p]) / (t[j + 1 + k - r] - t[j + k - p])
                d[j] = (1 - a) * d[j - 1] + a * d[j]
        return d[p][:3] / d[p][3]

    xs = np.linspace(0, 1, 97)
    assert np.abs(nb.evaluate(xs) - np.array([de_boor(x) for x in xs])).max() <= 1e-15


@pytest.mark.parametrize(
    "text, line, words",
    [
        ("GOTO/0,0,0\nKNOT/0.5,1\n", 2, ["KNOT record", "outside a NURBS"]),
        ("GOTO/0,0,0\nCNTRL/1,2,3\n", 2, ["CNTRL record", "outside a NURBS"]),
        ("NURBS/\nKNOT/1\nCNTRL/1,2,3\n", 1, ["NURBS record", "no start point"]),
        ("GOTO/0,0,0\nNURBS/\nKNOT/0.5,0.5,1\nCNTRL/1,2,3\nCNTRL/1,2,4\nCNTRL/1,3,4\n", 2,
         ["NURBS record", "repeated 2 times"]),
        ("GOTO/0,0,0\nNURBS/\nKNOT/0.5,1\nCNTRL/1,2,3\n", 2, ["NURBS record", "clamped B-spline", "degree 0"]),
        ("GOTO/0,0,0\nNURBS/\nKNOT/0.7,0.5,1\nCNTRL/1,2,3\nCNTRL/2,2,3\nCNTRL/3,2,3\nCNTRL/4,2,3\n", 2,
         ["NURBS record", "must increase"]),
        ("GOTO/0,0,0\nNURBS/\nKNOT/1\nCNTRL/1,2,3,0\nCNTRL/2,2,3,1\n", 4, ["field 4 of CNTRL", "weight"]),
        ("GOTO/0,0,0\nNURBS/\nKNOT/1\nCNTRL/1,2,3\nCNTRL/2,2,3,1\n", 5, ["CNTRL record", "has 4 values"]),
        ("GOTO/0,0,0\nNURBS/\nCNTRL/1,2,3\nKNOT/1\n", 4, ["KNOT record", "after the CNTRL"]),
        ("GOTO/0,0,0\nNURBS/\nGOTO/1,1,1\n", 2, ["NURBS record", "needs both"]),
    ],
)
def test_broken_nurbs_name_line_and_record(text, line, words):
    with pytest.raises(InputFileError) as exc:
        read(text)
    assert exc.value.line == line and str(exc.value).startswith(f"t.apt line {line}, ")
    for w in words:
        assert w in str(exc.value)
