"""Every RTDE data package of a run, recorded by ur_rtde's own receive thread and read back as the file grows.

Program mode watches the controller from Python, a loop of a few ms that a loaded machine can stall for tens of
ms; at 20x fast-forward a stall of the loop could hide a rapid's brief output-off. And a polled reading mixes
packages: ``getTimestamp()`` and ``getActualTCPPose()`` are two calls, a package can arrive between them, and a
sample then carries one package's time with the next one's pose (the speed computed from such samples spikes to
twice the feed). So the run is recorded by ur_rtde 1.6.5's ``RTDEReceiveInterface.startFileRecording``: its
receive thread writes one CSV row per data package, each row one package's timestamp, actual TCP pose, actual
joints and output bits. :class:`PackageLog` reads the rows written since its last read (complete lines only), so
the recording is reduced as the run goes (memory bounded); the file is deleted when the run ends.

The file holds 6 decimals per value (1 um, 1 urad, 1 us): ~200 bytes per package, ~0.36 GB an hour at 500 Hz
(deleted after the run).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from typing import BinaryIO

import numpy as np

from drivers.base import ConnectionLostError

#: The variables recorded: 14 columns (timestamp, actual_TCP_pose_0..5, actual_q_0..5, actual_digital_output_bits).
VARIABLES = ["timestamp", "actual_TCP_pose", "actual_q", "actual_digital_output_bits"]
COLUMNS = 14


class PackageLog:
    """ur_rtde's file recording of every data package of ``receive`` (an ``RTDEReceiveInterface``), read back
    incrementally (see the module doc). ConnectionLostError when the recording cannot start."""

    def __init__(self, receive) -> None:
        self._r = receive
        self._dir = tempfile.mkdtemp(prefix="ur-run-")
        self.path = os.path.join(self._dir, "packages.csv")
        self._f: BinaryIO | None = None
        self._rest = b""
        self._header = True
        self._recording = False
        try:
            ok = receive.startFileRecording(self.path, VARIABLES)
        except RuntimeError as exc:
            self.close()
            raise ConnectionLostError(f"cannot record the RTDE data packages: {exc}") from exc
        if ok is False:
            self.close()
            raise ConnectionLostError("ur_rtde refused to record the RTDE data packages to a file")
        self._recording = True

    def read(self) -> np.ndarray:
        """The packages written since the last read: (m, 14) rows of timestamp s, actual TCP pose (6) m, rad,
        actual joints (6) rad, output bits."""
        if self._f is None:
            try:
                self._f = open(self.path, "rb")  # noqa: SIM115 (read as it grows, closed in close())
            except FileNotFoundError:
                return np.zeros((0, COLUMNS))
        data = self._rest + self._f.read()
        end = data.rfind(b"\n")
        if end < 0:
            self._rest = data
            return np.zeros((0, COLUMNS))
        text, self._rest = data[:end], data[end + 1:]
        if self._header:
            first, _, text = text.partition(b"\n")
            names = first.decode("ascii", "replace").strip().split(",")
            if len(names) != COLUMNS or names[0] != "timestamp":
                raise ConnectionLostError(f"ur_rtde's package recording has unexpected columns: {names}")
            self._header = False
        if not text.strip():
            return np.zeros((0, COLUMNS))
        values = np.array(text.replace(b"\n", b",").split(b","), dtype=float)
        if values.size % COLUMNS:
            raise ConnectionLostError(f"ur_rtde's package recording has a row of other than {COLUMNS} values")
        return values.reshape(-1, COLUMNS)

    def stop(self) -> None:
        """Stop the recording (its file closed by ur_rtde: :meth:`read` then gives the last rows)."""
        if self._recording:
            self._recording = False
            try:
                self._r.stopFileRecording()
            except RuntimeError:
                pass

    def close(self) -> None:
        """Stop the recording and delete its file."""
        self.stop()
        if self._f is not None:
            self._f.close()
            self._f = None
        shutil.rmtree(self._dir, ignore_errors=True)
