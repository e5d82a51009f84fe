"""Public names of version 0.1.0 (commit 5839d4a) that the one planning pipeline replaced, importable for the next
release.

Each old module serves its removed names from a module ``__getattr__`` (PEP 562) made by :func:`removed_names`: a
class is the class that replaces it and a constant its value, returned after a ``DeprecationWarning``; a function is
a thin wrapper that warns on every call and returns what its replacement returns. The warning names the replacement.
They go in the release after the next one.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any

#: When the names of this module go.
REMOVED_IN = "the release after the next one"

#: An old name's entry: (its replacement, in the words of the warning; a function returning the object served).
Entry = tuple[str, Callable[[], Any]]


def removed_names(module: str, names: dict[str, Entry]) -> Callable[[str], Any]:
    """The ``__getattr__`` of ``module`` serving the removed ``names`` (anything else: the usual AttributeError)."""

    def __getattr__(name: str) -> Any:
        entry = names.get(name)
        if entry is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        replacement, target = entry
        obj = target()
        message = (f"{module}.{name} is deprecated and will be removed in {REMOVED_IN}: use {replacement}")
        if isinstance(obj, type) or not callable(obj):  # a class or a constant: itself, after the warning
            warnings.warn(message, DeprecationWarning, stacklevel=2)
            return obj

        def call(*args, **kwargs):
            warnings.warn(message, DeprecationWarning, stacklevel=2)
            return obj(*args, **kwargs)

        call.__name__ = call.__qualname__ = name
        call.__module__ = module
        call.__doc__ = f"Deprecated: {message}."
        return call

    return __getattr__


def _new(module: str, name: str) -> Any:
    """``name`` of ``module``, imported by name: the deprecated wrappers sit beside the layers (pyproject.toml's
    import contracts), not in them."""
    return getattr(importlib.import_module(module), name)


# ------------------------------------------------------------------ the wrappers whose call changed
def plan_cam_job(toolpath, *, read_options: dict | None = None, progress=None, **settings):
    """``planner.plan(toolpath, PlanSettings(path="cam", feed=0.01, **settings), ...)``: the old keywords are
    PlanSettings fields (tolerance, corner_deg, axis_jump_deg, arc_tolerance, part_frame, tcp, robot, feed,
    feed_override, rapid_speed, limits, turn_limits, rate, reach_step, joint_limits); the old default feed, 0.01
    m/s where the file gives none, is kept."""
    plan = _new("planner.plan", "plan")
    PlanSettings = _new("planner.settings", "PlanSettings")

    settings.setdefault("feed", 0.01)
    return plan(toolpath, PlanSettings(path="cam", **settings), read_options=read_options, progress=progress)


def write_job_csv(job, chunks=None, target=None, *, rate: float | None = None, parameters=None) -> int:
    """``planner.export.write_csv(job.trajectory(rate), target, parameters=parameters)``; ``chunks`` is not read
    (the trajectory has the poses, and the joints with a robot)."""
    write_csv = _new("planner.export", "write_csv")

    return write_csv(job.trajectory(rate), target, parameters=parameters)


def write_job_json(job, chunks=None, target=None, *, rate: float | None = None, parameters=None) -> int:
    """``planner.export.write_json(job.trajectory(rate), target, parameters=parameters)``; ``chunks`` is not read."""
    write_json = _new("planner.export", "write_json")

    return write_json(job.trajectory(rate), target, parameters=parameters)


def cam_job_parameters(job, rate: float | None = None, parameters=None, max_problems: int = 20) -> dict:
    """``planner.export.trajectory_parameters(job.trajectory(rate), parameters, max_problems)``."""
    trajectory_parameters = _new("planner.export", "trajectory_parameters")

    return trajectory_parameters(job.trajectory(rate), parameters, max_problems)


def iter_stream(job, rate: float):
    """``job.trajectory(rate).chunks(joints=False)``."""
    return job.trajectory(rate).chunks(joints=False)


def collect(job, rate: float, max_samples: int = 20_000_000):
    """``job.trajectory(rate).collect(joints=False, max_samples=max_samples)``."""
    return job.trajectory(rate).collect(joints=False, max_samples=max_samples)


def thin_chunk(chunk, step: int, offset: int = 0):
    """``chunk.every(step, offset)``."""
    return chunk.every(step, offset)


def _attr(module: str, name: str) -> Callable[[], Any]:
    """The object ``module.name``, imported when first asked for (no import cost, no cycle, until then)."""
    return lambda: getattr(importlib.import_module(module), name)


def _here(name: str) -> Callable[[], Any]:
    return lambda: globals()[name]


_PLAN = ("planner.plan(toolpath, planner.PlanSettings(path='cam', feed=0.01, ...)) (the old keywords are PlanSettings "
         "fields; 0.01 m/s was the old default feed)")
_CHUNK = _attr("planner.trajectory", "Chunk")
_STREAM = {
    "JobStream": ("planner.Chunk: job.trajectory(rate).collect() gives the whole stream as one", _CHUNK),
    "StreamChunk": ("planner.Chunk: job.trajectory(rate).chunks() gives them", _CHUNK),
}

_VERSION_SETTING = " (the controller's version is a setting now: python -m sim --polyscope, SimController(polyscope=))"

#: module -> its removed names.
REMOVED: dict[str, dict[str, Entry]] = {
    "planner.cam": {
        "plan_cam_job": (_PLAN, _here("plan_cam_job")),
        "CamJob": ("planner.PlannedJob, what planner.plan returns", _attr("planner.job", "PlannedJob")),
        "CamSettings": ("planner.PlanSettings with path='cam' (its default feed is 0.05 m/s, CamSettings' 0.01)",
                        _attr("planner.settings", "PlanSettings")),
        "PassReport": ("planner.job.PassReport (PlannedJob.passes)", _attr("planner.job", "PassReport")),
        "PlannedMove": ("planner.job.PlannedMove (PlannedJob.moves)", _attr("planner.job", "PlannedMove")),
        **_STREAM,
    },
    "planner.cam.stream": {
        "track_joints": ("planner.trajectory.track_joints, or job.trajectory(rate).chunks(), which has the joints "
                         "with a robot", _attr("planner.trajectory", "track_joints")),
        "iter_stream": ("job.trajectory(rate).chunks()", _here("iter_stream")),
        "collect": ("job.trajectory(rate).collect()", _here("collect")),
        "sample_counts": ("planner.trajectory.sample_counts", _attr("planner.trajectory", "sample_counts")),
        "thin_chunk": ("planner.Chunk.every (chunk.every(step, offset))", _here("thin_chunk")),
        **_STREAM,
    },
    "planner.export": {
        "write_job_csv": ("planner.export.write_csv(job.trajectory(rate), target)", _here("write_job_csv")),
        "write_job_json": ("planner.export.write_json(job.trajectory(rate), target)", _here("write_job_json")),
        "cam_job_parameters": ("planner.export.trajectory_parameters(job.trajectory(rate))",
                               _here("cam_job_parameters")),
    },
    "planner.export.job_tables": {
        "write_job_csv": ("planner.export.write_csv(job.trajectory(rate), target)", _here("write_job_csv")),
        "write_job_json": ("planner.export.write_json(job.trajectory(rate), target)", _here("write_job_json")),
    },
    "planner.plot_cam": {
        "plot_cam_job": ("planner.plot.plot_job (the same arguments)",
                         _attr("planner.plot", "plot_job")),
    },
    "planner.motion": {
        name: (f"planner.rotations.{name}", _attr("planner.rotations", name))
        for name in ("matrix_to_quaternion", "quaternion_to_matrix", "quaternion_to_rotvec", "rotation_angle")
    },
    # the simulator: the controller's version is a setting now, 30001-30003 serve the state streams
    "sim.rtde_server": {
        "CONTROLLER_VERSION": (f"sim.versions.DEFAULT{_VERSION_SETTING}",
                               lambda: (*_attr("sim.versions", "DEFAULT")().release,
                                        _attr("sim.versions", "DEFAULT")().build)),
    },
    "sim.dashboard": {
        "VERSION": (f"sim.versions.DEFAULT.text{_VERSION_SETTING}", lambda: _attr("sim.versions", "DEFAULT")().text),
        "POLYSCOPE_VERSION": (f"sim.versions.DEFAULT.polyscope_text{_VERSION_SETTING}",
                              lambda: _attr("sim.versions", "DEFAULT")().polyscope_text),
    },
    "sim.script_server": {
        "ScriptServer": ("sim.realtime_server.RealtimeServer (port 30003, which takes programs too) and "
                         "sim.primary_server.PrimaryServer (30001, 30002)",
                         _attr("sim.realtime_server", "RealtimeServer")),
        "SCRIPT_PORTS": ("the ports of sim.primary_server and sim.realtime_server", lambda: (30001, 30002, 30003)),
    },
}


def module_getattr(module: str) -> Callable[[str], Any]:
    """The ``__getattr__`` serving the removed names of ``module`` (a key of :data:`REMOVED`)."""
    return removed_names(module, REMOVED[module])


def moved_module(module: str, homes: tuple[str, ...], replacement: str) -> Callable[[str], Any]:
    """A module that moved whole (the layers of the next release): warn once on import, naming ``replacement``, and
    serve every name from the first of ``homes`` (modules, by name) that has it, as its ``__getattr__``."""
    warnings.warn(f"{module} is deprecated and will be removed in the next release: {replacement}", DeprecationWarning,
                  stacklevel=3)

    def __getattr__(name: str) -> Any:
        for home in homes:
            found = importlib.import_module(home)
            if hasattr(found, name):
                return getattr(found, name)
        raise AttributeError(f"{module} (deprecated) has no {name!r}: see {', '.join(homes)}")

    return __getattr__
