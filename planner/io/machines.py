"""Kinematics of 5-axis table-table machines: rotary angles of a G-code program to tool axes.

Derivation (table-table machine, spindle fixed)
-----------------------------------------------
The tool points along the machine's spindle axis ``s`` (``+Z``: from the tool tip towards the
spindle). The part is clamped on the rotary table (C), which rides on the tilting trunnion (B). With
the tables turned by the physical angles ``beta`` about the tilt axis ``u_B`` and ``gamma`` about the
rotary axis ``u_C`` (given at zero tilt), a vector ``v`` fixed in the part is seen in machine axes as

    Q v,    Q = Rot(u_B, beta) Rot(u_C, gamma)        (the C table is carried by the B trunnion)

so the tool axis expressed in the part frame is

    a = Q^T s = Rot(u_C, -gamma) Rot(u_B, -beta) s.

A program commands angles ``b``, ``c``; the table turns by ``beta = sign_B (b - b0)`` and
``gamma = sign_C (c - c0)``. ISO 841 names the positive sense of a rotary *table* axis opposite to
the tool's relative motion (a positive B command moves the tool by +B about +Y relative to the
part, which means turning the table by -B), i.e. ``sign = -1``. With ``u_B = Y``, ``u_C = Z``,
``s = Z`` and both signs -1:

    a = Rot(Z, c) Rot(Y, b) Z = (sin b cos c, sin b sin c, cos b),

the same formula as for a head that tilts by B then swivels by C. Hand checks: ``b = 0`` gives
``+Z`` for every ``c``; ``b = 90 deg, c = 0`` gives ``+X``; ``b = 90 deg, c = 90 deg`` gives ``+Y``;
``b = 90 deg, c = 180 deg`` gives ``-X``. (With both signs +1 the formula is
``a = Rot(Z, -c) Rot(Y, -b) Z = (-sin b cos c, sin b sin c, cos b)``.)

Frames of the programmed XYZ
----------------------------
* TCPC (Haas ``G234``, also G43.4/G43.5/RTCP on other controls): XYZ is the tool tip in the part
  (work) frame; only the axis needs the kinematics.
* DWO (Haas ``G254``, 3+2 work): XYZ is the tool tip in machine-aligned axes about the turned part
  origin, ``p_prog = Q p_part``, so ``p_part = Q^T p_prog``.
* Neither: XYZ are machine positions relative to the work offset, ``p_prog = T(p_part)`` with ``T``
  the rigid motion of the tables about their axes. This needs a point on each axis (``tilt_point``,
  ``rotary_point``, in the work frame at zero angles); without them the reader treats the block like
  DWO and warns.

The Haas UMC-750 preset was checked on the NX 2022 program in ``shared/data`` (a 4 in block):
its 3+2 pockets under G254 land in the block's faces with the tool pointing out of them
(``B82.875 C-180``: x from -0.04 to 0.35 in, axis within 8 deg of -X; ``B82.875 C0``: x from 3.65 to
4.04 in, axis near +X; likewise -Y and +Y for ``C-90``/``C90``), and its simultaneous operations
under G234 approach the faces from outside. With both signs +1 the pockets would fall 2 in below
the block and the TCPC tools would point into it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from planner.io.options import ReaderArgumentError, ReaderArgumentTypeError
from planner.validation import _described


def _unit(v, name: str) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise ValueError(f"{name} must be a finite 3-vector, got {v!r}")
    n = float(np.linalg.norm(a))
    if abs(n - 1.0) > 1e-9:
        raise ValueError(f"{name} must be a unit vector, got {v!r} (length {n:.9g})")
    return (float(a[0]), float(a[1]), float(a[2]))


@dataclass(frozen=True)
class TableTableKinematics:
    """A 5-axis machine whose two rotary axes both turn the table (the spindle never tilts).

    Parameters
    ----------
    name : str
        Name shown in messages.
    tilt_word, rotary_word : str
        G-code address letters of the tilting axis (carried first, e.g. "B") and of the rotary table
        carried by it (e.g. "C").
    tilt_axis : 3-vector
        Unit direction of the tilt axis in machine axes (Y for a B trunnion).
    rotary_axis : 3-vector
        Unit direction of the rotary-table axis at zero tilt (Z for a C table).
    tilt_sign, rotary_sign : {-1, +1}
        Table rotation per unit of positive command: -1 is the ISO 841 convention for table axes
        (the table turns backwards so that the tool turns forwards relative to the part).
    tilt_zero, rotary_zero : float
        Commanded angles (radians) at which the tables are at their zero pose.
    spindle_axis : 3-vector
        Tool axis (tip towards spindle) in machine axes.
    tilt_point, rotary_point : 3-vectors or None
        A point on each rotary axis, metres, in the work frame at zero angles. Needed only for
        blocks programmed with neither TCPC nor DWO at non-zero angles.
    """

    name: str = "table-table"
    tilt_word: str = "B"
    rotary_word: str = "C"
    tilt_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    rotary_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    tilt_sign: float = -1.0
    rotary_sign: float = -1.0
    tilt_zero: float = 0.0
    rotary_zero: float = 0.0
    spindle_axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    tilt_point: tuple[float, float, float] | None = None
    rotary_point: tuple[float, float, float] | None = None

    def __post_init__(self):
        for f in ("tilt_axis", "rotary_axis", "spindle_axis"):
            object.__setattr__(self, f, _unit(getattr(self, f), f))
        for f in ("tilt_sign", "rotary_sign"):
            if getattr(self, f) not in (-1, 1):
                raise ValueError(f"{f} must be -1 or +1, got {getattr(self, f)!r}")
        for f in ("tilt_word", "rotary_word"):
            w = str(getattr(self, f)).upper()
            if len(w) != 1 or w not in "ABCUVW":
                raise ValueError(f"{f} must be one of A, B, C, U, V, W, got {getattr(self, f)!r}")
            object.__setattr__(self, f, w)
        if self.tilt_word == self.rotary_word:
            raise ValueError("tilt_word and rotary_word must differ")
        for f in ("tilt_zero", "rotary_zero"):
            if not math.isfinite(getattr(self, f)):
                raise ValueError(f"{f} must be finite")
        for f in ("tilt_point", "rotary_point"):
            p = getattr(self, f)
            if p is not None:
                a = np.asarray(p, dtype=float)
                if a.shape != (3,) or not np.isfinite(a).all():
                    raise ValueError(f"{f} must be a finite 3-vector or None, got {p!r}")
                object.__setattr__(self, f, tuple(float(x) for x in a))

    @property
    def words(self) -> tuple[str, str]:
        """The G-code letters of the (tilt, rotary) axes."""
        return self.tilt_word, self.rotary_word

    def table_rotation(self, b, c) -> Rotation:
        """Orientation ``Q`` of the part in machine axes at commanded angles ``b``, ``c`` (radians).

        Parameters
        ----------
        b, c : float or ndarray, shape (n,)
            Commanded tilt and rotary angles, radians.

        Returns
        -------
        scipy.spatial.transform.Rotation
            ``Q = Rot(u_B, sign_B (b - b0)) Rot(u_C, sign_C (c - c0))`` (one rotation per angle pair).
        """
        b = np.atleast_1d(np.asarray(b, dtype=float))
        c = np.atleast_1d(np.asarray(c, dtype=float))
        beta = self.tilt_sign * (b - self.tilt_zero)
        gamma = self.rotary_sign * (c - self.rotary_zero)
        rb = Rotation.from_rotvec(beta[:, None] * np.asarray(self.tilt_axis))
        rc = Rotation.from_rotvec(gamma[:, None] * np.asarray(self.rotary_axis))
        return rb * rc

    def tool_axis(self, b, c) -> np.ndarray:
        """Unit tool axis in the part frame, ``a = Q^T s``.

        Parameters
        ----------
        b, c : float or ndarray, shape (n,)
            Commanded tilt and rotary angles, radians.

        Returns
        -------
        ndarray, shape (n, 3)
        """
        return self.table_rotation(b, c).inv().apply(np.asarray(self.spindle_axis))

    def part_points(self, points: np.ndarray, b, c, mode: str) -> np.ndarray:
        """Programmed tool-tip positions converted to the part frame.

        Parameters
        ----------
        points : ndarray, shape (n, 3)
            Programmed XYZ, metres.
        b, c : ndarray, shape (n,)
            Commanded angles, radians.
        mode : {"tcpc", "dwo", "machine"}
            How the program was written (see the module notes).

        Returns
        -------
        ndarray, shape (n, 3)
        """
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        if mode == "tcpc":
            return p.copy()
        if mode == "dwo" or self.tilt_point is None or self.rotary_point is None:
            return self.table_rotation(b, c).inv().apply(p)
        if mode != "machine":
            raise ValueError(f"mode must be 'tcpc', 'dwo' or 'machine', got {mode!r}")
        # p_prog = qb + Rb (qc + Rc (p - qc) - qb)  =>  p = qc + Rc^T (qb + Rb^T (p_prog - qb) - qc)
        b = np.atleast_1d(np.asarray(b, dtype=float))
        c = np.atleast_1d(np.asarray(c, dtype=float))
        qb, qc = np.asarray(self.tilt_point), np.asarray(self.rotary_point)
        rb = Rotation.from_rotvec((self.tilt_sign * (b - self.tilt_zero))[:, None] * np.asarray(self.tilt_axis))
        rc = Rotation.from_rotvec((self.rotary_sign * (c - self.rotary_zero))[:, None] * np.asarray(self.rotary_axis))
        return qc + rc.inv().apply(qb + rb.inv().apply(p - qb) - qc)


#: Haas UMC-750: B trunnion about Y, C table about Z, ISO table senses (signs -1), zeros at 0.
HAAS_UMC_750 = TableTableKinematics(name="Haas UMC-750")

#: Named machine presets accepted by ``read_gcode(machine=...)`` (keys compared without case,
#: spaces, dashes or underscores).
MACHINES = {"haasumc750": HAAS_UMC_750, "umc750": HAAS_UMC_750}


def machine_kinematics(machine) -> TableTableKinematics:
    """A :class:`TableTableKinematics` from itself or from a preset name such as ``"haas-umc-750"``.

    Raises
    ------
    ReaderArgumentError
        An unknown name (listing the presets), or a value that is neither a name nor a kinematics (also a
        ``TypeError``); the message names the argument ``machine``.
    """
    known = "'haas-umc-750'"
    if isinstance(machine, TableTableKinematics):
        return machine
    if isinstance(machine, str):
        key = "".join(ch for ch in machine.lower() if ch.isalnum())
        if key in MACHINES:
            return MACHINES[key]
        raise ReaderArgumentError("machine", f"machine {machine!r}: unknown machine; presets: {known} (or give a "
                                             "TableTableKinematics)")
    raise ReaderArgumentTypeError("machine", f"machine must be a preset name ({known}) or a TableTableKinematics, "
                                             f"got {_described(machine)}")
