"""Forward kinematics of UR arms from their standard DH table, vectorized over many joint vectors.

Poses follow the UR convention ``p[x, y, z, rx, ry, rz]``: position in metres and rotation vector
(axis times angle, rad) of the tool frame in the robot base frame.
"""

from __future__ import annotations

from math import cos, sin

import numpy as np

from planner.kinematics._checks import rows_of_six, six_floats
from planner.kinematics.poses import frame_matrix, tcp_frame
from planner.kinematics.ur_models import DH_COS_ALPHA, DH_SIN_ALPHA, URModel, get_model
from planner.rotations import matrix_to_rotvec_1, matrix_to_rotvec_n

__all__ = ["forward", "forward_matrix", "link_frames"]


def dh_link(theta: np.ndarray, d: float, a: float, sin_alpha: float, cos_alpha: float) -> np.ndarray:
    """Standard DH link transform Rz(theta) Tz(d) Tx(a) Rx(alpha), shape theta.shape + (4, 4)."""
    theta = np.asarray(theta, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    zero, one = np.zeros_like(c), np.ones_like(c)
    # Standard DH matrix (Denavit & Hartenberg 1955; UR article cited in ur_models).
    rows = (
        c, -s * cos_alpha, s * sin_alpha, a * c,
        s, c * cos_alpha, -c * sin_alpha, a * s,
        zero, zero + sin_alpha, zero + cos_alpha, zero + d,
        zero, zero, zero, one,
    )
    return np.stack(rows, axis=-1).reshape(theta.shape + (4, 4))


def link_frames(model: str | URModel, q) -> np.ndarray:
    """Frames of DH links 0..6 in the base frame.

    Parameters
    ----------
    model : str or URModel
    q : array_like, shape (6,) or (n, 6)
        Joint positions in rad.

    Returns
    -------
    ndarray, shape (7, 4, 4) or (n, 7, 4, 4)
        Frame 0 is the base (identity), frame 6 the tool flange.
    """
    m = get_model(model)
    q, single = rows_of_six(q, "q")
    frames = np.empty((len(q), 7, 4, 4))
    frames[:, 0] = np.eye(4)
    d, a = m.d, m.a
    for i in range(6):  # six links, each vectorized over the n joint vectors
        frames[:, i + 1] = frames[:, i] @ dh_link(q[:, i], d[i], a[i], DH_SIN_ALPHA[i], DH_COS_ALPHA[i])
    return frames[0] if single else frames


def flange_rp(m: URModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flange rotation (n, 3, 3) and position (n, 3) of validated joints q (n, 6), in closed form.

    The DH product T01 T14 T46 written out: in frame 1 (x1 = (c1, s1, 0), y1 = (0, 0, 1),
    z1 = (s1, -c1, 0)) the flange axes are x6 = (c5 c6 c234 - s6 s234, c5 c6 s234 + s6 c234, s5 c6),
    y6 = (-c5 s6 c234 - c6 s234, -c5 s6 s234 + c6 c234, -s5 s6), z6 = (-s5 c234, -s5 s234, c5) and the
    origin is (a2 c2 + a3 c23 - d6 s5 c234 + d5 s234, a2 s2 + a3 s23 - d6 s5 s234 - d5 c234, d4 + d6 c5).
    """
    c1, s1 = np.cos(q[:, 0]), np.sin(q[:, 0])
    q23 = q[:, 1] + q[:, 2]
    q234 = q23 + q[:, 3]
    c5, s5 = np.cos(q[:, 4]), np.sin(q[:, 4])
    c6, s6 = np.cos(q[:, 5]), np.sin(q[:, 5])
    c234, s234 = np.cos(q234), np.sin(q234)
    # Axes and origin in frame 1 (closed form of the standard DH chain, see docstring).
    x = np.stack([c5 * c6 * c234 - s6 * s234, c5 * c6 * s234 + s6 * c234, s5 * c6], axis=-1)
    y = np.stack([-c5 * s6 * c234 - c6 * s234, -c5 * s6 * s234 + c6 * c234, -s5 * s6], axis=-1)
    z = np.stack([-s5 * c234, -s5 * s234, c5], axis=-1)
    o = np.stack(
        [
            m.a2 * np.cos(q[:, 1]) + m.a3 * np.cos(q23) - m.d6 * s5 * c234 + m.d5 * s234,
            m.a2 * np.sin(q[:, 1]) + m.a3 * np.sin(q23) - m.d6 * s5 * s234 - m.d5 * c234,
            m.d4 + m.d6 * c5,
        ],
        axis=-1,
    )
    # Frame 1 to base: v0 = v1x x1 + v1y y1 + v1z z1 (origin of frame 1 at (0, 0, d1)).
    c1, s1 = c1[:, None], s1[:, None]

    def to_base(v: np.ndarray) -> np.ndarray:
        vx, vy, vz = v[:, :1], v[:, 1:2], v[:, 2:]
        return np.concatenate([c1 * vx + s1 * vz, s1 * vx - c1 * vz, vy], axis=1)

    R = np.stack([to_base(x), to_base(y), to_base(z)], axis=-1)
    p = to_base(o)
    p[:, 2] += m.d1
    return R, p


def flange_1(m: URModel, q) -> tuple[tuple[float, ...], tuple[float, float, float]]:
    """:func:`flange_rp` of one joint vector q (6 floats), on Python floats with the same operations in
    the same order (so the results are identical); returns the rotation's 9 entries row by row and
    the origin."""
    q1, q2, q3, q4, q5, q6 = q
    c1, s1 = cos(q1), sin(q1)
    q23 = q2 + q3
    q234 = q23 + q4
    c5, s5 = cos(q5), sin(q5)
    c6, s6 = cos(q6), sin(q6)
    c234, s234 = cos(q234), sin(q234)
    d5, d6 = m.d5, m.d6
    xx, xy, xz = c5 * c6 * c234 - s6 * s234, c5 * c6 * s234 + s6 * c234, s5 * c6
    yx, yy, yz = -c5 * s6 * c234 - c6 * s234, -c5 * s6 * s234 + c6 * c234, -s5 * s6
    zx, zy, zz = -s5 * c234, -s5 * s234, c5
    ox = m.a2 * cos(q2) + m.a3 * cos(q23) - d6 * s5 * c234 + d5 * s234
    oy = m.a2 * sin(q2) + m.a3 * sin(q23) - d6 * s5 * s234 - d5 * c234
    oz = m.d4 + d6 * c5
    R = (
        c1 * xx + s1 * xz, c1 * yx + s1 * yz, c1 * zx + s1 * zz,
        s1 * xx - c1 * xz, s1 * yx - c1 * yz, s1 * zx - c1 * zz,
        xy, yy, zy,
    )
    return R, (c1 * ox + s1 * oz, s1 * ox - c1 * oz, oy + m.d1)


def compose(R: np.ndarray, p: np.ndarray, Rb, pb) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transforms (R, p) (n, 3, 3), (n, 3) followed by one transform (Rb 9 entries row by row,
    pb 3): (R Rb, R pb + p), summed term by term in the order of :func:`compose_1` (identical results)."""
    B = np.asarray(Rb, dtype=float).reshape(3, 3)
    Rn = R[:, :, 0:1] * B[0] + R[:, :, 1:2] * B[1] + R[:, :, 2:3] * B[2]
    pn = R[:, :, 0] * pb[0] + R[:, :, 1] * pb[1] + R[:, :, 2] * pb[2] + p
    return Rn, pn


def compose_1(Ra, pa, Rb, pb) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """:func:`compose` of one transform (9 + 3 floats) with another."""
    R = tuple(
        Ra[i] * Rb[j] + Ra[i + 1] * Rb[j + 3] + Ra[i + 2] * Rb[j + 6] for i in (0, 3, 6) for j in (0, 1, 2)
    )
    p = tuple(Ra[i] * pb[0] + Ra[i + 1] * pb[1] + Ra[i + 2] * pb[2] + pa[k] for k, i in enumerate((0, 3, 6)))
    return R, p


def invert_1(R, p) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Inverse (R^T, -R^T p) of one rigid transform (9 + 3 floats)."""
    Rt = (R[0], R[3], R[6], R[1], R[4], R[7], R[2], R[5], R[8])
    return Rt, tuple(-(R[i] * p[0] + R[i + 3] * p[1] + R[i + 6] * p[2]) for i in (0, 1, 2))


def _tool_frames(m: URModel, q: np.ndarray, tcp) -> tuple[np.ndarray, np.ndarray]:
    R, p = flange_rp(m, q)
    frame = tcp_frame(tcp)
    return (R, p) if frame is None else compose(R, p, *frame)


def _tool_frame_1(m: URModel, q: list[float], tcp):
    R, p = flange_1(m, q)
    frame = tcp_frame(tcp)
    return (R, p) if frame is None else compose_1(R, p, *frame)


def forward_matrix(model: str | URModel, q, tcp=None) -> np.ndarray:
    """Tool transform(s) in the base frame.

    Parameters
    ----------
    model : str or URModel
        ``"ur3e"``, ``"ur5e"``, ``"ur10e"``, ``"ur16e"``, ``"ur20"`` or a :class:`URModel`.
    q : array_like, shape (6,) or (n, 6)
        Joint positions in rad.
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset as a pose in the flange frame (m, rotation vector); default: the
        flange itself.

    Returns
    -------
    ndarray, shape (4, 4) or (n, 4, 4)
    """
    m = get_model(model)
    one = six_floats(q, "q")
    if one is not None:  # one joint vector: Python floats (a few microseconds), the same results
        return frame_matrix(*_tool_frame_1(m, one, tcp))
    q, _ = rows_of_six(q, "q")
    R, p = _tool_frames(m, q, tcp)
    T = np.zeros((len(q), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, p, 1.0
    return T


def forward(model: str | URModel, q, tcp=None) -> np.ndarray:
    """Tool pose(s) ``p[x, y, z, rx, ry, rz]`` (m, rotation vector) in the base frame.

    One joint vector is computed on Python floats (:func:`flange_1`, :func:`matrix_to_rotvec_1`), many
    at once with numpy; both give identical results.

    Parameters
    ----------
    model : str or URModel
    q : array_like, shape (6,) or (n, 6)
        Joint positions in rad.
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset in the flange frame.

    Returns
    -------
    ndarray, shape (6,) or (n, 6)
    """
    m = get_model(model)
    one = six_floats(q, "q")
    if one is not None:
        R, p = _tool_frame_1(m, one, tcp)
        return np.array([p[0], p[1], p[2], *matrix_to_rotvec_1(*R)])
    q, _ = rows_of_six(q, "q")
    R, p = _tool_frames(m, q, tcp)
    pose = np.empty((len(q), 6))
    pose[:, :3] = p
    pose[:, 3:] = matrix_to_rotvec_n(R)
    return pose
