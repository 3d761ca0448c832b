"""What a request may ask of the machine: the scene's sizes, the memory they take, the seeds' range.

One home for the bounds every package checks before it allocates anything (the scene node, the
planner and the recon, their CLIs and nodes; ``vp_planner.request`` checks a plan's own memory
with :func:`check_memory_need` too):

==============================  ==========================================================
:data:`MAX_REALIZATIONS`        K, wind realizations of a scene: 100 (the paper's 5, twenty
                                times over; the recon reconstructs every one, minutes each)
:data:`MAX_POINTS_PER_PLANT`    points sampled per plant: 1,000,000 (the planner's coverage
                                reward uses 3000 of a realization, the default is 4000)
``vp_scene.layout.MAX_PLANTS``  plants of a layout: 200
:data:`MEMORY_FRACTION`         of the available memory (:func:`available_memory`) one
                                request's estimate may take: 0.8
:data:`MAX_SEED`                seeds of the scene, the wind, the planner and the capture:
                                0 to 2**32 - 1 (numpy's and torch's generators take them all)
==============================  ==========================================================

A scene of n plants, p points a plant and K realizations needs about
:func:`scene_memory` bytes at its peak (built, then packed into a PointCloud2 and handed to DDS
by the scene node, or unpacked by a node that receives it): :data:`REALIZATION_POINT_BYTES` a
point of every realization, :data:`SCENE_POINT_BYTES` a noise-free point and
:data:`PLANT_BYTES` a plant (its procedural mesh). :func:`check_scene_size` refuses a scene beyond
a cap or beyond the memory in one line naming the sizes and the limit (:class:`SceneTooLargeError`).

ROS-free, standard library only.
"""
from __future__ import annotations

import argparse
import operator
from typing import Optional

__all__ = ["MAX_REALIZATIONS", "MAX_POINTS_PER_PLANT", "MEMORY_FRACTION", "MAX_SEED", "REALIZATION_POINT_BYTES",
           "SCENE_POINT_BYTES", "PLANT_BYTES", "SceneTooLargeError", "available_memory", "check_memory_need",
           "scene_memory", "check_scene_size", "check_seed", "seed_arg"]

#: K: the most wind realizations a scene may have.
MAX_REALIZATIONS: int = 100
#: The most points a plant may be sampled at.
MAX_POINTS_PER_PLANT: int = 1_000_000
#: The fraction of the available memory one request's estimate may take.
MEMORY_FRACTION: float = 0.8
#: The largest seed (of the scene, the wind, the planner, the capture); the smallest is 0.
MAX_SEED: int = 2 ** 32 - 1

#: Bytes a point of one realization costs at the scene's peak (an upper estimate): the
#: realizations (24 bytes), their construction (24 more while they are stacked), the PointCloud2's
#: packing (about 20 a copy: the structured array, its bytes, the message's array) and DDS's
#: copies of the serialized message.
REALIZATION_POINT_BYTES: int = 160
#: Bytes a noise-free scene point costs (sampling, placing, colours, plant indices).
SCENE_POINT_BYTES: int = 250
#: Bytes a plant costs besides its points: its procedural mesh.
PLANT_BYTES: int = 4 << 20


class SceneTooLargeError(ValueError):
    """A scene above a cap (realizations, points per plant) or beyond the memory."""


def _first_number(path: str, key: str = "") -> Optional[int]:
    """The number of a one-value file, or the one after ``key`` in a key-value file; None where
    the file or the key is missing ("max" included)."""
    try:
        with open(path) as fh:
            for line in fh:
                words = line.split()
                if not key:
                    return int(words[0])
                if words and words[0] == key:
                    return int(words[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def available_memory() -> Optional[int]:
    """Bytes this process may still take: MemAvailable of /proc/meminfo, or less where a cgroup v2
    (a container) limits the memory: memory.max less what the cgroup uses (memory.current, its
    reclaimable inactive file cache left out); None where unknown."""
    have = _first_number("/proc/meminfo", "MemAvailable:")
    have = None if have is None else have * 1024
    limit = _first_number("/sys/fs/cgroup/memory.max")
    used = _first_number("/sys/fs/cgroup/memory.current")
    if limit is not None and used is not None:
        room = max(0, limit - used + (_first_number("/sys/fs/cgroup/memory.stat", "inactive_file") or 0))
        have = room if have is None else min(have, room)
    return have


def _gib(n: float) -> str:
    return f"{n / 2 ** 30:.1f} GiB"


def check_memory_need(need: int, what: str, error: type = ValueError, available: Optional[int] = None,
                      hint: str = "") -> None:
    """``error`` (one line: ``what``, the bytes needed, the memory available and the limit, then
    ``hint``) when ``need`` bytes exceed :data:`MEMORY_FRACTION` of ``available`` bytes (default:
    :func:`available_memory`; nothing is refused where that is unknown)."""
    have = available_memory() if available is None else int(available)
    if have is not None and need > MEMORY_FRACTION * have:
        raise error(f"{what} would need about {_gib(need)}; {_gib(have)} are available and a request may take "
                    f"{MEMORY_FRACTION:.0%} of them" + (f": {hint}" if hint else ""))


def scene_memory(points: int, realizations: int, plants: int = 0) -> int:
    """Bytes a scene of ``points`` points (all its plants') x ``realizations`` wind realizations
    needs at its peak, with the meshes of ``plants`` procedural plants (an upper estimate; the
    module docstring gives the parts)."""
    p = int(points)
    return REALIZATION_POINT_BYTES * p * int(realizations) + SCENE_POINT_BYTES * p + PLANT_BYTES * int(plants)


def _integer(value: object) -> Optional[int]:
    """``value`` as an int where it is an integer (numpy's too; not a bool, not a float), else None."""
    if isinstance(value, bool):
        return None
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        return None


def _count(name: str, value: object, hi: int) -> int:
    v = _integer(value)
    if v is None or v < 1:
        raise SceneTooLargeError(f"{name} must be an integer >= 1, got {value!r}")
    if v > hi:
        raise SceneTooLargeError(f"{name} = {v} is above the bound of {hi}")
    return v


def check_scene_size(plants: int, points_per_plant: object, realizations: object,
                     available: Optional[int] = None) -> tuple[int, int]:
    """(points_per_plant, realizations) as integers, checked: each at least 1 and at most
    :data:`MAX_POINTS_PER_PLANT` and :data:`MAX_REALIZATIONS`, and the scene's
    :func:`scene_memory` within :data:`MEMORY_FRACTION` of the ``available`` memory (default
    :func:`available_memory`); else :class:`SceneTooLargeError`, one line naming the sizes and
    the limit. ``plants`` is the layout's (its bound is the layout's)."""
    points = _count("points_per_plant", points_per_plant, MAX_POINTS_PER_PLANT)
    k = _count("realizations", realizations, MAX_REALIZATIONS)
    check_memory_need(scene_memory(plants * points, k, plants),
                      f"a scene of {plants} plant(s) x {points} points x {k} realizations",
                      SceneTooLargeError, available, "use fewer points per plant or realizations")
    return points, k


def check_seed(name: str, value: object) -> int:
    """``value`` as a seed, an integer from 0 to :data:`MAX_SEED` (bools and fractions refused);
    ValueError naming ``name`` and the range."""
    v = _integer(value)
    if v is None or not 0 <= v <= MAX_SEED:
        raise ValueError(f"{name} must be an integer from 0 to {MAX_SEED}, got {value!r}")
    return v


def seed_arg(text: str) -> int:
    """argparse ``type`` of a seed flag (``--seed``, ``--capture-seed``): an integer from 0 to
    :data:`MAX_SEED`, else argparse's one-line usage error naming the flag and the range."""
    try:
        return check_seed("a seed", int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer from 0 to {MAX_SEED}, got {text!r}") from None
