"""vp_scene.folders: run folders are never shared."""
from __future__ import annotations

import time
from pathlib import Path

import pytest

from vp_scene.folders import new_run_folder


def test_two_plans_in_the_same_second_get_two_folders(tmp_path: Path) -> None:
    """The recon node named its folder plan-<seconds>, so two plans that
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


def test_a_file_that_cannot_be_written_is_one_line_naming_it_and_leaves_nothing(tmp_path: Path) -> None:
    """write_atomic: the file whole or not at all; a failure is an OutputError naming the file and
    why, a full disk said so whether the OS (ENOSPC) or a library's short write ('N requested and
    M written', numpy's words) reports it; no temporary is left."""
    import errno

    from vp_scene.folders import OutputError, write_atomic

    assert write_atomic(tmp_path / "a.json", lambda tmp: tmp.write_text("{}")).read_text() == "{}"

    def fails(error: OSError):
        def write(tmp: Path) -> None:
            tmp.write_bytes(b"half")
            raise error
        return write

    for error, words in ((OSError(errno.ENOSPC, "No space left on device"), "the disk is full (No space left"),
                         (OSError("60000 requested and 12784 written"),
                          "the disk is full (a short write: 60000 requested and 12784 written)"),
                         (OSError(errno.EFBIG, "File too large"), "file size limit allows (File too large)")):
        with pytest.raises(OutputError) as ei:
            write_atomic(tmp_path / "b.npy", fails(error))
        text = str(ei.value)
        assert text.startswith(f"could not write {tmp_path / 'b.npy'}: ") and words in text and "\n" not in text
    (tmp_path / "c.ply").mkdir()  # a folder where the file goes
    with pytest.raises(OutputError, match=f"could not write {tmp_path / 'c.ply'}: Is a directory"):
        write_atomic(tmp_path / "c.ply", lambda tmp: tmp.write_bytes(b"x"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "c.ply"]  # no temporary left


_HOLD = """
import sys, time
from pathlib import Path
from vp_scene.folders import OwnedFolder
f = OwnedFolder(sys.argv[1], Path(sys.argv[2]))
print(f.path, flush=True)
sys.stdin.read()
"""


def test_a_killed_owners_folder_is_removed_by_the_next_and_a_live_ones_never(tmp_path: Path) -> None:
    """OwnedFolder: a process SIGKILLed leaves its folder (<prefix><pid>-*); the next OwnedFolder of
    that prefix removes it. A live owner's folder stays, and so does one whose pid is gone here
    but whose lock another process holds (an owner on another host or in another container)."""
    import os
    import signal
    import subprocess
    import sys

    from vp_scene.folders import OwnedFolder

    def hold(prefix: str = "vp_test_") -> tuple:
        proc = subprocess.Popen([sys.executable, "-c", _HOLD, prefix, str(tmp_path)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True)
        return proc, Path(proc.stdout.readline().strip())

    (killed, left), (live, kept) = hold(), hold()
    assert left.is_dir() and left.name.startswith(f"vp_test_{killed.pid}-") and kept.is_dir()
    (left / "database.db").write_bytes(b"x" * 1000)
    os.kill(killed.pid, signal.SIGKILL)
    killed.wait(30)
    assert left.is_dir()  # left behind by the kill
    # a folder named for the dead pid but locked by a live process: its owner is elsewhere
    (elsewhere_proc, elsewhere) = hold("vp_other_")
    foreign = tmp_path / f"vp_test_{killed.pid}-foreign"
    os.rename(elsewhere, foreign)
    other = tmp_path / "vp_test_notours"
    other.mkdir()
    try:
        mine = OwnedFolder("vp_test_", tmp_path)
        assert not left.exists() and kept.is_dir() and foreign.is_dir() and other.is_dir()
        assert mine.path.name.startswith(f"vp_test_{os.getpid()}-")
        mine.remove()
        assert not mine.path.exists()
    finally:
        for p in (live, elsewhere_proc):
            p.stdin.close()
            p.wait(30)
    OwnedFolder("vp_test_", tmp_path).remove()  # their owners gone: removed now
    assert not kept.exists() and not foreign.exists() and other.is_dir()
