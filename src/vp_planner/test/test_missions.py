"""Missions (vp_planner.missions, ``vp_planner.cli mission``): every exported .plan read back by a
real MAVLink implementation, MAVSDK (its QGroundControl import, then an upload to a loopback
autopilot, MAVSDK's mission_raw_server), against the plan: waypoints, headings, gimbal pitches.
Nothing here parses a .plan with code of its own."""
from __future__ import annotations

import json
import math
import socket
import threading
import xml.etree.ElementTree as ET

import numpy as np
import pymap3d
import pytest

from vp_planner import cli
from vp_scene.planfile import write_plan

ORIGIN = (47.397742, 8.545594, 488.0)
YAW = 0.4  # rad: the map's x from east


class Autopilot:
    """A loopback MAVLink pair: MAVSDK as ground station and MAVSDK's mission_raw_server as the
    vehicle; :meth:`load` imports a .plan on the ground and returns the items the vehicle received."""

    def __init__(self) -> None:
        from mavsdk import ComponentType, Configuration, Mavsdk
        from mavsdk.plugins.mission_raw import MissionRaw
        from mavsdk.plugins.mission_raw_server import MissionRawServer

        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.vehicle = Mavsdk(Configuration.create_with_component_type(ComponentType.AUTOPILOT))
        assert int(self.vehicle.add_any_connection(f"udpin://127.0.0.1:{port}")) == 0
        self.server = MissionRawServer(self.vehicle.server_component())
        self._got, self._event = [], threading.Event()
        self.server.subscribe_incoming_mission(self._incoming)
        self.ground = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        assert int(self.ground.add_any_connection(f"udpout://127.0.0.1:{port}")) == 0
        system = self.ground.first_autopilot(20.0)
        assert system is not None, "the loopback autopilot was not discovered"
        self.mission = MissionRaw(system)

    def _incoming(self, result, plan, _user) -> None:
        self._got.append(plan.mission_items)
        self._event.set()

    def load(self, path) -> list:
        data = self.mission.import_qgroundcontrol_mission(str(path))
        self._event.clear()
        self.mission.upload_mission(data.mission_items)
        assert self._event.wait(20.0), "the autopilot received no mission"
        return self._got[-1]

    def close(self) -> None:
        self.ground.destroy()
        self.vehicle.destroy()


@pytest.fixture(scope="module")
def autopilot():
    pilot = Autopilot()
    yield pilot
    pilot.close()


def _plan(tmp_path, cameras):
    return write_plan(tmp_path / "plan.json", {"cameras": np.asarray(cameras).tolist()})


CAMERAS = np.array([[2.0, 0.0, 1.5, -2.0, 0.0, -1.0], [0.0, 2.0, 1.2, 0.0, -2.0, -0.7],
                    [-2.0, 0.0, 1.8, 2.0, 0.0, -1.3], [0.0, -2.0, 1.0, 0.0, 2.0, -0.2],
                    [1.4, 1.4, 2.5, -1.4, -1.4, -2.0], [-1.4, 1.4, 2.2, 1.4, -1.4, -1.5],
                    [-1.4, -1.4, 0.9, 1.4, 1.4, 0.1], [1.4, -1.4, 3.0, -1.4, 1.4, -3.0]])


def _expected(cameras):
    """Each view's latitude, longitude, height above the ground, heading and pitch at its own
    point, from pymap3d and the plan alone."""
    c, s = math.cos(YAW), math.sin(YAW)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    enu, d = cameras[:, :3] @ rot.T, cameras[:, 3:] @ rot.T
    lat, lon, _ = pymap3d.enu2geodetic(enu[:, 0], enu[:, 1], enu[:, 2], *ORIGIN)
    u, v, w = pymap3d.enu2uvw(d[:, 0], d[:, 1], d[:, 2], ORIGIN[0], ORIGIN[1])
    e, n, up = pymap3d.uvw2enu(u, v, w, lat, lon)
    heading = np.mod(np.degrees(np.arctan2(e, n)), 360.0)
    pitch = np.degrees(np.arctan2(up, np.hypot(e, n)))
    return np.column_stack([lat, lon, cameras[:, 2], heading, pitch])


def _f32(x) -> float:
    return float(np.float32(x))


def test_every_mission_is_what_the_plan_says(tmp_path, autopilot, capsys):
    out = tmp_path / "missions"
    code = cli.main(["mission", "--plan", str(_plan(tmp_path, CAMERAS)), "--drones", "3", "--origin",
                     ",".join(map(str, ORIGIN)), "--map-yaw", str(YAW), "--out", str(out), "--hover-s", "3"])
    assert code == 0, capsys.readouterr().err
    fleet = json.loads((out / "fleet.json").read_text())
    want = _expected(CAMERAS)
    plans = sorted(out.glob("*.plan"))
    assert [p.stem for p in plans] == [fleet["drones"][r["drone"]] for r in fleet["routes"] if r["views"]]
    seen = []
    for path in plans:
        items = autopilot.load(path)
        cmds = [it.command for it in items]
        assert cmds[:2] == [178, 22] and cmds[-1] == 20 and items[0].param2 == pytest.approx(5.0)
        for k, it in enumerate(items):
            if it.command != 2000:
                continue
            gimbal, wp = items[k - 2], items[k - 1]
            assert (gimbal.command, wp.command, wp.frame) == (1000, 16, 3) and it.param3 == 1.0  # one image
            lat, lon, alt = wp.x * 1e-7, wp.y * 1e-7, wp.z
            match = np.flatnonzero((np.abs(want[:, 0] - lat) < 1e-6) & (np.abs(want[:, 1] - lon) < 1e-6))
            assert len(match) == 1, (lat, lon)
            i = int(match[0])
            seen.append(i)
            # 1e-7 degree integers: within 0.56 cm; the height above the home within 1 cm
            assert abs(lat - want[i, 0]) <= 0.51e-7 and abs(lon - want[i, 1]) <= 0.51e-7
            assert abs(alt - want[i, 2]) < 0.01
            assert wp.param4 == _f32(want[i, 3]) and gimbal.param1 == _f32(want[i, 4])  # the float32 params
            assert wp.param1 == pytest.approx(3.0, abs=1e-4) or wp.param1 > 3.0  # the hover (and any wait)
        takeoff = items[1]
        assert takeoff.z > 0 and math.isnan(takeoff.param4)
    assert sorted(seen) == list(range(len(CAMERAS)))
    kml = ET.parse(out / "fleet.kml").getroot()
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    assert len(kml.findall(".//k:LineString", ns)) == len(plans)
    assert len(kml.findall(".//k:Point", ns)) == len(CAMERAS)
    assert "time on site" in capsys.readouterr().err


@pytest.mark.parametrize("flags, code", [
    (["--origin", "95,8.5,488"], "INVALID_ORIGIN"),
    (["--origin", "nan,8.5,488"], "INVALID_ORIGIN"),
    (["--flight-time-s", "8"], "DOES_NOT_FIT"),
    (["--cruise-speed", "0"], "INVALID_FLIGHT_MODEL"),
])
def test_bad_requests_are_one_line_with_their_code(tmp_path, capsys, flags, code):
    plan = _plan(tmp_path, CAMERAS)
    argv = ["mission", "--plan", str(plan), "--drones", "2", "--origin", "47.4,8.5,488", "--out",
            str(tmp_path / "m")] + flags
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"[{code}]" in err, err
    if code == "DOES_NOT_FIT":
        assert " s short" in err
    assert not (tmp_path / "m").exists()  # nothing written
