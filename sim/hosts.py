"""The address rule every listener of the simulator obeys: loopback only, unless asked otherwise."""

from __future__ import annotations

import ipaddress


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
