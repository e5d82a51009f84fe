"""One project of a compose file under docker/, run by the tests with the real Docker engine.

:class:`ComposeStack` runs Compose (Debian's ``docker-compose`` 1.29, or Compose v2's ``docker compose``: the files
read the same in both) with a project name of its own, so that a test never meets another run's containers, and
``down`` removes every container, network and volume of it. The helpers raise AssertionError with the services' logs
when a service does not come up; nothing skips.
"""

from __future__ import annotations

import ipaddress
import json
import os
import random
import socket
import time
import uuid
from pathlib import Path

from tests.docker_images import ROOT, compose_command, docker, run

DOCKER = ROOT / "docker"


def free_port() -> int:
    """A TCP port free on the host's loopback now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_subnet() -> tuple[str, str]:
    """A /24 in 172.31.0.0/16 that no Docker network and no route of the host uses (the stacks' cell network, so
    that two runs at once never share one), and its address .10 for the simulated controller: (subnet, address)."""
    used = []
    for network in docker("network", "ls", "--quiet", timeout=60).split():
        out = docker("network", "inspect", "--format", "{{range .IPAM.Config}}{{.Subnet}} {{end}}", network,
                     timeout=60, check=False)
        used += [ipaddress.ip_network(s, strict=False) for s in out.split() if ":" not in s]
    for line in Path("/proc/net/route").read_text().splitlines()[1:]:
        fields = line.split()
        dest, mask = (ipaddress.IPv4Address(bytes.fromhex(f)[::-1]) for f in (fields[1], fields[7]))
        if int(mask):
            used.append(ipaddress.ip_network(f"{dest}/{mask}", strict=False))
    for third in random.sample(range(1, 255), 254):
        subnet = ipaddress.ip_network(f"172.31.{third}.0/24")
        if not any(subnet.overlaps(u) for u in used):
            return str(subnet), str(subnet.network_address + 10)
    raise AssertionError("no free /24 in 172.31.0.0/16 for a cell network")


class ComposeStack:
    """The compose ``file`` as project ``plannertest<random>``, with ``env`` (the files' variables) added to ours."""

    def __init__(self, file: Path, env: dict[str, str]):
        self.file = Path(file)
        self.project = f"plannertest{uuid.uuid4().hex[:10]}"
        self.env = {**os.environ, **env}
        self.command = compose_command()

    def compose(self, *args: str, timeout: float = 300.0, check: bool = True) -> str:
        """``compose -p PROJECT -f FILE ARGS`` run to its end; its standard output."""
        argv = [*self.command, "-p", self.project, "-f", str(self.file), *args]
        return run(argv, timeout=timeout, what=f"{' '.join(self.command)} {args[0]} ({self.file.name})", check=check,
                   env=self.env).stdout.decode()

    def containers(self, service: str) -> list[str]:
        """The ids of ``service``'s containers (running or not)."""
        return self.compose("ps", "-q", service, timeout=60).split()

    def container(self, service: str) -> str:
        """The id of ``service``'s one container."""
        ids = self.containers(service)
        assert len(ids) == 1, f"{service}: {len(ids)} containers, not 1\n{self.logs()}"
        return ids[0]

    def inspect(self, service: str) -> dict:
        """``docker inspect`` of ``service``'s one container."""
        return json.loads(docker("inspect", self.container(service), timeout=60))[0]

    def health(self, service: str) -> str:
        """starting, healthy or unhealthy (the image's HEALTHCHECK); the state (exited, ...) of a stopped one."""
        state = self.inspect(service)["State"]
        if not state["Running"]:
            return state["Status"]
        return state.get("Health", {}).get("Status", "none")

    def wait_healthy(self, service: str, timeout: float) -> float:
        """Seconds until ``service``'s healthcheck reads healthy; AssertionError with the logs otherwise."""
        t0 = time.monotonic()
        while (status := self.health(service)) != "healthy":
            if status in ("unhealthy", "exited", "dead") or time.monotonic() - t0 > timeout:
                raise AssertionError(f"{service} is {status}, not healthy, {time.monotonic() - t0:.0f} s after "
                                     f"start:\n{self.logs()}")
            time.sleep(0.5)
        return time.monotonic() - t0

    def exec(self, service: str, *args: str, timeout: float = 120.0) -> str:
        """``args`` run in ``service``'s container (no terminal); its standard output."""
        return self.compose("exec", "-T", service, *args, timeout=timeout)

    def logs(self, service: str | None = None) -> str:
        out = self.compose("logs", "--no-color", "--tail", "60", *([service] if service else []), timeout=60,
                           check=False)
        return out[-6000:]

    def resources(self) -> dict[str, list[str]]:
        """The project's containers, networks and volumes left on the engine (by Compose's project label)."""
        label = f"label=com.docker.compose.project={self.project}"
        return {kind: docker(*cmd, "--filter", label, "--quiet", timeout=60).split()
                for kind, cmd in (("containers", ("ps", "--all")), ("networks", ("network", "ls")),
                                  ("volumes", ("volume", "ls")))}

    def down(self) -> None:
        """Containers stopped and removed with the project's networks and volumes."""
        self.compose("down", "--volumes", "--remove-orphans", "--timeout", "10", timeout=300)
