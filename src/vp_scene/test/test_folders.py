"""vp_scene.folders: run folders are never shared."""
from __future__ import annotations

import time
from pathlib import Path

import pytest

from vp_scene.folders import new_run_folder


def test_two_plans_in_the_same_second_get_two_folders(tmp_path: Path) -> None:
    """Issue 10, item 5: the recon node named its folder plan-<seconds>, so two plans that
    started in the same second wrote into one folder, the second overwriting the first."""
    now = time.time()
    first = new_run_folder(tmp_path, now=now)
    (first / "recon_0.ply").write_text("first plan")
    second = new_run_folder(tmp_path, now=now)
    third = new_run_folder(tmp_path, now=now)
    assert len({first, second, third}) == 3 and all(p.is_dir() for p in (first, second, third))
    assert second.name == first.name + "-2" and third.name == first.name + "-3"
    assert (first / "recon_0.ply").read_text() == "first plan" and not list(second.iterdir())


def test_run_folder_in_an_unusable_root(tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.raises(OSError):
        new_run_folder(blocker / "sub")
