"""The bounds of a scene and of a seed (vp_scene.limits): every size that multiplies (plants x points
x realizations) is checked against its cap and the memory before anything is built, in one line."""
from __future__ import annotations

import argparse

import pytest

from vp_scene import build, limits
from vp_scene.build import build_noisy_scene, scene_shape
from vp_scene.limits import MAX_POINTS_PER_PLANT, MAX_REALIZATIONS, MAX_SEED, SceneTooLargeError, check_scene_size

GIB = 2 ** 30


@pytest.mark.parametrize("points, realizations, text", [
    (4000, MAX_REALIZATIONS + 1, f"realizations = {MAX_REALIZATIONS + 1} is above the bound of {MAX_REALIZATIONS}"),
    (10 ** 9, 5, f"points_per_plant = 1000000000 is above the bound of {MAX_POINTS_PER_PLANT}"),
    (0, 5, "points_per_plant must be an integer >= 1, got 0"),
    (4000, 2.5, "realizations must be an integer >= 1, got 2.5"),
    # within the caps, beyond the memory: the sizes, the need and the limit in one line
    (MAX_POINTS_PER_PLANT, MAX_REALIZATIONS, "a scene of 12 plant(s) x 1000000 points x 100 realizations would need "
                                             "about 181.7 GiB; 16.0 GiB are available and a request may take 80%"),
])
def test_a_scene_beyond_its_bounds_is_refused_in_one_line(points, realizations, text) -> None:
    with pytest.raises(SceneTooLargeError) as info:
        check_scene_size(12, points, realizations, available=16 * GIB)
    assert text in str(info.value) and "\n" not in str(info.value)


def test_the_default_scenes_fit() -> None:
    assert check_scene_size(12, 4000, 5, available=2 * GIB) == (4000, 5)  # row_12, the defaults, on 2 GiB


@pytest.mark.parametrize("scene", [
    {"scenario": "one_plant", "realizations": 100000},       # was never refused
    {"scenario": "one_plant", "points_per_plant": 10 ** 9},
    {"scenario": "row_12", "points_per_plant": MAX_POINTS_PER_PLANT, "realizations": MAX_REALIZATIONS},
])
def test_a_build_refuses_before_it_builds(scene, monkeypatch) -> None:
    """build_noisy_scene (the scene node's, the recon's and the CLIs' one way to a scene) and
    scene_shape check the sizes before a plant is made."""
    monkeypatch.setattr(limits, "available_memory", lambda: 16 * GIB)
    monkeypatch.setattr(build, "make_scene", lambda *a, **k: pytest.fail("the scene was built"))
    for call in (lambda: build_noisy_scene(**scene), lambda: scene_shape(scene)):
        with pytest.raises(SceneTooLargeError, match="above the bound|would need about"):
            call()


def test_scene_shape_is_the_shape_build_makes() -> None:
    scene = {"scenario": "three_row", "points_per_plant": 50, "realizations": 3, "seed": 2}
    noisy, _ = build_noisy_scene(**scene)
    assert scene_shape(scene) == noisy.points.shape[:2] == (3, 150)
    assert scene_shape({"scenario": "one_plant"}) == (5, 4000)  # build_noisy_scene's defaults


def test_memory_limit_names_the_need_and_the_limit() -> None:
    limits.check_memory_need(GIB, "this", available=2 * GIB)
    with pytest.raises(ValueError, match=r"^that would need about 2.0 GiB; 2.0 GiB are available and a request may "
                                         r"take 80% of them: a hint$"):
        limits.check_memory_need(2 * GIB, "that", available=2 * GIB, hint="a hint")


@pytest.mark.parametrize("value", [-1, MAX_SEED + 1, 2 ** 64, True, 1.0, "3"])
def test_seeds_outside_the_range_are_refused(value) -> None:
    with pytest.raises(ValueError, match=f"seed must be an integer from 0 to {MAX_SEED}"):
        limits.check_seed("seed", value)
    with pytest.raises(ValueError, match=f"seed must be an integer from 0 to {MAX_SEED}"):
        build_noisy_scene("one_plant", seed=value, points_per_plant=10, realizations=1)


def test_seed_flags_take_the_range() -> None:
    assert limits.seed_arg("0") == 0 and limits.seed_arg(str(MAX_SEED)) == MAX_SEED
    for text in (str(2 ** 64), "-1", "x"):
        with pytest.raises(argparse.ArgumentTypeError, match=f"must be an integer from 0 to {MAX_SEED}"):
            limits.seed_arg(text)


def test_a_containers_memory_limit_counts(monkeypatch) -> None:
    """In a cgroup of 4 GiB using 3 (1 of it reclaimable file cache) a request has 2 GiB, however
    much the machine has; without a cgroup limit, the machine's MemAvailable."""
    files = {("/proc/meminfo", "MemAvailable:"): 100 * GIB // 1024, ("/sys/fs/cgroup/memory.max", ""): 4 * GIB,
             ("/sys/fs/cgroup/memory.current", ""): 3 * GIB, ("/sys/fs/cgroup/memory.stat", "inactive_file"): GIB}
    monkeypatch.setattr(limits, "_first_number", lambda path, key="": files.get((path, key)))
    assert limits.available_memory() == 2 * GIB
    del files[("/sys/fs/cgroup/memory.max", "")]  # "max": no limit
    assert limits.available_memory() == 100 * GIB
