"""Simulated Universal Robots e-Series controller on loopback, for tests and dry runs.

`SimController` starts one in a child process; it serves the controller's real RTDE (30004),
dashboard (29999), primary, secondary and real-time interfaces (30001, 30002, 30003) and Modbus protocols so
the unmodified ur_rtde, pymodbus and UR's own clients drive it. The planning core never imports this package.
"""

from sim.controller import SimController, SimError

__all__ = ["SimController", "SimError"]
