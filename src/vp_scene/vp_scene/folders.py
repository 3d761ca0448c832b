"""Result folders of the suite's commands and nodes (the planner's and the recon's CLIs, the recon
node, ``make run``): a new run folder that is never shared (:func:`new_run_folder`), a folder
moved aside (:func:`move_aside`), a command's result replaced as a whole or not at all
(:class:`ResultFolder`, :class:`OutputExists`), an empty folder removed (:func:`remove_if_empty`),
a folder in use by a live run locked against every other (:class:`FolderLock`, :class:`FolderInUse`)."""
from __future__ import annotations

import fcntl
import fnmatch
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Optional, Sequence, Union

__all__ = ["new_run_folder", "remove_if_empty", "OutputExists", "ResultFolder", "move_aside", "FolderLock",
           "FolderInUse"]

PathLike = Union[str, os.PathLike]


def new_run_folder(root: PathLike, prefix: str = "plan", now: Optional[float] = None) -> Path:
    """A new, empty folder ``root/<prefix>-<YYYYmmdd-HHMMSS>`` for one plan's outputs, never one
    that exists: a second plan in the same second gets ``-2``, then ``-3``, ... (the folder is
    created here, atomically, so two callers cannot get the same one). OSError when ``root``
    cannot hold it."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(now))
    for n in range(1, 10000):
        folder = root / (f"{prefix}-{stamp}" if n == 1 else f"{prefix}-{stamp}-{n}")
        try:
            folder.mkdir()
        except FileExistsError:
            continue
        return folder
    raise FileExistsError(f"no free {prefix}-{stamp}-<n> folder in {root}")


def remove_if_empty(folder: Optional[PathLike]) -> bool:
    """Remove ``folder`` when it holds no file (empty sub-folders are removed with it); True when
    it is gone. Only ``os.rmdir`` is used, which never deletes a file: a file written meanwhile
    by another thread keeps the folder (and is never lost)."""
    if folder is None or not Path(folder).is_dir():
        return folder is not None
    for parent, _dirs, _files in sorted(os.walk(folder), key=lambda t: -len(Path(t[0]).parts)):
        try:
            os.rmdir(parent)
        except OSError:
            return False
    return True


class FolderInUse(OSError):
    """An output folder that another live run holds (:class:`FolderLock`; the CLIs and ``make
    run``: one line, exit 2)."""


def _lock_holder(st: os.stat_result) -> Optional[int]:
    """The live process that took the flock on the file of ``st`` (Linux's /proc/locks), or None."""
    key = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return None
    for fields in (line.split() for line in lines):
        if len(fields) > 5 and fields[1] == "FLOCK" and fields[5] == key and fields[4].isdigit():
            pid = int(fields[4])
            return pid if pid > 0 and Path(f"/proc/{pid}").exists() else None
    return None


class FolderLock:
    """An exclusive lock on an existing folder, for as long as a run writes into it: ``flock`` on the
    folder's own descriptor (:attr:`fd`). The kernel releases it when the last process holding the
    descriptor ends, by a SIGKILL too, and nothing is written into the folder: a crash leaves no
    lock behind, unlike a marker file. A child process given :attr:`fd` (``pass_fds``) holds the
    lock with its parent. The lock goes with the folder when it is renamed; a path that names
    another folder once the lock is taken (moved aside meanwhile by the run that held it) is locked
    again. :class:`FolderInUse` when another run holds it (the message names the folder as the
    option ``flag`` that gave it, and the holder's pid), FileNotFoundError when it is missing."""

    def __init__(self, folder: PathLike, flag: str = "--out") -> None:
        self.folder = Path(folder)
        while True:
            fd = os.open(self.folder, os.O_RDONLY | os.O_DIRECTORY)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _lock_holder(os.fstat(fd))
                os.close(fd)
                by = f" (pid {holder})" if holder is not None else ""
                raise FolderInUse(f"{flag} {self.folder} is in use by another run{by}: wait until it ends, "
                                  f"or give another {flag}") from None
            held, now = os.fstat(fd), os.stat(self.folder)
            if (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino):
                self.fd: Optional[int] = fd
                return
            os.close(fd)  # the path names another folder now: lock that one

    @staticmethod
    def check(folder: PathLike, flag: str = "--out") -> None:
        """FolderInUse when another run holds ``folder`` (a missing folder is held by none)."""
        if Path(folder).is_dir():
            FolderLock(folder, flag).release()

    def release(self) -> None:
        """Give the lock up (idempotent); children given :attr:`fd` keep holding it until they end."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None

    def __enter__(self) -> "FolderLock":
        return self

    def __exit__(self, *_exc) -> None:
        self.release()


class OutputExists(FileExistsError):
    """An output folder that already holds the result a command would write there (the CLIs: one
    line, exit 2, the hint ``--overwrite``)."""


class ResultFolder:
    """A command's result in the folder ``out``, written where it cannot mix with an earlier one.

    ``names`` (fnmatch patterns) are the entries of the command's result (e.g. ``recon.json``,
    ``recon_*.ply``); other entries of ``out`` (the plan beside its reconstruction) are never
    touched. :meth:`check` refuses an ``out`` that holds an earlier result (any entry named so:
    :class:`OutputExists`) unless ``overwrite``, and one that another live run holds
    (:class:`FolderInUse`); from :attr:`stage` on, this one holds ``out`` (:class:`FolderLock`) until
    the commit or the discard. The command writes into :attr:`stage`, a hidden
    folder ``out/.partial-<tool>-<random>``; :meth:`commit` moves the earlier result's entries
    into a hidden folder, the new ones into ``out``, then deletes the earlier ones: ``out`` holds
    one result or the other, never a mix. Leaving a ``with`` block without a commit (an error, an
    interrupt) removes the stage, and ``out`` when it did not exist before and is empty. A run
    killed with SIGKILL leaves its stage (hidden; a later run ignores it).
    """

    def __init__(self, out: PathLike, names: Sequence[str], tool: str, overwrite: bool = False) -> None:
        self.out = Path(out)
        self.names = tuple(names)
        self.tool = tool
        self.overwrite = bool(overwrite)
        self._made = not os.path.lexists(self.out)  # removed again when nothing is committed
        self._stage: Optional[Path] = None
        self._lock: Optional[FolderLock] = None
        self.committed = False

    def _named(self, name: str) -> bool:
        return any(fnmatch.fnmatchcase(name, n) for n in self.names)

    def earlier(self) -> list[str]:
        """The entries of an earlier result in ``out``, sorted (none: ``[]``)."""
        if not self.out.is_dir():
            return []
        return sorted(p.name for p in self.out.iterdir() if self._named(p.name))

    def check(self) -> "ResultFolder":
        """FolderInUse when another run holds ``out``; OutputExists when it holds an earlier result
        and ``overwrite`` is not set."""
        FolderLock.check(self.out)
        found = self.earlier()
        if found and not self.overwrite:
            shown = ", ".join(found[:3]) + (", ..." if len(found) > 3 else "")
            raise OutputExists(f"{self.out} already holds a result ({shown}): give --overwrite to replace it "
                               "when this run succeeds, or another --out")
        return self

    @property
    def stage(self) -> Path:
        """The folder the command writes into (made, with ``out``, on first use, ``out`` then locked;
        FolderInUse when another run holds it, OSError when it cannot be made)."""
        if self._stage is None:
            self.out.mkdir(parents=True, exist_ok=True)
            if self._lock is None:
                self._lock = FolderLock(self.out)
            self._stage = Path(tempfile.mkdtemp(prefix=f".partial-{self.tool}-", dir=self.out))
        return self._stage

    def _release(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def commit(self) -> Path:
        """Move the staged result into ``out``, replacing an earlier one as a whole; ``out``."""
        stage = self.stage
        new = sorted(stage.iterdir())
        stray = [p.name for p in new if not self._named(p.name)]
        if stray:  # a bug of the command: it could replace a file that is not its own
            raise ValueError(f"{', '.join(stray)} in {stage} is not part of a {self.tool} result")
        old = self.earlier()
        trash = Path(tempfile.mkdtemp(prefix=f".replaced-{self.tool}-", dir=self.out)) if old else None
        for name in old:
            os.replace(self.out / name, trash / name)
        for p in new:
            os.replace(p, self.out / p.name)
        stage.rmdir()
        self._stage, self.committed = None, True
        if trash is not None:
            shutil.rmtree(trash, ignore_errors=True)
        self._release()
        return self.out

    def discard(self) -> None:
        """Remove the stage (what was written so far), and ``out`` when this made it and it is empty."""
        if self._stage is not None:
            shutil.rmtree(self._stage, ignore_errors=True)
            self._stage = None
        if self._made:
            remove_if_empty(self.out)
        self._release()

    def __enter__(self) -> "ResultFolder":
        return self

    def __exit__(self, *_exc) -> None:
        if not self.committed:
            self.discard()


def move_aside(folder: PathLike) -> Path:
    """Rename ``folder`` to a new sibling ``<name>-<YYYYmmdd-HHMMSS>[-n]`` stamped with the time
    of its newest entry (when its run last wrote); the new path. Nothing is deleted."""
    folder = Path(folder)
    times = [p.stat().st_mtime for p in folder.iterdir()] or [folder.stat().st_mtime]
    target = new_run_folder(folder.parent, prefix=folder.name, now=max(times))
    os.replace(folder, target)  # over the empty folder just made for it (atomic: no other can take it)
    return target
