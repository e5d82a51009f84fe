"""A planned job as one compact URScript program: ``movep`` along the passes, ``movel`` between them.

Millions of inline ``servoj`` targets are no program for a job of hours (streaming them is the driver's
work). The program is one statement per ``movep`` target, rapid and turn:

- ``movej`` to the job's first pose, given as joint positions on the inverse-kinematics branch the
  job's reachability check followed: the Cartesian moves after it stay on that branch;
- each change of the arm configuration (a "reconfiguration" move the planner put at a rapid's safe
  point) as ``movej`` to the new joint positions at the same pose, timed (``t``) as planned from the
  joint limits: the Cartesian moves after it stay on the new branch;
- each cutting pass as ``movep`` moves (:func:`~planner.export.movep.plan_movep`): targets on the
  planned PH path whose polyline stays within ``tolerance / 2`` of it, blend radii with a corner cut
  of at most ``tolerance / 2``, so the program follows the planned path within ``tolerance``; the
  speed of every move is the pass's feed there, the acceleration the job's; the last target of a
  pass has r = 0 (passes end where the CAM system stops: rapids, corners, axis jumps);
- each rapid as ``movel`` (a straight line, as the CAM system checked it, at the rapid speed, r = 0).
  movel interpolates the orientation about one fixed axis, which is what the planned rapid does
  (the tool axis turns about z0 x z1); where it turns, ``t`` = the planned duration keeps the
  angular speed to the plan's (the time setting takes precedence over v and a);
- each turn in place as ``movel`` to the same point with ``t`` = the planned duration of the turn
  (movel's v is a tool speed in m/s, which a pure rotation does not have);
- each dwell (G04, a drilling cycle's dwell at the hole bottom) as ``sleep(t)``: the arm stands still at the
  pose the move before ended at (every move before it ends with r = 0);
- comments: what generated the program and the job's parameters, each pass, rapid and turn with
  its source lines, and the file's operation, tool-change, spindle, coolant, INSERT and machine
  records where they occur. With ``cut_output`` set, that output is switched on before and off after
  every pass.

movej/movel/movep semantics: UR Script Manual (e-Series); shared/UR-PROTOCOLS.md does not cover them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from planner.cam.passes import CutPass
from planner.export.header import ExportError, trajectory_parameters
from planner.export.movep import MovePPlan, plan_movep
from planner.export.script_text import as_written, check_name, comment, header, num, output_switch, pose, vec
from planner.export.urscript import movep_lines
from planner.kinematics.poses import as_transform, matrix_to_pose
from planner.motion.limits import positive

#: Kinds of CAM records written as comments where they occur.
NOTED_EVENTS = ("operation", "tool_change", "spindle", "coolant", "insert", "machine")


@dataclass(frozen=True, eq=False)
class ProgramMove:
    """One move of a whole-job program.

    Attributes
    ----------
    move : int
        Index of the move in ``PlannedJob.moves``.
    kind : str
        "cut", "rapid", "reorientation", "reconfiguration" or "dwell".
    pass_index : int
        Pass number of a cut, -1 otherwise.
    first_line, last_line : int
        Source lines of the move.
    motion_line : int
        Source line of the first record the move carries out (CAM records before it come first).
    plan : MovePPlan or None
        The movep targets of a cut.
    start, target : ndarray (6,)
        TCP poses p[x, y, z, rx, ry, rz] (base frame) where the move starts and ends.
    speed : float
        Tool speed of a rapid, m/s (the cut's speeds are in its plan; 0 for a turn).
    duration : float
        Planned time of the move, s.
    turn : float
        Angle the tool turns by (rapids and turns), rad.
    joints : ndarray (6,) or None
        Target joint positions of a reconfiguration (rad).
    acceleration : float or None
        The move's ``a`` where it was lowered for the joints (m/s^2; rad/s^2 for a reconfiguration), None: the
        job's (a cut's are in its plan).
    slowed : str
        Where and how much the move was slowed for the joints' limits, for a person ("" if not; see
        :mod:`planner.export.move_check`).
    slowed_moves : int
        Statements slowed: a cut's movep moves, 1 for a slowed rapid, turn or reconfiguration (0: none).
    stretch : float
        The largest stretch c of a slowed statement (v over c, a over c^2; 1: none slowed).
    """

    move: int
    kind: str
    pass_index: int
    first_line: int
    last_line: int
    motion_line: int
    plan: MovePPlan | None
    start: np.ndarray
    target: np.ndarray
    speed: float
    duration: float
    turn: float
    joints: np.ndarray | None = None
    acceleration: float | None = None
    slowed: str = ""
    slowed_moves: int = 0
    stretch: float = 1.0


def _turn_pose(m, Tb: np.ndarray, angle: float) -> np.ndarray:
    """TCP pose (6,) in the base frame of a turn in place after turning by ``angle``."""
    R = Tb[:3, :3] @ m.frames.frames(np.array([angle]))[0]
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, Tb[:3, :3] @ m.point + Tb[:3, 3]
    return matrix_to_pose(T)


def _hold_pose(m, Tb: np.ndarray) -> np.ndarray:
    """TCP pose (6,) in the base frame of a move in place at its start frame (a dwell)."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Tb[:3, :3] @ m.start_frame, Tb[:3, :3] @ m.point + Tb[:3, 3]
    return matrix_to_pose(T)


def plan_job_program(job, *, tolerance: float | None = None, angle_tolerance: float = math.radians(1.0),
                     progress=None) -> tuple[ProgramMove, ...]:
    """The moves of a whole-job program (see the module doc), skipped records left out.

    Parameters
    ----------
    job : PlannedJob
    tolerance : float, optional
        Largest distance of the programmed motion from the planned path, m (default: the job's
        tolerance, so the program stays within twice it of the CAM polyline).
    angle_tolerance : float
        Largest orientation error of the interpolated tool frame between movep targets, rad.
    progress : callable(stage, done, total), optional
        Called every 25 moves.
    """
    from planner.errors import PlannerError
    from planner.motion import poses_at_length, tool_orientation

    tol = positive(job.settings.tolerance if tolerance is None else tolerance, "tolerance")
    Tb = as_transform(job.settings.part_frame, "part_frame")
    out = []
    for k, m in enumerate(job.moves):
        if progress is not None and k % 25 == 0:
            progress("script", k, len(job.moves))
        if m.kind == "dwell":  # the tool waits where it is
            at = _hold_pose(m, Tb)
            out.append(ProgramMove(k, "dwell", -1, m.line, m.line, m.line, None, at, at, 0.0, m.duration, 0.0))
            continue
        if m.profile is None:  # skipped records and zero turns: nothing moves
            continue
        if m.kind == "cut":
            try:
                plan = plan_movep(m.path, tool_orientation(m.frames), m.profile, tolerance=tol,
                                  angle_tolerance=angle_tolerance, base=Tb)
            except ExportError as exc:
                raise PlannerError(f"{job.source} pass {m.pass_index} (lines {m.item.first_line}-"
                                    f"{m.item.last_line}): {exc}") from None
            lines = m.item.lines
            out.append(ProgramMove(k, "cut", m.pass_index, int(lines[0]), int(lines[-1]), int(lines[1]), plan,
                                   plan.poses[0], plan.poses[-1], float(np.max(plan.speeds)), m.duration, 0.0))
        elif m.kind == "reconfiguration":
            from planner.kinematics import forward

            r = m.item
            ends = forward(job.settings.robot, np.vstack((r.q_from, r.q_to)), tcp=job.settings.tcp)
            out.append(ProgramMove(k, m.kind, -1, m.line, m.line, m.line, None, ends[0], ends[1], 0.0, m.duration,
                                   0.0, r.q_to.copy()))
        elif m.kind == "rapid":
            _, _, ends = poses_at_length(m.path, tool_orientation(m.frames), [0.0, m.path.length], base=Tb)
            speed = float(np.max(m.profile.commanded))
            out.append(ProgramMove(k, "rapid", -1, m.line, m.line, m.line, None, ends[0], ends[1], speed, m.duration,
                                   float(m.frames.angle)))
        else:
            angle = float(m.frames.angle)
            out.append(ProgramMove(k, m.kind, -1, m.line, m.line, m.line, None, _turn_pose(m, Tb, 0.0),
                                   _turn_pose(m, Tb, angle), 0.0, m.duration, angle))
    if progress is not None:
        progress("script", len(job.moves), len(job.moves))
    return _checked_moves(job, out)


def _target_lines(job, m: ProgramMove, which) -> str:
    """The source lines of a cut's movep targets ``which`` (indices of its moves, each into target i + 1)."""
    from planner.motion.evaluator import span_bounds

    pm = job.moves[m.move]
    assert m.plan is not None
    b = span_bounds(pm.path)
    lines = pm.item.lines
    span = np.clip(np.searchsorted(b, m.plan.s[np.asarray(which) + 1], side="left"), 1, len(lines) - 1)
    ln = np.unique(np.asarray(lines)[span])
    return f"line {ln[0]}" if ln.size == 1 else f"lines {ln[0]}-{ln[-1]}"


def _checked_moves(job, moves: list[ProgramMove]) -> tuple[ProgramMove, ...]:
    """The moves checked on the controller's samples, in order from the job's start joints, each slowed where a
    joint would go too fast (:mod:`planner.export.move_check`); ExportError naming the move where that cannot help."""
    from dataclasses import replace

    from planner.export.move_check import check_run, stretch_text
    from planner.kinematics import get_model
    from planner.kinematics.ur_moves import Segment

    s = job.settings
    if s.robot is None or not moves:
        return tuple(moves)
    model = get_model(s.robot)
    tcp = as_written(matrix_to_pose(as_transform(s.tcp, "tcp")))
    a = float(as_written(s.limits.acceleration))
    jl = s.joint_limits
    q = as_written(_start_joints(job))
    out = []
    for m in moves:
        where = (f"pass {m.pass_index} (lines {m.first_line}-{m.last_line})" if m.kind == "cut"
                 else f"{m.kind} at line {m.first_line}")
        if m.kind == "dwell":
            out.append(m)
            continue
        if m.kind == "cut":
            p = m.plan
            assert p is not None
            P, V, R = as_written(p.poses[1:]), as_written(p.speeds[1:]), as_written(p.radii[1:])
            segs = [Segment(P[i], V[i], a, R[i]) for i in range(len(V))]
            run = check_run(model, tcp, q, segs, what=f"{job.source} {where}")
            if run.slowed:
                speeds, acc = p.speeds.copy(), np.full(p.s.size, a)
                speeds[1:] = [x.v for x in run.segs]
                acc[1:] = [x.a for x in run.segs]
                acc[0] = 0.0
                m = replace(m, plan=replace(p, speeds=speeds, accelerations=acc), slowed_moves=len(run.slowed),
                            stretch=run.factor, slowed=(
                    f"{where}: {len(run.slowed)} movep move{'s' * (len(run.slowed) > 1)} at "
                    f"{_target_lines(job, m, run.slowed)} slowed ({stretch_text(run.factor)}): "
                    f"{run.before.describe()}, {run.after.describe()} now"))
        else:
            if m.kind == "reconfiguration":
                seg = Segment(as_written(m.joints), float(as_written(jl.speed)), float(as_written(jl.acceleration)))
                dur = float(as_written(m.duration))
            else:
                v = m.speed if m.kind == "rapid" else s.limits.speed
                seg = Segment(as_written(m.target), float(as_written(v)), a)
                dur = float(as_written(m.duration)) if m.kind != "rapid" or m.turn > 0.0 else 0.0
            run = check_run(model, tcp, q, [seg], dur, joint=m.kind == "reconfiguration",
                            what=f"{job.source} {where}")
            if run.slowed:
                new = run.segs[0]
                m = replace(m, speed=new.v, acceleration=new.a, duration=run.duration if dur > 0.0 else m.duration,
                            slowed_moves=1, stretch=run.factor,
                            slowed=f"{where}: slowed ({stretch_text(run.factor)}): {run.before.describe()}, "
                                   f"{run.after.describe()} now")
        q = run.q_end
        out.append(m)
    return tuple(out)


def _start_joints(job) -> np.ndarray:
    """Joint positions (6,) at the job's first pose, on the branch the reachability check follows."""
    for chunk in job.trajectory().chunks(joints=True):
        q = chunk.joints
        if not np.isfinite(q[0]).all():  # pragma: no cover - job.problems names it first
            raise ExportError(f"{job.source}: the job's first pose has no inverse kinematics solution")
        return q[0]
    raise ExportError(f"{job.source}: the job has no motion")


def _noted_events(job) -> list:
    tp = job.toolpath
    return sorted(tp.events_of(*NOTED_EVENTS), key=lambda e: e.line) if hasattr(tp, "events_of") else []


#: Largest program, in bytes, that the program writers send to a controller's script ports or write to a file by
#: default. UR documents no size limit for a program sent to ports 30001-30003 (the URScript manual, "Connecting to
#: URControl", only asks that the client reads before closing), nor for interpreter mode (PolyScope 5.10+, port
#: 30020: "there exists an upper limit" on the interpreted statements, no figure; UR's own example clears the
#: interpreter after every 500 statements). Users report CB-Series controllers that do not react to programs of
#: 1,000 moves (a UR10 through ur_modern_driver, about 100 kB) or of more than about 2,500 moves (a UR5 streamed by
#: the Robots plug-in), and a UR5 that crashed on 200,000 lines (18 MB); RoboDK's UR post-processor split programs
#: into pages of 5,000 lines (about 350 kB of its short lines). ur_rtde 1.6.5's control script, which every e-Series
#: controller takes, is 42 kB. The choice for the e-Series controller simulated here: 250,000 bytes (about 1,450 of
#: this writer's movep lines), under RoboDK's page and enough for the longest pass of the shared NX job (207 kB,
#: 1,220 movep targets), which no seam can cut without stopping the tool in the cut. For a CB-Series controller,
#: 100,000 (``--max-program-bytes``). The simulated controller (sim.programs) refuses larger programs.
MAX_PROGRAM_BYTES = 250_000


@dataclass(frozen=True)
class ProgramPiece:
    """One program of a job sent in pieces (:func:`job_program_pieces`).

    Attributes
    ----------
    text : str
        The program (``def name_k(): ... end``), at most the limit in bytes (UTF-8).
    first_move, last_move : int
        Indices of its first and last move in the job's program moves (:func:`plan_job_program`), inclusive.
    start, end : ndarray (6,)
        TCP poses (base frame) where the piece starts (the previous piece's end, the arm at rest there) and ends.
    passes : tuple of int
        The pass numbers of its cuts, in order.
    line : int
        Source line of its first move.
    """

    text: str
    first_move: int
    last_move: int
    start: np.ndarray
    end: np.ndarray
    passes: tuple[int, ...]
    line: int

    @property
    def size(self) -> int:
        """Bytes of the program text (UTF-8)."""
        return len(self.text.encode("utf-8"))


def _checked_job(job) -> None:
    s = job.settings
    if s.robot is None:
        raise ExportError("a whole-job URScript program needs the robot (start joints, reachability): plan it "
                          "with a robot model")
    if job.problems:
        more = f" (and {len(job.problems) - 1} more moves with problems)" if len(job.problems) > 1 else ""
        raise ExportError(f"the robot cannot make the job: {job.problems[0]}{more}")


def _program_moves(job, moves: tuple[ProgramMove, ...] | None, tolerance, angle_tolerance,
                   progress) -> tuple[ProgramMove, ...]:
    """The moves of the job's program (``moves`` as given, or planned now), after the job's checks; ExportError for
    a job without motion."""
    _checked_job(job)
    if moves is None:
        moves = plan_job_program(job, tolerance=tolerance, angle_tolerance=angle_tolerance, progress=progress)
    if not moves:
        raise ExportError(f"{job.source}: the job has no motion")
    return moves


def _program_parts(job, moves, *, tolerance, angle_tolerance, approach_speed, approach_acceleration, parameters,
                   progress) -> tuple[list[str], list[list[str]], list[str], np.ndarray]:
    """(head lines after ``def``, the body lines of each move (comments of the CAM records before it first), the
    lines after the last move, the start joints)."""
    va = positive(approach_speed, "approach_speed")
    aa = positive(approach_acceleration, "approach_acceleration")
    s = job.settings
    q0 = _start_joints(job)
    a = s.limits.acceleration
    plans = [m.plan for m in moves if m.plan is not None]
    stats = {
        "tolerance_m": float(plans[0].tolerance) if plans else tolerance,
        "angle_tolerance_deg": math.degrees(angle_tolerance),
        "movep_targets": int(sum(p.s.size - 1 for p in plans)),
        "movep_deviation_m": max((p.deviation for p in plans), default=0.0),
        "movep_angle_deviation_deg": math.degrees(max((p.angle_deviation for p in plans), default=0.0)),
        "movel_moves": sum(1 for m in moves if m.plan is None and m.kind not in ("reconfiguration", "dwell")),
        "movej_reconfigurations": sum(1 for m in moves if m.kind == "reconfiguration"),
        "dwells": sum(1 for m in moves if m.kind == "dwell"),
        "start_joints_rad": [float(x) for x in q0],
    }
    if parameters is not None and "program" in parameters:
        raise ExportError("parameters: key 'program' is reserved (set by the exporter)")
    params = trajectory_parameters(job.trajectory(), {**dict(parameters or {}), "program": stats})
    tcp_pose = matrix_to_pose(as_transform(s.tcp, "tcp"))
    head = header("whole-job movep/movel", params, [])
    head += [
        "  # movej/movel/movep semantics: UR Script Manual (e-Series), not covered by shared/UR-PROTOCOLS.md.",
        "  # Passes: movep within tolerance of the planned path, ending with r = 0 where the CAM system stops.",
        "  # Rapids and turns in place: movel (straight, orientation about one axis); t = planned time where",
        "  # the tool turns. " + ("No outputs are switched (no cut_output set)." if s.cut_output is None else
                                f"The {s.cut_output[0]} digital output {s.cut_output[1]} is on during every pass "
                                "(and through a corner that joins two)."),
        "  # Changes of the arm configuration: movej at a rapid's safe point, t = planned time of the joint move.",
        f"  set_tcp({pose(tcp_pose)})",
    ]
    events = _noted_events(job)
    e_next = 0
    body: list[list[str]] = []
    for i, m in enumerate(moves):
        lines: list[str] = []
        body.append(lines)
        while e_next < len(events) and events[e_next].line < m.motion_line:
            ev = events[e_next]
            lines.append(comment(f"line {ev.line}: {ev.text or ev.kind}"[:200]))
            e_next += 1
        if m.slowed:
            lines.append(comment(f"slowed for the joint limits: {m.slowed}"[:300]))
        if i == 0:
            lines += [f"  # start of the job (line {m.first_line}): joint move onto the planned branch",
                      f"  movej({vec(q0)}, a={num(aa)}, v={num(va)})"]
        if m.kind == "cut":
            item = job.moves[m.move].item
            assert m.plan is not None and isinstance(item, CutPass)  # every pass has its movep plan
            op = f" ({item.operation})" if item.operation else ""
            lines.append(comment(
                f"pass {m.pass_index}{op}, lines {m.first_line}-{m.last_line}: {1e3 * m.plan.s[-1]:.3f} mm at up to "
                f"{1e3 * m.speed:.3f} mm/s in movep moves: {m.plan.s.size - 1}, planned {m.duration:.3f} s"))
            # two passes joined at a corner keep the output on through it (as the trajectory's io bits do)
            if s.cut_output is not None and not (i > 0 and moves[i - 1].kind == "cut"):
                lines.append(output_switch(s.cut_output[0], s.cut_output[1], True))
            lines += movep_lines(m.plan, a)
            if s.cut_output is not None and not (i + 1 < len(moves) and moves[i + 1].kind == "cut"):
                lines.append(output_switch(s.cut_output[0], s.cut_output[1], False))
        elif m.kind == "reconfiguration":
            r = job.moves[m.move].item
            jl = s.joint_limits
            lines.append(comment(f"change of the arm configuration for pass {r.pass_index}, line {m.first_line} "
                                 f"({r.where}): {r.change}; joint move of {m.duration:.3f} s"))
            ja = jl.acceleration if m.acceleration is None else m.acceleration
            jv = m.speed if m.speed > 0.0 else jl.speed
            lines.append(f"  movej({vec(m.joints)}, a={num(ja)}, v={num(jv)}, t={num(m.duration)})")
        elif m.kind == "rapid":
            dist = float(np.linalg.norm(m.target[:3] - m.start[:3]))
            timing = f", t={num(m.duration)}" if m.turn > 0.0 else ""
            lines.append(comment(f"rapid, line {m.first_line}: {1e3 * dist:.3f} mm, tool axis turns "
                                 f"{math.degrees(m.turn):.3f} deg"))
            ma = a if m.acceleration is None else m.acceleration
            lines.append(f"  movel({pose(m.target)}, a={num(ma)}, v={num(m.speed)}{timing}, r={num(0.0)})")
        elif m.kind == "dwell":
            lines.append(comment(f"dwell, line {m.first_line} ({job.moves[m.move].item.name}): the tool waits "
                                 f"{m.duration:.6g} s"))
            lines.append(f"  sleep({num(m.duration)})")
        else:
            lines.append(comment(f"turn in place, line {m.first_line}: {math.degrees(m.turn):.3f} deg in "
                                 f"{m.duration:.3f} s"))
            ma = a if m.acceleration is None else m.acceleration
            tv = m.speed if m.speed > 0.0 else s.limits.speed
            lines.append(f"  movel({pose(m.target)}, a={num(ma)}, v={num(tv)}, t={num(m.duration)}, r={num(0.0)})")
    tail = [comment(f"line {ev.line}: {ev.text or ev.kind}"[:200]) for ev in events[e_next:]]
    return head, body, tail, q0


def job_program(
    job,
    moves: tuple[ProgramMove, ...] | None = None,
    *,
    tolerance: float | None = None,
    angle_tolerance: float = math.radians(1.0),
    approach_speed: float = 0.25,
    approach_acceleration: float = 0.5,
    parameters: Mapping | None = None,
    name: str = "planner_job",
    progress=None,
) -> str:
    """A URScript program that runs a whole CAM job (see the module doc), whatever its size (a controller may not
    take a program above :data:`MAX_PROGRAM_BYTES`: :func:`job_program_pieces` cuts it into programs that it does).

    Parameters
    ----------
    job : PlannedJob
        Planned with a robot, every move reachable (``job.problems`` empty).
    moves : tuple of ProgramMove, optional
        From :func:`plan_job_program` (default: planned here with ``tolerance`` and ``angle_tolerance``).
    tolerance, angle_tolerance : float, optional
        See :func:`plan_job_program`.
    approach_speed, approach_acceleration : float
        movej to the job's first pose, rad/s and rad/s^2.
    parameters : mapping, optional
        Extra header entries (e.g. the input file name).
    name : str
        Program name.

    Raises
    ------
    ExportError
        Without a robot, or when the job reports a move the robot cannot make (the message names
        the pass and source line).
    """
    name = check_name(name)
    moves = _program_moves(job, moves, tolerance, angle_tolerance, progress)
    head, body, tail, _ = _program_parts(job, moves, tolerance=tolerance, angle_tolerance=angle_tolerance,
                                         approach_speed=approach_speed, approach_acceleration=approach_acceleration,
                                         parameters=parameters, progress=progress)
    lines = [f"def {name}():", *head]
    for part in body:
        lines += part
    lines += [*tail, "end", ""]
    return "\n".join(lines)


def _size(lines: list[str]) -> int:
    """UTF-8 bytes of ``lines`` joined, each with its line break."""
    return sum(len(x.encode("utf-8")) + 1 for x in lines)


def job_program_pieces(
    job,
    moves: tuple[ProgramMove, ...] | None = None,
    *,
    max_bytes: int = MAX_PROGRAM_BYTES,
    tolerance: float | None = None,
    angle_tolerance: float = math.radians(1.0),
    approach_speed: float = 0.25,
    approach_acceleration: float = 0.5,
    parameters: Mapping | None = None,
    name: str = "planner_job",
    progress=None,
) -> tuple[ProgramPiece, ...]:
    """The job's program (:func:`job_program`, the same statements in the same order) cut into programs of at most
    ``max_bytes`` bytes each, to be run one after the other, each started once the one before has ended.

    Every move of the job ends with the arm at rest (passes, rapids and turns end with r = 0: passes end where the
    CAM system stops, at rapids, corners and axis jumps), so a seam between two programs is a wait at rest, never a
    stop in a cut; a seam is placed between moves only, preferably where the cut output is off: between two passes
    joined at a corner only when that run of passes needs more than one program (the output stays on through the
    seam; the next piece sets it on again first, in case the controller switched it off at the program's end). The
    first piece holds the whole header and the joint move onto the start; each later one a header naming the piece,
    its moves and passes, and ``set_tcp``, and continues from where the one before ended. Consecutive moves are
    packed greedily, so a job whose whole program fits is one piece, identical to :func:`job_program`'s text.

    Raises
    ------
    ExportError
        As :func:`job_program`; and when one pass alone needs a program larger than ``max_bytes`` (a seam in a cut
        would stop the tool there), naming the pass, its lines, the size and the limit.
    """
    name = check_name(name)
    max_bytes = int(max_bytes)
    if max_bytes < 4096:
        raise ExportError(f"max_bytes must be at least 4096 bytes, got {max_bytes}")
    moves = _program_moves(job, moves, tolerance, angle_tolerance, progress)
    head, body, tail, _ = _program_parts(job, moves, tolerance=tolerance, angle_tolerance=angle_tolerance,
                                         approach_speed=approach_speed, approach_acceleration=approach_acceleration,
                                         parameters=parameters, progress=progress)
    s_out = job.settings.cut_output
    whole = _size([f"def {name}():", *head, *tail, "end"]) + sum(_size(b) for b in body)
    if whole <= max_bytes:
        text = "\n".join([f"def {name}():", *head, *(x for b in body for x in b), *tail, "end", ""])
        passes = tuple(m.pass_index for m in moves if m.kind == "cut")
        return (ProgramPiece(text, 0, len(moves) - 1, moves[0].start, moves[-1].target, passes, moves[0].first_line),)
    # units: runs of moves a seam cuts only when they need more than one program (passes joined at corners)
    units: list[tuple[int, int]] = []
    for i, m in enumerate(moves):
        if units and m.kind == "cut" and moves[i - 1].kind == "cut":
            units[-1] = (units[-1][0], i)
        else:
            units.append((i, i))
    restate = "" if s_out is None else output_switch(s_out[0], s_out[1], True)
    later_head = 400 + len(name) + len(restate)  # the header of a later piece (comments, set_tcp, the output), generous
    groups: list[list[int]] = [[]]
    used = _size([f"def {name}():", *head, "end"])
    tail_size = _size(tail)
    last = len(moves) - 1

    def room(b: int) -> int:
        return max_bytes - (tail_size if b == last else 0)

    def refuse(a: int, b: int, need: int):
        first, final = moves[a], moves[b]
        what = (f"pass {first.pass_index}" if a == b else f"passes {first.pass_index}-{final.pass_index} "
                "(joined at corners)") if first.kind == "cut" else f"the {first.kind}"
        return ExportError(f"{job.source}: {what} (lines {first.first_line}-{final.last_line}) alone needs a program "
                           f"of {need} bytes, over the limit of {max_bytes} bytes per program; plan it with a larger "
                           "tolerance (fewer movep targets), or stream it")

    for a, b in units:
        need = sum(_size(body[k]) for k in range(a, b + 1))
        if used + need > room(b) and groups[-1]:
            groups.append([])
            used = later_head + _size(["end"])
        if used + need <= room(b):
            groups[-1] += list(range(a, b + 1))
            used += need
            continue
        # a run of passes joined at corners that needs more than one program: cut at its corners, where the arm is
        # at rest (each pass ends with r = 0); the cut output stays on through the seam
        for k in range(a, b + 1):
            need = _size(body[k])
            if used + need > room(k) and groups[-1]:
                groups.append([])
                used = later_head + _size(["end"])
            if used + need > room(k):
                raise refuse(k, k, used + need)
            groups[-1].append(k)
            used += need
    tcp_line = head[-1]  # set_tcp(...)
    pieces = []
    for k, g in enumerate(groups):
        a, b = g[0], g[-1]
        passes = tuple(moves[i].pass_index for i in range(a, b + 1) if moves[i].kind == "cut")
        piece_name = f"{name}_{k + 1}" if len(name) < 56 else f"{name[:55]}_{k + 1}"
        if k == 0:
            lines = [f"def {piece_name}():", *head]
        else:
            span = f"passes {passes[0]}-{passes[-1]}" if passes else "no pass"
            lines = [f"def {piece_name}():",
                     comment(f"piece {k + 1} of {len(groups)} of the whole-job program of {job.source}: program moves "
                             f"{a}-{b} ({span}), lines {moves[a].first_line}-{moves[b].last_line}"),
                     comment(f"continues where piece {k} ended, the arm at rest there (each piece at most "
                             f"{max_bytes} bytes)"),
                     tcp_line]
            if restate and moves[a].kind == "cut" and moves[a - 1].kind == "cut":  # within passes joined at a corner
                lines += [comment("the cut output stays on from the piece before (passes joined at a corner)"),
                          restate]
        for i in range(a, b + 1):
            lines += body[i]
        if k == len(groups) - 1:
            lines += tail
        lines += ["end", ""]
        text = "\n".join(lines)
        assert len(text.encode("utf-8")) <= max_bytes, (k, len(text))
        pieces.append(ProgramPiece(text, a, b, moves[a].start, moves[b].target, passes, moves[a].first_line))
    return tuple(pieces)
