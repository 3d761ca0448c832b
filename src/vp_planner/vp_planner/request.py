"""One planning request: :class:`PlanRequest`, everything :func:`vp_planner.optimizers.plan_views`
needs besides the scene realizations and the callbacks, typed, grouped and validated in one place.

A request is the method, its budget and seed, and typed groups, each validated in its own
constructor, each field's default written once (in the group's class):

==================  ========================================================================================
``cameras``         :class:`CameraSpec`: num_cameras, fov, image_size, shell_depth
``feasibility``     :class:`vp_planner.feasibility.Feasibility`: min_standoff, min_altitude, min_separation
``reward``          :class:`RewardSpec`: name (the reward model), theta_match, dtype
``bo``              :class:`BOSpec`, egp/gp's settings: initial_evaluations, structured_init, mode, parts
``arc``             :class:`ArcSpec`, arc's setting: spacing
``lawnmower``       :class:`LawnmowerSpec`, lawnmower's settings: overlap, tilt
``sortie``          :class:`Sortie`, a second sortie: fixed_cameras, reconstruction, tau, reconstructed_weight
``candidates``      :class:`CandidateSet`, the poses to choose N of (None: plan in free space)
``flights``         :class:`FlightSpec`, the simulated flights that check the plans: count and setting
==================  ========================================================================================

The planner node builds it from a goal and its parameters, the CLI from its flags, the benchmarks
from their variants (``bench/common.py``), all through the flat names below
(:meth:`PlanRequest.from_dict`; :meth:`PlanRequest.as_dict` writes them, the form of JSON records);
``plan_views(request, realizations, callback, should_stop)`` plans it, handing the groups on to
the planners (``request.bo``, ``request.arc``, ...). A request is frozen and validated once, on
construction: each group in its ``__post_init__`` by the rules of its fields, the request its own
fields and the checks between fields (the budget's bound for the method, the initial design
within the budget, candidates for the method); a changed request (:meth:`PlanRequest.replace`) is
a new one, its changed groups built anew. So a request that exists is one ``plan_views`` accepts
up to the checks that need the scene (its memory, the parts' camera count) or the machine
(:func:`check_memory`). :func:`check_fields` checks flat values one field at a time (not against
each other): the planner node's parameters, which a goal may override.

Field metadata: every field states its rule where it is declared (:func:`_field`): ``help``,
``range`` (inclusive, an upper end of None: none; ``open``: both ends excluded), ``choices``, the
``error`` it raises, a ``check`` of its own (arrays, the image size, the reward model), ``flat``
(its flat name where it differs from the field's), ``split`` (a pair set by two settings: image
width and height) and ``param=False`` for the fields no node parameter or flag sets (the arrays a
goal or a file carries, the automatic shell, the precision). :data:`SETTINGS` is every other field
as a setting (name, default, help, range): the planner node's parameters and the CLI's flags are
made from it, so that a new field of a group is both without a copy.

Flat names (units; validation; the error raised, every one a ValueError; :data:`DEFAULTS` holds
every default):

==========================  ===========================================================================
``method``                  one of :data:`vp_planner.methods.METHODS` (UnknownMethodError)
``num_cameras``             N, an integer in [2, :data:`MAX_CAMERAS`] (InvalidNumCamerasError)
``evaluations``             the budget E of reward evaluations (eq. 7), an integer >= 1 (InvalidBudgetError)
                            and <= :data:`vp_planner.methods.MAX_EVALUATIONS` [method] (BudgetTooLargeError)
``initial_evaluations``     egp/gp: initial design size, an integer >= 1 (InvalidBudgetError), <= E for
                            egp/gp (InvalidBudgetError)
``seed``                    random seed of numpy and torch, an integer from 0 to
                            :data:`vp_scene.limits.MAX_SEED`
``min_standoff``            m from every scene point, finite >= 0 (feasibility, :mod:`vp_planner.feasibility`)
``min_altitude``            m above the ground, finite >= 0
``min_separation``          m between cameras, finite >= 0
``fov``                     horizontal field of view, rad, in (0, pi) (eq. 6)
``theta_match``             matching angle of the reward, rad, in (0, pi) (eq. 6)
``shell_depth``             m, outer bound of camera distances (:class:`vp_planner.space.ViewSpace`);
                            None (automatic) or finite > 0
``structured_init``         egp/gp: structured plans in the initial design, an integer >= 0 (0: random)
``reward``                  one of :data:`vp_planner.reward_models.REWARD_MODELS` (UnknownRewardModelError)
``image_size``              (width, height) of the cameras' images, pixels, integers in
                            :data:`vp_scene.camera.IMAGE_SIDE_RANGE`
``bo_mode``                 egp/gp: ``'trust_region'`` or ``'global'`` (the paper's)
``arc_spacing``             arc: rad between neighbouring cameras, in (0, 2 pi)
``parts``                   egp/gp: parts a field is planned by, an integer >= 0 (0: automatic)
``lawnmower_overlap``       lawnmower: image overlap, in [0, 0.95]
``lawnmower_tilt``          lawnmower: camera tilt from nadir, rad, in [0, 60 degrees]
``fixed_cameras``           (M, 6) cameras already flown [cx cy cz vx vy vz] (m; viewing vector),
                            finite, non-zero viewing vectors, M <= :data:`MAX_FIXED_CAMERAS`
                            (InvalidFixedCamerasError); stored read-only, (0, 6) for none
``reconstruction``          (Q, 3) points (m) an earlier sortie reconstructed, finite, or None
                            (InvalidReconstructionError); stored read-only
``tau``                     m: a scene point this close to the reconstruction counts as
                            reconstructed, finite >= 0 (InvalidReconstructionError)
``reconstructed_weight``    reward weight of a reconstructed point, in [0, 1] (InvalidReconstructionError)
``dtype``                   reward precision, ``'float64'`` or ``'float32'``
``report_position_sigma``   m per axis, the reported camera centres' error the coverage models'
                            registration term assumes, in (0, :data:`MAX_POSITION_SIGMA`)
``report_attitude_sigma``   degrees per axis, the reported attitudes' error, in (0, :data:`MAX_ATTITUDE_SIGMA`)
``ground_control``          bool: ground-control markers place the model as a whole (else the reported
                            poses alone place it)
``candidates``              (M, 6) candidate cameras [cx cy cz vx vy vz] the plan chooses N of
                            (:mod:`vp_planner.candidates`), finite, non-zero viewing vectors,
                            N <= M <= :data:`MAX_CANDIDATES`, a method with a candidates mode
                            (InvalidCandidatesError); stored read-only; None: plan in free space
``sim_flights``             simulated flights that check the cheap reward's plans
                            (:mod:`vp_planner.flight_planning`), an integer in [-1, :data:`vp_scene.flights.MAX_FLIGHTS`];
                            -1: the method's default (:attr:`vp_planner.methods.Method.flights`), 0: none
``flight_width``,           the flights' image size, pixels (:class:`vp_scene.flights.FlightSettings`)
``flight_height``
``flight_sift_octave``      the flights' SIFT first octave, -1 or 0
``flight_dense_scale``      the flights' dense-step scale, in [0.1, 1]
==========================  ===========================================================================

Other bad fields raise :class:`InvalidRequestError` (the feasibility minima: ValueError, from
:class:`~vp_planner.feasibility.Feasibility`); ``from_dict`` refuses names that are not fields.
A plan file records the request as :meth:`PlanRequest.record` writes it.

The checks of a request against the scene and the machine live here too, run by ``plan_views``
before anything is allocated: :func:`check_plan_memory` (one evaluation of the plan's N cameras
and of N + M with the cameras already flown: :func:`check_memory`), :func:`check_budget_memory`
(the run's records and GPs), :func:`check_reconstruction_memory`, :func:`check_parts` (the parts
a field is planned by) and :func:`total_evaluations`. Each refuses an estimate beyond the share of
the available memory a request may take (:func:`vp_scene.limits.check_memory_need`, the one
home of that limit); a caller that knows the scene's shape before building it (the CLI) runs
:func:`check_plan_memory` first.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields
from typing import Any, Mapping, Optional

import numpy as np
from numpy.typing import NDArray

from vp_scene import limits
from vp_scene.camera import IMAGE_SIDE_RANGE, IMAGE_SIZE, check_image_side
from vp_scene.flights import MAX_FLIGHTS, FlightSettings

from .feasibility import Feasibility
from .methods import BY_NAME, DEFAULT_METHOD, METHODS, REGISTRY
from .reward import DEFAULT_FOV, DEFAULT_THETA_MATCH
from .reward_models import (DEFAULT_RECONSTRUCTED_WEIGHT, DEFAULT_REWARD_MODEL, DEFAULT_TAU, REWARD_MODELS,
                            CoverageParams, check_fixed_cameras, check_reward_model, reward_model)

__all__ = [
    "MAX_CAMERAS",
    "MAX_FIXED_CAMERAS",
    "PlanRequest",
    "CameraSpec",
    "RewardSpec",
    "BOSpec",
    "ArcSpec",
    "LawnmowerSpec",
    "Sortie",
    "GROUPS",
    "FLAT",
    "DEFAULTS",
    "check_fields",
    "ARRAYS",
    "REGISTRATION",
    "Setting",
    "SETTINGS",
    "values_of_settings",
    "InvalidRequestError",
    "InvalidNumCamerasError",
    "UnknownMethodError",
    "UnknownRewardModelError",
    "InvalidBudgetError",
    "BudgetTooLargeError",
    "InvalidFixedCamerasError",
    "InvalidReconstructionError",
    "InvalidCandidatesError",
    "CandidateSet",
    "MAX_CANDIDATES",
    "check_candidates",
    "check_lawnmower",
    "check_reconstruction",
    "DTYPES",
    "BO_MODES",
    "estimate_memory",
    "estimate_run_memory",
    "check_memory",
    "check_budget_memory",
    "check_reconstruction_memory",
    "check_plan_memory",
    "check_parts",
    "total_evaluations",
    "MAX_POSITION_SIGMA",
    "MAX_ATTITUDE_SIGMA",
    "FlightSpec",
]

#: The largest number of cameras N of a plan (:mod:`vp_planner.optimizers` says why).
MAX_CAMERAS: int = 100
#: The most cameras already flown a request may carry: a full sortie of MAX_CAMERAS. The reward
#: scores a plan together with them, so an evaluation costs what a plan of N + M cameras does.
MAX_FIXED_CAMERAS: int = MAX_CAMERAS
#: Reward precisions a request may ask for.
DTYPES: tuple[str, ...] = ("float64", "float32")
#: egp/gp searches of the acquisition.
BO_MODES: tuple[str, ...] = ("trust_region", "global")
#: The largest reported-pose errors a request takes (m per axis; degrees per axis, the capture
#: model's bound on attitudes): a flight whose poses are worse than these is not placed by them.
MAX_POSITION_SIGMA: float = 10.0
MAX_ATTITUDE_SIGMA: float = 10.0
#: The coverage models' ingredients as the planner uses them (the request sets the flight's errors).
_COVERAGE = CoverageParams()


class InvalidRequestError(ValueError):
    """A request field out of its range (the fields without an error of their own)."""


class InvalidNumCamerasError(ValueError):
    """num_cameras not an integer in [2, MAX_CAMERAS], or more cameras than the memory holds."""


class UnknownMethodError(ValueError):
    """method is not one of METHODS."""


class UnknownRewardModelError(ValueError):
    """reward is not one of REWARD_MODELS."""


class InvalidBudgetError(ValueError):
    """evaluations < 1, or smaller than initial_evaluations for egp/gp."""


class BudgetTooLargeError(InvalidBudgetError):
    """evaluations above :data:`MAX_EVALUATIONS`, or a run the memory cannot hold."""


class InvalidFixedCamerasError(ValueError):
    """Cameras already flown that are not finite (M, 6) cameras with a viewing direction, more
    than :data:`MAX_FIXED_CAMERAS`, or more than the memory holds together with the plan
    (:func:`check_memory` of N + M)."""


class InvalidReconstructionError(ValueError):
    """A reconstruction (of an earlier sortie) with non-finite points, more points than the
    memory holds, or a tau / reconstructed_weight out of range."""


class InvalidCandidatesError(ValueError):
    """Candidates that are not finite (M, 6) cameras with a viewing direction, more than
    :data:`MAX_CANDIDATES`, fewer than the plan's cameras, or a method without a candidates mode."""


#: The most candidate poses a request may carry (the BO encoding has one input a candidate).
MAX_CANDIDATES: int = 2000


def check_candidates(candidates: Any) -> NDArray[np.float64]:
    """Candidate cameras as a finite (M, 6) array [c, v], 2 <= M <= :data:`MAX_CANDIDATES`, each
    with a viewing direction; InvalidCandidatesError naming the problem."""
    try:
        C = np.asarray(candidates, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidCandidatesError(f"candidates must be (M, 6) cameras [cx cy cz vx vy vz]: {exc}") from None
    if C.ndim != 2 or C.shape[1] != 6:
        raise InvalidCandidatesError(f"candidates must have shape (M, 6) [cx cy cz vx vy vz], got {C.shape}")
    if not 2 <= len(C) <= MAX_CANDIDATES:
        raise InvalidCandidatesError(f"candidates: {len(C)} poses; between 2 and {MAX_CANDIDATES} are planned among")
    bad = ~np.isfinite(C).all(axis=1)
    bad[~bad] = np.linalg.norm(C[~bad, 3:], axis=1) <= 1e-12
    if bad.any():
        raise InvalidCandidatesError(f"candidate {int(np.flatnonzero(bad)[0])} of {len(C)} is not finite or has a "
                                     "zero viewing direction")
    return C


def _integer(name: str, value: Any, lo: int, hi: Optional[int] = None, error: type = InvalidRequestError) -> int:
    """``value`` as an int in [lo, hi] (bools and fractions refused), else ``error`` naming it."""
    try:
        ok = not isinstance(value, (bool, np.bool_)) and int(value) == value
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok or value < lo or (hi is not None and value > hi):
        bound = f"from {lo} to {hi}" if hi is not None else f">= {lo}"
        raise error(f"{name} must be {bound} (an integer), got {value!r}")
    return int(value)


def _real(name: str, value: Any, lo: float, hi: float = math.inf, open_ends: bool = False,
          error: type = InvalidRequestError) -> float:
    """``value`` as a finite float in [lo, hi] ((lo, hi) with ``open_ends``), else ``error`` naming it."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None
    inside = lo < x < hi if open_ends else lo <= x <= hi
    if not (math.isfinite(x) and inside):
        if hi == math.inf:
            ends = f"> {lo:g}" if open_ends else f">= {lo:g}"
        else:
            ends = "in " + (f"({lo:g}, {hi:g})" if open_ends else f"[{lo:g}, {hi:g}]")
        raise error(f"{name} must be finite and {ends}, got {value!r}")
    return x


def _field(default: Any = None, help: str = "", *, flat: Optional[str] = None, range: Optional[tuple] = None,
           open: bool = False, choices: Optional[tuple] = None, error: Optional[type] = None,
           check: Optional[Any] = None, param: bool = True, split: Optional[tuple] = None,
           limits: str = "") -> Any:
    """A request field with its rule in its metadata (module docstring, "Field metadata")."""
    meta = {"help": help, "param": param, "open": open, "limits": limits}
    for key, value in (("flat", flat), ("range", range), ("choices", choices), ("error", error), ("check", check),
                       ("split", split)):
        if value is not None:
            meta[key] = value
    return field(default=default, metadata=meta)


def _flat(default: Any, name: str, help: str = "", **rule: Any) -> Any:
    """A group field whose flat name (:data:`FLAT`) is not its own."""
    return _field(default, help, flat=name, **rule)


def _check_field(f: Any, value: Any) -> Any:
    """``value`` of the field ``f`` (a dataclass Field of a group or of the request) checked by its
    rule and normalized: its ``check``, else its range (an integer or a finite number), its
    choices or a bool; the field's error (default InvalidRequestError) names it by its flat name."""
    m = f.metadata
    name = m.get("flat", f.name)
    if "check" in m:
        return m["check"](value)
    error = m.get("error", InvalidRequestError)
    if value is None and f.default is None:
        return None
    if "range" in m:
        lo, hi = m["range"]
        if isinstance(f.default, int) and not isinstance(f.default, bool):
            return _integer(name, value, lo, hi, error)
        return _real(name, value, lo, hi, m.get("open", False), error)
    if "choices" in m:
        if value not in m["choices"]:
            raise error(f"{name} must be one of {', '.join(m['choices'])}, got {value!r}")
        return value
    if isinstance(f.default, bool):
        if not isinstance(value, (bool, np.bool_)):
            raise error(f"{name} must be true or false, got {value!r}")
        return bool(value)
    return value


def _check_fields(obj: Any) -> None:
    """Every field of ``obj`` (a frozen dataclass) checked by its rule, in field order, and stored
    normalized: the one validation of a group, run in its ``__post_init__``."""
    for f in fields(obj):
        if f.metadata:
            _put(obj, f.name, _check_field(f, getattr(obj, f.name)))


def check_lawnmower(overlap: float, tilt: float) -> None:
    """ValueError unless overlap and tilt are finite and in :class:`LawnmowerSpec`'s ranges
    (0..0.95; 0..60 degrees, rad)."""
    lo, hi = _rule(LawnmowerSpec, "overlap")["range"]
    if not (math.isfinite(overlap) and lo <= overlap <= hi):
        raise InvalidRequestError(f"lawnmower overlap must be in [{lo:g}, {hi:g}], got {overlap}")
    lo, hi = _rule(LawnmowerSpec, "tilt")["range"]
    if not (math.isfinite(tilt) and lo <= tilt <= hi + 1e-12):
        raise InvalidRequestError(f"lawnmower tilt must be in [0, {math.degrees(hi):g} degrees] (rad), got {tilt}")


def _rule(cls: type, name: str) -> Mapping[str, Any]:
    """The metadata of the field ``name`` of the dataclass ``cls``."""
    return next(f.metadata for f in fields(cls) if f.name == name)


def check_reconstruction(reconstruction: Any) -> NDArray[np.float64]:
    """A reconstruction as finite (Q, 3) points (a flat array of 3 Q values is read as Q points);
    InvalidReconstructionError otherwise."""
    Q = np.asarray(reconstruction, dtype=np.float64)
    if Q.size % 3 or (Q.ndim == 2 and Q.shape[1] != 3) or Q.ndim > 2:
        raise InvalidReconstructionError(f"the reconstruction must be (Q, 3) points, got shape {Q.shape}")
    Q = Q.reshape(-1, 3)
    if not np.all(np.isfinite(Q)):
        raise InvalidReconstructionError("the reconstruction contains non-finite coordinates")
    return Q


def _read_only(a: NDArray[np.float64]) -> NDArray[np.float64]:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def _put(obj: Any, name: str, value: Any) -> None:
    object.__setattr__(obj, name, value)


def _image_size(value: Any) -> tuple[int, int]:
    try:
        width, height = value
    except (TypeError, ValueError):
        raise InvalidRequestError(f"image_size must be (width, height), got {value!r}") from None
    try:  # the suite's one range of image sides (vp_scene.camera.IMAGE_SIDE_RANGE)
        return check_image_side("image width", width), check_image_side("image height", height)
    except ValueError as exc:
        raise InvalidRequestError(str(exc)) from None


def _reward_name(value: Any) -> str:
    try:
        return check_reward_model(value)
    except ValueError as exc:
        raise UnknownRewardModelError(str(exc)) from None


def _fixed_cameras(value: Any) -> NDArray[np.float64]:
    try:
        F = _read_only(check_fixed_cameras(value))
    except ValueError as exc:
        raise InvalidFixedCamerasError(f"fixed cameras: {exc}") from None
    if len(F) > MAX_FIXED_CAMERAS:
        raise InvalidFixedCamerasError(f"fixed cameras: {len(F)} cameras already flown are above the bound of "
                                       f"{MAX_FIXED_CAMERAS} (a full sortie)")
    return F


def _optional_points(check: Any) -> Any:
    """The check of an optional array field: None stays None, else ``check``'s array, read-only."""
    return lambda value: None if value is None else _read_only(check(value))


# ---------------------------------------------------------------------- the groups
_OPEN = "the ends are excluded"


@dataclass(frozen=True)
class CameraSpec:
    """The cameras of the plan: how many (N), their horizontal field of view (rad), their images'
    (width, height) in pixels, and how far they may be (``shell_depth``, m beyond the scene's box
    grown by the stand-off; None: automatic)."""

    num_cameras: int = _field(4, "N, the cameras of the plan", range=(2, MAX_CAMERAS), error=InvalidNumCamerasError)
    fov: float = _field(DEFAULT_FOV, "horizontal field of view, rad", range=(0.0, math.pi), open=True)
    image_size: tuple[int, int] = _field(IMAGE_SIZE, "(width, height) of the cameras' images, pixels",
                                         check=_image_size, range=IMAGE_SIDE_RANGE,
                                         split=(("image_width", "image width of the cameras, pixels (the coverage "
                                                 "reward)"), ("image_height", "image height of the cameras, pixels")))
    shell_depth: Optional[float] = _field(None, "m beyond the scene's box grown by the stand-off (None: automatic)",
                                          range=(0.0, math.inf), open=True, param=False)

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class RewardSpec:
    """The reward the plan maximizes: its model (``name``), the matching angle (rad), the
    precision of its sums, and what the flight reports to place the model by (the coverage
    models' registration term, :mod:`vp_planner.reward_models`): the reported camera centres'
    error (``position_sigma``, m per axis: RTK about 0.02, plain GNSS 1-3), the reported
    attitudes' (``attitude_sigma``, degrees per axis) and whether ground-control markers place
    the model as a whole (``ground_control``). A zero error would make the placement's
    information infinite: the errors are in (0, MAX)."""

    name: str = _flat(DEFAULT_REWARD_MODEL, "reward", "reward model", check=_reward_name, choices=REWARD_MODELS)
    theta_match: float = _field(DEFAULT_THETA_MATCH, "matching angle of the reward, rad", range=(0.0, math.pi),
                                open=True)
    dtype: str = _field("float64", "reward precision", choices=DTYPES, param=False)
    position_sigma: float = _flat(_COVERAGE.position_sigma, "report_position_sigma",
                                  "m per axis: the error of the camera centres the flight reports (RTK about 0.02, "
                                  "plain GNSS 1-3; the registration term)", range=(0.0, MAX_POSITION_SIGMA), open=True)
    attitude_sigma: float = _flat(_COVERAGE.attitude_sigma, "report_attitude_sigma",
                                  "degrees per axis: the error of the reported attitudes",
                                  range=(0.0, MAX_ATTITUDE_SIGMA), open=True)
    ground_control: bool = _flat(_COVERAGE.ground_control, "ground_control",
                                 "ground-control markers place the model as a whole (false: the reported poses "
                                 "alone place it)")

    def __post_init__(self) -> None:
        _check_fields(self)

    def model_spec(self) -> Any:
        """What :func:`vp_planner.reward_models.make_reward` takes: the name for a model without
        parameters (``paper``: no registration term), else the model with the coverage parameters
        of this flight's reported-pose errors."""
        if not reward_model(self.name).coverage:
            return self.name
        return self.name, dataclasses.replace(_COVERAGE, position_sigma=self.position_sigma,
                                              attitude_sigma=self.attitude_sigma, ground_control=self.ground_control)


@dataclass(frozen=True)
class BOSpec:
    """egp/gp's settings: the initial design's size and how many of it are structured plans, the
    acquisition's search (``mode``) and the parts a field is planned by (0: automatic)."""

    initial_evaluations: int = _field(50, "initial design of egp/gp", range=(1, None), error=InvalidBudgetError)
    structured_init: int = _field(20, "structured plans in the egp/gp initial design (0: random, as the paper)",
                                  range=(0, None))
    mode: str = _flat("trust_region", "bo_mode", "egp/gp: search of the acquisition", choices=BO_MODES)
    parts: int = _field(0, "egp/gp: plan the field by this many parts (0: automatic, 1: none)", range=(0, None))

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class ArcSpec:
    """arc's setting: rad between neighbouring cameras."""

    spacing: float = _flat(math.radians(30.0), "arc_spacing", "arc: rad between neighbouring cameras",
                           range=(0.0, 2 * math.pi), open=True)

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True)
class LawnmowerSpec:
    """lawnmower's settings: the images' overlap along and across the flight lines, the camera's
    tilt from nadir (rad); :func:`check_lawnmower` checks both."""

    overlap: float = _flat(0.7, "lawnmower_overlap", "lawnmower: image overlap along and across the flight lines",
                           range=(0.0, 0.95))
    tilt: float = _flat(0.0, "lawnmower_tilt", "lawnmower: camera tilt from nadir, rad (0: nadir, up to 60 degrees)",
                        range=(0.0, math.radians(60.0)))

    def __post_init__(self) -> None:
        check_lawnmower(self.overlap, self.tilt)


@dataclass(frozen=True, eq=False)
class Sortie:
    """A second sortie's context: the cameras already flown (stored read-only, (0, 6) for none),
    what they reconstructed (read-only, or None), and how a reconstructed scene point weighs."""

    fixed_cameras: Any = _field(None, "(M, 6) cameras already flown", check=_fixed_cameras, param=False)
    reconstruction: Any = _field(None, "(Q, 3) points an earlier sortie reconstructed",
                                 check=_optional_points(check_reconstruction), param=False)
    tau: float = _field(DEFAULT_TAU, "m: a scene point this close to the reconstruction counts as reconstructed",
                        range=(0.0, math.inf), error=InvalidReconstructionError)
    reconstructed_weight: float = _field(DEFAULT_RECONSTRUCTED_WEIGHT, "reward weight of a reconstructed scene point "
                                         "(the others weigh 1)", range=(0.0, 1.0), error=InvalidReconstructionError)

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True, eq=False)
class CandidateSet:
    """The poses a plan chooses its N cameras among (stored read-only), or None: free space."""

    poses: Any = _flat(None, "candidates", "(M, 6) candidate cameras the plan chooses N of",
                       check=_optional_points(check_candidates), param=False)

    def __post_init__(self) -> None:
        _check_fields(self)


_FLIGHT = FlightSettings()


@dataclass(frozen=True)
class FlightSpec:
    """The simulated flights that check the cheap reward's plans (:mod:`vp_planner.flight_planning`):
    how many (``count``; -1: the method's default, 0: none) and how each is photographed and
    reconstructed (:class:`vp_scene.flights.FlightSettings`)."""

    count: int = _flat(-1, "sim_flights", "simulated flights that check the cheap reward's plans (the recon "
                       "node's /simulate_flights; goals with sim_flights -1); -1: the method's default, 0: none",
                       range=(-1, MAX_FLIGHTS))
    width: int = _flat(_FLIGHT.width, "flight_width", "the simulated flights' image width, pixels",
                       range=IMAGE_SIDE_RANGE)
    height: int = _flat(_FLIGHT.height, "flight_height", "the simulated flights' image height, pixels",
                        range=IMAGE_SIDE_RANGE)
    sift_first_octave: int = _flat(_FLIGHT.sift_first_octave, "flight_sift_octave",
                                   "the simulated flights' SIFT first octave: -1 (each image doubled first) or 0",
                                   range=(-1, 0))
    dense_scale: float = _flat(_FLIGHT.dense_scale, "flight_dense_scale",
                               "the simulated flights' dense step on the images resized by this factor",
                               range=(0.1, 1.0))

    def __post_init__(self) -> None:
        _check_fields(self)
        try:
            self.settings()
        except ValueError as exc:
            raise InvalidRequestError(str(exc)) from None

    def settings(self) -> FlightSettings:
        return FlightSettings(width=self.width, height=self.height, sift_first_octave=self.sift_first_octave,
                              dense_scale=self.dense_scale)

    def flights_of(self, method: str) -> int:
        """The flights a run of ``method`` makes: ``count``, or the method's default for -1."""
        return BY_NAME[method].flights if self.count < 0 else self.count


#: The request's groups: attribute -> class, in the order a request is validated.
GROUPS: dict[str, type] = {"cameras": CameraSpec, "feasibility": Feasibility, "reward": RewardSpec, "bo": BOSpec,
                           "arc": ArcSpec, "lawnmower": LawnmowerSpec, "sortie": Sortie, "candidates": CandidateSet,
                           "flights": FlightSpec}


def _check_method(method: Any) -> str:
    if not isinstance(method, str) or method not in BY_NAME:
        raise UnknownMethodError(f"unknown method {method!r}; one of {', '.join(METHODS)}")
    return method


def _check_evaluations(evaluations: Any) -> int:
    """The budget as a field: an integer >= 1 (its bound for the method: :meth:`PlanRequest.__post_init__`)."""
    return _integer("evaluations", evaluations, 1, None, InvalidBudgetError)


def _check_budget(method: str, evaluations: int, bo: BOSpec) -> None:
    """The budget within the bound of ``method``, and for egp/gp the initial design within it."""
    if evaluations > BY_NAME[method].max_evaluations:
        raise BudgetTooLargeError(f"evaluations = {evaluations} is above the bound of "
                                  f"{BY_NAME[method].max_evaluations} for method {method} (README, 'Planner node')")
    if BY_NAME[method].bayesian and evaluations < bo.initial_evaluations:
        raise InvalidBudgetError(f"evaluation budget {evaluations} is smaller than the initial "
                                 f"design ({bo.initial_evaluations})")


def _check_candidates_for(method: str, num_cameras: int, candidates: "CandidateSet") -> None:
    """With candidates: the method has a candidates mode and there are at least N of them."""
    if candidates.poses is None:
        return
    if BY_NAME[method].candidates is None:
        raise InvalidCandidatesError(f"method {method} has no candidates mode; one of "
                                     f"{', '.join(m for m in METHODS if BY_NAME[m].candidates)}")
    if num_cameras > len(candidates.poses):
        raise InvalidCandidatesError(f"{num_cameras} cameras cannot be chosen among {len(candidates.poses)} "
                                     "candidates")


@dataclass(frozen=True, eq=False)
class PlanRequest:
    """What to plan: the method, its budget and seed, and the groups (the module docstring gives
    every field's unit and rule). Build one from flat values with :meth:`from_dict` (or
    :meth:`of`), change one with :meth:`replace`. Each group validated itself on construction;
    the request checks its own fields and those between fields (the budget's bound for the
    method, the initial design within the budget, candidates for the method)."""

    method: str = _field(DEFAULT_METHOD, "planning method", check=_check_method, choices=METHODS)
    cameras: CameraSpec = field(default_factory=CameraSpec)
    evaluations: int = _field(100, "reward evaluations", check=_check_evaluations,
                              range=(1, max(m.max_evaluations for m in REGISTRY)),
                              limits="at most " + ", ".join(f"{m.name} {m.max_evaluations}" for m in REGISTRY))
    seed: int = _field(0, "random seed", range=(0, limits.MAX_SEED))
    feasibility: Feasibility = field(default_factory=Feasibility)
    reward: RewardSpec = field(default_factory=RewardSpec)
    bo: BOSpec = field(default_factory=BOSpec)
    arc: ArcSpec = field(default_factory=ArcSpec)
    lawnmower: LawnmowerSpec = field(default_factory=LawnmowerSpec)
    sortie: Sortie = field(default_factory=Sortie)
    candidates: CandidateSet = field(default_factory=CandidateSet)
    flights: FlightSpec = field(default_factory=FlightSpec)

    def __post_init__(self) -> None:
        for name, cls in GROUPS.items():
            if not isinstance(getattr(self, name), cls):
                raise InvalidRequestError(f"{name} must be a {cls.__name__}, got {getattr(self, name)!r}")
        _check_fields(self)
        _check_budget(self.method, self.evaluations, self.bo)
        _check_candidates_for(self.method, self.cameras.num_cameras, self.candidates)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "PlanRequest":
        """A request of flat values (:data:`FLAT` names, any subset: the others default; the form
        of :meth:`as_dict`, of JSON records, node parameters and CLI flags); InvalidRequestError
        naming names that are not fields, else the first bad field's error (the groups in the
        order of :data:`GROUPS`, then the request's own fields and those between fields)."""
        _refuse_unknown(data)
        return cls(**{name: data[name] for name in _OWN if name in data},
                   **{name: _group(name, data) for name in GROUPS})

    @classmethod
    def of(cls, method: str, num_cameras: int, **values: Any) -> "PlanRequest":
        """``from_dict`` of ``method``, ``num_cameras`` and flat ``values``: the short form of code
        and tests (``PlanRequest.of("sa", 3, evaluations=30, seed=1)``)."""
        return cls.from_dict({"method": method, "num_cameras": num_cameras, **values})

    def as_dict(self, arrays: bool = True) -> dict:
        """The request as flat plain data (lists for the arrays), :meth:`from_dict`'s input;
        ``arrays=False`` leaves out the arrays a goal or a file carries (:data:`ARRAYS`)."""
        out: dict = {}
        for name, (group, attr) in FLAT.items():
            if not arrays and name in ARRAYS:
                continue
            value = getattr(self if group is None else getattr(self, group), attr)
            out[name] = value.tolist() if isinstance(value, np.ndarray) else list(value) if isinstance(value, tuple) \
                else value
        return out

    def record(self) -> dict:
        """The request as a plan file records it (``vp_planner.cli``'s plan.json): ``request``, the
        flat form (:meth:`as_dict` without :data:`ARRAYS`, which the file names elsewhere), and the
        keys the plan file's readers read: method, num_cameras, seed, fov, theta_match,
        image_size, feasibility (the group), registration (:data:`REGISTRATION`), fixed_cameras,
        and the method's settings (egp/gp: initial_evaluations, structured_init, bo_mode;
        lawnmower: the group; None for a method without them)."""
        flat = self.as_dict(arrays=False)
        settings = BY_NAME[self.method].settings
        return {
            "method": self.method, "num_cameras": self.cameras.num_cameras, "seed": self.seed,
            **{k: flat[k] if settings == "bo" else None for k in ("initial_evaluations", "structured_init", "bo_mode")},
            "lawnmower": dataclasses.asdict(self.lawnmower) if settings == "lawnmower" else None,
            "fov": self.cameras.fov, "theta_match": self.reward.theta_match,
            "registration": {k: flat[k] for k in REGISTRATION}, "image_size": flat["image_size"],
            "feasibility": dataclasses.asdict(self.feasibility), "fixed_cameras": self.sortie.fixed_cameras.tolist(),
            "request": flat,
        }

    def replace(self, **values: Any) -> "PlanRequest":
        """This request with the flat ``values`` changed (the groups changed are built again, and
        validate themselves, and so does the request)."""
        _refuse_unknown(values)
        top: dict = {}
        changes: dict = {}
        for name, value in values.items():
            group, attr = FLAT[name]
            if group is None:
                top[attr] = value
            else:
                changes.setdefault(group, {})[attr] = value
        return dataclasses.replace(self, **top, **{g: dataclasses.replace(getattr(self, g), **kw)
                                                   for g, kw in changes.items()})

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, PlanRequest):
            return NotImplemented
        return self.as_dict() == other.as_dict()

    __hash__ = None  # type: ignore[assignment]


#: The request's own fields (not groups), by name.
_OWN: dict[str, Any] = {f.name: f for f in fields(PlanRequest) if f.name not in GROUPS}


def _flat_fields() -> dict[str, tuple[Optional[str], str]]:
    out: dict[str, tuple[Optional[str], str]] = {name: (None, name) for name in _OWN}
    for group, cls in GROUPS.items():
        for f in fields(cls):
            out[f.metadata.get("flat", f.name)] = (group, f.name)
    return out


#: Flat name (JSON records, node parameters, CLI flags) -> (group of :data:`GROUPS` or None for
#: the request's own fields, the field's name there).
FLAT: dict[str, tuple[Optional[str], str]] = _flat_fields()


def _field_of(name: str) -> Any:
    """The dataclass Field of the flat ``name``."""
    group, attr = FLAT[name]
    return _OWN[attr] if group is None else next(f for f in fields(GROUPS[group]) if f.name == attr)


#: The flat names of the arrays a goal or a file carries (:meth:`PlanRequest.as_dict`'s ``arrays``).
ARRAYS: tuple[str, ...] = ("fixed_cameras", "reconstruction", "candidates")
#: The flat names of what the flight reports to place the model by (a plan file's ``registration``).
REGISTRATION: tuple[str, ...] = ("report_position_sigma", "report_attitude_sigma", "ground_control")

#: Flat name -> its default: the one home of every default of a request (the groups' classes).
DEFAULTS: dict[str, Any] = {name: _field_of(name).default for name in FLAT}


@dataclass(frozen=True)
class Setting:
    """One setting of a request a node parameter or a command-line flag sets: its ``name`` (the
    parameter's; an element of a pair, e.g. image_width of image_size, has a name of its own),
    the ``flat`` name of the field it sets (and its ``index`` in the pair), its ``default``, ``help``,
    inclusive ``range`` (None: none; an upper end of None or inf: none), whether the ends are
    excluded (``open``), its ``choices`` and the ``limits`` its range cannot say."""

    name: str
    flat: str
    default: Any
    help: str
    range: Optional[tuple] = None
    open: bool = False
    choices: Optional[tuple] = None
    limits: str = ""
    index: Optional[int] = None


def _settings() -> tuple[Setting, ...]:
    out = []
    for name in FLAT:
        f = _field_of(name)
        m = f.metadata
        if not m.get("param", True):
            continue
        common = dict(help=m.get("help") or name.replace("_", " "), range=m.get("range"), open=m.get("open", False),
                      choices=m.get("choices"), limits=m.get("limits", ""))
        if "split" in m:
            out += [Setting(part, name, f.default[i], **{**common, "help": text}, index=i)
                    for i, (part, text) in enumerate(m["split"])]
        else:
            out.append(Setting(name, name, f.default, **common))
    return tuple(out)


#: The settings of a request that a node parameter or a CLI flag sets, in :data:`FLAT`'s order: every
#: field but those whose metadata says ``param=False`` (the arrays a goal or a file carries, the
#: automatic shell and the precision), each from its field's metadata (module docstring).
SETTINGS: tuple[Setting, ...] = _settings()


def values_of_settings(values: Mapping[str, Any]) -> dict:
    """The flat request values of settings' values ({setting name: value}, any subset): the
    elements of a pair joined (both given, or the missing one from its default)."""
    out: dict = {}
    for s in SETTINGS:
        if s.name not in values:
            continue
        if s.index is None:
            out[s.flat] = values[s.name]
        else:
            pair = list(out.get(s.flat, DEFAULTS[s.flat]))
            pair[s.index] = values[s.name]
            out[s.flat] = tuple(pair)
    return out


def _refuse_unknown(values: Mapping[str, Any]) -> None:
    unknown = sorted(set(values) - set(FLAT))
    if unknown:
        raise InvalidRequestError(f"not fields of a plan request: {', '.join(unknown)}")


def _group(name: str, values: Mapping[str, Any]) -> Any:
    """The group ``name`` of the flat ``values`` it has (the others default), validated."""
    kw = {attr: values[flat] for flat, (group, attr) in FLAT.items() if group == name and flat in values}
    return GROUPS[name](**kw)


def check_fields(values: Mapping[str, Any]) -> None:
    """Check flat ``values`` (any subset of :data:`FLAT`) one field at a time, as a request does,
    but not against each other (the method's budget bound, the initial design within the budget):
    a node's parameters, which a goal may override. The field's ValueError."""
    _refuse_unknown(values)
    for name in GROUPS:
        _group(name, values)
    for name, f in _OWN.items():
        if name in values:
            _check_field(f, values[name])


# ---------------------------------------------------------------------- against the scene and the machine
#: Bytes a reconstruction point costs the hole weighting (the points and their KD-tree).
RECONSTRUCTION_POINT_BYTES = 64


def check_reconstruction_memory(num_points: int, available: Optional[int] = None) -> None:
    """InvalidReconstructionError when a reconstruction of ``num_points`` points needs more than
    a request may take of the available memory (``available`` bytes; default:
    :func:`vp_scene.limits.available_memory`)."""
    limits.check_memory_need(int(num_points) * RECONSTRUCTION_POINT_BYTES, f"the reconstruction's {num_points} points",
                             InvalidReconstructionError, available)


def estimate_memory(num_cameras: int, num_realizations: int, num_points: int, reward: str) -> int:
    """Bytes one reward evaluation of an N-camera plan needs at most (an upper estimate).

    ``paper`` (a model without coverage parameters): its chunks (``reward.DEFAULT_MAX_ELEMENTS``
    elements, about 10 float64 arrays of that size alive at once) plus per pair S = N (N - 1) / 2
    an accumulator, two indices and the pair's coefficients (about 80 bytes). The coverage models:
    the per-camera terms, N x K x min(P, max_points) elements (each realization subsampled) of at
    most 200 bytes in all, and their pair blocks (``max_elements`` = 2^22 float32 elements, about
    6 arrays).
    """
    from .reward import DEFAULT_MAX_ELEMENTS
    from .reward_models import CoverageParams

    N, K, P = int(num_cameras), int(num_realizations), int(num_points)
    S = N * (N - 1) // 2
    if not reward_model(reward).coverage:
        return 10 * 8 * DEFAULT_MAX_ELEMENTS + 80 * S
    kp = K * min(P, CoverageParams().max_points or P)
    return 200 * N * kp + 6 * 4 * (1 << 22) + 80 * S


def estimate_run_memory(method: str, num_cameras: int, evaluations: int) -> int:
    """Bytes a run of ``evaluations`` reward evaluations (all of them, parts included) keeps
    beyond one evaluation's own (an upper estimate): every evaluation is recorded (its U row and
    its cameras, 6N float64 each with their array headers, the value and flags: about
    300 + 96 N bytes), the grid methods hold their candidate plans at once (48 N bytes each)
    and egp/gp's GPs hold n x n kernel matrices and their factors and gradients while fitting
    (four models of about six float64 matrices: 192 n^2 bytes)."""
    N, E = int(num_cameras), int(evaluations)
    need = E * (300 + 96 * N) + E * 48 * N
    if BY_NAME[method].bayesian:
        need += 192 * E * E
    return need


def check_budget_memory(method: str, num_cameras: int, evaluations: int,
                        available: Optional[int] = None) -> None:
    """BudgetTooLargeError when :func:`estimate_run_memory` exceeds what a request may take of
    the available memory (``available`` bytes; default: :func:`vp_scene.limits.available_memory`),
    before anything is allocated."""
    limits.check_memory_need(estimate_run_memory(method, num_cameras, evaluations),
                             f"{evaluations} evaluations of {num_cameras} cameras with {method}", BudgetTooLargeError,
                             available, "use a smaller budget")


def check_memory(num_cameras: int, realizations_shape: tuple, reward: str,
                 available: Optional[int] = None) -> None:
    """InvalidNumCamerasError when :func:`estimate_memory` exceeds what a request may take of the
    available memory (``available`` bytes; default: :func:`vp_scene.limits.available_memory`),
    before anything is allocated."""
    K, P = int(realizations_shape[0]), int(realizations_shape[1])
    limits.check_memory_need(estimate_memory(num_cameras, K, P, reward),
                             f"num_cameras = {num_cameras} on {K} x {P} points with the {reward} reward",
                             InvalidNumCamerasError, available, "use fewer cameras or points")


def check_plan_memory(request: "PlanRequest", realizations_shape: tuple, available: Optional[int] = None) -> None:
    """:func:`check_memory` of the request's N cameras on realizations of ``realizations_shape``
    (K, P, ...), and, with cameras already flown, of the N + M cameras every evaluation scores
    (InvalidFixedCamerasError)."""
    n, model = request.cameras.num_cameras, request.reward.name
    check_memory(n, realizations_shape, model, available)
    m = len(request.sortie.fixed_cameras)
    if m:
        try:
            check_memory(n + m, realizations_shape, model, available)
        except ValueError as exc:
            raise InvalidFixedCamerasError(f"fixed cameras: {m} with the plan's {n}: {exc}") from None


def check_parts(parts: int, method: str, realizations: NDArray[np.float64], num_cameras: int) -> int:
    """The number of parts a run plans by (1 for methods other than egp/gp): ``parts`` (an integer
    >= 0, :class:`BOSpec`), or :func:`vp_planner.parts.auto_parts` for 0.
    InvalidNumCamerasError for more parts than pairs of cameras."""
    if not BY_NAME[method].bayesian:
        return 1
    if parts == 0:
        from .parts import auto_parts

        return auto_parts(realizations, num_cameras)
    if 2 * int(parts) > num_cameras:
        raise InvalidNumCamerasError(f"parts = {parts} needs at least {2 * int(parts)} cameras (2 a part), got {num_cameras}")
    return int(parts)


def total_evaluations(method: str, evaluations: int, parts: int) -> int:
    """Reward evaluations a run makes: ``evaluations``; for egp/gp by G > 1 parts, G times that
    (one plan's budget a part) plus ``evaluations // 2`` for the joint refinement; for a method
    whose entry fixes its evaluations (:attr:`vp_planner.methods.Method.evaluations`), that number
    (``lawnmower``: 1, a survey is flown as planned, not tuned)."""
    entry = BY_NAME[method]
    if entry.evaluations is not None:
        return entry.evaluations
    if entry.bayesian and parts > 1:
        return parts * int(evaluations) + max(1, int(evaluations) // 2)
    return int(evaluations)
