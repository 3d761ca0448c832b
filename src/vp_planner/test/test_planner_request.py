"""PlanRequest: one typed, validated request object behind plan_views."""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from vp_planner.optimizers import plan_views
from vp_planner.request import (BudgetTooLargeError, InvalidBudgetError, InvalidFixedCamerasError,
                                InvalidNumCamerasError, InvalidReconstructionError, InvalidRequestError, PlanRequest,
                                UnknownMethodError, UnknownRewardModelError)

#: Plans of the keyword-argument plan_views (main 411f42e) on the conftest's ``realizations``,
#: recorded before the request object replaced its 27 keywords: the same seeds give the same plans.
SA_SEED1 = np.array([
    [1.071422530041, -0.43742185273, 2.314836127031, -0.931062714442, 0.423005768515, -1.317325501135],
    [1.071422530041, -0.014416084215, 1.587115883923, -0.931062714442, 0.0, -0.589605258027],
    [1.93477126207, -0.014416084215, 2.085570506764, -1.79441144647, 0.0, -1.088059880868],
])
SA_SEED1_REWARD = 0.25154024362564087
SECOND_SORTIE_REWARD = 0.18577361106872559  # coverage with the registration


def test_a_plan_through_the_request_is_the_keyword_path_plan(realizations: np.ndarray) -> None:
    res = plan_views(PlanRequest.of("sa", 3, evaluations=30, seed=1), realizations)
    np.testing.assert_allclose(res.cameras, SA_SEED1, atol=1e-9)
    assert res.reward == pytest.approx(SA_SEED1_REWARD, abs=1e-12)
    # a second sortie's fields travel in the request too
    request = PlanRequest.of("random", 3, evaluations=20, seed=0, fixed_cameras=[[3.0, 0.0, 1.0, -1.0, 0.0, 0.0]],
                             reconstruction=realizations[0, :200], tau=0.05, reconstructed_weight=0.2)
    res = plan_views(request, realizations)
    assert res.fixed_cameras == 1 and res.reconstructed_fraction is not None
    # float32 sums: the last bits differ between CPUs (1e-12 held on one machine, 4.5e-8 off on
    # another with the same wheels); any change of the plan or the reward is far larger than 1e-6
    assert res.reward == pytest.approx(SECOND_SORTIE_REWARD, rel=1e-6)


def test_request_round_trips_and_is_frozen(realizations: np.ndarray) -> None:
    request = PlanRequest.of("egp", 4, evaluations=60, initial_evaluations=20, seed=3, reward="paper",
                             image_size=(640, 480), parts=1,
                             fixed_cameras=np.array([[3.0, 0.0, 1.0, -1.0, 0.0, 0.0]]),
                             reconstruction=realizations[0, :5].ravel(), dtype="float32")
    again = PlanRequest.from_dict(json.loads(json.dumps(request.as_dict())))
    assert again == request and again is not request
    assert again.sortie.reconstruction.shape == (5, 3) and again.cameras.image_size == (640, 480)
    assert PlanRequest.of("circle", 4).sortie.fixed_cameras.shape == (0, 6)
    assert PlanRequest.of("circle", 4).sortie.reconstruction is None
    assert dataclasses.replace(request, seed=4) != request
    with pytest.raises(dataclasses.FrozenInstanceError):
        request.seed = 5  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        request.sortie.fixed_cameras[0, 0] = 1.0
    with pytest.raises(InvalidRequestError, match="not fields of a plan request: cameras"):
        PlanRequest.from_dict({"method": "circle", "num_cameras": 4, "cameras": 4})
    with pytest.raises(TypeError, match="PlanRequest"):
        plan_views("circle", realizations)  # type: ignore[arg-type]


@pytest.mark.parametrize("fields, error, text", [
    ({"method": "nelder-mead"}, UnknownMethodError, "unknown method"),
    ({"num_cameras": 1}, InvalidNumCamerasError, "from 2 to 100"),
    ({"num_cameras": 2.5}, InvalidNumCamerasError, "integer"),
    ({"evaluations": 0}, InvalidBudgetError, "evaluations must be >= 1"),
    ({"evaluations": 1001}, BudgetTooLargeError, "above the bound of 1000"),
    ({"evaluations": 20, "initial_evaluations": 30}, InvalidBudgetError, "smaller than the initial design"),
    ({"reward": "magic"}, UnknownRewardModelError, "unknown reward model"),
    ({"seed": -1}, InvalidRequestError, "seed"),
    ({"min_separation": math.nan}, ValueError, "min_separation"),
    ({"fov": math.pi}, InvalidRequestError, "fov"),
    ({"shell_depth": 0.0}, InvalidRequestError, "shell_depth"),
    ({"image_size": (8, 480)}, InvalidRequestError, "image width"),
    ({"bo_mode": "local"}, InvalidRequestError, "bo_mode"),
    ({"arc_spacing": 0.0}, InvalidRequestError, "arc_spacing"),
    ({"parts": -1}, InvalidRequestError, "parts must be >= 0"),
    ({"lawnmower_overlap": 1.0}, InvalidRequestError, "overlap"),
    ({"fixed_cameras": [[0, 0, 1, math.nan, 0, 0]]}, InvalidFixedCamerasError, "not finite"),
    ({"reconstruction": [[0.0, 1.0]]}, InvalidReconstructionError, "shape"),
    ({"tau": -1.0}, InvalidReconstructionError, "tau"),
    ({"reconstructed_weight": 1.5}, InvalidReconstructionError, "reconstructed_weight"),
    ({"dtype": "float16"}, InvalidRequestError, "dtype"),
    ({"report_position_sigma": 0.0}, InvalidRequestError, r"report_position_sigma must be finite and in \(0, 10\)"),
    ({"report_attitude_sigma": 45.0}, InvalidRequestError, "report_attitude_sigma"),
    ({"ground_control": "yes"}, InvalidRequestError, "ground_control must be true or false"),
])
def test_each_bad_field_is_refused_with_its_error(fields: dict, error: type, text: str) -> None:
    good = {"method": "egp", "num_cameras": 4, "evaluations": 30, "initial_evaluations": 10}
    with pytest.raises(error, match=text):
        PlanRequest.from_dict({**good, **fields})
    with pytest.raises(error, match=text):  # replace validates again
        PlanRequest.from_dict(good).replace(**fields)


# ---------------------------------------------------------------- one request, built once
def test_the_request_is_grouped_and_each_group_validates_itself() -> None:
    """The request is typed groups (cameras, feasibility, reward, the methods' settings, sortie),
    each refusing its own bad value on construction, and the flat names reach every field."""
    from vp_planner.feasibility import Feasibility
    from vp_planner.request import FLAT, GROUPS, ArcSpec, BOSpec, CameraSpec, LawnmowerSpec, RewardSpec, Sortie

    request = PlanRequest.of("egp", 5, evaluations=30, initial_evaluations=10, min_standoff=0.7, bo_mode="global",
                             arc_spacing=0.4, lawnmower_tilt=0.2, reward="paper", tau=0.05)
    assert request.cameras == CameraSpec(5) and request.feasibility == Feasibility(min_standoff=0.7)
    assert request.bo == BOSpec(initial_evaluations=10, mode="global") and request.arc == ArcSpec(0.4)
    assert request.lawnmower == LawnmowerSpec(tilt=0.2) and request.reward == RewardSpec("paper")
    assert isinstance(request.sortie, Sortie) and request.sortie.tau == 0.05
    assert set(GROUPS) == {"cameras", "feasibility", "reward", "bo", "arc", "lawnmower", "sortie", "candidates",
                           "flights"}
    assert len(FLAT) == 33 and set(request.as_dict()) == set(FLAT)
    for group, bad, error in ((CameraSpec, {"num_cameras": 1}, InvalidNumCamerasError),
                              (Feasibility, {"min_altitude": -1.0}, ValueError),
                              (RewardSpec, {"name": "magic"}, UnknownRewardModelError),
                              (BOSpec, {"structured_init": -1}, InvalidRequestError),
                              (ArcSpec, {"spacing": 7.0}, InvalidRequestError),
                              (LawnmowerSpec, {"overlap": 1.0}, InvalidRequestError),
                              (Sortie, {"tau": -1.0}, InvalidReconstructionError)):
        with pytest.raises(error):
            group(**bad)
    with pytest.raises(InvalidRequestError, match="feasibility must be a Feasibility"):
        PlanRequest("circle", feasibility={"min_standoff": 0.5})  # type: ignore[arg-type]


def test_each_default_lives_in_one_place() -> None:
    """min_standoff = 0.5 was written in 7 places and 2000 x 1500 in 16: now the request's groups
    (and vp_scene.camera.IMAGE_SIZE) hold each default, and the node's parameters, the CLI's flags,
    the dispatcher, the search space, the feasibility rules and the drones read them."""
    import inspect

    from vp_planner import cli, dispatcher_node, fleet, planner_node
    from vp_scene import sim_drone_node
    from vp_planner.feasibility import Feasibility, FeasibilityRules
    from vp_planner.request import DEFAULTS, FLAT
    from vp_planner.space import ViewSpace
    from vp_scene.camera import IMAGE_SIZE, CameraModel

    params = {name: spec.default for name, spec in planner_node.PARAMS.items()}
    shared = set(params) & set(FLAT)
    assert len(shared) == 27, sorted(shared)  # the simulated flights' five among them
    assert {n: params[n] for n in shared} == {n: DEFAULTS[n] for n in shared}
    assert (params["image_width"], params["image_height"]) == DEFAULTS["image_size"] == IMAGE_SIZE
    flags = vars(cli.parse_args(["--out", "x"]))
    for flag, value in flags.items():
        name = cli.REQUEST_FLAGS.get(flag, flag)
        if name in FLAT:  # None: not given, the request's default (--fov: among candidates, the camera's)
            assert value is None or value == DEFAULTS[name], flag
    assert cli.request_of(cli.parse_args(["--out", "x"])) == PlanRequest()
    feasibility = Feasibility()
    for function in (FeasibilityRules.__init__, ViewSpace.__init__, fleet.plan_problems):
        sig = inspect.signature(function).parameters
        assert all(sig[n].default == getattr(feasibility, n) for n in ("min_standoff", "min_altitude",
                                                                        "min_separation")), function
    assert all(dispatcher_node.PARAMS[n].default == getattr(feasibility, n)
               for n in ("min_standoff", "min_altitude", "min_separation"))
    assert inspect.signature(ViewSpace.__init__).parameters["image_size"].default == IMAGE_SIZE
    assert (CameraModel().width, CameraModel().height) == IMAGE_SIZE
    assert (sim_drone_node.PARAMS["width"].default, sim_drone_node.PARAMS["height"].default) == IMAGE_SIZE


@pytest.mark.parametrize("node, flags, api", [
    ({"num_cameras": 500}, ["--cameras", "500"], {"num_cameras": 500}),
    ({"parts": -1}, ["--parts", "-1"], {"parts": -1}),
    ({"lawnmower_overlap": 1.0}, ["--lawnmower-overlap", "1.0"], {"lawnmower_overlap": 1.0}),
    ({"fov": 4.0}, ["--fov", "4.0"], {"fov": 4.0}),
    ({"structured_init": -2}, ["--structured-init", "-2"], {"structured_init": -2}),
    ({"image_width": 8}, ["--image-width", "8"], {"image_size": (8, 1500)}),
    ({"reconstructed_weight": 1.5}, ["--reconstructed-weight", "1.5"], {"reconstructed_weight": 1.5}),
])
def test_a_bad_value_is_the_same_one_line_error_via_node_cli_and_api(node, flags, api, tmp_path,
                                                                      capsys: pytest.CaptureFixture) -> None:
    """The planner node's parameter check was a copy of the request's validation with messages of
    its own ('parts must be >= 0 (0: automatic)' beside 'parts must be an integer >= 0, got -1');
    now the node, the CLI and the API refuse a bad value with the request's one message."""
    from vp_planner import cli, planner_node

    with pytest.raises(ValueError) as api_error:
        PlanRequest.from_dict({"method": "egp", "num_cameras": 4, **api})
    with pytest.raises(ValueError) as node_error:
        planner_node.check_parameters(node)
    assert str(node_error.value) == str(api_error.value)
    capsys.readouterr()
    assert cli.main(["--out", str(tmp_path / "x"), "--no-progress", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"plan: error: {api_error.value}"]
    assert not (tmp_path / "x").exists()


# ---------------------------------------------------------------- the flight's reported poses
def test_the_flights_reported_pose_errors_reach_the_reward(realizations: np.ndarray) -> None:
    """report_position_sigma, report_attitude_sigma and ground_control (node parameters, CLI flags,
    plan.json's ``registration``) set the coverage models' registration term: an arc (one part of
    the model) under ground markers scores as with RTK whatever the GNSS; without markers its
    placement from 3 m GNSS poses loses (nearly) every pair; paper has no such term."""
    from vp_planner.request import RewardSpec
    from vp_planner.reward_models import CoverageParams

    spec = RewardSpec(position_sigma=3.0, attitude_sigma=2.0, ground_control=False).model_spec()
    assert spec == ("coverage", CoverageParams(position_sigma=3.0, attitude_sigma=2.0, ground_control=False))
    assert RewardSpec("paper", position_sigma=3.0).model_spec() == "paper"
    rewards = {}
    for name, fields in (("rtk", {}), ("gnss, markers", {"report_position_sigma": 3.0}),
                         ("gnss, no markers", {"report_position_sigma": 3.0, "ground_control": False})):
        result = plan_views(PlanRequest.of("arc", 4, evaluations=1, **fields), realizations)
        rewards[name] = result.reward
    assert rewards["gnss, markers"] == pytest.approx(rewards["rtk"], abs=1e-9) and rewards["rtk"] > 0.1
    assert rewards["gnss, no markers"] < 0.01 * rewards["rtk"], rewards
