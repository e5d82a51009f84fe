"""CSV and JSON waypoint readers: columns, units, modal values, and broken files naming line and field."""

from __future__ import annotations

import io
import json
import warnings

import numpy as np
import pytest

from planner.io import InputFileError, InputFileWarning, read_csv, read_json

MM = 1e-3


def csv(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_csv(io.StringIO(text), source="t.csv", **kw)


def js(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_json(io.StringIO(text), source="t.json", **kw)


def test_csv_without_header_three_columns_mm():
    tp = csv("0,0,0\n10,0,5.5\n# a comment\n\n10,-2.5,5.5\n")
    np.testing.assert_allclose(tp.points / MM, [[0, 0, 0], [10, 0, 5.5], [10, -2.5, 5.5]], atol=1e-12)
    assert tp.lines.tolist() == [1, 2, 5]
    assert tp.axes is None and np.isnan(tp.feeds).all() and not tp.rapid.any()
    assert tp.units == "mm"


@pytest.mark.parametrize("sep", [",", ";", "\t", " ", "  "])
def test_csv_separators_and_metres(sep):
    rows = [[0.1, 0.2, 0.3, 0, 0, 1, 0.05], [0.2, 0.2, 0.3, 0, 0.6, 0.8, 0.1]]
    text = "\n".join(sep.join(str(v) for v in r) for r in rows) + "\n"
    tp = csv(text, units="m")
    np.testing.assert_allclose(tp.points, [r[:3] for r in rows], atol=0)
    np.testing.assert_allclose(tp.axes, [r[3:6] for r in rows], atol=0)
    np.testing.assert_allclose(tp.feeds, [0.05, 0.1], rtol=1e-15)  # m/s by default for metres


def test_csv_header_aliases_suffixes_modal_axis_and_feed():
    text = (
        "X [mm],Y [mm],Z [mm],nx,ny,nz,Feed (mm/min),rapid\n0,0,0,0,0,1,600,1\n10,0,0,,,,,0\n10,5,1,1,0,0,1200,false\n"
    )
    tp = csv(text)
    np.testing.assert_allclose(tp.axes, [[0, 0, 1], [0, 0, 1], [1, 0, 0]], atol=0)
    assert tp.axis_given.tolist() == [True, False, True]
    assert tp.rapid.tolist() == [True, False, False]
    # A rapid has no feed; the feed given on it holds for the next (empty-cell) row.
    np.testing.assert_allclose(tp.feeds, np.array([np.nan, 600, 1200]) * MM / 60, rtol=1e-15)
    assert tp.lines.tolist() == [2, 3, 4]


def test_csv_feed_units_inch_and_normalize():
    tp = csv("x,y,z,i,j,k,feed\n1,2,3,0,0,2,10\n", units="inch", normalize_axes=True)
    np.testing.assert_allclose(tp.points, np.array([[1, 2, 3]]) * 0.0254, atol=0)
    np.testing.assert_allclose(tp.axes, [[0, 0, 1]], atol=0)
    assert tp.feeds[0] == pytest.approx(10 * 0.0254 / 60, rel=1e-15)
    assert csv("0,0,0,5\n", feed_units="mm/s").feeds[0] == pytest.approx(5e-3, rel=1e-15)


def test_csv_unknown_columns_warn():
    with pytest.warns(InputFileWarning, match=r"t\.csv line 1: columns \['colour'\] not understood"):
        tp = read_csv(io.StringIO("x,y,z,colour\n1,2,3,red\n"), source="t.csv")
    assert len(tp) == 1


@pytest.mark.parametrize(
    "text, line, field, problem",
    [
        ("0,0,0\n1,x1.5,2\n", 2, "column y", "'x1.5' is not a number"),
        ("0,0,0\n1,,2\n", 2, "column y", "value is missing"),
        ("0 0 0\n1 2\n", 2, "row", "has 2 values, expected 3"),
        ("0,0,0,0,0\n", 1, "row", "has 5 values and there is no header"),
        ("x,y,z\n0,0,0\n1,2,3,4\n", 3, "row", "has 4 values, expected 3"),
        ("x,y\n1,2\n", 1, "header", "has no column 'z'"),
        ("x,y,z,i,j\n1,2,3,0,0\n", 1, "header", "needs all three columns i, j, k"),
        ("x,y,z,x\n1,2,3,4\n", 1, "header", "column 'x' appears twice"),
        ("0;0;0;0;0;1\n1;1;1;0;0;0.5\n", 2, "columns i,j,k", "is not a unit vector (length 0.5"),
        ("0,0,0,0,0,1\n1,1,1,0,nan,1\n", 2, "column j", "'nan' is not a finite number"),
        ("0,0,0\n1,inf,2\n", 2, "column y", "'inf' is not a finite number"),
        ("x,y,z,i,j,k\n0,0,0,,,\n", 2, "columns i,j,k", "the first row must give the tool axis"),
        ("0,0,0,-600\n", 1, "column feed", "feed rate must be positive"),
        ("x,y,z,rapid\n0,0,0,maybe\n", 2, "column rapid", "'maybe' is not 0/1 or true/false"),
    ],
)
def test_csv_broken_files_name_line_and_column(text, line, field, problem):
    with pytest.raises(InputFileError) as exc:
        csv(text)
    assert (exc.value.line, exc.value.field) == (line, field)
    assert str(exc.value).startswith(f"t.csv line {line}, {field}: ")
    assert problem in str(exc.value)


def test_csv_empty_file():
    with pytest.raises(InputFileError, match="t.csv: no data rows"):
        csv("# nothing\n")


# ---------------------------------------------------------------------------- JSON
POINTS = [[0.0, 0.0, 0.0], [10.0, 0.0, 5.0], [10.0, -2.5, 5.0]]
AXES = [[0.0, 0.0, 1.0], None, [0.0, 0.6, 0.8]]
FEEDS = [600.0, None, 1200.0]


def _check_standard(tp):
    np.testing.assert_allclose(tp.points / MM, POINTS, atol=1e-12)
    np.testing.assert_allclose(tp.axes, [[0, 0, 1], [0, 0, 1], [0, 0.6, 0.8]], atol=0)
    assert tp.axis_given.tolist() == [True, False, True]
    np.testing.assert_allclose(tp.feeds, np.array([600, 600, 1200]) * MM / 60, rtol=1e-15)


def test_json_list_of_objects():
    items = []
    for p, a, f in zip(POINTS, AXES, FEEDS, strict=True):
        d = dict(zip("xyz", p, strict=True))
        if a:
            d.update(zip("ijk", a, strict=True))
        if f:
            d["feed"] = f
        items.append(d)
    text = "[\n" + ",\n".join(json.dumps(d) for d in items) + "\n]"
    tp = js(text)
    _check_standard(tp)
    assert tp.lines.tolist() == [2, 3, 4]


def test_json_object_of_rows_and_of_columns():
    tp = js(json.dumps({"units": "mm", "points": POINTS, "axes": AXES, "feeds": FEEDS, "rapid": [False, True, False]}))
    assert tp.rapid.tolist() == [False, True, False]
    np.testing.assert_allclose(tp.feeds, np.array([600, np.nan, 1200]) * MM / 60, rtol=1e-15)
    tp = js(json.dumps({"units": "mm", "points": POINTS, "axes": AXES, "feeds": FEEDS}))
    _check_standard(tp)
    cols = {c: [p[k] for p in POINTS] for k, c in enumerate("xyz")}
    cols.update({c: [a[k] if a else None for a in AXES] for k, c in enumerate("ijk")})
    cols["feed"] = FEEDS
    _check_standard(js(json.dumps(cols)))


def test_json_units_from_file_and_conflicts():
    tp = js('{"units": "m", "feed_units": "m/s", "points": [[0.1, 0.2, 0.3]], "feeds": [0.05]}')
    np.testing.assert_allclose(tp.points, [[0.1, 0.2, 0.3]], atol=0)
    assert tp.feeds[0] == 0.05 and tp.units == "m"
    with pytest.raises(InputFileError, match=r"t\.json line 1, units: the file says 'm' but units='mm'"):
        js('{"units": "m", "points": [[0, 0, 0]]}', units="mm")


@pytest.mark.parametrize(
    "text, line, field, problem",
    [
        ('[{"x": 0, "y": 0, "z": 0},\n {"x": 1, "y": "a", "z": 0}]', 2, "[1].y", "'a' is not a number"),
        ('[{"x": 0, "y": 0, "z": 0},\n {"x": 1, "z": 0}]', 2, "[1]", "point has no 'y'"),
        ('{"points": [[0,0,0],\n[1,2]]}', 2, "points[1]", "must be [x, y, z]"),
        ('{"points": [[0,0,0],\n[1,2,3]], "axes": [[0,0,1],\n [0,0,2]]}', 3, "axes[1]", "is not a unit vector"),
        ('[{"x":0,"y":0,"z":NaN}]', 1, "[0].z", "nan is not a finite number"),
        ('[{"x":0,\n"y":0 "z":1}]', 2, "column 7", "invalid JSON"),
        ('{"x":[0,1],"y":[0,1],\n"z":[0]}', 2, "z", "has 1 entries, column x has 2"),
        ('[{"x":0,"y":0,"z":0,"i":0,"j":1}]', 1, "[0]", "'k' is missing"),
        ('[{"x":0,"y":0,"z":0,\n"feed":0}]', 2, "[0].feed", "feed rate must be positive"),
        ('[{"x":0,"y":0,"z":0,"rapid":"yes"}]', 1, "[0].rapid", "is not true or false"),
        ('{"points": []}', 1, "document", "holds no points"),
        ("42", 1, "document", "must be a list of points or an object"),
    ],
)
def test_json_broken_files_name_line_and_path(text, line, field, problem):
    with pytest.raises(InputFileError) as exc:
        js(text)
    assert (exc.value.line, exc.value.field) == (line, field)
    assert problem in str(exc.value)
