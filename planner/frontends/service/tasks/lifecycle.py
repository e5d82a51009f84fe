"""The life cycle of a task and the messages a task sends.

One life cycle for both kinds of task: queued, running, done, failed, cancelled. An execution says "starting" for
queued (its controller is being readied: a robot moves only when an operator asks, so an execution never waits in a
queue behind others) and has one more state, "stopping" (a stop was asked; the arm is being brought to rest).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Literal

#: States of a planning job.
JOB_STATES = ("queued", "running", "done", "failed", "cancelled")
#: States of an execution.
EXECUTION_STATES = ("starting", "running", "stopping", "done", "failed", "cancelled")
#: States no task leaves.
FINAL_STATES = ("done", "failed", "cancelled")


@dataclass(frozen=True)
class Kind:
    """A kind of task: its table, its states and what a restart does with one left active.

    Attributes
    ----------
    name : "job" or "execution"
    queued : str
        The state a new task is stored in.
    active : tuple of str
        States of a task that has not ended (an execution holds its robot in these).
    states : tuple of str
        Every state, in life-cycle order.
    rerun : bool
        A task whose holder died is queued again (planning: pure, repeatable) or failed "interrupted" (executions:
        a robot moves only when an operator asks).
    """

    name: Literal["job", "execution"]
    queued: str
    active: tuple[str, ...]
    states: tuple[str, ...]
    rerun: bool


JOB = Kind("job", "queued", ("queued", "running"), JOB_STATES, rerun=True)
EXECUTION = Kind("execution", "starting", ("starting", "running", "stopping"), EXECUTION_STATES, rerun=False)
KINDS = {k.name: k for k in (JOB, EXECUTION)}


@dataclass(frozen=True)
class Progress:
    """A task's progress: ``done`` of ``total`` units of ``stage``. ``started`` marks the moment the work proper
    begins (an execution's run after its approach move: the state becomes running)."""

    stage: str
    done: int = 0
    total: int = 0
    started: bool = False


@dataclass(frozen=True, eq=False)
class Live:
    """An execution's recorded samples, thinned (the page's live view): t (n,) job time s, q (n, 6) actual joints
    rad, xyz (n, 3) actual TCP position m, io (n,) actual output bits."""

    t: Any
    q: Any
    xyz: Any
    io: Any


@dataclass(frozen=True)
class Outcome:
    """How a task ended.

    Attributes
    ----------
    state : "done", "failed" or "cancelled"
    error_kind, error : str or None
        The failure's kind ("input": the user's; "internal", "limit", "interrupted", or the driver's kind) and its
        one-line reason.
    values : dict
        Further columns to store with the end (a job's summary and describe as JSON, an execution's report and
        the failure's job time, pose and line).
    plan : bytes or None
        A planned job's saved plan (:meth:`planner.PlannedJob.to_bytes`).
    planning_s : float or None
        Planning time (parse to saved plan), s.
    files : dict of str to bytes
        Further bytes stored with the task's end under its id (an execution's trace of its run, "run.trace").
    later : bool
        The worker process has more to store after the task's end (a large job's 3D view data): the runner asks it
        for them (``("later", task_id)``) once the end is stored, and stores the :class:`Files` that come back.
    """

    state: Literal["done", "failed", "cancelled"]
    error_kind: str | None = None
    error: str | None = None
    values: dict = field(default_factory=dict)
    plan: bytes | None = None
    planning_s: float | None = None
    files: dict[str, bytes] = field(default_factory=dict)
    later: bool = False


@dataclass(frozen=True, eq=False)
class Files:
    """Bytes made from a task after its end (:attr:`Outcome.later`), stored under its id: name -> bytes."""

    task_id: str
    files: dict[str, bytes]


def failed(kind: str, reason: str, **values) -> Outcome:
    """A failed task's outcome."""
    return Outcome("failed", error_kind=kind, error=reason, values=values)


# -- progress as people read it -----------------------------------------------------------------------------------
# A task's progress is stored as (stage, done, total) (the store's columns): a planning job's counts are cutting
# passes (planner.plan's progress); an execution's are job time in milliseconds, with the move being carried out
# in its stage ("cut pass 3 line 120", "rapid line 140": :func:`execution_stage`).

#: The longest stage the store keeps (its column's width).
STAGE_CHARS = 32
_PLACE = re.compile(r"^(?P<kind>[a-z]+)(?: pass (?P<pass>\d+))?(?: line (?P<line>-?\d+))?$")
#: What a planning stage does, for a person.
PLAN_STAGES = {"fit": "fitting the passes", "plan": "planning tool frames and time laws",
               "place": "placing the part for the robot", "reach": "checking the robot's reach",
               "view": "preparing the 3D view"}
#: The execution's stages before its run, for a person.
EXECUTION_STAGES = {"starting": "starting", "controller": "starting the simulated controller",
                    "connecting": "connecting to the robot"}
#: Execution progress is stored in these units of job time per second.
EXECUTION_TICKS = 1000


def execution_stage(kind: str, pass_index: int, line: int) -> str:
    """The stage of an execution's run carrying out a move: its kind, pass (cuts) and source line (fits the
    store's column)."""
    out = kind or "move"
    if pass_index >= 0:
        out += f" pass {pass_index}"
    if line >= 0:
        out += f" line {line}"
    return out[:STAGE_CHARS]


def progress_view(kind: str, state: str, stage: str, done: int, total: int) -> dict[str, Any]:
    """A task's stored progress as the API shows it (:class:`..schemas.Progress`): the stage, done of total in
    ``unit`` ("passes" for planning, "s" of job time for an execution's run), the pass and source line being carried
    out, and one line of ``text`` for a person."""
    view: dict[str, Any] = {"stage": stage, "done": float(done), "total": float(total), "unit": "", "pass": None,
                            "line": None}
    if kind == "job":
        if stage in PLAN_STAGES or stage == "done":
            view["unit"] = "passes"
            what = PLAN_STAGES.get(stage)
            view["text"] = (f"{total} passes planned" if stage == "done" else
                            f"{what}: {done} of {total} passes" if stage in ("fit", "plan") else
                            f"{what} ({total} passes)")
        else:
            view["text"] = {"": "waiting for a worker", "starting": "starting: reading the input"}.get(stage, stage)
        if state in ("failed", "cancelled") and stage != "done":
            view["text"] = f"{state} while {view['text']}"
        return view
    place = _PLACE.match(stage)
    if stage == "execute":  # stored by an earlier version: samples
        view.update(unit="samples", text=f"executing: {done} of {total} samples")
    elif stage == "done" or (place is not None and stage not in EXECUTION_STAGES):
        seconds, of = done / EXECUTION_TICKS, total / EXECUTION_TICKS
        view.update(done=seconds, total=of, unit="s")
        text = f"{seconds:.1f} of {of:.1f} s of job time"
        if stage == "done":
            view["text"] = f"executed: {text}"
        else:
            assert place is not None
            p, line = place["pass"], place["line"]
            view.update({"pass": None if p is None else int(p), "line": None if line is None else int(line)})
            where = f"pass {p}" if p is not None else f"{place['kind']} move"
            view["text"] = f"executing: {text}, {where}" + (f", source line {line}" if line is not None else "")
    else:
        view["text"] = EXECUTION_STAGES.get(stage, stage)
    if state in ("failed", "cancelled") and stage != "done":
        view["text"] = f"{state} while {view['text']}"
    return view
