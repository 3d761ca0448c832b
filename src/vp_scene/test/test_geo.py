"""The field's geographic origin (vp_scene.geo): validated once, the map <-> geodetic round trip,
the map's yaw from east, compass headings and pitches at the points."""
import math

import numpy as np
import pymap3d
import pytest

from vp_scene.geo import GeoError, GeoOrigin


@pytest.mark.parametrize("args, text", [
    ((91.0, 8.0, 400.0), "origin latitude must be in [-90, 90] deg, got 91.0"),
    ((math.nan, 8.0, 400.0), "origin latitude must be in [-90, 90] deg, got nan"),
    ((47.0, -180.5, 400.0), "origin longitude must be in [-180, 180] deg, got -180.5"),
    ((47.0, 8.0, math.inf), "origin height must be in [-1000, 10000] m, got inf"),
])
def test_bad_origins_are_one_line_with_their_code(args, text):
    with pytest.raises(GeoError) as err:
        GeoOrigin(*args)
    assert err.value.code == "INVALID_ORIGIN" and str(err.value) == f"[INVALID_ORIGIN] {text}"


def test_parse():
    assert GeoOrigin.parse("47.5, 8.25,420", yaw=0.1) == GeoOrigin(47.5, 8.25, 420.0, 0.1)
    for text in ("47.5,8.25", "a,b,c", "95,0,0"):
        with pytest.raises(GeoError) as err:
            GeoOrigin.parse(text)
        assert err.value.code == "INVALID_ORIGIN" and "\n" not in str(err.value)


def test_map_is_enu_turned_by_the_yaw():
    origin = GeoOrigin(47.3977, 8.5456, 488.0, yaw=math.pi / 2)  # map x points north
    p = np.array([[10.0, 0.0, 2.0], [0.0, 10.0, 0.0], [3.0, -4.0, 1.0]])
    geo = origin.to_geodetic(p)
    lat, lon, h = pymap3d.enu2geodetic(0.0, 10.0, 2.0, 47.3977, 8.5456, 488.0)  # 10 m north, 2 m up
    assert geo[0].tolist() == pytest.approx([lat, lon, h], abs=1e-12)
    assert geo[1, 1] < 8.5456 and geo[1, 0] == pytest.approx(47.3977, abs=1e-6)  # map y is west
    np.testing.assert_allclose(origin.to_map(geo), p, atol=1e-8)
    assert GeoOrigin(0, 0, 0).to_geodetic([1.0, 0.0, 0.0])[1] == pytest.approx(1 / 111319.49, rel=1e-6)


def test_headings_and_pitches():
    for yaw, heading in ((0.0, 90.0), (math.pi / 2, 0.0), (math.pi, 270.0)):
        h, pitch = GeoOrigin(47.0, 8.0, 400.0, yaw).heading_pitch([0, 0, 2], [1.0, 0.0, -1.0])
        assert float(h) == pytest.approx(heading, abs=1e-9) and float(pitch) == pytest.approx(-45.0, abs=1e-9)
    # 100 m east at 45 degrees: north there is turned from the origin's by the meridians' convergence
    h, _ = GeoOrigin(45.0, 8.0, 0.0).heading_pitch([100.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    dlon = 100.0 / (111319.49 * math.cos(math.radians(45.0)))
    assert float(h) == pytest.approx(dlon * math.sin(math.radians(45.0)), abs=2e-5)  # the pole lies west of it
