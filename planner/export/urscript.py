"""URScript programs a UR controller runs as they are: a ``servoj`` stream or ``movep`` moves.

Facts used (shared/UR-PROTOCOLS.md): a program is ``def name(): ... end``; sent whole to the script
port (30002/30003) the controller runs it at once (that is how ur_rtde uploads ``rtde_control``);
``servoj`` takes t, lookahead_time and gain. Where UR-PROTOCOLS.md is silent this follows the UR Script
Manual (e-Series, as the author knows it), and the program says so in its comments:

- ``servoj(q, a, v, t, lookahead_time, gain)``: joint target q (rad), a and v unused; blocks for t
  seconds (>= 0.002 on e-Series, 0.008 on CB-Series); lookahead_time in [0.03, 0.2] s; gain in
  [100, 2000]. One call per sample at t = 1 / rate makes sample i's target current from i / rate on.
- ``stopj(a)`` ends the servo stream, decelerating the joints at a rad/s^2.
- ``movej(q, a, v)`` with a pose target solves the inverse kinematics on the controller.
- ``movep(pose, a, v, r)``: linear moves at constant tool speed v (m/s), circular blends of radius r;
  statements after a blended move run when the blend starts.
- ``set_tcp(pose)``; ``set_standard_digital_out(n, b)`` n 0..7, ``set_configurable_digital_out(n, b)``
  n 0..7, ``set_tool_digital_out(n, b)`` n 0..1; booleans ``True``/``False``; ``#`` comments.

Numbers are written in fixed point with 12 decimals (no exponents), far below the robot's resolution.
"""

from __future__ import annotations

from collections.abc import Mapping

from planner.export.header import ExportError, check_joints, event_dicts, job_parameters
from planner.export.movep import MovePPlan
from planner.export.script_text import check_name, header, initial_io, io_line, num, pose, vec
from planner.motion.limits import MotionInputError, positive
from planner.motion.stream import as_transform, transform_to_pose

#: servoj parameter ranges (UR Script Manual, e-Series).
SERVOJ_MIN_T = 0.002
LOOKAHEAD_RANGE = (0.03, 0.2)
GAIN_RANGE = (100.0, 2000.0)


def servoj_program(
    stream,
    joints=None,
    *,
    model=None,
    lookahead_time: float = 0.1,
    gain: float = 300.0,
    approach_speed: float = 0.25,
    approach_acceleration: float = 0.5,
    stop_acceleration: float = 2.0,
    parameters: Mapping | None = None,
    name: str = "planner_job",
) -> str:
    """A URScript program that streams the joint targets with ``servoj`` at the stream's rate.

    Parameters
    ----------
    stream : PoseStream
    joints : array_like (n, 6), optional
        Joint target of every sample, rad. Without it ``model`` is required and the joints come from
        ``planner.kinematics.inverse_path(model, stream.poses, tcp=stream.tcp_pose)``.
    model : str or URModel, optional
    lookahead_time : float
        servoj lookahead time, s, in [0.03, 0.2].
    gain : float
        servoj proportional gain, in [100, 2000].
    approach_speed, approach_acceleration : float
        movej to the first sample before the stream, rad/s and rad/s^2.
    stop_acceleration : float
        stopj deceleration after the last sample, rad/s^2.
    parameters : mapping, optional
        Extra job parameters for the header.
    name : str
        Program name.

    Returns
    -------
    str
        The program: header comments, set_tcp, initial output states, movej to the start, one
        servoj line per sample (I/O switches just before the servoj of their sample), stopj.
    """
    name = check_name(name)
    t = 1.0 / stream.rate
    if t < SERVOJ_MIN_T - 1e-15:
        raise MotionInputError("rate", f"servoj needs t = 1 / rate >= {SERVOJ_MIN_T} s (500 Hz), got rate "
                                       f"{stream.rate} Hz")
    la = positive(lookahead_time, "lookahead_time")
    if not LOOKAHEAD_RANGE[0] <= la <= LOOKAHEAD_RANGE[1]:
        raise MotionInputError("lookahead_time", f"must be in {list(LOOKAHEAD_RANGE)} s, got {la}")
    g = positive(gain, "gain")
    if not GAIN_RANGE[0] <= g <= GAIN_RANGE[1]:
        raise MotionInputError("gain", f"must be in {list(GAIN_RANGE)}, got {g}")
    va = positive(approach_speed, "approach_speed")
    aa = positive(approach_acceleration, "approach_acceleration")
    sa = positive(stop_acceleration, "stop_acceleration")
    if joints is None:
        if model is None:
            raise ExportError("joints: give the joint solution (n, 6) or a robot model to compute it")
        from planner.kinematics import inverse_path

        joints = inverse_path(model, stream.poses, tcp=stream.tcp_pose)
    q = check_joints(joints, stream.times)
    params = job_parameters(stream, {**(dict(parameters) if parameters else {}),
                                     "servoj": {"t": t, "lookahead_time": la, "gain": g}})
    lines = [f"def {name}():"]
    lines += header("servoj stream", params, event_dicts(stream))
    lines += [
        "  # servoj/stopj/movej semantics: UR Script Manual (e-Series); shared/UR-PROTOCOLS.md covers only the",
        "  # servoJ parameters (t, lookahead_time, gain). Sample i's target is commanded from t = i / rate.",
        f"  set_tcp({pose(stream.tcp_pose)})",
    ]
    lines += initial_io(stream.events)
    lines.append(f"  movej({vec(q[0])}, a={num(aa)}, v={num(va)})")
    tail = f", t={num(t)}, lookahead_time={num(la)}, gain={num(g)})"
    body = ["  servoj(" + vec(row) + tail for row in q]
    for e in reversed(stream.events):  # insert before the servoj of its sample (reverse keeps order)
        body.insert(e.index, io_line(e))
    lines += body
    lines += [f"  stopj({num(sa)})", "end", ""]
    return "\n".join(lines)


def movep_program(
    plan: MovePPlan,
    profile,
    *,
    tcp=None,
    acceleration: float | None = None,
    approach_speed: float = 0.25,
    approach_acceleration: float = 0.5,
    parameters: Mapping | None = None,
    name: str = "planner_job",
) -> str:
    """A URScript program that follows the path with ``movep`` moves and blends (see :func:`plan_movep`).

    Parameters
    ----------
    plan : MovePPlan
    profile : FeedProfile
        The time law the plan was made with (header facts, default acceleration).
    tcp : pose (6,), optional
        TCP in the flange frame, for ``set_tcp``.
    acceleration : float, optional
        Tool acceleration of the moves, m/s^2 (default: the profile's acceleration limit).
    approach_speed, approach_acceleration : float
        movej to the first target, rad/s and rad/s^2.
    """
    name = check_name(name)
    a = profile.limits.acceleration if acceleration is None else positive(acceleration, "acceleration")
    va = positive(approach_speed, "approach_speed")
    aa = positive(approach_acceleration, "approach_acceleration")
    tcp_pose = transform_to_pose(as_transform(tcp, "tcp"))
    evs = [{"time": e.time, "index": e.index, "s": e.event.s, "output": e.event.output, "pin": e.event.pin,
            "value": e.event.value, "lead_time": e.event.lead_time, "name": e.event.name} for e in plan.events]
    params = job_parameters(None, {**(dict(parameters) if parameters else {}),
                                   "movep": {"targets": int(plan.s.size), "tolerance_m": plan.tolerance,
                                             "deviation_m": plan.deviation,
                                             "angle_deviation_rad": plan.angle_deviation}},
                            profile=profile, tcp_pose=tcp_pose, n_events=len(plan.events))
    lines = [f"def {name}():"]
    lines += header("movep", params, evs)
    lines += [
        "  # movep/movej semantics: UR Script Manual (e-Series), not covered by shared/UR-PROTOCOLS.md.",
        "  # An I/O switch follows the move to its target; with a blend it runs when the blend starts,",
        "  # so blends at those targets are limited to speed * event_time_tolerance.",
        f"  set_tcp({pose(tcp_pose)})",
    ]
    lines += initial_io(plan.events)
    lines.append(f"  movej({pose(plan.poses[0])}, a={num(aa)}, v={num(va)})")
    lines += movep_lines(plan, a)
    lines += ["end", ""]
    return "\n".join(lines)


def movep_lines(plan: MovePPlan, acceleration: float) -> list[str]:
    """The body lines that follow a plan from its first target (where the tool is) to its last.

    One ``movep(p[...], a, v, r)`` per target after the first (speed and blend radius of the plan),
    each target's I/O switches after its move; the switches at the first target come first.
    """
    a = positive(acceleration, "acceleration")
    by_target: dict[int, list] = {}
    for e in plan.events:
        by_target.setdefault(e.index, []).append(e)
    lines = [io_line(e) for e in by_target.get(0, [])]
    for i in range(1, plan.s.size):
        lines.append(f"  movep({pose(plan.poses[i])}, a={num(a)}, v={num(plan.speeds[i])}, r={num(plan.radii[i])})")
        lines += [io_line(e) for e in by_target.get(i, [])]
    return lines


def write_script(program: str, target) -> None:
    """Write a program text to a path or text file."""
    if hasattr(target, "write"):
        target.write(program)
        return
    with open(target, "w", encoding="utf-8") as f:
        f.write(program)

