"""Atomic output files: written to a temporary file beside the target, then renamed over it.

A failure in the middle of an export leaves no partial file at the target (and the temporary file is
removed); an input is never overwritten: :func:`check_output` refuses a target that is the input file.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from planner.errors import PlannerError


def check_output(target, *inputs) -> Path:
    """``target`` as a Path, or PlannerError when it names one of the ``inputs`` (never overwrite an input)."""
    out = as_path(target, "target")
    for src in inputs:
        if src is None:
            continue
        src = as_path(src, "input")
        if out.exists() and src.exists() and out.resolve() == src.resolve():
            raise PlannerError(f"{out}: is the input file; refusing to overwrite it")
    return out


def as_path(target, name: str = "target") -> Path:
    """A file name (str or os.PathLike) as a Path, or PlannerError naming ``name`` (None, numbers, lists, ...)."""
    if not isinstance(target, str | os.PathLike) or isinstance(target, bytes):
        raise PlannerError(f"{name} must be a file name (str or path), got {type(target).__name__}")
    text = os.fspath(target)
    if not isinstance(text, str) or not text or "\0" in text:
        raise PlannerError(f"{name} must be a file name, got {text!r}")
    return Path(text)


def _umask_mode() -> int:
    """The mode a new file gets from the process umask (mkstemp makes 0600 files)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def _atomic(target, mode: str, **options) -> Iterator[IO]:
    """A file opened with ``mode`` that appears at ``target`` (its parent made) only when the block completes;
    on any failure, the temporary file is removed and an existing target is untouched."""
    out = as_path(target)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent)
    try:
        with os.fdopen(fd, mode, **options) as f:
            yield f
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, out)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


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
