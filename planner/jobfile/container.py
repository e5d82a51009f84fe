"""The saved job's container: a ZIP archive of ``manifest.json`` and one ``.npy`` file per array pool.

Written deterministically (fixed entry order and dates: the same job gives the same bytes). Read with bounds
fixed before anything is decompressed: only stored or deflated entries, no duplicates, every declared size
within :data:`MAX_TOTAL` and within :data:`MAX_EXPANSION` times the size of the file; a ``.npy`` entry's header
is parsed alone (no pickle: only the dtypes of :data:`~planner.jobfile.codec.DTYPES`, one dimension) and its
element count checked against the entry's size before the data are read.
"""

from __future__ import annotations

import io
import json
import os
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np
from numpy.lib import format as npy

from planner.jobfile.codec import DTYPES, Damaged, Foreign

MANIFEST = "manifest.json"
#: Folder of the array pools inside the archive.
ARRAYS = "arrays/"
#: Largest total of the entries' declared (uncompressed) sizes, bytes.
MAX_TOTAL = 8 * 2**30
#: The entries together may hold at most this many times the bytes of the file (plus :data:`SLACK`): a
#: planned job's arrays and manifest deflate by about 2 to 5.
MAX_EXPANSION = 64
SLACK = 2**20
#: Largest number of entries.
MAX_ENTRIES = 10_000
#: How the first bytes of a ZIP archive (a local file header) read.
ZIP_MAGIC = b"PK\x03\x04"
_DATE = (1980, 1, 1, 0, 0, 0)


def pack(manifest: dict, pools: dict[str, np.ndarray]) -> bytes:
    """The archive's bytes: the manifest (compact JSON, deflated), then the pools in name order."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", allowZip64=True) as z:
        _put(z, MANIFEST, json.dumps(manifest, separators=(",", ":"), ensure_ascii=False,
                                     allow_nan=False).encode("utf-8"))
        for name in sorted(pools):
            out = io.BytesIO()
            npy.write_array(out, np.ascontiguousarray(pools[name]), version=(1, 0), allow_pickle=False)
            _put(z, f"{ARRAYS}{name}.npy", out.getvalue())
    return buf.getvalue()


def _put(z: zipfile.ZipFile, name: str, data: bytes) -> None:
    info = zipfile.ZipInfo(name, date_time=_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    z.writestr(info, data, compresslevel=6)


def unpack(source, name: str) -> tuple[object, dict[str, np.ndarray]]:
    """The manifest (parsed JSON, not yet checked) and the pools (name -> 1-D array) of an archive.

    ``source``: a path or bytes; ``name`` names it in messages. Raises :class:`Damaged` (or
    :class:`~planner.errors.PlannerError` for an unreadable path).
    """
    f, size = _open(source, name)
    try:
        with f, zipfile.ZipFile(f) as z:
            infos = _checked_entries(z, size)
            manifest = _manifest(z, infos)
            pools = {}
            for key, info in infos.items():
                if key.startswith(ARRAYS) and key.endswith(".npy") and len(key) > len(ARRAYS) + 4:
                    pools[key[len(ARRAYS):-4]] = _array(z, info)
                elif key != MANIFEST:
                    raise Damaged(f"unexpected entry {key[:60]!r}")
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError, struct.error, NotImplementedError,
            RuntimeError, ValueError, OSError) as exc:
        if isinstance(exc, Damaged):
            raise
        raise Damaged(f"not a readable archive ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") from None
    return manifest, pools


def _open(source, name: str):
    if isinstance(source, bytes | bytearray | memoryview):
        data = bytes(source)
        return io.BytesIO(data), len(data)
    from planner.errors import PlannerError

    try:
        f = Path(os.fspath(source)).open("rb")
    except OSError as exc:
        raise PlannerError(f"{name}: cannot read the saved job ({exc.strerror or type(exc).__name__})") from None
    return f, os.fstat(f.fileno()).st_size


def _checked_entries(z: zipfile.ZipFile, size: int) -> dict[str, zipfile.ZipInfo]:
    infos = z.infolist()
    if len(infos) > MAX_ENTRIES:
        raise Damaged(f"{len(infos)} entries (at most {MAX_ENTRIES})")
    out: dict[str, zipfile.ZipInfo] = {}
    total = 0
    budget = min(MAX_TOTAL, MAX_EXPANSION * size + SLACK)
    for info in infos:
        if info.filename in out:
            raise Damaged(f"entry {info.filename[:60]!r} appears twice")
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise Damaged(f"entry {info.filename[:60]!r}: compression method {info.compress_type} (the format "
                          "uses stored or deflated entries only)")
        if info.flag_bits & 0x1:
            raise Damaged(f"entry {info.filename[:60]!r} is encrypted")
        if info.compress_size > size or info.file_size < 0:
            raise Damaged(f"entry {info.filename[:60]!r} declares {info.compress_size} bytes in a file of {size}")
        total += info.file_size
        if total > budget:
            raise Damaged(f"the entries declare {total} bytes, more than the format allows for a file of {size} "
                          f"bytes ({budget}): not a job this planner wrote")
        out[info.filename] = info
    return out


def _read(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> bytes:
    """The entry's bytes: at most its declared size (checked against the budget); CRC checked."""
    with z.open(info) as f:
        data = f.read(info.file_size + 1)
    if len(data) != info.file_size:
        raise Damaged(f"entry {info.filename[:60]!r} holds {len(data)} bytes, not the {info.file_size} declared")
    return data


def _manifest(z: zipfile.ZipFile, infos: dict) -> object:
    if MANIFEST not in infos:
        raise Foreign(f"a ZIP archive without {MANIFEST}")
    text = _read(z, infos[MANIFEST])
    try:
        return json.loads(text.decode("utf-8"), parse_constant=_no_constant, object_pairs_hook=_unique_keys)
    except UnicodeDecodeError:
        raise Damaged(f"{MANIFEST} is not UTF-8 text") from None
    except RecursionError:
        raise Damaged(f"{MANIFEST} nests too deeply") from None
    except ValueError as exc:  # JSONDecodeError, a duplicate key, a number of too many digits
        raise Damaged(f"{MANIFEST} is not valid JSON ({' '.join(str(exc).split())[:120]})") from None


def _no_constant(token: str):
    raise ValueError(f"{token} is not a JSON number")


def _unique_keys(pairs):
    out = dict(pairs)
    if len(out) != len(pairs):
        raise ValueError("an object has a key twice")
    return out


def _array(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    """One pool: a 1-D .npy of an allowed dtype whose size matches its header (no pickle, no object arrays)."""
    data = _read(z, info)
    f = io.BytesIO(data)
    where = f"entry {info.filename[:60]!r}"
    try:
        version = npy.read_magic(f)
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f"npy version {version}")
        reader = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
        shape, fortran, dtype = reader(f, max_header_size=1024)
    except (ValueError, SyntaxError, TypeError, EOFError) as exc:
        raise Damaged(f"{where}: not a NumPy array file ({' '.join(str(exc).split())[:80]})") from None
    if dtype not in DTYPES.values() or dtype.hasobject:
        raise Damaged(f"{where}: dtype {dtype.str} (the format has {', '.join(d.str for d in DTYPES.values())})")
    if len(shape) != 1 or fortran:
        raise Damaged(f"{where}: shape {shape} (the format's pools are one-dimensional)")
    body = memoryview(data)[f.tell():]
    if shape[0] * dtype.itemsize != len(body):
        raise Damaged(f"{where}: the header declares {shape[0]} elements, the entry holds {len(body)} bytes of data")
    return np.frombuffer(body, dtype=dtype)
