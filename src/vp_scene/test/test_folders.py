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


HOLD = ("import sys\nfrom vp_scene.folders import FolderLock\nlock = FolderLock(sys.argv[1])\n"
        "print('held', flush=True)\nsys.stdin.read()\n")


def test_a_folder_held_by_a_live_process_is_refused_and_freed_by_its_death(tmp_path: Path) -> None:
    """Two runs wrote into one output folder at once (make run twice into one --out: two plan
    folders, one summary, a recording of two recorders). A folder another live process holds is
    refused in one line naming it and that process; a SIGKILL of the holder leaves no lock and no
    file behind (the kernel's flock, not a marker file)."""
    import signal
    import subprocess
    import sys

    from vp_scene.folders import FolderInUse, FolderLock, ResultFolder

    folder = tmp_path / "out"
    folder.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(FolderInUse) as refused:
            FolderLock(folder)
        assert str(refused.value) == (f"--out {folder} is in use by another run (pid {holder.pid}): wait until it "
                                      "ends, or give another --out")
        with pytest.raises(FolderInUse):
            ResultFolder(folder, ["recon.json"], "recon").check()
        holder.send_signal(signal.SIGKILL)
        assert holder.wait(10) == -signal.SIGKILL
    finally:
        if holder.poll() is None:
            holder.kill()
    with FolderLock(folder) as lock:
        assert lock.fd is not None
    assert list(folder.iterdir()) == []


def test_a_lock_goes_with_its_folder_and_a_result_holds_it_until_committed(tmp_path: Path) -> None:
    from vp_scene.folders import FolderInUse, FolderLock, ResultFolder, move_aside

    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "summary.json").write_text("{}")
    with FolderLock(folder):
        moved = move_aside(folder)  # as make run moves an earlier run aside, holding it
        folder.mkdir()
        with pytest.raises(FolderInUse):
            FolderLock(moved)
        FolderLock(folder).release()  # the new folder at the path is another one
    FolderLock(moved).release()
    result = ResultFolder(folder, ["recon.json"], "recon")
    with result:
        (result.stage / "recon.json").write_text("{}")
        with pytest.raises(FolderInUse):  # the stage's folder is held while the command writes
            FolderLock.check(folder)
        result.commit()
        FolderLock.check(folder)  # and free once committed
    assert (folder / "recon.json").is_file()


def test_a_folder_moved_aside_while_it_is_being_locked_is_not_the_one_held(tmp_path: Path, monkeypatch) -> None:
    """A run that opened --out just before another moved it aside (and made a new one) would hold
    the moved folder while writing by path into the new one: the lock is taken again on the folder
    the path names once it is held."""
    import fcntl
    import os

    from vp_scene import folders

    folder, moved = tmp_path / "out", tmp_path / "out-earlier"
    folder.mkdir()
    real, calls = fcntl.flock, []

    def flock_after_a_move(fd: int, op: int) -> None:
        if not calls:  # the other run moves the folder aside between our open and our lock
            folder.rename(moved)
            folder.mkdir()
        calls.append(os.fstat(fd).st_ino)
        real(fd, op)

    monkeypatch.setattr(folders.fcntl, "flock", flock_after_a_move)
    with folders.FolderLock(folder) as lock:
        assert calls == [moved.stat().st_ino, folder.stat().st_ino]
        assert os.fstat(lock.fd).st_ino == folder.stat().st_ino
