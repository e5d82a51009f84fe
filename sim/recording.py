"""Recording of everything a simulated controller executes: write at stop, read back, plot.

Every control period (2 ms of simulated time) the recorder keeps the time, the commanded joints
(servo targets as the client sent them, trajectory samples as planned), the actual joints and TCP
pose, the digital I/O words, the safety mode and the runtime state; program and safety events are
kept with their time and text. :meth:`Recorder.save` writes an ``.npz`` (or ``.csv``: the samples,
events in a ``<name>.events.csv`` beside it) atomically; :func:`load` reads either back;
:func:`plot` draws planned against actual (matplotlib, Agg).
"""

from __future__ import annotations

import csv
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.export.files import atomic_binary, atomic_text

COLUMNS = (
    ["t"] + [f"target_q{j}" for j in range(6)] + [f"actual_q{j}" for j in range(6)]
    + [f"tcp_{k}" for k in ("x", "y", "z", "rx", "ry", "rz")]
    + ["digital_out", "digital_in", "safety_mode", "runtime_state"]
)
_CHUNK = 8192


class Recorder:
    """Collects samples and events in the controller's tick thread; :meth:`save` writes them."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        if self.path.suffix not in (".npz", ".csv"):
            raise ValueError(f"recording file {self.path}: use a .npz or .csv name")
        self._chunks: list[np.ndarray] = []
        self._buf = np.empty((_CHUNK, len(COLUMNS)))
        self._n = 0
        self.events: list[tuple[float, str, str]] = []

    def sample(self, core) -> None:
        """One control period of ``core`` (a :class:`sim.core.Core`)."""
        if self._n == _CHUNK:
            self._chunks.append(self._buf)
            self._buf = np.empty((_CHUNK, len(COLUMNS)))
            self._n = 0
        row = self._buf[self._n]
        m = core.motion
        row[0] = core.time
        row[1:7] = m.commanded
        row[7:13] = m.q
        row[13:19] = core.tcp_pose()
        row[19] = core.io.digital_out
        row[20] = core.io.digital_in
        row[21] = core.safety_mode
        row[22] = core.runtime_state
        self._n += 1

    def event(self, t: float, source: str, text: str) -> None:
        self.events.append((float(t), source, text))

    def samples(self) -> np.ndarray:
        """All samples so far, shape (n, len(COLUMNS))."""
        return np.vstack(self._chunks + [self._buf[: self._n]])

    def save(self) -> Path:
        """Write the recording atomically (temporary file in the same directory, then rename)."""
        data = self.samples()
        if self.path.suffix == ".npz":
            with atomic_binary(self.path) as f:
                np.savez_compressed(f, samples=data, columns=np.array(COLUMNS),
                                    event_t=np.array([e[0] for e in self.events], dtype=float),
                                    event_source=np.array([e[1] for e in self.events], dtype=str),
                                    event_text=np.array([e[2] for e in self.events], dtype=str))
        else:
            with atomic_binary(self.path) as f:
                np.savetxt(f, data, delimiter=",", header=",".join(COLUMNS), comments="", fmt="%.10g")
            with atomic_text(self.path.with_suffix(".events.csv")) as f:
                w = csv.writer(f)
                w.writerow(["t", "source", "text"])
                w.writerows(self.events)
        return self.path


@dataclass(frozen=True)
class Recording:
    """A recording read back.

    Attributes
    ----------
    t : ndarray (n,)
        Simulated time, s.
    target_q, actual_q : ndarray (n, 6)
        Commanded and actual joints, rad.
    tcp_pose : ndarray (n, 6)
        Actual TCP pose p[x, y, z, rx, ry, rz].
    digital_out, digital_in, safety_mode, runtime_state : ndarray (n,) of int
    events : list of (t, source, text)
    """

    t: np.ndarray
    target_q: np.ndarray
    actual_q: np.ndarray
    tcp_pose: np.ndarray
    digital_out: np.ndarray
    digital_in: np.ndarray
    safety_mode: np.ndarray
    runtime_state: np.ndarray
    events: list


def _from_samples(data: np.ndarray, events: list) -> Recording:
    data = data.reshape(-1, len(COLUMNS))
    i = data[:, 19:23].astype(np.int64)
    return Recording(data[:, 0], data[:, 1:7], data[:, 7:13], data[:, 13:19], i[:, 0], i[:, 1], i[:, 2], i[:, 3],
                     events)


def load(path: str | os.PathLike) -> Recording:
    """Read a recording written by :meth:`Recorder.save` (``.npz`` or ``.csv``)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"recording {path} does not exist")
    if path.suffix == ".npz":
        with np.load(path) as z:
            events = list(zip(z["event_t"].tolist(), z["event_source"].tolist(), z["event_text"].tolist(),
                              strict=True))
            return _from_samples(z["samples"], events)
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    events = []
    ev = path.with_suffix(".events.csv")
    if ev.exists():
        with open(ev, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))[1:]
        events = [(float(r[0]), r[1], r[2]) for r in rows]
    return _from_samples(data, events)


def plot(rec: Recording, out: str | os.PathLike, title: str = "Simulated UR: planned vs actual") -> Path:
    """Plot commanded and actual joints and their difference over time to an image file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for j in range(6):
        line, = ax1.plot(rec.t, rec.target_q[:, j], "--", lw=1.0, label=f"q{j} planned")
        ax1.plot(rec.t, rec.actual_q[:, j], "-", lw=1.0, color=line.get_color(), label=f"q{j} actual")
    ax1.set_ylabel("joint position (rad)")
    ax1.legend(ncol=4, fontsize=7)
    ax1.set_title(title)
    err = np.degrees(rec.target_q - rec.actual_q)
    for j in range(6):
        ax2.plot(rec.t, err[:, j], lw=0.8, label=f"q{j}")
    stops: np.ndarray = rec.t[np.flatnonzero(np.diff(rec.safety_mode) != 0) + 1] if len(rec.t) > 1 else np.zeros(0)
    for ts in stops:
        ax2.axvline(ts, color="r", lw=0.8)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("planned - actual (deg)")
    ax2.legend(ncol=6, fontsize=7)
    fig.tight_layout()
    out = Path(out)
    try:
        with atomic_binary(out) as f:
            fig.savefig(f, format=out.suffix.lstrip(".").lower() or "png")
    finally:
        plt.close(fig)
    return out
