"""Process-level rules of the simulator: loopback addresses only (unless asked otherwise), thread priorities, the
fast-forward factor's bounds."""

from __future__ import annotations

import ipaddress
import os


def check_host(host: str, allow_remote: bool = False) -> str:
    """``host`` as an IPv4 address string; non-loopback addresses only with ``allow_remote``."""
    try:
        addr = ipaddress.IPv4Address(host)
    except ValueError:
        raise ValueError(f"host must be an IPv4 address such as 127.0.0.2, got {host!r}") from None
    if not addr.is_loopback and not allow_remote:
        raise ValueError(
            f"host {host} is not a loopback address (127.0.0.0/8); pass allow_remote=True to serve on it"
        )
    return str(addr)


def set_realtime_priority(priority: int = 10) -> bool:
    """Run the calling thread under SCHED_FIFO ``priority`` if the system allows it (a controller's loop
    is real-time); the threads sleep most of each period and the kernel's RT throttling bounds them."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (OSError, AttributeError):
        return False


#: Largest fast-forward factor: simulated time this much faster than the wall clock (more only starves the machine).
MAX_SPEED = 10_000.0


def check_speed(speed) -> float:
    """``speed`` (simulated seconds per wall-clock second) as a float, or ValueError naming it."""
    if isinstance(speed, bool) or not isinstance(speed, int | float) or not 0 < speed <= MAX_SPEED:
        raise ValueError(f"speed must be a number > 0 and <= {MAX_SPEED:g}, got {speed!r}")
    return float(speed)
