"""Result folders of the suite's commands and nodes (the planner's and the recon's CLIs, the recon
node, ``make run``): a new run folder that is never shared (:func:`new_run_folder`), a folder
moved aside (:func:`move_aside`), a command's result replaced as a whole or not at all
(:class:`ResultFolder`, :class:`OutputExists`), an empty folder removed (:func:`remove_if_empty`),
a folder in use by a live run locked against every other (:class:`FolderLock`, :class:`FolderInUse`),
every result file written whole or not at all (:func:`write_atomic`; a file that cannot be
written is an :class:`OutputError`: one line naming it and why, "the disk is full" for a full
disk or a short write), and scratch folders that a killed run leaves are removed by the next
(:class:`OwnedFolder`, :func:`remove_abandoned`: only those whose owner process is gone); and the
per-user cache folders (:func:`user_cache`)."""
from __future__ import annotations

import errno
import fcntl
import fnmatch
import os
import re
import shutil
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable, Optional, Sequence, Union

__all__ = ["new_run_folder", "remove_if_empty", "OutputExists", "ResultFolder", "move_aside", "FolderLock",
           "FolderInUse", "OutputError", "write_atomic", "user_cache", "OwnedFolder", "remove_abandoned"]

PathLike = Union[str, os.PathLike]


class OutputError(OSError):
    """A result that could not be written: one line naming the file or folder and why."""


def _why(exc: OSError) -> str:
    """Why a write failed, in words: a full disk (ENOSPC, or a write that stopped short, as numpy's
    ``N requested and M written``) is named so, whatever the library's words for it."""
    text = " ".join(str(exc).split())
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return f"the disk is full ({exc.strerror})"
    if exc.errno == errno.EFBIG:
        return f"the file is larger than the disk or the process's file size limit allows ({exc.strerror})"
    if exc.errno is None and re.search(r"\d+ requested and \d+ written", text):
        return f"the disk is full (a short write: {text})"
    return exc.strerror or text


def write_atomic(path: PathLike, write: Callable[[Path], object]) -> Path:
    """Write the file ``path`` whole or not at all: ``write(tmp)`` writes a hidden temporary
    sibling, which is then renamed over ``path`` (a reader never sees half a file; a failed write
    leaves no temporary; each process and thread writes a temporary of its own, so two writers of
    one path never write into one file). OutputError naming ``path`` when anything fails (the
    folder missing, a full disk, a folder where the file goes)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise OutputError(f"could not write {path}: {_why(exc)}") from None
    return path


def user_cache(name: str, env: str) -> Path:
    """A per-user cache folder: ``$<env>`` when set, else ``$XDG_CACHE_HOME/vp_suite/<name>``
    (default ``~/.cache/vp_suite/<name>``)."""
    if os.environ.get(env):
        return Path(os.environ[env])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "vp_suite" / name


def _process_alive(pid: int) -> bool:
    """Whether a process of this id runs here (a zombie has ended: its files and locks are closed)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def remove_abandoned(parent: PathLike, prefix: str) -> list[Path]:
    """Remove the folders ``parent/<prefix><pid>-*`` (:class:`OwnedFolder`) whose owner is gone:
    no process of that pid runs here and none holds the folder's lock (an owner on another host
    or in another container, which this pid check cannot see, holds it); the folders removed.
    A folder of a live owner is never touched; one that cannot be removed stays."""
    parent = Path(parent)
    pattern = re.compile(re.escape(prefix) + r"(\d+)-[^-]+\Z")
    removed = []
    try:
        entries = list(parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        m = pattern.match(entry.name)
        if m is None or int(m.group(1)) == os.getpid() or _process_alive(int(m.group(1))):
            continue
        try:
            fd = os.open(entry, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
        except OSError:  # gone meanwhile, or not a folder
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: its owner lives elsewhere
            os.close(fd)
            continue
        try:
            shutil.rmtree(entry, ignore_errors=True)
        finally:
            os.close(fd)
        if not entry.exists():
            removed.append(entry)
    return removed


class OwnedFolder:
    """A new folder ``parent/<prefix><pid>-<random>`` (default parent: the temporary directory)
    that this process owns: the name carries the owner's pid, and the process holds an OS lock
    (flock) on the folder until :meth:`remove` or :meth:`release`, or until it dies (the kernel
    drops the lock, SIGKILL included). Making one first removes the folders of the same prefix
    whose owner is gone (:func:`remove_abandoned`): what a killed run left, the next run cleans
    up. OSError when the folder cannot be made."""

    def __init__(self, prefix: str, parent: Optional[PathLike] = None) -> None:
        parent = Path(tempfile.gettempdir() if parent is None else parent)
        remove_abandoned(parent, prefix)
        self.path = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-", dir=parent))
        try:
            self._fd: Optional[int] = os.open(self.path, os.O_RDONLY | os.O_DIRECTORY)
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            shutil.rmtree(self.path, ignore_errors=True)
            raise

    def release(self) -> None:
        """Give up the lock (the folder itself stays, e.g. renamed or emptied by its user)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def remove(self) -> None:
        """Delete the folder and what it holds, then give up the lock."""
        shutil.rmtree(self.path, ignore_errors=True)
        self.release()


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
    killed with SIGKILL leaves its stage, which the next run into ``out`` removes when it makes
    its own (:class:`OwnedFolder`: only a stage whose owner process is gone).
    """

    def __init__(self, out: PathLike, names: Sequence[str], tool: str, overwrite: bool = False) -> None:
        self.out = Path(out)
        self.names = tuple(names)
        self.tool = tool
        self.overwrite = bool(overwrite)
        self._made = not os.path.lexists(self.out)  # removed again when nothing is committed
        self._stage: Optional[OwnedFolder] = None
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
        FolderInUse when another run holds it, OutputError when it cannot be made)."""
        if self._stage is None:
            try:
                self.out.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise OutputError(f"could not make a folder in {self.out}: {_why(exc)}") from None
            if self._lock is None:
                self._lock = FolderLock(self.out)
            try:
                self._stage = OwnedFolder(f".partial-{self.tool}-", self.out)
            except OSError as exc:
                raise OutputError(f"could not make a folder in {self.out}: {_why(exc)}") from None
        return self._stage.path

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
        try:  # renames within one folder: no data is written, but the folder may have gone
            trash = Path(tempfile.mkdtemp(prefix=f".replaced-{self.tool}-", dir=self.out)) if old else None
            for name in old:
                os.replace(self.out / name, trash / name)
            for p in new:
                os.replace(p, self.out / p.name)
            stage.rmdir()
        except OSError as exc:
            raise OutputError(f"could not move the result into {self.out}: {_why(exc)}") from None
        self._stage.release()
        self._stage, self.committed = None, True
        if trash is not None:
            shutil.rmtree(trash, ignore_errors=True)
        self._release()
        return self.out

    def discard(self) -> None:
        """Remove the stage (what was written so far), and ``out`` when this made it and it is empty."""
        if self._stage is not None:
            self._stage.remove()
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
