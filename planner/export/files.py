"""Atomic output files: written to a temporary file beside the target, then renamed over it.

Every output file of the project (exports, saved jobs, plots, recordings, the service's stored files) is written
here, by :func:`_atomic`. A failure in the middle of an export leaves no partial file at the target (and the
temporary file is removed); an input is never overwritten: :func:`check_output` refuses a target that is an input
file, by name, through a symbolic link or as a hard link of it.

A target that is a symbolic link (or a chain of them) is written at the file the link names: the link stays a
link and its target gets the new contents (a dangling link: its target is created, in the folder the link names,
which must exist). A target that is not a regular file (a directory, a FIFO, a device such as /dev/null, a
socket) is refused by :func:`output_target` with a one-line :class:`PlannerError` naming the path and what it is,
before anything is written.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from planner.errors import PlannerError

#: What a file that is not a regular one is, for a person (stat's test, words).
_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


@dataclass(frozen=True)
class OutputTarget:
    """Where an output named ``path`` is written.

    path: the name given; file: the file replaced (``path`` itself, or the end of its chain of symbolic links,
    absolute); existing: the file's ``os.stat`` if it exists (a regular file), else None (a new file)."""

    path: Path
    file: Path
    existing: os.stat_result | None

    @property
    def mode(self) -> int | None:
        """The permission bits the written file keeps (an existing file's), or None for a new file."""
        return None if self.existing is None else stat.S_IMODE(self.existing.st_mode)


def _kind(mode: int) -> str:
    for test, words in _KINDS:
        if test(mode):
            return words
    return "not a regular file"


def output_target(target, name: str = "target") -> OutputTarget:
    """The file an output named ``target`` replaces (see the module doc), or PlannerError naming the path and
    what is wrong: a directory, FIFO, device, socket or other non-regular file (at the end of its links, if any),
    a loop of symbolic links, a dangling link into a folder that does not exist, a path through a file."""
    out = as_path(target, name)
    shown = os.fspath(out)
    try:
        st: os.stat_result | None = os.stat(out)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise PlannerError(f"{shown}: a loop of symbolic links; refusing to write through it") from None
        if exc.errno == errno.ENOTDIR:
            raise PlannerError(f"{shown}: a part of the path before the file name is a file, not a folder") from None
        raise PlannerError(f"{shown}: cannot be written ({exc.strerror})") from None
    is_link = os.path.islink(out)
    file = Path(os.path.realpath(out))
    via = f"a symbolic link to {file}, which is " if is_link else "is "
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise PlannerError(f"{shown}: {via}{_kind(st.st_mode)}, not a regular file; refusing to write to it")
    if st is None and not file.parent.is_dir():
        if is_link:
            raise PlannerError(f"{shown}: a symbolic link to {file}, whose folder {file.parent} does not exist")
        folder = Path(os.path.abspath(out)).parent  # missing folders are made, but not at the end of a link
        while not os.path.lexists(folder):
            folder = folder.parent
        if os.path.islink(folder):
            raise PlannerError(f"{shown}: its folder {folder} is a symbolic link to {os.path.realpath(folder)}, "
                               "which does not exist")
    return OutputTarget(out, file, st)


def check_output(target, *inputs) -> Path:
    """``target`` as a Path, checked by :func:`output_target`; PlannerError when it is one of the ``inputs`` (the
    same file: by name, through symbolic links, or a hard link of it): an input is never overwritten."""
    t = output_target(target)
    if t.existing is None:
        return t.path
    for src in inputs:
        if src is None:
            continue
        src = as_path(src, "input")
        try:
            s = os.stat(src)
        except OSError:
            continue
        if (s.st_dev, s.st_ino) == (t.existing.st_dev, t.existing.st_ino):
            how = []
            if os.path.islink(t.path):
                how.append(f"a symbolic link to {t.file}")
            if os.path.realpath(src) != os.fspath(t.file):
                how.append(f"a hard link of {os.path.realpath(src)}")
            raise PlannerError(f"{t.path}: is the input file; refusing to overwrite it"
                               + (f" ({', '.join(how)})" if how else ""))
    return t.path


def as_path(target, name: str = "target") -> Path:
    """A file name (str or os.PathLike) as a Path, or PlannerError naming ``name`` (None, numbers, lists, ...)."""
    if not isinstance(target, str | os.PathLike) or isinstance(target, bytes):
        raise PlannerError(f"{name} must be a file name (str or path), got {type(target).__name__}")
    text = os.fspath(target)
    if not isinstance(text, str) or not text or "\0" in text:
        raise PlannerError(f"{name} must be a file name, got {text!r}")
    return Path(text)


def _umask_mode() -> int:
    """The mode a new file gets from the process umask (mkstemp makes 0600 files). Read from /proc where it is
    shown, so that no other thread ever creates a file while the umask is changed to read it."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _fsync_folder(folder: Path) -> None:
    """The rename made durable (where a folder can be opened and synced)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def _atomic(target, mode: str, **options) -> Iterator[IO]:
    """A file opened with ``mode`` that appears at ``target`` (see :func:`output_target`: through symbolic links,
    a regular file only; a plain name's missing folders made) only when the block completes, with an existing
    file's permissions (a new file: the umask's); its data synced to disk before the rename. On any failure the
    temporary file is removed and an existing target is untouched."""
    t = output_target(target)
    folder = t.file.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{t.file.name[:100]}.", suffix=".part", dir=folder)  # a name <= 255
    except OSError as exc:
        raise PlannerError(f"{t.path}: cannot write in the folder {folder} ({exc.strerror})") from None
    try:
        with os.fdopen(fd, mode, **options) as f:
            yield f
            f.flush()
            os.fchmod(f.fileno(), _umask_mode() if t.mode is None else t.mode)
            os.fsync(f.fileno())
        os.replace(tmp, t.file)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_folder(folder)


def atomic_text(target):
    """A text file (UTF-8, "\\n" newlines) that appears at ``target`` only when the block completes."""
    return _atomic(target, "w", encoding="utf-8", newline="\n")


def atomic_binary(target):
    """A binary file that appears at ``target`` only when the block completes (for writers that stream)."""
    return _atomic(target, "wb")


def write_bytes_atomic(target, data: bytes) -> None:
    """Write ``data`` (bytes) to ``target`` atomically."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise PlannerError(f"data must be bytes, got {type(data).__name__}")
    with atomic_binary(target) as f:
        f.write(data)


@contextlib.contextmanager
def text_target(target) -> Iterator[IO[str]]:
    """An open text file for ``target``: the file object itself, or an atomic file at a path."""
    if hasattr(target, "write"):
        yield target
        return
    with atomic_text(target) as f:
        yield f
