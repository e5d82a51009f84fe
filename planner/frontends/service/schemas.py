"""Request and response models of the REST API (pydantic v2, strict: unknown fields, NaN and inf are refused).

:class:`SettingsModel` is generated from the settings' declaration (:data:`planner.settings.SETTINGS`): one field
per :class:`planner.PlanSettings` field, of the same name, SI unit and default, typed by its kind, its unit and range
in the field's description (and ``x-unit``, ``minimum``/``exclusiveMinimum``/``maximum`` in the schema). It checks
types and shapes; :meth:`PlanSettings.checked` then checks ranges and combinations with the planner's own messages,
whose ``field`` is the 422's ``loc``.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from planner.settings import OUTPUT_KINDS, SETTINGS, PlanSettings, Setting

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


def _limits(name: str) -> Any:
    """A limits field whose default is built per request (a shared model default would be deep-copied for every
    request, the largest cost of parsing a small job), shown in the schema as PlanSettings' default."""
    return lambda: LimitsModel(**_D[name])


def _type(s: Setting) -> Any:
    """The JSON type of a setting, by its kind."""
    kind = s.kind
    if kind == "number":
        return Finite | None if s.optional else Finite
    if kind == "choice":
        return Literal[s.choices]
    if kind == "limits":
        return LimitsModel
    if kind == "robot":
        return Annotated[str, Field(max_length=32)] | None
    if kind == "pose":
        return Pose6 | Literal[s.choices] | None if s.choices else Pose6 | None
    if kind == "output":
        return tuple[Literal[tuple(OUTPUT_KINDS)], int] | None  # type: ignore[misc]
    if kind == "passes":
        return Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=1, max_length=100_000)] | Literal[
            "longest"] | None
    raise AssertionError(f"setting {s.name}: no JSON type for kind {kind!r}")


def _schema(s: Setting) -> dict:
    """What the OpenAPI schema says of a setting beside its type: its SI unit, its range (documented; checked by
    PlanSettings.checked with the planner's message) and its command-line option."""
    extra: dict[str, Any] = {"default": _D[s.name]}
    if s.unit:
        extra["x-unit"] = s.unit
    if s.kind == "number":
        extra["exclusiveMinimum" if not s.lo_closed else "minimum"] = s.lo
        extra["maximum"] = s.hi
    if s.flag:
        extra["x-cli"] = f"{s.flag} ({s.typed_unit})" if s.typed_unit else s.flag
    return extra


def _description(s: Setting) -> str:
    unit = f"; unit: {s.unit}" if s.unit else ""
    span = f"; range {s.range_text()}" if s.kind == "number" else ""
    return f"{s.doc}{unit}{span}"


def _field(s: Setting) -> tuple[Any, Any]:
    if s.kind == "limits":
        return (_type(s), Field(default_factory=_limits(s.name), description=_description(s),
                                json_schema_extra=_schema(s)))
    return (_type(s), Field(default=_D[s.name], description=_description(s), json_schema_extra=_schema(s)))


#: The settings' fields, generated from the declaration (the base of :class:`SettingsModel`).
_FIELDS: dict[str, Any] = {s.name: _field(s) for s in SETTINGS}
_SettingsFields: Any = create_model("_SettingsFields", __base__=Strict, **_FIELDS)


class SettingsModel(_SettingsFields):
    """:class:`planner.PlanSettings` as JSON (SI units: m, s, rad; ``*_deg`` in degrees; each field's unit in its
    description). See its docstring."""

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
