"""Request and response models of the REST API (pydantic v2; requests strict: unknown fields, NaN and inf are
refused). Every response is typed (no free-form objects); units as :data:`UNITS` says.

:class:`SettingsModel` is generated from the settings' declaration (:data:`planner.settings.SETTINGS`): one field
per :class:`planner.PlanSettings` field, of the same name, SI unit and default, typed by its kind, its unit and range
in the field's description (and ``x-unit``, ``minimum``/``exclusiveMinimum``/``maximum`` in the schema). It checks
types and shapes; :meth:`PlanSettings.checked` then checks ranges and combinations with the planner's own messages,
whose ``field`` is the 422's ``loc``.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from drivers.base import DEFAULT_MODE, Mode
from planner.settings import OUTPUT_KINDS, SETTINGS, PlanSettings, Setting

#: A finite number (NaN and +-inf refused, naming the field; true and false are not numbers).
Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]
#: An integer the store can hold (signed 64 bits): a larger one is refused naming its field.
INT64_MAX = 2**63 - 1
Int64 = Annotated[int, Field(ge=-INT64_MAX - 1, le=INT64_MAX, strict=True)]
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
        return tuple[Literal[tuple(OUTPUT_KINDS)], Int64] | None  # type: ignore[misc]
    if kind == "passes":
        index = Annotated[int, Field(ge=0, le=INT64_MAX, strict=True)]
        return Annotated[list[index], Field(min_length=1, max_length=100_000)] | Literal["longest"] | None
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

    model_config = ConfigDict(json_schema_extra={"examples": [
        {"waypoints": [[0.0, 0.0, 0.0], [0.1, 0.02, 0.0], [0.2, 0.0, 0.01]], "settings": {"feed": 0.05}}]})

    waypoints: Annotated[list[Vec3], Field(min_length=2)]
    axes: list[Vec3] | None = Field(default=None, description="tool axis per waypoint (CAM convention)")
    feeds: list[Finite | None] | None = Field(default=None, description="feed into each waypoint, m/s (null: "
                                              "the job's feed)")
    settings: SettingsModel = Field(default_factory=SettingsModel, json_schema_extra={"default": {}})


# -- responses ---------------------------------------------------------------------------------------------------
# Units in every response: a quantity's name ends with its unit (_s, _m, _mm, _deg, _rad, _hz, _bytes); a name
# without a unit suffix is SI (m, s, rad), as in the settings (:class:`SettingsModel`, PlanSettings' units);
# instants (``created_at``, ...) are Unix time in seconds. Where a person reads small lengths and angles (the job's
# summary, the I/O switch distances) the names say mm and deg.
UNITS = ("Units: a quantity's name ends with its unit (_s, _m, _mm, _deg, _rad, _hz, _bytes); a name without a unit "
         "suffix is SI (m, s, rad) as in the settings; instants (created_at, started_at, finished_at) are Unix time, "
         "s.")


class Closed(BaseModel):
    """A response object whose keys are all declared: a key the service would add without declaring it fails the
    response (and the tests) instead of vanishing from the JSON."""

    model_config = ConfigDict(extra="forbid")


class Progress(BaseModel):
    """Where a job (or an execution) is: its stage and ``done`` of the stage's ``total`` in ``unit``: a planning job
    counts cutting passes (passes planned of the job's passes), an execution's run job time (s of job time done of
    the job's) with the pass and source line being carried out; ``text`` says it in one line."""

    model_config = ConfigDict(populate_by_name=True)

    stage: str = Field(description="planning: fit, plan, place, reach, done; an execution: starting, controller, "
                                   "connecting, then the move being carried out (\"cut pass 3 line 120\"), done")
    done: float
    total: float
    unit: str = Field(description="of done and total: passes (planning), s (job time of an execution's run), or "
                                  "empty before the counting begins")
    pass_: int | None = Field(None, alias="pass", description="an execution: the pass being cut (null between passes)")
    line: int | None = Field(None, description="an execution: the source line of the move being carried out")
    text: str = Field(description="the progress in one line, as the page shows it")


class ErrorView(BaseModel):
    kind: str
    message: str


class InputView(BaseModel):
    kind: str = Field(description="waypoints or file")
    name: str
    format: str
    bytes: int = Field(description="size of the input, bytes")


class Timings(BaseModel):
    """How long the job waited and ran, s."""

    queued_s: float
    running_s: float | None
    planning_s: float | None


class JobLinks(BaseModel):
    """Where the job and (once done) its exports are; ``script`` for a job planned for a robot."""

    model_config = ConfigDict(populate_by_name=True)

    self_: str = Field(alias="self", description="this job")
    csv: str | None = Field(default=None, description="the trajectory as CSV")
    json_: str | None = Field(default=None, alias="json", description="the trajectory as JSON")
    plot: str | None = Field(default=None, description="the picture of the job (PNG)")
    script: str | None = Field(default=None, description="the URScript program")


class PartFrameAuto(Closed):
    """The placement found for ``part_frame: "auto"``: the part frame (m, rad) to reuse, and its margins."""

    part_frame: list[float | None]
    option: str
    singularity_margin: float | None
    joint_margin_deg: float | None


class JobSummary(Closed):
    """The figures ``planner plan`` prints (lengths in mm, angles in deg, times in s, as the names say; a figure
    that does not apply is null). The keys after ``warnings`` come with a robot only."""

    source: str
    path_model: str
    axes: str
    frame: str
    points: int
    passes: int
    rapids: int
    reorientations: int
    skipped: int
    dwells: int
    dwell_s: float | None
    corners: int
    cut_length_mm: float | None
    duration_s: float | None
    tolerance_mm: float | None
    max_deviation_mm: float | None
    max_waypoint_error_mm: float | None
    max_twist_vs_exact_rmf_deg: float | None
    max_axis_error_deg: float | None
    max_axis_departure_deg: float | None
    spin_deg: float | None
    slerp_spin_deg: float | None
    knots_added: int
    planning_s: float | None
    warnings: list[str]
    robot: str | None = None
    part_frame_auto: PartFrameAuto | None = None
    reachable: bool | None = None
    executable: bool | None = Field(None, description="with a robot: whether the job can run on it (nothing moves "
                                    "otherwise; executions of it are refused with not_executable)")
    not_executable: str | None = Field(None, description="why it cannot run, in one line (the moves the robot cannot "
                                       "make, counted in moves, with the first); null when it can")
    unreachable_passes: list[int] | None = None
    slowed_passes: list[int] | None = None
    slowed: list[str] | None = None
    reconfigurations: list[str] | None = None
    reconfigured_passes: list[int] | None = None
    start: str | None = None


class JobView(BaseModel):
    """A job as ``GET /v1/jobs/{id}`` shows it. Units: a quantity's name ends with its unit (_s, _m, _mm, _deg,
    _rad, _hz, _bytes); a name without one is SI (m, s, rad), as in the settings; instants are Unix time, s."""

    id: str
    state: str
    created_at: float
    started_at: float | None
    finished_at: float | None
    progress: Progress
    attempts: int
    input: InputView
    settings: SettingsModel = Field(description="the settings as the planner took them (SI: m, s, rad; *_deg)")
    read_options: ReadOptions
    timings: Timings
    summary: JobSummary | None
    describe: list[str] | None
    error: ErrorView | None
    note: str | None
    storage_bytes: int
    links: JobLinks


class JobCreated(BaseModel):
    id: str
    state: str
    location: str


class JobList(BaseModel):
    jobs: list[JobView]
    next_cursor: int | None


class ExecutionRequest(Strict):
    """Run a done job on a configured robot."""

    model_config = ConfigDict(json_schema_extra={"examples": [{"robot": "sim", "mode": "program"}]})

    robot: str = Field(max_length=32, description="the name of a robot of the key's team (GET /v1/robots)")
    mode: Mode = Field(
        default=DEFAULT_MODE, description=f"program: the job's URScript program, run by the controller; stream: "
                                          f"servoJ with the planner's joints at the job's rate, sent from the "
                                          f"service's machine every control period (default {DEFAULT_MODE})")


class ExecutionCreated(BaseModel):
    id: str
    state: str
    location: str


class ExecutionError(BaseModel):
    kind: str
    reason: str
    t: float | None = Field(description="job time of the failure, s")
    pose: list[float | None] | None = Field(description="planned TCP pose there, p[x, y, z, rx, ry, rz] (m, rad)")
    line: int | None = Field(description="source line of the toolpath being carried out")


class IoEventView(Closed):
    """One switch of a digital output: where (arc length along the job, m) and when (job time, s) it was planned
    and made, and the distance between them (mm)."""

    bit: int
    output: str
    value: bool
    planned_s_m: float | None
    actual_s_m: float | None
    distance_mm: float | None
    planned_t_s: float | None
    actual_t_s: float | None
    resolution_mm: float | None


class ExecutionReport(Closed):
    """The figures of a run (SI units with the unit in each name, distances of the I/O switches in mm; a figure not
    measured is null); ``io_events`` lists the first switches (all are counted)."""

    mode: str
    ok: bool
    reason: str | None
    planned_duration_s: float | None
    duration_s: float | None
    samples: int
    path_length_m: float | None
    max_path_error_m: float | None
    max_path_error_t_s: float | None
    joint_limit_margin_rad: float | None
    recorded_every_s: float | None
    recording_gaps: int
    recording_samples_missed: int
    recording_longest_gap_s: float | None
    io_switches_planned: int
    io_switches_made: int
    max_io_distance_mm: float | None
    io_events: list[IoEventView]
    describe: list[str]
    failure: ExecutionError | None


class ExecutionLinks(BaseModel):
    model_config = ConfigDict(populate_by_name=True)

    self_: str = Field(alias="self", description="this execution")
    job: str = Field(description="the job executed")
    plot: str | None = Field(None, description="the picture of the run over the planned job (PNG), once it has "
                                               "ended after its run began")


class ExecutionView(BaseModel):
    """An execution as ``GET /v1/executions/{id}`` shows it. Units: a quantity's name ends with its unit (_s, _m,
    _mm, _rad); a name without one is SI (m, s, rad); instants are Unix time, s."""

    id: str
    job_id: str
    robot: str
    mode: str
    state: str
    created_at: float
    started_at: float | None
    finished_at: float | None
    progress: Progress
    report: ExecutionReport | None
    error: ExecutionError | None
    note: str | None
    links: ExecutionLinks


class ExecutionList(BaseModel):
    executions: list[ExecutionView]


class RobotView(BaseModel):
    name: str
    model: str | None
    simulated: bool
    mode_default: Mode = Field(description="the execution mode a request without one runs in")
    busy: bool


class RobotList(BaseModel):
    robots: list[RobotView]


def links(param: str, *operations: str) -> dict[str, dict]:
    """OpenAPI links from a 202's ``id`` to the operations (by operationId: the route function's name) taking it as
    the path parameter ``param``: clients and test tools follow them (a job created, then read, cancelled,
    exported, executed)."""
    return {operation: {"operationId": operation, "parameters": {param: "$response.body#/id"},
                        "description": f"the {param} of the resource created"} for operation in operations}


class FieldError(BaseModel):
    """One refused field: where (``loc``: "body", "query", "path" then the field's names and indices), why."""

    loc: list[str | int]
    msg: str
    type: str


class Problem(BaseModel):
    """Every error answer (4xx, 503): ``detail`` is one line saying what is wrong, or (422) a list of the refused
    fields, each naming its place."""

    detail: str | list[FieldError]


class Health(BaseModel):
    """``GET /healthz``: the database answers; planning workers alive and busy; development mode (no keys)."""

    status: Literal["ok"]
    workers: int
    busy: int
    dev_no_auth: bool
