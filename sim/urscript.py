"""The URScript subset the planner's exporter writes, compiled whole and run on the motion model.

Supported: one ``def name(): ... end`` program of straight-line statements (the exporter writes no
branches or loops); ``#`` comments; ``[local|global] name = expression``; expressions of numbers,
``True``/``False``, strings, lists ``[...]``, poses ``p[...]``, variables, unary minus and ``+ - * /``;
calls

* ``movej(q | pose, a=1.4, v=1.05, t=0, r=0)``, ``movel(pose | q, a=1.2, v=0.25, t=0, r=0)``,
  ``movep(pose, a=1.2, v=0.25, r=0)``: consecutive moves of one family (joint, or linear/process)
  whose blend radius is > 0 are executed as one blended path; statements between them run when the
  arm reaches the next move (the controller runs them as the blend starts). ``t > 0`` makes a
  single move last t seconds (speed and acceleration scaled down);
* ``servoj(q, a, v, t=0.002, lookahead_time=0.1, gain=300)`` (blocks for t), ``stopj(a)``, ``stopl(a)``;
* ``sleep(t)``, ``sync()``, ``textmsg(...)``, ``set_tcp(pose)``,
  ``set_standard_digital_out(n, b)``, ``set_configurable_digital_out(n, b)``, ``set_tool_digital_out(n, b)``;
  the deprecated ``set_digital_out(n, b)`` (n 0-7 standard, 8-9 tool outputs 0-1) and the CB controllers' statement
  ``digital_out[n] = b`` that python-urx sends for it.

Anything else (another statement, an unknown function or argument, an undefined variable, a value of
the wrong kind or range) is a compile error naming its line, and the program is refused before the
arm moves, as the controller refuses a program that does not compile. A target that turns out
unreachable while running is a protective stop (the motion model's rules).
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass, field

import numpy as np

from planner.kinematics import UnreachableError, forward, inverse_nearest
from planner.kinematics.ur_outputs import UR_OUTPUTS
from sim.motion import DT, MotionError, Segment
from sim.programs import ProgramError

_HEAD_PREFIXES = ("def ", "sec ")
_MOVES = {"movej": "joint", "movel": "linear", "movep": "linear"}
_SIGNATURES = {
    "movej": (("q", "a", "v", "t", "r"), {"a": 1.4, "v": 1.05, "t": 0.0, "r": 0.0}),
    "movel": (("pose", "a", "v", "t", "r"), {"a": 1.2, "v": 0.25, "t": 0.0, "r": 0.0}),
    "movep": (("pose", "a", "v", "r"), {"a": 1.2, "v": 0.25, "r": 0.0}),
    "servoj": (("q", "a", "v", "t", "lookahead_time", "gain"),
               {"a": 0.0, "v": 0.0, "t": 0.002, "lookahead_time": 0.1, "gain": 300.0}),
    "stopj": (("a",), {}),
    "stopl": (("a", "aRot"), {"aRot": 0.0}),
    "sleep": (("t",), {}),
    "sync": ((), {}),
    "set_tcp": (("pose",), {}),
    **{k.script_setter: (("n", "b"), {}) for k in UR_OUTPUTS.values()},
    "set_digital_out": (("n", "b"), {}),
}
#: The deprecated set_digital_out's numbering: outputs 0-7 standard, 8-9 the tool's.
_LEGACY_OUTPUTS = 10
#: The output setters: (first bit in the 18-bit word, pins), from the UR output table.
_OUTPUT_BASE = {k.script_setter: (k.bit_offset, k.pins) for k in UR_OUTPUTS.values()}


class Pose(tuple):
    """A URScript pose ``p[x, y, z, rx, ry, rz]``."""


@dataclass
class Statement:
    """One compiled statement: a call (name, args) or an assignment (target, expression)."""

    line: int
    kind: str  # "call" or "assign"
    name: str
    args: list = field(default_factory=list)
    kwargs: dict = field(default_factory=dict)
    expr: ast.expr | None = None


def _err(line: int, text: str) -> ProgramError:
    return ProgramError(f"line {line}: {text}")


def _check_expr(node: ast.expr, names: set[str], line: int) -> None:
    """Compile-time check that an expression stays inside the subset and uses defined names."""
    if isinstance(node, ast.Constant):
        if not isinstance(node.value, int | float | str | bool):
            raise _err(line, f"unsupported constant {node.value!r}")
    elif isinstance(node, ast.Name):
        if node.id not in names and node.id not in ("True", "False"):
            raise _err(line, f"undefined variable {node.id!r}")
    elif isinstance(node, ast.List):
        for e in node.elts:
            _check_expr(e, names, line)
    elif isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id == "p":
        elts = node.slice.elts if isinstance(node.slice, ast.Tuple) else None
        if elts is None or len(elts) != 6:
            raise _err(line, "a pose p[...] needs 6 values")
        for e in elts:
            _check_expr(e, names, line)
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        _check_expr(node.operand, names, line)
    elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add | ast.Sub | ast.Mult | ast.Div):
        _check_expr(node.left, names, line)
        _check_expr(node.right, names, line)
    else:
        raise _err(line, f"unsupported expression {ast.unparse(node)!r}")


def _eval(node: ast.expr, env: dict, line: int):
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.Name):
        return {"True": True, "False": False}.get(node.id, env.get(node.id))
    if isinstance(node, ast.List):
        return [_eval(e, env, line) for e in node.elts]
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Tuple):  # p[...], checked when compiled
        return Pose(float(_eval(e, env, line)) for e in node.slice.elts)
    if isinstance(node, ast.UnaryOp):
        v = _eval(node.operand, env, line)
        return -v if isinstance(node.op, ast.USub) else v
    if not isinstance(node, ast.BinOp):  # _check_expr admits nothing else
        raise _err(line, f"unsupported expression {ast.unparse(node)!r}")
    left, right = _eval(node.left, env, line), _eval(node.right, env, line)
    try:
        if isinstance(node.op, ast.Add):
            return left + right
        if isinstance(node.op, ast.Sub):
            return left - right
        if isinstance(node.op, ast.Mult):
            return left * right
        return left / right
    except (TypeError, ZeroDivisionError) as exc:
        raise _err(line, f"cannot evaluate {ast.unparse(node)!r}: {exc}") from None


def _statement(text: str, line: int, names: set[str]) -> Statement:
    src = text
    for prefix in ("local ", "global "):
        if src.startswith(prefix):
            src = src[len(prefix):]
    try:
        tree = ast.parse(src, mode="exec")
    except SyntaxError:
        raise _err(line, f"cannot compile {text!r}") from None
    if len(tree.body) != 1:
        raise _err(line, f"cannot compile {text!r}")
    node = tree.body[0]
    target = node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 else None
    if isinstance(node, ast.Assign) and isinstance(target, ast.Name):
        _check_expr(node.value, names, line)
        names.add(target.id)
        return Statement(line, "assign", target.id, expr=node.value)
    if (isinstance(node, ast.Assign) and isinstance(target, ast.Subscript) and isinstance(target.value, ast.Name)
            and target.value.id == "digital_out"):  # digital_out[n] = b: set_digital_out(n, b)
        _check_expr(target.slice, names, line)
        _check_expr(node.value, names, line)
        return Statement(line, "call", "set_digital_out", kwargs={"n": target.slice, "b": node.value})
    call = node.value if isinstance(node, ast.Expr) else None
    if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name)):
        raise _err(line, f"unsupported statement {text!r}")
    name = call.func.id
    if name == "textmsg":
        for a in call.args:
            _check_expr(a, names, line)
        return Statement(line, "call", name, list(call.args))
    if name not in _SIGNATURES:
        raise _err(line, f"the simulator does not support {name}()")
    params, defaults = _SIGNATURES[name]
    if len(call.args) > len(params):
        raise _err(line, f"{name}() takes at most {len(params)} arguments, got {len(call.args)}")
    kwargs = {}
    for kw in call.keywords:
        if kw.arg not in params:
            raise _err(line, f"{name}() has no argument {kw.arg!r}")
        _check_expr(kw.value, names, line)
        kwargs[kw.arg] = kw.value
    for a in call.args:
        _check_expr(a, names, line)
    args = dict(zip(params, call.args, strict=False))
    dup = set(args) & set(kwargs)
    if dup:
        raise _err(line, f"{name}(): argument {sorted(dup)[0]!r} given twice")
    args.update(kwargs)
    missing = [p for p in params if p not in args and p not in defaults]
    if missing:
        raise _err(line, f"{name}() needs argument {missing[0]!r}")
    return Statement(line, "call", name, kwargs=args)


def compile_program(text: str) -> list[Statement]:
    """Compile a whole program; raises :class:`ProgramError` (with its line) on anything unsupported."""
    lines = text.split("\n")
    first = lines[0].strip()
    if not first.startswith(_HEAD_PREFIXES) or not first.endswith(":"):
        raise _err(1, f"expected 'def name():', got {first[:60]!r}")
    body: list[Statement] = []
    names: set[str] = set()
    ended = False
    for i, raw in enumerate(lines[1:], start=2):
        s = raw.split("#", 1)[0].strip() if not raw.strip().startswith("textmsg") else raw.strip()
        if not s:
            continue
        if ended:
            raise _err(i, "statement after the program's end")
        if s == "end" and raw.rstrip() == "end":
            ended = True
            continue
        body.append(_statement(s, i, names))
    if not ended:
        raise _err(len(lines), "missing 'end'")
    return body


def compile_line(text: str) -> list[Statement]:
    """Compile a one-line program (a statement sent alone to a client port, as python-urx sends its commands)."""
    line = text.strip()
    if not line.startswith("textmsg"):
        line = line.split("#", 1)[0].strip()
    return [_statement(line, 1, set())]


class URScriptProgram:
    """A compiled exporter program, stepped by the controller once per control period."""

    def __init__(self, core, name: str, body: list[Statement]) -> None:
        self.core = core
        self.motion = core.motion
        self.name = name
        self.body = body
        self.pc = 0
        self.env: dict = {}
        self.keep_running = True
        self.wait_periods = 0  # sleep / servoj / sync
        self.blocked = False  # a trajectory (move run, stop) in progress
        self.pending: list[list[Statement]] = []  # statements to run as the run reaches move i + 1
        self._progress = 0

    # ---- values ------------------------------------------------------------------------------
    def _value(self, st: Statement, key: str):
        node = st.kwargs.get(key)
        if node is None:
            return _SIGNATURES[st.name][1][key]
        return _eval(node, self.env, st.line)

    def _number(self, st: Statement, key: str, lo: float = -math.inf, hi: float = math.inf) -> float:
        v = self._value(st, key)
        if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi or not math.isfinite(v):
            raise ProgramError(f"line {st.line}: {st.name}() argument {key} = {v!r} out of range [{lo}, {hi}]")
        return float(v)

    def _six(self, st: Statement, key: str) -> tuple[np.ndarray, bool]:
        v = self._value(st, key)
        if not isinstance(v, list | tuple) or len(v) != 6:
            raise ProgramError(f"line {st.line}: {st.name}() needs 6 values for {key}, got {v!r}")
        return np.array([float(x) for x in v]), isinstance(v, Pose)

    # ---- the interpreter ---------------------------------------------------------------------
    def step(self) -> None:
        try:
            self._step()
        except ProgramError as exc:
            self.core.runtime_error(str(exc))
            self.keep_running = False

    def _step(self) -> None:
        if self.wait_periods > 0:
            self.wait_periods -= 1
            return
        if self.blocked:
            if self.pending:
                k = self.motion.progress()
                while self._progress < k and self.pending:
                    self._progress += 1
                    for st in self.pending.pop(0):
                        self._run_simple(st)
            if self.motion.busy:
                return
            for group in self.pending:
                for st in group:
                    self._run_simple(st)
            self.pending = []
            self.blocked = False
        while self.pc < len(self.body):
            st = self.body[self.pc]
            if st.kind == "call" and st.name in _MOVES:
                self._start_run()
                return
            self.pc += 1
            if self._run_simple(st):
                return
        self.keep_running = False

    def _run_simple(self, st: Statement) -> bool:
        """Run a non-move statement; True if it blocks (the rest waits for a later period)."""
        m = self.motion
        if st.kind == "assign":
            if st.expr is None:
                raise ProgramError(f"line {st.line}: assignment to {st.name} without a value")
            self.env[st.name] = _eval(st.expr, self.env, st.line)
            return False
        if st.name == "textmsg":
            self.core.message("".join(str(_eval(a, self.env, st.line)) for a in st.args), source=self.name, level=3)
            return False
        if st.name in _OUTPUT_BASE:
            base, count = _OUTPUT_BASE[st.name]
            n = self._number(st, "n", 0, count - 1)
            if int(n) != n:
                raise ProgramError(f"line {st.line}: {st.name}() output number must be an integer, got {n}")
            b = self._value(st, "b")
            bit = 1 << (base + int(n))
            self.core.io.set_digital_out(bit, bit if b else 0)
            return False
        if st.name == "set_digital_out":
            n = self._number(st, "n", 0, _LEGACY_OUTPUTS - 1)
            if int(n) != n:
                raise ProgramError(f"line {st.line}: set_digital_out() output number must be an integer, got {n}")
            tool = UR_OUTPUTS["tool"]
            bit = 1 << int(n) if n < 8 else 1 << (tool.bit_offset + int(n) - 8)
            self.core.io.set_digital_out(bit, bit if self._value(st, "b") else 0)
            return False
        if st.name == "set_tcp":
            m.tcp, _ = self._six(st, "pose")
            self.core.tcp_changed()
            return False
        if st.name == "sleep":
            self.wait_periods = max(0, round(self._number(st, "t", 0.0) / DT) - 1)
            return True
        if st.name == "sync":
            return True
        if st.name == "servoj":
            q, is_pose = self._six(st, "q")
            if is_pose:
                raise ProgramError(f"line {st.line}: servoj() takes joint positions, not a pose")
            t = self._number(st, "t", DT - 1e-12, 10.0)
            try:
                m.servo(q, t, self._number(st, "lookahead_time", 0.03, 0.2), self._number(st, "gain", 100, 2000))
            except MotionError as exc:
                self.core.protective_stop(str(exc))
                return True
            self.wait_periods = max(0, round(t / DT) - 1)
            return True
        if st.name in ("stopj", "stopl"):
            try:
                m.plan_stop(self._number(st, "a", 1e-9), st.name == "stopl")
            except MotionError as exc:
                raise ProgramError(f"line {st.line}: {exc}") from None
            self.blocked = True
            return True
        raise ProgramError(f"line {st.line}: {st.name}() is not supported")

    def _target(self, st: Statement, family: str) -> np.ndarray:
        key = "q" if st.name == "movej" else "pose"
        v, is_pose = self._six(st, key)
        m = self.motion
        if family == "joint" and is_pose:
            try:
                return inverse_nearest(m.model, v, m.q, tcp=m.tcp if np.any(m.tcp) else None)
            except UnreachableError as exc:
                raise MotionError(f"line {st.line}: movej target: {exc}") from None
        if family == "linear" and not is_pose:
            return forward(m.model, v, m.tcp if np.any(m.tcp) else None)
        return v

    def _start_run(self) -> None:
        """Collect the blended run of moves from pc and start it as one trajectory."""
        first = self.body[self.pc]
        family = _MOVES[first.name]
        segs: list[Segment] = []
        pending: list[list[Statement]] = []
        timed = 0.0
        while self.pc < len(self.body):
            st = self.body[self.pc]
            if st.kind != "call" or st.name not in _MOVES or _MOVES[st.name] != family:
                break
            if segs and (segs[-1].r <= 0.0 or timed > 0):
                break
            a = self._number(st, "a", 1e-9)
            v = self._number(st, "v", 1e-9)
            t = self._number(st, "t", 0.0) if "t" in _SIGNATURES[st.name][0] else 0.0
            r = self._number(st, "r", 0.0)
            if t > 0 and segs:
                break  # a timed move stands alone
            try:
                target = self._target(st, family)
            except MotionError as exc:
                self.core.protective_stop(str(exc))
                self.blocked = True
                return
            segs.append(Segment(target, v, a, r))
            timed = t
            self.pc += 1
            # statements up to the next move ride along with the run
            group: list[Statement] = []
            while (self.pc < len(self.body) and self.body[self.pc].name not in _MOVES
                   and self.body[self.pc].name in _OUTPUT_BASE | {"textmsg": 0}):
                group.append(self.body[self.pc])
                self.pc += 1
            pending.append(group)
            if r <= 0.0 or t > 0:
                break
        try:
            traj = self.motion.plan_joint(segs) if family == "joint" else self.motion.plan_linear(segs)
        except MotionError as exc:
            self.core.protective_stop(str(exc))
            self.blocked = True
            return
        if timed > 0:
            self._retime(traj, timed)
        self.pending = pending
        self._progress = 0
        self.blocked = True

    def _retime(self, traj, duration: float) -> None:
        """Stretch a planned single move to last ``duration`` s (never faster than planned)."""
        K = len(traj.q)
        K_new = max(K, math.ceil(duration / DT - 1e-9))
        if K_new == K:
            return
        src = np.arange(1, K + 1) / K
        dst = np.arange(1, K_new + 1) / K_new
        origin = self.motion.q
        Q = np.vstack([origin, traj.q])
        xs = np.concatenate([[0.0], src])
        traj.q = np.stack([np.interp(dst, xs, Q[:, j]) for j in range(6)], axis=1)
