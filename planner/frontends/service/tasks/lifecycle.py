"""The life cycle of a task and the messages a task sends.

One life cycle for both kinds of task: queued, running, done, failed, cancelled. An execution says "starting" for
queued (its controller is being readied: a robot moves only when an operator asks, so an execution never waits in a
queue behind others) and has one more state, "stopping" (a stop was asked; the arm is being brought to rest).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

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
    """

    state: Literal["done", "failed", "cancelled"]
    error_kind: str | None = None
    error: str | None = None
    values: dict = field(default_factory=dict)
    plan: bytes | None = None
    planning_s: float | None = None


def failed(kind: str, reason: str, **values) -> Outcome:
    """A failed task's outcome."""
    return Outcome("failed", error_kind=kind, error=reason, values=values)
