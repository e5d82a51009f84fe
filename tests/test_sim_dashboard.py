"""The simulated controller's dashboard server (29999) through ur_rtde's DashboardClient and a raw socket."""

from __future__ import annotations

import socket
import time

import dashboard_client
import pytest
import rtde_control
import rtde_receive

from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture


def _raw(host: str, *lines: str) -> list[str]:
    with socket.create_connection((host, 29999), timeout=3) as s:
        f = s.makefile("rw", newline="\n")
        replies = [f.readline().rstrip("\n")]
        for line in lines:
            f.write(line + "\n")
            f.flush()
            replies.append(f.readline().rstrip("\n"))
        return replies


def test_dashboard_replies(make_sim):
    sim = make_sim()
    d = dashboard_client.DashboardClient(sim.host)
    d.connect()
    try:
        assert d.isConnected()
        assert d.polyscopeVersion() == "5.11.6.108949"
        assert d.getSerialNumber().isdigit() and d.isInRemoteControl()
        assert d.robotmode() == "Robotmode: RUNNING"
        assert d.safetymode() == "Safetymode: NORMAL" and d.safetystatus() == "Safetystatus: NORMAL"
        assert d.getRobotModel() == "UR5"
        assert not d.running() and d.programState().startswith("STOPPED")
        d.closeSafetyPopup()
        d.closePopup()
        d.popup("hello")
        d.unlockProtectiveStop()  # nothing to unlock: still the controller's answer
        with pytest.raises(Exception, match="File not found"):
            d.loadURP("missing.urp")
        with pytest.raises(Exception, match="Failed to execute: play"):
            d.play()
        d.stop()  # "Stopped" even with nothing running
        # power cycle: the modes follow, and a program cannot start while powered off
        d.powerOff()
        assert d.robotmode() == "Robotmode: POWER_OFF"
        r = rtde_receive.RTDEReceiveInterface(sim.host)
        time.sleep(0.01)
        assert r.getRobotMode() == 3 and not r.getRobotStatus() & 1
        d.powerOn()
        assert d.robotmode() == "Robotmode: IDLE"
        d.brakeRelease()
        assert d.robotmode() == "Robotmode: RUNNING"
        time.sleep(0.01)  # the next data package
        assert r.getRobotMode() == 7
        r.disconnect()
    finally:
        d.disconnect()


def test_dashboard_controls_the_running_program(make_sim):
    sim = make_sim()
    c = rtde_control.RTDEControlInterface(sim.host)
    d = dashboard_client.DashboardClient(sim.host)
    d.connect()
    try:
        assert d.running() and d.programState() == "PLAYING rtde_control"
        d.pause()
        assert d.programState() == "PAUSED rtde_control"
        d.play()
        assert d.running()
        d.stop()
        time.sleep(0.05)
        assert not d.running() and not c.isProgramRunning()
    finally:
        c.disconnect()
        d.disconnect()


def test_raw_dashboard_lines(make_sim):
    sim = make_sim()
    replies = _raw(sim.host, "PolyscopeVersion", "is in remote control", "get loaded program", "version",
                   "no such command", "addToLog hello", "isProgramSaved", "quit")
    assert replies[0] == "Connected: Universal Robots Dashboard Server"
    assert replies[1].startswith("URSoftware 5.11.6.108949")
    assert replies[2:5] == ["true", "No program loaded", "5.11.6.108949"]
    assert replies[5] == "could not understand: 'no such command'"
    assert replies[6] == "Added log message"
    assert replies[7].startswith("true")
    assert replies[8] == "Disconnected"
