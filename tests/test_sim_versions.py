"""The controller's PolyScope version as a setting: refused when the simulator cannot be it, reported alike on every
interface, and deciding what the controller has (RTDE fields, dashboard commands, the real-time package), checked with
raw sockets and with ur_rtde as a user runs it against a PolyScope 5.4 controller.
"""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
import time

import numpy as np
import pytest
import rtde_control
import rtde_receive

from sim import SimController
from sim.motion import HOME
from sim.versions import parse_polyscope
from tests import sim_fixtures
from tests.sim_fixtures import RawRTDE

make_sim = sim_fixtures.make_sim  # fixture


@pytest.mark.parametrize(("text", "says"), [
    ("3.15.8", "3.15.8.0 is a CB3 controller's version"),
    ("10.7.0", "10.7.0.0 is PolyScope X"),
    ("4.1.0", "no PolyScope release"),
    ("5.27.0", "newer than 5.26.0, the newest release whose RTDE fields the simulator knows"),
    ("5.x", "give a PolyScope 5 version such as 5.11.6"),
    ("", "give a PolyScope 5 version"),
    ("5.4.0.99999999999", "build number 99999999999 does not fit"),
    ("5.4.4294967296", "bugfix number 4294967296 does not fit"),
])
def test_a_version_the_simulator_cannot_be_is_refused_in_one_line(text, says):
    with pytest.raises(ValueError, match="^polyscope: ") as exc:
        SimController("127.0.0.2", polyscope=text)
    assert says in str(exc.value) and "\n" not in str(exc.value)
    # the command line says the same on one line, and starts nothing
    done = subprocess.run([sys.executable, "-m", "sim", "--polyscope", text], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip().splitlines() == [f"error: {exc.value}"]


def test_versions_are_read_as_written_and_take_the_known_build():
    assert parse_polyscope("5.4.0").words == (5, 4, 0, 0)
    assert parse_polyscope("5.4").words == (5, 4, 0, 0)
    assert parse_polyscope(" 5.9.4.1234 ").words == (5, 9, 4, 1234)
    assert parse_polyscope("5.11.6").words == (5, 11, 6, 108949)  # the build the simulator always reported
    assert parse_polyscope("5.11.6").polyscope_text == "URSoftware 5.11.6.108949 (Jul 27 2021)"
    assert parse_polyscope("5.4.0").polyscope_text == "URSoftware 5.4.0.0 (build date unknown)"
    assert parse_polyscope("5.26.0").at_least((5, 26, 0)) and not parse_polyscope("5.25.9").at_least((5, 26, 0))


def test_local_control_needs_polyscope_56():
    with pytest.raises(ValueError, match=r"^remote_control: PolyScope 5\.5\.1\.0 has no local control mode"):
        SimController("127.0.0.2", polyscope="5.5.1", remote_control=False)
    SimController("127.0.0.2", polyscope="5.6.0", remote_control=False)  # not started: only checked


def _dashboard(host: str, commands: list[str]) -> list[str]:
    with socket.create_connection((host, 29999), timeout=5.0) as s:
        f = s.makefile("rwb")
        replies = [f.readline().decode().strip()]
        for cmd in commands:
            f.write(cmd.encode() + b"\n")
            f.flush()
            replies.append(f.readline().decode().strip())
    return replies[1:]


def _first_package(host: str, port: int) -> bytes:
    """The first whole package a primary (int32 size, uint8 type ...) or real-time (int32 size ...) client gets."""
    with socket.create_connection((host, port), timeout=5.0) as s:
        buf = b""
        while len(buf) < 4 or len(buf) < struct.unpack_from(">i", buf)[0]:
            chunk = s.recv(65536)
            assert chunk, "connection closed"
            buf += chunk
    return buf[: struct.unpack_from(">i", buf)[0]]


def test_a_54_controller_reports_54_everywhere_and_has_what_54_has(make_sim):
    sim = make_sim(polyscope="5.4.0")
    assert sim.version.words == (5, 4, 0, 0)
    # RTDE
    raw = RawRTDE(sim.host)
    try:
        raw.send("V", struct.pack(">H", 2))
        assert raw.recv() == ("V", b"\x01")
        raw.send("v")
        kind, payload = raw.recv()
        assert kind == "v" and struct.unpack(">IIII", payload) == (5, 4, 0, 0)
        # tcp_offset came with 5.5.1: refused, as an unknown name; safety_status (5.4.0) is there
        raw.send("O", struct.pack(">d", 125.0) + b"timestamp,tcp_offset")
        assert raw.recv() == ("O", b"\x00DOUBLE,NOT_FOUND")
        raw.send("O", struct.pack(">d", 125.0) + b"timestamp,safety_status")
        assert raw.recv() == ("O", b"\x01DOUBLE,INT32")
        # the upper input registers (5.3) are there
        raw.send("I", b"input_int_register_24")
        assert raw.recv() == ("I", b"\x01INT32")
    finally:
        raw.close()
    # the dashboard: its version, and the commands 5.4 has (safetystatus) and has not (is in remote control: 5.6)
    assert _dashboard(sim.host, ["PolyscopeVersion", "version", "safetystatus", "is in remote control",
                                 "get serial number"]) == [
        "URSoftware 5.4.0.0 (build date unknown)", "5.4.0.0", "Safetystatus: NORMAL",
        "could not understand: 'is in remote control'", "could not understand: 'get serial number'"]
    # the primary interface's version message: URControl 5.4.0, build 0
    pkg = _first_package(sim.host, 30001)
    assert pkg[4] == 20 and pkg[4 + 1 + 8 + 1] == 3  # robot message (uint64 time, int8 source), version
    body = pkg[4 + 1 + 8 + 1 + 1 :]
    n = body[0]
    assert body[1 : 1 + n] == b"URControl"
    assert struct.unpack_from(">BBii", body, 1 + n) == (5, 4, 0, 0)
    assert body[1 + n + 10 :] == b"unknown"
    # the real-time interface sends 5.4's package: 1116 bytes, the 5.10 package's first 1116
    rt = _first_package(sim.host, 30003)
    assert len(rt) == struct.unpack_from(">i", rt)[0] == 1116


def test_the_default_controller_is_511_with_its_1220_byte_real_time_package(make_sim):
    sim = make_sim()
    assert sim.version.text == "5.11.6.108949"
    rt = _first_package(sim.host, 30003)
    assert len(rt) == 1220
    assert _dashboard(sim.host, ["is in remote control"]) == ["true"]


def test_ur_rtde_against_a_54_controller_builds_its_54_recipe_and_moves(make_sim):
    """ur_rtde asks the controller's version before building its recipes: against 5.4 its receive interface leaves out
    payload (5.5.1), ft_raw_wrench (5.9) and payload_inertia (5.11) and works; a recipe naming a newer field fails
    as against a real 5.4 controller; the control interface uploads its script and moves."""
    sim = make_sim(polyscope="5.4.0")
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    try:
        t0 = r.getTimestamp()
        time.sleep(0.2)
        assert r.getTimestamp() > t0
        np.testing.assert_allclose(r.getActualQ(), HOME, atol=1e-9)
        assert r.getSafetyMode() == 1
        for getter in (r.getFtRawWrench, r.getPayload):  # left out of ur_rtde's 5.4 recipe
            with pytest.raises(RuntimeError, match="unable to get state data for specified key: (ft_raw_wrench|payload)"):
                getter()
    finally:
        r.disconnect()
    with pytest.raises(RuntimeError, match=r"not found by the controller: \[payload\]"):
        rtde_receive.RTDEReceiveInterface(sim.host, 500.0, ["timestamp", "payload"])
    c = rtde_control.RTDEControlInterface(sim.host)
    try:
        target = (HOME + np.array([0.2, -0.1, 0.1, 0.0, 0.0, 0.3])).tolist()
        assert c.moveJ(target, 1.0, 4.0)
        r = rtde_receive.RTDEReceiveInterface(sim.host, 125.0, ["timestamp", "actual_q"])
        try:
            np.testing.assert_allclose(r.getActualQ(), target, atol=1e-6)
        finally:
            r.disconnect()
        c.stopScript()
    finally:
        c.disconnect()
