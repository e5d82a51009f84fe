"""The saved-job file (``.job``): a planned job as named arrays and a JSON manifest, never code.

:meth:`planner.PlannedJob.save` writes it and :func:`planner.load_job` reads it back to a job whose trajectory and
exports (CSV, JSON, URScript, ``describe()``, ``summary()``) are identical, byte for byte, to those of the job
saved, without planning again. Format version 2; version 1 was a pickle, which is refused (reading it could run
code): such a job must be planned again.

Layout
------
A ZIP archive (entries stored or deflated) of:

``manifest.json``
    A UTF-8 JSON object::

        {"format": "planner-job", "version": 2, "writer": "ph-toolpath-planner 0.1.0",
         "arrays": {"f8": {"dtype": "f8", "size": 1337415}, "i8": {...}, "b1": {...}},
         "objects": [["MotionLimits", {"speed": 0.25, ...}], ..., ["PlannedJob", {...}]],
         "root": 8838}

``arrays/f8.npy``, ``arrays/i8.npy``, ``arrays/b1.npy``
    The array pools: one one-dimensional array per element type (NumPy's ``.npy`` format 1.0, little endian:
    float64, int64, bool) holding every array of the job of that type, those of each field side by side.

Each entry of ``objects`` is ``[type, state]``: a type name of the table below (never a Python path: classes
are chosen from the fixed table by this name, and renaming or moving a class changes no file) and an object
holding exactly the fields of that type. Objects are written children first: a reference is the index of an
earlier entry, so the graph has no cycles and is rebuilt in one pass; an object referred to from several
places (the path of a cut, of its fit and of its frames) is stored once. ``root`` is the last entry, the
``PlannedJob``. A field's value, by its kind:

- float: a JSON number; where the kind allows it, ``"nan"``, ``"inf"`` or ``"-inf"``;
- int, bool, str: as JSON; an optional field may be ``null``;
- array: ``[offset, n0, n1, ...]``, the elements ``offset`` to ``offset + n0 * n1 * ...`` of the pool of the
  field's element type, in C order, with that shape (an array held by several fields is stored once);
- ref: the index of an earlier object of one of the types named;
- inline: the state of a part its owner builds (it cannot be built alone), as a nested object;
- list, object: JSON lists and objects of the above.

Types, with their fields in order (what each field means: the class's docstring; SI units). Kinds: ``float``
(``float|nan``: or "nan", "inf", "-inf"), ``int`` (``int>=0``, ``int a..b``: in that range), ``bool``, ``str``
(``"a"|"b"``: one of those), ``f8(n,3)``: an array of that dtype and shape, n any size (``+nan``: elements
need not be finite), ``->T``: a reference to a T, ``{T}``: T's state inline, ``[X]``: a list (``*3``: of 3),
``{str: X}``: an object, ``X?``: X or null, ``{...}``: the settings, the JSON object of
:meth:`PlanSettings.to_dict <planner.settings.PlanSettings.to_dict>`::

    PlannedJob: source str, settings {...}, toolpath ->Toolpath, segmentation ->Segmentation,
        moves [->PlannedMove], passes [->PassReport], timings {str: float|nan}, problems [str], slowed [str],
        start_joints f8(6)?, start_note str, warnings [str], placement ->Placement?
    PlannedMove: kind "cut"|"rapid"|"reorientation"|"reconfiguration"|"dwell"|"skipped",
        item ->CutPass|RapidMove|Reorientation|Reconfiguration|Dwell|Skipped, path ->PHSpline?,
        frames ->AxisField|TurningFrames|PathToolField|SpunFrames?, profile ->FeedProfile?, start_frame f8(3,3),
        end_frame f8(3,3), point f8(3), pass_index int>=-1, fit ->PassFit?
    PassReport: index int>=0, operation str, first_line int>=-1, last_line int>=-1, points int>=0,
        length float|nan, max_deviation float|nan, max_axis_error_deg float|nan,
        max_axis_departure_deg float|nan, knots_added int>=0, start_reason str, end_reason str,
        start_corner_deg float|nan, duration float|nan, spin_deg float|nan, slerp_spin_deg float|nan,
        planning_time float|nan, merged int>=0, reachable bool?, reach_message str, feed_caps [->CapWindow],
        max_twist_deg float|nan, max_waypoint_error float|nan
    PHSpline: A f8(n,2|3,4), starts f8(n,3), knots f8(n), continuity "G1"|"C1"|"C2", iterations int>=0,
        waypoint_index i8(n)?
    CutPass: index int>=0, points f8(n,3), axes f8(n,3)+nan?, axis_given b1(n)?, feeds f8(n)+nan, lines i8(n),
        source_index i8(n), operation str, tool float|nan, start_reason str, end_reason str,
        start_corner_deg float|nan, end_corner_deg float|nan, merged int>=0
    RapidMove: start f8(3), end f8(3), start_axis f8(3)?, end_axis f8(3)?, line int>=-1, source_index int>=-1,
        reason str
    Reorientation: point f8(3), axis_from f8(3), axis_to f8(3), line int>=-1, reason str
    Dwell: point f8(3), seconds float, line int>=-1, name str
    Skipped: point f8(3), first_line int>=-1, last_line int>=-1, reason str
    Segmentation: moves [->CutPass|RapidMove|Reorientation|Dwell|Skipped], corners int>=0, corner_deg float,
        axis_jump_deg float, source str, counts {str: int}
    Reconfiguration: q_from f8(6), q_to f8(6), point f8(3), line int>=-1, pass_index int>=0, passes [int>=0],
        reason str, change str, where str, tcp_excursion float
    PassFit: path ->PHSpline, points f8(n,3), max_deviation float|nan, span_deviation f8(n)+nan,
        knots_added int>=0, straight_chords int>=0, rounds int>=0
    MotionLimits: speed float, acceleration float, jerk float, angular_speed float?
    FeedProfile: t f8(n), s0 f8(n), v0 f8(n), a0 f8(n), j f8(n), length float, limits ->MotionLimits,
        level_bounds f8(n), commanded f8(n), cruise f8(n)
    CapWindow: start float, end float, factor float, speed float, tag int, first_span int?, last_span int?,
        floored bool
    TurningFrames: path ->PHSpline?, start f8(3,3), n f8(3), angle float, span float
    SpinTable (inline): pieces f8(n), bases f8(n,3), base_quaternions f8(n,4), panels f8(n), panel_piece i8(n),
        spin_start f8(n), coeffs f8(n,n)
    AxisField: path ->PHSpline, axes f8(n,3), start f8(3,3), motion {SpinTable}?
    SpinCurve (inline): knots f8(n), coeffs f8(n)
    SpinFigures (inline): samples int>=0, branch int 0..7, rmm f8(5)+nan, reach f8(5)+nan
    SpunFrames: base ->AxisField|TurningFrames, spin {SpinCurve}, figures {SpinFigures}?
    PathRMFAngles: panels i8(n), cum f8(n), offsets i8(n), q f8(n,n), sig f8(n,n)
    GRMFrame (inline): a f8(5), b f8(5), weight str, objective float|nan, constraint_residual float|nan,
        max_twist_deg float|nan, start_angle float, seconds float|nan
    PathFrames: path ->PHSpline, method "rmf"|"grm"|"er", offsets f8(n), stations f8(n), corrections f8(n),
        grm_frames [{GRMFrame}]?, panels ->PathRMFAngles?
    PiecewiseArcMotion: knots f8(n), phi f8(n), psi f8(n), rho f8(n), w0 f8(n), w1 f8(n), left f8(n,4),
        right f8(4), axis_column int 0..2, rational bool, r2_weights "paper"|"reparameterized"
    MotionFrames: path ->PHSpline, method "juttler"|"double-reflection", motion ->PiecewiseArcMotion?,
        start f8(3,3)
    SampledFrames: path ->PHSpline, u f8(n), grid_quaternions f8(n,4)
    PathToolField: path ->PHSpline, method "rmf"|"grm"|"er"|"juttler"|"double-reflection",
        field ->PathFrames|MotionFrames|SampledFrames, reference ->PathFrames
    Event: kind str (one of planner.io.EVENT_KINDS), line int>=-1, index int>=0, name str, value float|nan,
        text str
    Arc: line int>=-1, index int>=0, start int>=0, centre [float]*3, axis [float]*3, radius float|nan
    Nurbs: line int>=-1, index int>=0, start int>=0, degree int>=0, knots f8(n), control f8(n,3), weights f8(n),
        axes f8(n,3)?
    Toolpath: points f8(n,3), axes f8(n,3)+nan?, axis_given b1(n)?, feeds f8(n)+nan, rapid b1(n), lines i8(n),
        events [->Event|Arc|Nurbs], units str, source str, rotary f8(n,2)+nan?
    Placement: part_frame [float]*6, singularity_margin float|nan, joint_margin float|nan,
        factors [float|nan]*3, branch int 0..7, poses int>=0, ratings int>=0, seconds float|nan

What is not data is rebuilt from data: the PCHIP interpolant of a cut's tool axes (``AxisField``) from
the path's CAM-point parameters and the axes, the spin table's axis functions from that interpolant, the
GRM angle functions from the GRM solutions (``GRMFrame``) on the path's segments, the slerp of sampled frames
(``SampledFrames``) from its grid and quaternions, the settings from their JSON object
(:meth:`~planner.settings.PlanSettings.from_dict`). Cached figures (control points, arc-length tables) are
computed again as the planner computes them.

Reading a file sent by anyone is safe: nothing in it is executed (no pickle, no class paths, no object
arrays), and nothing is allocated before its size is checked: the entries' declared sizes against the file's
size and a limit (:mod:`planner.jobfile.container`), each pool's header against its entry, each array
reference against its pool, each field against its kind, each object against its type's checks (sizes that
agree, parameters that increase, indices in range), references only to earlier objects of the types allowed,
and the job against the largest trajectory a job may have. A damaged or hostile file is refused with one line
(a :class:`~planner.errors.PlannerError`) naming the file and what is wrong.

A later version of the planner reads this version: a change of the layout or of a type's fields gets a new
format version, and the reader converts the versions before it.
"""

from __future__ import annotations

from collections.abc import Mapping

from planner.errors import PlannerError
from planner.jobfile.codec import DTYPES, Damaged, Decoder, Encoder, Foreign, StoredType
from planner.jobfile.container import ZIP_MAGIC, pack, unpack

#: The format's name in the manifest.
FORMAT = "planner-job"
#: The format version written and read.
VERSION = 2
#: How files of the former pickle format (version 1) begin: the magic, then the version as 2 bytes.
PICKLE_MAGIC = b"planner-job\n"

__all__ = ["FORMAT", "VERSION", "Damaged", "StoredType", "describe_types", "dump", "load"]


def dump(root, types: Mapping[str, StoredType]) -> bytes:
    """The file's bytes for the object graph of ``root`` (every object's class in ``types``)."""
    enc = Encoder(types)
    enc.ref(root, (enc._by_class[type(root)].name,), "the job")
    pools = enc.pool_arrays()
    manifest = {
        "format": FORMAT,
        "version": VERSION,
        "writer": _writer(),
        "arrays": {name: {"dtype": name, "size": int(a.size)} for name, a in pools.items()},
        "objects": enc.objects,
        "root": len(enc.objects) - 1,
    }
    return pack(manifest, pools)


def load(source, types: Mapping[str, StoredType], root_type: str, name: str):
    """The object graph saved by :func:`dump` (``source`` a path or bytes; ``name`` names it in messages).

    Raises PlannerError, one line: not a saved job, the former pickle format, another format version, or
    damaged (saying where).
    """
    head = _head(source, name)
    if head.startswith(PICKLE_MAGIC):
        version = int.from_bytes(head[len(PICKLE_MAGIC):len(PICKLE_MAGIC) + 2], "big")
        raise PlannerError(f"{name}: a saved job in the former pickle format (version {version}), which this planner "
                           "no longer reads (loading a pickle can run code): plan the job again and save it")
    if not head.startswith(ZIP_MAGIC):
        raise PlannerError(f"{name}: not a saved planner job")
    try:
        manifest, pools = unpack(source, name)
        objects = _checked_manifest(manifest, pools, name)
        dec = Decoder(types, pools)
        for k, raw in enumerate(objects):
            dec.entry(k, raw)
        if not dec.objects or dec.names[-1] != root_type:
            raise Damaged(f"the last object is not a {root_type}")
        return dec.objects[-1]
    except Foreign as exc:
        raise PlannerError(f"{name}: not a saved planner job ({exc})") from None
    except Damaged as exc:
        raise PlannerError(f"{name}: the saved job is damaged: {exc}") from None


def _head(source, name: str) -> bytes:
    if isinstance(source, bytes | bytearray | memoryview):
        return bytes(source[:16])
    import os

    try:
        with open(os.fspath(source), "rb") as f:
            return f.read(16)
    except (OSError, TypeError, ValueError) as exc:
        raise PlannerError(f"{name}: cannot read the saved job ({getattr(exc, 'strerror', None) or exc})") from None


def _checked_manifest(manifest, pools: dict, name: str) -> list:
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise Foreign(f"a ZIP archive whose manifest is not a {FORMAT} manifest")
    version = manifest.get("version")
    if type(version) is not int or version != VERSION:
        shown = version if type(version) is int else repr(version)[:20]
        raise PlannerError(f"{name}: saved job format version {shown}, this planner reads version {VERSION}")
    keys = {"format", "version", "writer", "arrays", "objects", "root"}
    if set(manifest) != keys:
        raise Damaged(f"manifest fields {sorted(map(str, manifest))[:8]}, the format has {sorted(keys)}")
    arrays, objects = manifest["arrays"], manifest["objects"]
    if not isinstance(arrays, dict) or set(arrays) != set(pools):
        raise Damaged("the manifest's arrays and the archive's array entries differ")
    for pool, desc in arrays.items():
        data = pools[pool]
        if (not isinstance(desc, dict) or set(desc) != {"dtype", "size"} or desc["dtype"] != pool or pool not in DTYPES
                or DTYPES[desc["dtype"]] != data.dtype or desc["size"] != data.size):
            raise Damaged(f"array pool {pool[:60]!r}: the manifest and the entry disagree")
    if not isinstance(objects, list) or manifest["root"] != len(objects) - 1:
        raise Damaged("the root is not the last object")
    return objects


def _writer() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"ph-toolpath-planner {version('ph-toolpath-planner')}"
    except PackageNotFoundError:  # pragma: no cover - run from a checkout without installing
        return "ph-toolpath-planner"


def describe_types(types: Mapping[str, StoredType], width: int = 108) -> str:
    """The table of types of the layout above: per type its fields and their kinds, wrapped at ``width``."""
    lines = []
    for t in types.values():
        line = f"{t.name}{' (inline)' * (t.cls is None)}:"
        for k, (name, kind) in enumerate(t.fields.items()):
            item = f" {name} {kind.text()}" + ("," if k < len(t.fields) - 1 else "")
            if len(line) + len(item) > width:
                lines.append(line)
                line = "   "
            line += item
        lines.append(line)
    return "\n".join(lines)
