"""Running a planned job on a UR robot, as a library: what the command line (``planner run``, ``planner demo``) and
the REST service's executions both call.

- :func:`execute_job`: connect a :class:`drivers.ur.URDriver` to a controller, execute a job, disconnect.
- :func:`start_sim`: a simulated controller (:class:`sim.SimController`) on a free loopback address.
- :func:`run_demo_on_sim`: a job executed on a simulator it starts (the end of ``planner demo``).
- :func:`plot_run`: the job's picture with the run drawn over it.

Examples
--------
A planned job executed on a simulated UR5e through the real ur_rtde client (program mode, ten times faster than
real time), and the report of how the tracked TCP followed the plan:

>>> import numpy as np
>>> from planner import PlanSettings, plan
>>> from drivers.execute import execute_job, start_sim
>>> t = np.linspace(0.0, 1.0, 9)
>>> bead = np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), np.zeros_like(t)]
>>> job = plan(bead, PlanSettings(feed=0.02, robot="ur5e", part_frame=(0.4, -0.1, 0.2, 0, 0, 0)))
>>> sim = start_sim("ur5e", speed=10.0)         # on a free loopback address
>>> try:
...     report = execute_job(job, sim.host, mode="program")
... finally:
...     sim.stop()
>>> report.ok, report.max_path_error < 1e-4     # m
(True, True)
"""

from __future__ import annotations

import random
import socket

from drivers.base import DEFAULT_MODE, DriverError

#: The controller's ports (RTDE, dashboard, primary, secondary, real-time) a simulated controller serves.
UR_PORTS = (30004, 29999, 30001, 30002, 30003)


def free_loopback_host(rng: random.Random | None = None) -> str:
    """A loopback address on which nothing serves the UR ports."""
    rng = rng or random.Random()
    for _ in range(200):
        host = f"127.{rng.randint(100, 250)}.{rng.randint(0, 255)}.{rng.randint(2, 254)}"
        ok = True
        for port in UR_PORTS:
            with socket.socket() as s:
                try:
                    s.bind((host, port))
                except OSError:
                    ok = False
                    break
        if ok:
            return host
    raise DriverError("no free loopback address for a simulated controller")


def _free_port(host: str) -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def start_sim(model: str, *, host: str | None = None, modbus: bool = False, speed: float = 1.0):
    """A started :class:`sim.SimController` (on ``host`` or a free loopback address; Modbus on a free port).
    DriverError when it cannot start (no free loopback address, the address taken, the child process failing)."""
    from sim import SimController, SimError

    host = host or free_loopback_host()
    try:
        return SimController(host, model=model, modbus_port=_free_port(host) if modbus else None,
                             speed=speed).start()
    except (SimError, OSError) as exc:
        # the child's reason is the last line of what it printed (SimError carries its whole traceback)
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
        raise DriverError(f"cannot start a simulated controller on {host}: {lines[-1] if lines else exc}") from exc


def execute_job(job, host: str, *, mode: str = DEFAULT_MODE, io: str = "rtde", modbus_port: int = 502,
                progress=None, cancel=None, **driver_options):
    """Connect a :class:`drivers.ur.URDriver` to ``host``, execute ``job``, disconnect; the ExecutionReport."""
    from drivers.ur import URDriver

    driver = URDriver(host, job.settings.robot, io=io, modbus_port=modbus_port, **driver_options)
    driver.connect()
    try:
        return driver.execute(job, mode=mode, progress=progress, cancel=cancel)
    finally:
        driver.close()


def run_demo_on_sim(job, *, mode: str = DEFAULT_MODE, speed: float = 10.0, progress=None, plot=None):
    """Execute a planned job on a simulated controller through real ur_rtde (the end of ``planner demo``).

    Program mode runs the job's URScript in fast-forward (``speed`` simulated seconds per second); stream
    mode streams servoJ in real time (``speed`` is then 1). ``plot``: a picture of the job with the run drawn
    over it is written there (atomically). Returns the :class:`ExecutionReport`."""
    sim = start_sim(job.settings.robot, speed=speed if mode == "program" else 1.0)
    try:
        report = execute_job(job, sim.host, mode=mode, progress=progress)
    finally:
        sim.stop()
    if plot is not None:
        plot_run(job, report, plot)
    return report


def plot_run(job, report, target) -> None:
    """The job's picture with the run drawn over it: the export verb's plot (:func:`planner.export.write`) with
    ``execution=``."""
    from planner.export import write

    write(job, target, execution=report)
