"""Words for the reports people read: a count with its noun ("1 pass", "3 passes"), a pose as the command line
types it ("400mm,996.5mm,-100mm,0,0,90deg")."""

from __future__ import annotations

import math


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, in the plural unless n is 1: ``counted(1, "pass")`` is "1 pass", ``counted(2, "pass")``
    "2 passes", ``counted(0, "rapid")`` "0 rapids" (``plural`` for an irregular one)."""
    many = plural or (noun + "es" if noun.endswith(("s", "x", "ch", "sh")) else noun + "s")
    return f"{n} {noun if n == 1 else many}"


def quantity(value: float, unit: str) -> str:
    """A value with its unit as the command line takes it, to 4 decimals: ``quantity(180.00042, "deg")`` is
    "180.0004deg", a zero is a bare "0"."""
    t = f"{value:.4f}".rstrip("0").rstrip(".")
    return "0" if t in ("0", "-0") else t + unit


def pose_option(frame) -> str:
    """A pose x,y,z,rx,ry,rz (m, rad: six numbers) as the command line's ``--part-frame`` / ``--tcp`` value: mm and
    deg to 4 decimals, each with its unit, 0 bare (``"400mm,996.5mm,-100mm,0,0,90deg"``)."""
    x = [float(v) for v in frame]
    return ",".join([quantity(v * 1e3, "mm") for v in x[:3]] + [quantity(math.degrees(v), "deg") for v in x[3:]])
