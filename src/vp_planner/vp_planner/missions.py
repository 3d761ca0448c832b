"""Missions an autopilot accepts: each drone's route as a QGroundControl plan, the fleet's routes as
KML (ROS-free; ``python -m vp_planner.cli mission`` and the dispatcher write them).

A drone's ``.plan`` (QGroundControl's JSON plan file: ``fileType`` Plan, ``mission.items`` of
SimpleItems, each a MAVLink mission item: ``command``, ``frame``, ``params[7]`` with latitude,
longitude and altitude in params 5-7) flies its timed route (:mod:`vp_planner.routes`):

1. ``MAV_CMD_DO_CHANGE_SPEED`` (178): the ground speed of the flight model;
2. ``MAV_CMD_NAV_TAKEOFF`` (22) above the home, to the route's first altitude;
3. per view, in the route's order: ``MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW`` (1000) with the view's
   pitch (degrees, positive up; yaw 0 relative to the vehicle), executed as the drone leaves the
   previous waypoint so the gimbal turns on the way; ``MAV_CMD_NAV_WAYPOINT`` (16) at the view,
   holding its hover (and any wait of the separation) and facing the view's heading (degrees, 0
   north, clockwise); ``MAV_CMD_IMAGE_START_CAPTURE`` (2000), one image, once the hold is over;
   the corners of a leg over the plants are waypoints without a heading, holding their waits;
4. ``MAV_CMD_NAV_RETURN_TO_LAUNCH`` (20) from above the home: the autopilot descends and lands.

Positions come from the field's origin (:class:`vp_scene.geo.GeoOrigin`); navigation items use
``MAV_FRAME_GLOBAL_RELATIVE_ALT`` (3): altitudes above the drone's home, its take-off point.
``plannedHomePosition`` carries the home's ellipsoidal height (QGroundControl shows it as AMSL:
subtract the geoid's undulation there to read it so). A MAVLink mission item holds latitude and
longitude as integers of 1e-7 degree (under 1.1 cm) and its params as 32-bit floats: the
headings and pitches arrive rounded to those.

``fleet.kml``: one path per drone (its route, heights above the ground) and a point per view;
``fleet.json``: the origin, the drones' names and the routes' record (``FleetRoutes.to_dict``).
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from vp_scene.geo import GeoOrigin

from .routes import FleetRoutes, FlightModel, Route

__all__ = ["NAV_WAYPOINT", "NAV_RETURN_TO_LAUNCH", "NAV_TAKEOFF", "DO_CHANGE_SPEED", "DO_GIMBAL_MANAGER_PITCHYAW",
           "IMAGE_START_CAPTURE", "MISSION_FILES", "mission_plan", "fleet_kml", "write_missions"]

NAV_WAYPOINT, NAV_RETURN_TO_LAUNCH, NAV_TAKEOFF = 16, 20, 22
DO_CHANGE_SPEED, DO_GIMBAL_MANAGER_PITCHYAW, IMAGE_START_CAPTURE = 178, 1000, 2000
_FRAME_MISSION, _FRAME_RELATIVE_ALT = 2, 3
#: The entries of a mission folder (fnmatch patterns): what ``--overwrite`` replaces together.
MISSION_FILES = ("*.plan", "fleet.kml", "fleet.json")
_KML = "http://www.opengis.net/kml/2.2"


def _item(command: int, frame: int, params: Sequence[float]) -> dict:
    return {"type": "SimpleItem", "command": int(command), "frame": int(frame), "autoContinue": True,
            "params": [None if isinstance(p, float) and math.isnan(p) else p for p in params]}


def mission_plan(route: Route, views: ArrayLike, origin: GeoOrigin, model: FlightModel) -> dict:
    """The QGroundControl plan (a dict to dump as JSON) of one drone's route (module docstring);
    ``views`` (N, 6) the plan's cameras in map."""
    cams = np.asarray(views, dtype=np.float64).reshape(-1, 6)
    home = route.points[0]
    geo = origin.to_geodetic(route.points)
    heading, pitch = origin.heading_pitch(cams[:, :3], cams[:, 3:]) if len(cams) else (np.zeros(0), np.zeros(0))
    rest = route.departure - route.arrival
    nan = math.nan
    items = [_item(DO_CHANGE_SPEED, _FRAME_MISSION, [1.0, model.cruise_speed, -1.0, 0.0, 0.0, 0.0, 0.0])]
    if len(route.views):
        items.append(_item(NAV_TAKEOFF, _FRAME_RELATIVE_ALT,
                           [0.0, 0.0, 0.0, nan, geo[1, 0], geo[1, 1], float(route.points[1, 2] - home[2])]))
        for k in range(2, len(route.points) - 1):
            lat, lon, alt = geo[k, 0], geo[k, 1], float(route.points[k, 2] - home[2])
            v = int(route.view_of_point[k])
            if v < 0:
                items.append(_item(NAV_WAYPOINT, _FRAME_RELATIVE_ALT, [float(rest[k]), 0.0, 0.0, nan, lat, lon, alt]))
                continue
            items.append(_item(DO_GIMBAL_MANAGER_PITCHYAW, _FRAME_MISSION,
                               [float(pitch[v]), 0.0, nan, nan, 0.0, 0.0, 0.0]))
            items.append(_item(NAV_WAYPOINT, _FRAME_RELATIVE_ALT,
                               [float(rest[k]), 0.0, 0.0, float(heading[v]), lat, lon, alt]))
            items.append(_item(IMAGE_START_CAPTURE, _FRAME_MISSION, [0.0, 0.0, 1.0, 0.0, nan, nan, nan]))
        items.append(_item(NAV_RETURN_TO_LAUNCH, _FRAME_MISSION, [0.0] * 7))
    for i, item in enumerate(items, 1):
        item["doJumpId"] = i
    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "geoFence": {"circles": [], "polygons": [], "version": 2},
            "rallyPoints": {"points": [], "version": 2},
            "mission": {"version": 2, "firmwareType": 0, "vehicleType": 2, "cruiseSpeed": model.cruise_speed,
                        "hoverSpeed": model.cruise_speed, "globalPlanAltitudeMode": 1,
                        "plannedHomePosition": [float(geo[0, 0]), float(geo[0, 1]), float(geo[0, 2])],
                        "items": items}}


def fleet_kml(fleet: FleetRoutes, names: Sequence[str], origin: GeoOrigin) -> str:
    """The fleet's routes as KML: a path per drone with views, a point per view (heights above the
    ground, map z)."""
    ET.register_namespace("", _KML)
    kml = ET.Element(f"{{{_KML}}}kml")
    doc = ET.SubElement(kml, f"{{{_KML}}}Document")
    ET.SubElement(doc, f"{{{_KML}}}name").text = "fleet"

    def coords(points: np.ndarray) -> str:
        geo = origin.to_geodetic(points)
        return " ".join(f"{lon:.9f},{lat:.9f},{z:.3f}" for (lat, lon, _), z in zip(geo, points[:, 2]))

    def placemark(name: str, text: str, kind: str, points: np.ndarray) -> None:
        mark = ET.SubElement(doc, f"{{{_KML}}}Placemark")
        ET.SubElement(mark, f"{{{_KML}}}name").text = name
        ET.SubElement(mark, f"{{{_KML}}}description").text = text
        shape = ET.SubElement(mark, f"{{{_KML}}}{kind}")
        ET.SubElement(shape, f"{{{_KML}}}altitudeMode").text = "relativeToGround"
        ET.SubElement(shape, f"{{{_KML}}}coordinates").text = coords(points)

    for r in fleet.routes:
        if not len(r.views):
            continue
        name = names[r.drone]
        placemark(name, f"{len(r.views)} views, {r.flight_time:.1f} s flight, {r.distance:.1f} m", "LineString", r.points)
        for k in np.flatnonzero(r.view_of_point >= 0):
            placemark(f"{name} view {int(r.view_of_point[k])}", f"arrival {r.arrival[k]:.1f} s", "Point", r.points[k][None])
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(kml, encoding="unicode") + "\n"


def write_missions(folder: Path, fleet: FleetRoutes, views: ArrayLike, names: Sequence[str],
                   origin: GeoOrigin) -> list[Path]:
    """``folder/<drone>.plan`` for every drone with views, ``folder/fleet.kml`` and
    ``folder/fleet.json``; the files written."""
    folder = Path(folder)
    out = []
    for r in fleet.routes:
        if len(r.views):
            path = folder / f"{names[r.drone]}.plan"
            path.write_text(json.dumps(mission_plan(r, views, origin, fleet.model), indent=1))
            out.append(path)
    (folder / "fleet.kml").write_text(fleet_kml(fleet, names, origin))
    record = {"origin": {"latitude": origin.latitude, "longitude": origin.longitude, "height": origin.height,
                         "yaw": origin.yaw}, "drones": list(names), **fleet.to_dict()}
    (folder / "fleet.json").write_text(json.dumps(record, indent=1))
    return out + [folder / "fleet.kml", folder / "fleet.json"]
