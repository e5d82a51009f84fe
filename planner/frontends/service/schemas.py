"""Request and response models of the REST API (pydantic v2, strict: unknown fields, NaN and inf are refused).

:class:`SettingsModel` mirrors :class:`planner.PlanSettings` one to one: the same field names, SI units and
defaults (``PlanSettings().to_dict()``); it checks types and shapes, and :meth:`PlanSettings.checked` then checks
ranges and combinations with the planner's own messages. A test keeps the two in step.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from planner.settings import AXIS_SOURCES, FRAME_METHODS, PATH_MODELS, PlanSettings

#: A finite number (NaN and +-inf refused, naming the field).
Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = tuple[Finite, Finite, Finite]
Pose6 = tuple[Finite, Finite, Finite, Finite, Finite, Finite]

_D = PlanSettings().to_dict()


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class LimitsModel(Strict):
    """:class:`planner.motion.MotionLimits`: speed, acceleration, jerk (m/s, m/s^2, m/s^3 or rad/...), angular speed."""

    speed: Finite
    acceleration: Finite
    jerk: Finite
    angular_speed: Finite | None = None


def _limits(name: str):
    """A limits field whose default is built per request (a shared model default would be deep-copied for every
    request, the largest cost of parsing a small job), shown in the schema as PlanSettings' default."""
    return Field(default_factory=lambda: LimitsModel(**_D[name]), json_schema_extra={"default": _D[name]})


PathModel = Literal[PATH_MODELS]  # type: ignore[valid-type]
AxisSource = Literal[AXIS_SOURCES]  # type: ignore[valid-type]
FrameMethod = Literal[FRAME_METHODS]  # type: ignore[valid-type]


class SettingsModel(Strict):
    """:class:`planner.PlanSettings` as JSON (SI units: m, s, rad; ``*_deg`` in degrees). See its docstring."""

    path: PathModel = _D["path"]
    tolerance: Finite = _D["tolerance"]
    corner_deg: Finite = _D["corner_deg"]
    axis_jump_deg: Finite = _D["axis_jump_deg"]
    arc_tolerance: Finite | None = _D["arc_tolerance"]
    axes: AxisSource = _D["axes"]
    frame: FrameMethod = _D["frame"]
    feed: Finite = _D["feed"]
    feed_override: Finite = _D["feed_override"]
    rapid_speed: Finite = _D["rapid_speed"]
    limits: LimitsModel = _limits("limits")
    turn_limits: LimitsModel = _limits("turn_limits")
    joint_limits: LimitsModel = _limits("joint_limits")
    rate: Finite = _D["rate"]
    robot: str | None = Field(default=_D["robot"], max_length=32)
    part_frame: Pose6 | Literal["auto"] | None = _D["part_frame"]
    tcp: Pose6 | None = _D["tcp"]
    feed_floor: Finite = _D["feed_floor"]
    reach_step: Finite = _D["reach_step"]
    cut_output: tuple[Literal["standard", "configurable", "tool"], int] | None = _D["cut_output"]
    passes: Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=1, max_length=100_000)] | Literal[
        "longest"] | None = _D["passes"]
    max_poses: Finite = _D["max_poses"]
    max_points: Finite = _D["max_points"]

    def to_settings(self) -> PlanSettings:
        """The PlanSettings (not yet checked)."""
        return PlanSettings.from_dict(self.model_dump())


class ReadOptions(Strict):
    """Options of the file readers, as ``planner plan --units/--machine``."""

    units: Literal["mm", "m", "inch"] | None = None
    machine: str | None = Field(default=None, max_length=64, pattern=r"^[A-Za-z0-9 _.-]+$")

    def as_dict(self) -> dict:
        return {k: v for k, v in self.model_dump().items() if v is not None}


class WaypointJob(Strict):
    """A job from waypoints in metres (part frame): one pass, interpolated by default."""

    waypoints: Annotated[list[Vec3], Field(min_length=2)]
    axes: list[Vec3] | None = Field(default=None, description="tool axis per waypoint (CAM convention)")
    feeds: list[Finite | None] | None = Field(default=None, description="feed into each waypoint, m/s (null: "
                                              "the job's feed)")
    settings: SettingsModel = Field(default_factory=SettingsModel, json_schema_extra={"default": {}})


class Progress(BaseModel):
    stage: str
    done: int
    total: int


class ErrorView(BaseModel):
    kind: str
    message: str


class InputView(BaseModel):
    kind: str
    name: str
    format: str
    bytes: int


class JobView(BaseModel):
    """A job as ``GET /v1/jobs/{id}`` shows it."""

    id: str
    state: str
    created_at: float
    started_at: float | None
    finished_at: float | None
    progress: Progress
    attempts: int
    input: InputView
    settings: dict
    read_options: dict
    timings: dict
    summary: dict | None
    describe: list[str] | None
    error: ErrorView | None
    note: str | None
    storage_bytes: int
    links: dict


class JobCreated(BaseModel):
    id: str
    state: str
    location: str


class JobList(BaseModel):
    jobs: list[JobView]
    next_cursor: int | None


class ExecutionRequest(Strict):
    """Run a done job on a configured robot."""

    robot: str = Field(max_length=32, description="a robot name from the service's configuration (GET /v1/robots)")
    mode: Literal["stream", "program"] = Field(
        default="stream", description="stream: servoJ with the planner's joints at the job's rate; program: the "
                                      "job's URScript program on the controller")


class ExecutionCreated(BaseModel):
    id: str
    state: str
    location: str


class ExecutionError(BaseModel):
    kind: str
    reason: str
    t: float | None = Field(description="job time of the failure, s")
    pose: list[float] | None = Field(description="planned TCP pose there, p[x, y, z, rx, ry, rz] (m, rad)")
    line: int | None = Field(description="source line of the toolpath being carried out")


class ExecutionView(BaseModel):
    """An execution as ``GET /v1/executions/{id}`` shows it."""

    id: str
    job_id: str
    robot: str
    mode: str
    state: str
    created_at: float
    started_at: float | None
    finished_at: float | None
    progress: Progress
    report: dict | None
    error: ExecutionError | None
    note: str | None
    links: dict


class ExecutionList(BaseModel):
    executions: list[ExecutionView]


class RobotView(BaseModel):
    name: str
    model: str | None
    simulated: bool
    mode_default: str
    busy: bool


class RobotList(BaseModel):
    robots: list[RobotView]
