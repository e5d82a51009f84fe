"""Words for the reports people read: a count with its noun ("1 pass", "3 passes")."""

from __future__ import annotations


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, in the plural unless n is 1: ``counted(1, "pass")`` is "1 pass", ``counted(2, "pass")``
    "2 passes", ``counted(0, "rapid")`` "0 rapids" (``plural`` for an irregular one)."""
    many = plural or (noun + "es" if noun.endswith(("s", "x", "ch", "sh")) else noun + "s")
    return f"{n} {noun if n == 1 else many}"
