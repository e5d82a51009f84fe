"""servoJ as the drivers assume it, and the servo targets shaped so that the arm follows the PLANNED joints.

What UR documents for ``servoj(q, a, v, t, lookahead_time, gain)`` (URScript manual): ``lookahead_time``
(0.03..0.2 s) "smoothens the trajectory" (a low value gives fast reaction, a high value prevents overshoot);
``gain`` (100..2000) is the proportional gain for following the target (the higher, the faster the reaction);
a high gain or a short lookahead time may cause instability and vibration, especially when the targets are
noisy or updated at a low frequency (one target per control period is the intended use). UR documents no
transfer function. The model assumed here is the simulated controller's (:mod:`sim.motion`), per joint, every
control period ``dt``:

- the target passes a first-order smoothing filter of time constant ``lookahead / 2``:
  ``f[k+1] = f[k] + a_f (u[k] - f[k])``, ``a_f = 1 - exp(-dt / (lookahead / 2))``;
- the joint follows the filtered target with a first-order loop of time constant ``GAIN_TIME / gain``:
  ``q[k+1] = q[k] + a_t (f[k+1] - q[k])``, ``a_t = 1 - exp(-dt gain / GAIN_TIME)``.

Sent the planned joints as they are, the arm lags them by ``lookahead / 2 + GAIN_TIME / gain`` (0.083 s at the
old defaults 0.1 s, 300: 4 mm behind at 50 mm/s, on the path) and, worse, cuts every bend: a circle of radius r
run at speed v comes out smaller by about ``v^2 / r (tau_f^2 + tau_t^2) / 2`` (0.6 mm on a 6 mm bend at
50 mm/s with the old defaults, 0.05 mm with the shortest time constants UR allows, 0.03 s and 2000).

:class:`ServoShaper` inverts the model: the target sent at period k is the one that puts the joints, one period
later, exactly on the planned sample k (``q[k+1] = y[k]``): ``f[k+1] = y[k-1] + (y[k] - y[k-1]) / a_t``,
``u[k] = f[k] + (f[k+1] - f[k]) / a_f``. The targets lead the plan by about the lag and bulge out of bends by
what the filters take off; the arm, through the filters, is back on the plan. Its cost: a target that stops
(a pause, a stalled client loop) leaves the arm converging on a shaped target, off the planned point by about
``v (tau_f + tau_t)`` along the path; hence the shortest time constants are the default (0.03 s, 2000: 20 ms).
A real controller whose servo differs from this model is followed as well as the model is right about it:
``compensate=False`` in the drivers sends the planned joints unshaped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Time constant scale of servoj's tracking loop, s: tau = GAIN_TIME / gain (gain 300: 33 ms; 2000: 5 ms). The
#: simulated controller's figure (sim.motion.SERVO_GAIN_TIME); UR publishes none.
GAIN_TIME = 10.0
#: The servo settings the drivers use unless told otherwise: the shortest time constants UR allows (measured on the
#: simulated controller: bench/bench_tracking.py).
DEFAULT_LOOKAHEAD = 0.03
DEFAULT_GAIN = 2000.0
#: UR's documented ranges of servoj's lookahead_time (s) and gain.
LOOKAHEAD_RANGE = (0.03, 0.2)
GAIN_RANGE = (100.0, 2000.0)


def check_servo(lookahead, gain) -> tuple[float, float]:
    """``(lookahead, gain)`` as floats within UR's ranges; ValueError naming the option otherwise."""
    try:
        la, g = float(lookahead), float(gain)
    except (TypeError, ValueError):
        raise ValueError(f"lookahead and gain must be numbers, got {lookahead!r}, {gain!r}") from None
    if not LOOKAHEAD_RANGE[0] <= la <= LOOKAHEAD_RANGE[1]:
        raise ValueError(f"lookahead must be within 0.03..0.2 s, got {lookahead!r}")
    if not GAIN_RANGE[0] <= g <= GAIN_RANGE[1]:
        raise ValueError(f"gain must be within 100..2000, got {gain!r}")
    return la, g


@dataclass(frozen=True)
class ServoModel:
    """servoj's response as assumed (see the module doc): ``lookahead`` s, ``gain``, control period ``dt`` s."""

    lookahead: float
    gain: float
    dt: float = 0.002

    @property
    def tau_lookahead(self) -> float:
        """Time constant of the smoothing filter, s."""
        return 0.5 * self.lookahead

    @property
    def tau_gain(self) -> float:
        """Time constant of the tracking loop, s."""
        return GAIN_TIME / self.gain

    @property
    def lag(self) -> float:
        """How long the arm lags targets moving at a steady speed, s."""
        return self.tau_lookahead + self.tau_gain

    @property
    def alphas(self) -> tuple[float, float]:
        """Per-period factors (a_f, a_t) of the two filters."""
        return (1.0 - math.exp(-self.dt / self.tau_lookahead), 1.0 - math.exp(-self.dt / self.tau_gain))

    def bend_error(self, speed: float, radius: float) -> float:
        """How far inside a bend of ``radius`` m run at ``speed`` m/s the arm runs on unshaped targets, m (the
        circle's gain |H(i w)| at w = v / r)."""
        w = speed / radius
        return radius * (1.0 - 1.0 / math.sqrt((1 + (w * self.tau_lookahead) ** 2) * (1 + (w * self.tau_gain) ** 2)))

    def response(self, u: np.ndarray, q0) -> np.ndarray:
        """The joints (n, 6) after each of the targets ``u`` (n, 6), sent one per period from rest at ``q0`` (6,):
        the model run forward (what :meth:`ServoShaper.shape` inverts)."""
        from scipy.signal import lfilter

        u = np.asarray(u, dtype=float).reshape(-1, 6)
        q0 = np.asarray(q0, dtype=float).reshape(1, 6)
        af, at = self.alphas
        f = lfilter([af], [1.0, af - 1.0], u, axis=0, zi=(1.0 - af) * q0)[0]
        return lfilter([at], [1.0, at - 1.0], f, axis=0, zi=(1.0 - at) * q0)[0]


class ServoShaper:
    """The servo targets that put the arm on the planned joints one period later (see the module doc), chunk by
    chunk: :meth:`shape` takes consecutive planned joints and keeps the two samples it needs of the past.

    ``model``: the :class:`ServoModel`; ``q0``: the joints the arm rests at before the first target (the job's
    start). ``compensate=False``: the planned joints are returned as they are."""

    def __init__(self, model: ServoModel, q0, *, compensate: bool = True) -> None:
        self.model = model
        self.compensate = bool(compensate)
        q0 = np.asarray(q0, dtype=float).reshape(1, 6)
        self._past = np.vstack((q0, q0))  # y[k-2], y[k-1]

    def shape(self, y: np.ndarray) -> np.ndarray:
        """Targets (n, 6) rad for the planned joints ``y`` (n, 6) rad, the next of the job's samples."""
        y = np.asarray(y, dtype=float).reshape(-1, 6)
        yy = np.vstack((self._past, y))
        self._past = yy[-2:].copy()
        if not self.compensate or y.shape[0] == 0:
            return y
        af, at = self.model.alphas
        f = yy[:-1] + (yy[1:] - yy[:-1]) / at  # f[k+1] for k = -1 .. n-1: puts q[k+1] on y[k]
        return f[:-1] + (f[1:] - f[:-1]) / af

    def hold(self, n: int) -> np.ndarray:
        """Targets (n, 6) that bring the arm to rest on the last planned joints shaped so far and hold it there (the
        end of a stream: a job ends at rest, so these settle within a few periods on those joints)."""
        return self.shape(np.repeat(self._past[-1:], max(int(n), 0), axis=0))
