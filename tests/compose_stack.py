"""One project of a compose file under docker/, run by the tests with the real Docker engine.

:class:`ComposeStack` runs Compose (Debian's ``docker-compose`` 1.29, or Compose v2's ``docker compose``: the files
read the same in both) with a project name of its own, so that a test never meets another run's containers, and
``down`` removes every container, network and volume of it (the anonymous volumes of the images' ``VOLUME``s too,
which carry no project label: :meth:`ComposeStack.resources` still finds those it saw). The helpers raise
AssertionError with the services' logs when a service does not come up; nothing skips. :func:`planner_image` builds
the planner's image once per test session, :func:`print_times` shows a module's step times in the test report.
"""

from __future__ import annotations

import contextlib
import ipaddress
import json
import os
import random
import socket
import time
import uuid
from pathlib import Path

from tests.docker_images import PYTHON, ROOT, compose_command, docker, ensure_test_images, run

DOCKER = ROOT / "docker"
#: The planner's image the tests build (a tag of its own: a user's ph-toolpath-planner:latest is left alone).
IMAGE = "ph-toolpath-planner:test"
_built: list[str] = []


def planner_image(times: dict[str, float]) -> str:
    """The planner's image :data:`IMAGE`, built by Compose from docker/compose.yaml's build section FROM the local
    stand-in for python:3.11-slim, once per session (a later call finds it built); the seconds of each step added to
    ``times``."""
    if _built:
        return _built[0]
    for tag, seconds in ensure_test_images((PYTHON,)).items():
        times[f"stand-in {tag}"] = seconds
    before = image_id(IMAGE)
    t0 = time.monotonic()
    ComposeStack(DOCKER / "compose.yaml", {"PLANNER_IMAGE": IMAGE, "PLANNER_BASE_IMAGE": PYTHON}).compose(
        "build", "planner", timeout=1800)
    times["image build"] = time.monotonic() - t0
    if before and before != image_id(IMAGE):  # the former build's 430 MB of installed packages, untagged now
        docker("image", "rm", before, check=False)
    _built.append(IMAGE)
    return IMAGE


def image_id(tag: str) -> str:
    """The image id of ``tag``; "" when there is none."""
    return run(["docker", "image", "inspect", "--format", "{{.Id}}", tag], timeout=60, what="docker image inspect",
               check=False).stdout.decode().strip()


def print_times(config, title: str, times: dict[str, float], notes: list[str] | None = None) -> None:
    """``times`` (step: seconds) and ``notes`` (lines) written to the test session's report (also under -q and
    without -s)."""
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    capture = config.pluginmanager.get_plugin("capturemanager")
    lines = [f"{title} step {name}: {seconds:.1f} s" for name, seconds in times.items()]
    lines += [f"{title}: {note}" for note in notes or []]
    if reporter is None:
        print("\n".join(lines))
        return
    with capture.global_and_fixture_disabled() if capture else contextlib.nullcontext():
        reporter.write_line("")
        for line in lines:
            reporter.write_line(line)


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
        #: Every volume seen mounted in the project's containers (named or anonymous), for :meth:`resources`.
        self.volumes_seen: set[str] = set()

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

    def address(self, service: str, index: int = 0) -> str:
        """The IP address of ``service``'s container number ``index`` on the project's default network (reached from
        the host through the engine's bridge: a replica addressed directly, past the proxy)."""
        info = json.loads(docker("inspect", self.containers(service)[index], timeout=60))[0]
        return info["NetworkSettings"]["Networks"][f"{self.project}_default"]["IPAddress"]

    def _note_volumes(self) -> None:
        label = f"label=com.docker.compose.project={self.project}"
        ids = docker("ps", "--all", "--quiet", "--filter", label, timeout=60).split()
        if ids:
            for info in json.loads(docker("inspect", *ids, timeout=60)):
                self.volumes_seen.update(m["Name"] for m in info["Mounts"] if m["Type"] == "volume")

    def exec(self, service: str, *args: str, timeout: float = 120.0) -> str:
        """``args`` run in ``service``'s container (no terminal); its standard output."""
        return self.compose("exec", "-T", service, *args, timeout=timeout)

    def logs(self, service: str | None = None) -> str:
        out = self.compose("logs", "--no-color", "--tail", "60", *([service] if service else []), timeout=60,
                           check=False)
        return out[-6000:]

    def resources(self) -> dict[str, list[str]]:
        """The project's containers, networks and volumes left on the engine (by Compose's project label, and the
        volumes its containers were seen to mount before :meth:`down`)."""
        label = f"label=com.docker.compose.project={self.project}"
        left = {kind: docker(*cmd, "--filter", label, "--quiet", timeout=60).split()
                for kind, cmd in (("containers", ("ps", "--all")), ("networks", ("network", "ls")),
                                  ("volumes", ("volume", "ls")))}
        every = set(docker("volume", "ls", "--quiet", timeout=60).split())
        left["volumes"] = sorted(set(left["volumes"]) | (self.volumes_seen & every))
        return left

    def down(self) -> None:
        """Containers stopped and removed with the project's networks and volumes (the anonymous ones too)."""
        self._note_volumes()
        self.compose("down", "--volumes", "--remove-orphans", "--timeout", "10", timeout=300)
