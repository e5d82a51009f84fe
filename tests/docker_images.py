"""The Docker engine and images for the ``docker`` tests, on a machine that reaches no container registry.

``FROM python:3.11-slim`` cannot be pulled here, nor ``redis:7``, ``postgres:15`` or ``nginx``: this module builds
stand-ins from Debian's packages and the tests pass them in (the Dockerfile's ``BASE`` argument, the compose files'
``PLANNER_*_IMAGE`` variables; the defaults stay the official images for users):

================================  =================================================================================
``planner-test-debian:bookworm``  ``debootstrap --variant=minbase bookworm``, ``docker import``-ed, with the host's
                                  CA bundle (the builds reach Debian's mirrors and PyPI through the host's own trust
                                  store; this test base is the only image that gets it, docker/Dockerfile never)
``planner-test-python:3.11``      + python3.11 and its headers, a venv first on PATH (docker/local/python.Dockerfile)
``planner-test-redis:7``          + redis-server 7.0 (docker/local/redis.Dockerfile)
``planner-test-postgres:15``      + postgresql-15 and an entrypoint with the official image's variables
``planner-test-nginx:1.22``       + nginx (docker/local/nginx.Dockerfile)
================================  =================================================================================

Each is built only when its tag is absent and a test asks for it, so one machine builds them once (``--rebuild`` to
start over); a file lock keeps two test sessions from building at once. Nothing here skips: without an engine,
debootstrap or root the helpers raise AssertionError naming what to install or start (``./run test`` installs
docker.io, debootstrap and docker-compose and starts dockerd when none answers).

``python tests/docker_images.py [--rebuild]`` builds what is missing and prints the time each step took.
"""

from __future__ import annotations

import argparse
import fcntl
import os
import shutil
import ssl
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOCAL = ROOT / "docker" / "local"
SUITE = "bookworm"
MIRROR = os.environ.get("PLANNER_DEBIAN_MIRROR", "http://deb.debian.org/debian")

DEBIAN = "planner-test-debian:bookworm"
PYTHON = "planner-test-python:3.11"
REDIS = "planner-test-redis:7"
POSTGRES = "planner-test-postgres:15"
NGINX = "planner-test-nginx:1.22"
#: The images built FROM the Debian base: tag -> its Dockerfile under docker/local.
DERIVED = {PYTHON: "python.Dockerfile", REDIS: "redis.Dockerfile", POSTGRES: "postgres.Dockerfile",
           NGINX: "nginx.Dockerfile"}

INSTALL = "apt-get install -y docker.io debootstrap docker-compose, and start dockerd (./run test does both)"


def run(args: list[str], *, timeout: float, what: str, input: bytes | None = None, check: bool = True,
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """``args`` run to its end (with the environment ``env``, else ours), its output captured; AssertionError naming
    ``what`` and the output's tail when it fails (``check``) or outlives ``timeout`` seconds."""
    try:
        r = subprocess.run(args, input=input, capture_output=True, timeout=timeout, env=env)
    except FileNotFoundError:
        raise AssertionError(f"{what}: {args[0]} is not installed: {INSTALL}") from None
    except subprocess.TimeoutExpired as e:
        tail = ((e.stdout or b"") + (e.stderr or b""))[-3000:].decode(errors="replace")
        raise AssertionError(f"{what}: not done in {timeout:.0f} s ({' '.join(args[:4])} ...)\n{tail}") from None
    if check and r.returncode != 0:
        tail = (r.stdout + r.stderr)[-4000:].decode(errors="replace")
        raise AssertionError(f"{what} failed ({r.returncode}): {' '.join(args[:6])} ...\n{tail}")
    return r


def docker(*args: str, timeout: float = 120.0, what: str = "docker", check: bool = True,
           input: bytes | None = None) -> str:
    """``docker ARGS``; its standard output as text."""
    return run(["docker", *args], timeout=timeout, what=what, check=check, input=input).stdout.decode()


def require_engine() -> None:
    """AssertionError unless a Docker engine answers ``docker info``."""
    r = run(["docker", "info", "--format", "{{.ServerVersion}}"], timeout=60, what="docker info", check=False)
    if r.returncode != 0 or not r.stdout.strip():
        raise AssertionError(f"no Docker engine answers `docker info`: {r.stderr.decode(errors='replace').strip()}; "
                             f"{INSTALL}")


def image_exists(tag: str) -> bool:
    r = run(["docker", "image", "inspect", tag], timeout=60, what="docker image inspect", check=False)
    return r.returncode == 0


def host_ca_bundle() -> Path:
    """The host's CA bundle: the file Python's ssl verifies with (SSL_CERT_FILE, else OpenSSL's default file:
    Debian's /etc/ssl/certs/ca-certificates.crt)."""
    paths = ssl.get_default_verify_paths()
    bundle = Path(paths.cafile or paths.openssl_cafile).resolve()
    if not bundle.is_file():
        raise AssertionError(f"the host has no CA bundle at {bundle} (OpenSSL's default file): "
                             "apt-get install -y ca-certificates")
    return bundle


def compose_command() -> list[str]:
    """Compose: ``docker-compose`` (Debian's 1.29) when installed, else Compose v2's ``docker compose``."""
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    if run(["docker", "compose", "version"], timeout=60, what="docker compose", check=False).returncode == 0:
        return ["docker", "compose"]
    raise AssertionError(f"neither docker-compose nor `docker compose` is installed: {INSTALL}")


@contextmanager
def _lock() -> Iterator[None]:
    """One builder at a time on this machine (other sessions wait, then find the tags)."""
    path = Path(tempfile.gettempdir()) / "planner-test-images.lock"
    with open(path, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def build_debian(tag: str = DEBIAN) -> None:
    """``debootstrap --variant=minbase bookworm`` in a temporary folder, imported as ``tag`` (:func:`import_rootfs`)."""
    if os.geteuid() != 0:
        raise AssertionError("debootstrap needs root (the test command runs as root, as in CI)")
    if shutil.which("debootstrap") is None:
        raise AssertionError(f"debootstrap is not installed: {INSTALL}")
    with tempfile.TemporaryDirectory(prefix="planner-debootstrap-", dir="/var/tmp") as tmp:
        rootfs = Path(tmp) / "rootfs"
        run(["debootstrap", "--variant=minbase", SUITE, str(rootfs), MIRROR], timeout=1800,
            what=f"debootstrap of {SUITE} from {MIRROR}")
        import_rootfs(rootfs, tag)


def import_rootfs(rootfs: Path, tag: str = DEBIAN) -> None:
    """The debootstrapped ``rootfs`` with the host's CA bundle added (also as a local certificate, so that an
    update-ca-certificates in a derived image keeps it, and as pip's ``cert``), apt kept from installing recommended
    packages and its caches emptied, ``docker import``-ed as ``tag``."""
    bundle = host_ca_bundle()
    for cache in ("var/cache/apt/archives", "var/lib/apt/lists"):
        for f in (rootfs / cache).glob("*"):
            if f.is_file():
                f.unlink()
    (rootfs / "etc/ssl/certs").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(bundle, rootfs / "etc/ssl/certs/ca-certificates.crt")
    (rootfs / "usr/local/share/ca-certificates").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(bundle, rootfs / "usr/local/share/ca-certificates/host-trust-store.crt")
    (rootfs / "etc/pip.conf").write_text("[global]\ncert = /etc/ssl/certs/ca-certificates.crt\n")
    (rootfs / "etc/apt/apt.conf.d/90no-recommends").write_text(
        'APT::Install-Recommends "false";\nAPT::Install-Suggests "false";\n')
    tar = subprocess.Popen(["tar", "-C", str(rootfs), "--numeric-owner", "-c", "."], stdout=subprocess.PIPE)
    try:
        r = subprocess.run(["docker", "import", "--change", 'CMD ["bash"]', "--change", "ENV LANG=C.UTF-8", "-", tag],
                           stdin=tar.stdout, capture_output=True, timeout=900)
    finally:
        if tar.stdout:
            tar.stdout.close()
        tar.wait(60)
    if r.returncode != 0 or tar.returncode != 0:
        raise AssertionError(f"docker import of {rootfs} as {tag} failed (tar {tar.returncode}, docker import "
                             f"{r.returncode}): {r.stderr.decode(errors='replace')[-2000:]}")


def build_derived(tag: str) -> None:
    """``tag`` built from its Dockerfile under docker/local, FROM the Debian base."""
    docker("build", "--tag", tag, "--file", str(LOCAL / DERIVED[tag]), "--build-arg", f"DEBIAN={DEBIAN}", str(LOCAL),
           timeout=1800, what=f"the build of {tag}")


def ensure_test_images(tags: tuple[str, ...] = tuple(DERIVED), rebuild: bool = False) -> dict[str, float]:
    """The Debian base and the stand-ins ``tags`` (all by default), each built when its tag is absent (every one of
    them with ``rebuild``): {tag: seconds spent building it in this call (0.0 when it was there)}."""
    require_engine()
    spent: dict[str, float] = {}
    with _lock():
        for tag in (DEBIAN, *tags):
            t0 = time.monotonic()
            if rebuild or not image_exists(tag):
                build_debian(tag) if tag == DEBIAN else build_derived(tag)
            spent[tag] = time.monotonic() - t0
    return spent


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Build the tests' stand-in images from Debian's packages.")
    parser.add_argument("--rebuild", action="store_true", help="build every image again, even when its tag exists")
    args = parser.parse_args(argv)
    spent = ensure_test_images(rebuild=args.rebuild)
    print(f"{'image':32} {'seconds':>8}")
    for tag, seconds in spent.items():
        print(f"{tag:32} {seconds:8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
