"""Image sizes have one range (vp_scene.camera.IMAGE_SIDE_RANGE), checked where they are given:
the command lines at parse time, the nodes' parameter descriptors, plan files, a flight's
intrinsics (``--width 0`` silently became 2000, a 2000 x 480 render, and ``--width 100000``
failed only at render with a GLError)."""
from __future__ import annotations

import pytest

from vp_scene.camera import IMAGE_SIDE_RANGE, check_image_side


@pytest.mark.parametrize("value", ["0", "15", "16385", "100000", "-640", "2.5"])
def test_the_recon_and_entry_script_flags_refuse_a_size_at_parse_time(value: str, capsys, tmp_path) -> None:
    import run_suite  # tools/, on sys.path through conftest.py
    from vp_recon import cli as recon

    for flag in ("--width", "--height"):
        with pytest.raises(SystemExit) as exc:  # nothing read, nothing written: argparse stops first
            recon.parse_args(["--plan", str(tmp_path / "none.json"), "--out", str(tmp_path / "out"), flag, value])
        err = capsys.readouterr().err
        assert exc.value.code == 2 and err.count("\n") == 1, err
        assert f"recon: error: argument {flag}: must be an integer of 16 to 16384 pixels, got '{value}'" in err, err
        with pytest.raises(SystemExit) as exc:
            run_suite.parse_args([flag, value])
        err = capsys.readouterr().err
        assert exc.value.code == 2 and f"argument {flag}: must be an integer of 16 to 16384 pixels" in err, err
    assert not (tmp_path / "out").exists()


def test_the_bounds_are_the_ones_of_every_command_and_node(tmp_path) -> None:
    """The range's ends are taken everywhere; the planner's flags go through its request (one
    message with the node and the API: test_planner_request)."""
    import run_suite
    from vp_planner import planner_node
    from vp_planner.request import CameraSpec, InvalidRequestError
    from vp_recon import cli as recon
    from vp_recon import recon_node
    from vp_recon.config import ReconConfig
    from vp_scene import sim_drone_node

    lo, hi = IMAGE_SIDE_RANGE
    for ok in (lo, hi):
        assert check_image_side("w", ok) == ok and ReconConfig(width=ok, height=ok).validate().width == ok
        assert run_suite.parse_args(["--width", str(ok)]).width == ok
        assert recon.parse_args(["--plan", "p.json", "--out", str(tmp_path), "--height", str(ok)]).height == ok
        assert CameraSpec(image_size=(ok, ok)).image_size == (ok, ok)
    for bad in (lo - 1, hi + 1, True, 640.5):
        with pytest.raises(ValueError, match="must be an integer of 16 to 16384 pixels"):
            check_image_side("width", bad)
        with pytest.raises(InvalidRequestError, match=f"image width must be an integer of 16 to 16384 pixels, got"):
            CameraSpec(image_size=(bad, 480))
    with pytest.raises(ValueError, match="height must be an integer of 16 to 16384 pixels, got 100000"):
        ReconConfig(height=100000).validate()
    for params, names in ((recon_node.PARAMS, ("width", "height")), (sim_drone_node.PARAMS, ("width", "height")),
                          (planner_node.PARAMS, ("image_width", "image_height"))):
        assert all(tuple(params[n].range) == IMAGE_SIDE_RANGE for n in names), params
