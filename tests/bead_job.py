"""A glue bead as a user of a glue cell would give it: CSV waypoints (mm) of an S-shaped bead in a plane, straight
runs joined by two half-circle bends of a chosen radius, the tool axis along -z (dispensing downwards)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def s_bead_points(radius: float = 6.0, straight: float = 27.5, step: float = 1.0) -> np.ndarray:
    """Waypoints (n, 2) mm of the S: ``straight`` mm along +x, a half circle of ``radius`` mm, ``straight`` mm back
    along -x, a half circle the other way, ``straight`` mm along +x; a waypoint every ``step`` mm or less. With the
    defaults the bead is 120 mm long."""

    def line(p, q):
        p, q = np.asarray(p, float), np.asarray(q, float)
        n = max(2, int(np.ceil(np.linalg.norm(q - p) / step)) + 1)
        return p + np.linspace(0.0, 1.0, n)[:, None] * (q - p)

    def arc(cx, cy, a0, a1):
        n = max(3, int(np.ceil(abs(a1 - a0) * radius / step)) + 1)
        a = np.linspace(a0, a1, n)
        return np.c_[cx + radius * np.cos(a), cy + radius * np.sin(a)]

    r, L = float(radius), float(straight)
    parts = [line((0.0, 0.0), (L, 0.0)), arc(L, r, -np.pi / 2, np.pi / 2)[1:], line((L, 2 * r), (0.0, 2 * r))[1:],
             arc(0.0, 3 * r, -np.pi / 2, -3 * np.pi / 2)[1:], line((0.0, 4 * r), (L, 4 * r))[1:]]
    return np.vstack(parts)


def write_s_bead(path, radius: float = 6.0, straight: float = 27.5) -> Path:
    """The bead's CSV (``x,y,z,i,j,k``, mm; the axis 0,0,-1 as in the CSV the issue was found with) at ``path``."""
    p = s_bead_points(radius, straight)
    rows = "\n".join(f"{x:.4f},{y:.4f},0,0,0,-1" for x, y in p)
    path = Path(path)
    path.write_text("x,y,z,i,j,k\n" + rows + "\n")
    return path
