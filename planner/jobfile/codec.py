"""Objects to JSON states and pooled arrays, and back: the typed fields of the saved-job format.

A :class:`Kind` describes one field of a stored type: how a value is written into the manifest (JSON) and how
a value read from a file is checked and rebuilt. The :class:`Encoder` turns an object graph into the list of
``[type, state]`` entries and the array pools; the :class:`Decoder` rebuilds it, entry by entry in file order,
with every field checked against its kind before any object is built (types by name from the fixed table,
references only to earlier entries, arrays only as slices of the pools within their sizes). Nothing here
knows the planner's classes: the table (:class:`StoredType` entries) is given by the caller.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from planner.errors import PlannerError

#: Element types of the array pools (little endian): floats, integers, booleans.
DTYPES = {"f8": np.dtype("<f8"), "i8": np.dtype("<i8"), "b1": np.dtype("|b1")}
#: Largest integer a field holds (int64 range with margin).
INT_LIMIT = 2**62
#: Largest magnitude of a (finite) element of a float array: far beyond any figure of a robot cell (the budget keeps
#: coordinates within 5 km and a trajectory within 1e12 poses), small enough that no evaluation overflows.
MAX_MAGNITUDE = 1e15
#: Non-finite floats are written as these strings (JSON has no NaN or infinity).
NONFINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}


class Damaged(PlannerError):
    """A saved job's contents do not match the format (the message says where)."""


class Foreign(Damaged):
    """The file is not a saved job at all (a ZIP archive without the manifest)."""


class Kind:
    """How one field is written and read. ``group`` is the field's name, "<type>.<field>" (its arrays lie side by
    side in the pools); ``where`` names the place for messages: (object label, field name, list indices...),
    formatted by :func:`_place` only when a message is made."""

    def encode(self, value, enc: Encoder, group: str):
        raise NotImplementedError

    def decode(self, raw, dec: Decoder, group: str, where: tuple):
        raise NotImplementedError

    def text(self) -> str:
        """The kind for the format description."""
        raise NotImplementedError


@dataclass(frozen=True)
class Float(Kind):
    """A float; ``finite=False`` allows NaN and infinities (written "nan", "inf", "-inf")."""

    finite: bool = True

    def encode(self, value, enc, group):
        x = float(value)
        if math.isfinite(x):
            return x
        if self.finite:
            raise PlannerError(f"cannot save the job: {group} is {x}, which the format keeps finite")
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")

    def decode(self, raw, dec, group, where):
        if isinstance(raw, float | int) and not isinstance(raw, bool):
            x = float(raw) if abs(raw) <= 1e308 or isinstance(raw, float) else math.inf
            if math.isfinite(x):
                return x
        elif not self.finite and isinstance(raw, str) and raw in NONFINITE:
            return NONFINITE[raw]
        raise Damaged(f"{_place(where)}: expected a {'finite ' * self.finite}number, got {_shown(raw)}")

    def text(self):
        return "float" if self.finite else "float|nan"


@dataclass(frozen=True)
class Int(Kind):
    lo: int = -INT_LIMIT
    hi: int = INT_LIMIT

    def encode(self, value, enc, group):
        return int(value)

    def decode(self, raw, dec, group, where):
        if isinstance(raw, int) and not isinstance(raw, bool) and self.lo <= raw <= self.hi:
            return raw
        raise Damaged(f"{_place(where)}: expected an integer in [{self.lo}, {self.hi}], got {_shown(raw)}")

    def text(self):
        if self.hi == INT_LIMIT:
            return "int" if self.lo == -INT_LIMIT else f"int>={self.lo}"
        return f"int {self.lo}..{self.hi}"


@dataclass(frozen=True)
class Bool(Kind):
    def encode(self, value, enc, group):
        return bool(value)

    def decode(self, raw, dec, group, where):
        if isinstance(raw, bool):
            return raw
        raise Damaged(f"{_place(where)}: expected true or false, got {_shown(raw)}")

    def text(self):
        return "bool"


@dataclass(frozen=True)
class Str(Kind):
    """A string; ``choices``: the values allowed (any when empty), ``label`` names them in the description."""

    choices: tuple = ()
    label: str = ""

    def encode(self, value, enc, group):
        if not isinstance(value, str):
            raise PlannerError(f"cannot save the job: {group} is a {type(value).__name__}, not a string")
        return value

    def decode(self, raw, dec, group, where):
        if isinstance(raw, str) and (not self.choices or raw in self.choices):
            return raw
        want = f"one of {', '.join(self.choices)}" if self.choices else "a string"
        raise Damaged(f"{_place(where)}: expected {want}, got {_shown(raw)}")

    def text(self):
        if self.label:
            return f"str ({self.label})"
        return "str" if not self.choices else "|".join(f'"{c}"' for c in self.choices)


@dataclass(frozen=True)
class Opt(Kind):
    """The inner kind, or None (JSON null)."""

    inner: Kind

    def encode(self, value, enc, group):
        return None if value is None else self.inner.encode(value, enc, group)

    def decode(self, raw, dec, group, where):
        return None if raw is None else self.inner.decode(raw, dec, group, where)

    def text(self):
        return f"{self.inner.text()}?"


@dataclass(frozen=True)
class Seq(Kind):
    """A list of the inner kind, read back as a tuple (``length``: the exact length, when fixed)."""

    inner: Kind
    length: int | None = None

    def encode(self, value, enc, group):
        return [self.inner.encode(v, enc, group) for v in value]

    def decode(self, raw, dec, group, where):
        if not isinstance(raw, list) or (self.length is not None and len(raw) != self.length):
            size = "a list" if self.length is None else f"a list of {self.length}"
            raise Damaged(f"{_place(where)}: expected {size}, got {_shown(raw)}")
        return tuple(self.inner.decode(v, dec, group, where + (k,)) for k, v in enumerate(raw))

    def text(self):
        return f"[{self.inner.text()}]" + ("" if self.length is None else f"*{self.length}")


@dataclass(frozen=True)
class Map(Kind):
    """An object with string keys and values of the inner kind (a dict)."""

    inner: Kind

    def encode(self, value, enc, group):
        return {str(k): self.inner.encode(v, enc, group) for k, v in value.items()}

    def decode(self, raw, dec, group, where):
        if not isinstance(raw, dict):
            raise Damaged(f"{_place(where)}: expected an object, got {_shown(raw)}")
        return {k: self.inner.decode(v, dec, group, where + (k,)) for k, v in raw.items()}

    def text(self):
        return f"{{str: {self.inner.text()}}}"


@dataclass(frozen=True)
class Json(Kind):
    """Plain JSON data (an object of numbers, strings, booleans, nulls, lists and objects, at most ``depth``
    levels), checked by the type that holds it."""

    depth: int = 3

    def encode(self, value, enc, group):
        return value

    def decode(self, raw, dec, group, where):
        if not isinstance(raw, dict) or not _plain(raw, self.depth):
            raise Damaged(f"{_place(where)}: expected an object of plain values, got {_shown(raw)}")
        return raw

    def text(self):
        return "{...}"


@dataclass(frozen=True)
class Arr(Kind):
    """An ndarray of ``dtype`` ("f8", "i8", "b1") whose shape matches ``shape``: per dimension an int (that
    size), None (any size) or a tuple of the sizes allowed. Written as ``[offset, *shape]`` into the pool of its
    dtype; ``finite``: floats must be finite."""

    dtype: str
    shape: tuple
    finite: bool = True

    def encode(self, value, enc, group):
        a = np.asarray(value)
        if a.dtype != DTYPES[self.dtype].newbyteorder("=") or not _shape_ok(a.shape, self.shape):
            raise PlannerError(f"cannot save the job: {group} is an array of {a.dtype} {a.shape}, the format "
                               f"has {self.dtype} {self.text_shape()}")
        return enc.array(group, self.dtype, value)

    def decode(self, raw, dec, group, where):
        if type(raw) is list and len(raw) == 1 + len(self.shape):
            shape = tuple(raw[1:])
            if shape == self.shape and type(raw[0]) is int and raw[0] >= 0:  # a fixed shape: (3,), (3, 3), (6,)
                return dec.array(self.dtype, raw[0], shape, self.finite and self.dtype == "f8", where)
            for n, want in zip(shape, self.shape, strict=True):
                if type(n) is not int or n < 0 or (want is not None and n != want and not (
                        type(want) is tuple and n in want)):
                    break
            else:
                if type(raw[0]) is int and raw[0] >= 0:
                    return dec.array(self.dtype, raw[0], shape, self.finite and self.dtype == "f8", where)
        raise Damaged(f"{_place(where)}: expected an array reference [offset, {', '.join('n' * len(self.shape))}] "
                      f"of non-negative integers with shape {self.text_shape()}, got {_shown(raw)}")

    def text_shape(self) -> str:
        dims = ["n" if d is None else ("|".join(map(str, d)) if isinstance(d, tuple) else str(d)) for d in self.shape]
        return "(" + ",".join(dims) + ")"

    def text(self):
        return f"{self.dtype}{self.text_shape()}" + ("" if self.finite or self.dtype != "f8" else "+nan")


@dataclass(frozen=True)
class Ref(Kind):
    """An object of one of the named types, by the index of its (earlier) entry."""

    types: tuple

    def __init__(self, *types: str):
        object.__setattr__(self, "types", types)

    def encode(self, value, enc, group):
        return enc.ref(value, self.types, group)

    def decode(self, raw, dec, group, where):
        return dec.ref(raw, self.types, where)

    def text(self):
        return "->" + "|".join(self.types)


@dataclass(frozen=True)
class Inline(Kind):
    """The state of a sub-type written inside its owner (a part that cannot be built alone: the owner builds it
    from the state read back, a dict)."""

    type: str

    def encode(self, value, enc, group):
        return enc.fields(enc.types[self.type], value)

    def decode(self, raw, dec, group, where):
        return dec.fields(dec.types[self.type], raw, where)

    def text(self):
        return f"{{{self.type}}}"


@dataclass(frozen=True)
class StoredType:
    """One entry of the table of stored types.

    Attributes
    ----------
    name : str
        The name in the file (never a Python path: renaming a class changes nothing in the files).
    cls : type or None
        The class written under this name (None: an :class:`Inline` part, written by its owner).
    fields : dict of Kind
        The state's fields, each written and read by its kind.
    build : callable (state dict) -> object, optional
        Rebuilds the object from the fields read back (default ``cls.from_state``).
    check : callable (state dict) -> None, optional
        Checks what the kinds cannot (sizes that must agree, order, ranges); raises PlannerError.
    """

    name: str
    cls: type | None
    fields: Mapping[str, Kind]
    build: Callable | None = None
    check: Callable | None = None

    @cached_property
    def groups(self) -> dict[str, str]:
        """Each field's group name, "<name>.<field>" (its arrays lie side by side in the pools)."""
        return {name: f"{self.name}.{name}" for name in self.fields}

    def rebuild(self, state: dict):
        make = self.build if self.build is not None else self.cls.from_state  # type: ignore[union-attr]
        return make(state)


@dataclass
class Encoder:
    """Builds the entries (``objects``) and array pools of an object graph, children before their owners."""

    types: Mapping[str, StoredType]
    objects: list = field(default_factory=list)
    #: dtype -> field ("<type>.<field>") -> [(array, its reference, whose offset is set by :meth:`pool_arrays`)]
    pending: dict = field(default_factory=dict)
    _by_class: dict = field(default_factory=dict)
    _memo: dict = field(default_factory=dict)
    _arrays: dict = field(default_factory=dict)
    _keep: list = field(default_factory=list)

    def __post_init__(self):
        self._by_class = {t.cls: t for t in self.types.values() if t.cls is not None}

    def ref(self, obj, allowed: tuple, group: str) -> int:
        t = self._by_class.get(type(obj))
        if t is None or t.name not in allowed:
            raise PlannerError(f"cannot save the job: {group} is a {type(obj).__qualname__}, which the job file "
                               f"format does not hold there (it holds {', '.join(allowed)})")
        key = id(obj)
        if key in self._memo:
            return self._memo[key]
        body = self.fields(t, obj.to_state())
        self.objects.append([t.name, body])
        self._memo[key] = len(self.objects) - 1
        self._keep.append(obj)  # ids stay unique while encoding
        return len(self.objects) - 1

    def fields(self, t: StoredType, state: dict) -> dict:
        if set(state) != set(t.fields):
            raise PlannerError(f"cannot save the job: the state of {t.name} has fields {sorted(state)}, the format "
                               f"{sorted(t.fields)}")
        groups = t.groups
        return {name: kind.encode(state[name], self, groups[name]) for name, kind in t.fields.items()}

    def array(self, group: str, dtype: str, value) -> list:
        """The reference ``[offset, *shape]`` of an array of the field ``group`` (an array held by several fields
        is stored once); the offset is set when the pools are laid out (:meth:`pool_arrays`)."""
        key = (dtype, id(value))
        if key in self._arrays:
            return self._arrays[key]
        a = np.ascontiguousarray(value, dtype=DTYPES[dtype])
        ref = [0, *a.shape]
        self.pending.setdefault(dtype, {}).setdefault(group, []).append((a.ravel(), ref))
        self._arrays[key] = ref
        self._keep.append(value)
        return ref

    def pool_arrays(self) -> dict[str, np.ndarray]:
        """One 1-D array per dtype: the arrays of each field together (they compress better side by side), the
        fields in name order, and the references' offsets set."""
        out = {}
        for dtype, fields in sorted(self.pending.items()):
            parts, offset = [], 0
            for name in sorted(fields):
                for a, ref in fields[name]:
                    ref[0] = offset
                    offset += a.size
                    parts.append(a)
            out[dtype] = np.concatenate(parts) if parts else np.zeros(0, DTYPES[dtype])
        return out


@dataclass
class Decoder:
    """Rebuilds objects entry by entry; ``pools``: the arrays read (1-D, checked against the manifest)."""

    types: Mapping[str, StoredType]
    pools: Mapping[str, np.ndarray]
    objects: list = field(default_factory=list)
    names: list = field(default_factory=list)
    _bad_before: dict = field(default_factory=dict)

    def __post_init__(self):  # the pools in native byte order (a no-op on little-endian machines)
        self.pools = {k: v.astype(v.dtype.newbyteorder("="), copy=False) for k, v in self.pools.items()}
        self._bad_before = {}  # pool -> number of non-finite elements before each position (n + 1,)
        for name, data in self.pools.items():
            if data.dtype.kind == "f" and data.size:
                finite = np.isfinite(data)
                big = np.abs(data, where=finite, out=np.zeros_like(data)).max()
                if big > MAX_MAGNITUDE:
                    raise Damaged(f"the {name} pool holds {big:.3g}, beyond the format's {MAX_MAGNITUDE:g}")
                if not finite.all():
                    self._bad_before[name] = np.concatenate(([0], np.cumsum(~finite)))

    def entry(self, index: int, raw) -> None:
        """Check and build entry ``index`` of the manifest's objects."""
        if (not isinstance(raw, list) or len(raw) != 2 or not isinstance(raw[0], str)
                or not isinstance(raw[1], dict)):
            raise Damaged(f"object {index}: expected [type, state], got {_shown(raw)}")
        name, body = raw
        t = self.types.get(name)
        if t is None or t.cls is None:
            raise Damaged(f"object {index}: unknown type {_shown(name)}")
        label = f"object {index} ({name})"
        state = self.fields(t, body, (label,))
        try:
            if t.check is not None:
                t.check(state)
            obj = t.rebuild(state)
        except (PlannerError, ValueError, TypeError, KeyError, IndexError, AttributeError, ArithmeticError) as exc:
            raise Damaged(f"{label}: {_one_line(exc)}") from None
        self.objects.append(obj)
        self.names.append(name)

    def fields(self, t: StoredType, body, where: tuple) -> dict:
        if type(body) is not dict:
            raise Damaged(f"{_place(where)}: expected an object, got {_shown(body)}")
        if body.keys() != t.fields.keys():
            missing, extra = sorted(set(t.fields) - set(body)), sorted(set(body) - set(t.fields))
            what = "; ".join(x for x in (f"missing {', '.join(missing)}" * bool(missing),
                                         f"unknown {', '.join(map(_shown, extra))}" * bool(extra)) if x)
            raise Damaged(f"{_place(where)}: fields do not match the format ({what})")
        groups = t.groups
        return {name: kind.decode(body[name], self, groups[name], where + (name,)) for name, kind in t.fields.items()}

    def ref(self, raw, allowed: tuple, where: tuple):
        if type(raw) is not int or not 0 <= raw < len(self.objects):
            raise Damaged(f"{_place(where)}: expected the index of an earlier object (0..{len(self.objects) - 1}), "
                          f"got {_shown(raw)}")
        if self.names[raw] not in allowed:
            raise Damaged(f"{_place(where)}: object {raw} is a {self.names[raw]}, expected {' or '.join(allowed)}")
        return self.objects[raw]

    def array(self, dtype: str, offset: int, shape: tuple, finite: bool, where: tuple) -> np.ndarray:
        """A copy of the elements ``offset ..`` of the ``dtype`` pool in ``shape`` (all finite if ``finite``)."""
        data = self.pools.get(dtype)
        if data is None or data.dtype != DTYPES[dtype]:
            raise Damaged(f"{_place(where)}: no {dtype} array pool")
        count = math.prod(shape)
        if not 0 <= offset <= data.size - count or count == 0 and max(shape, default=0) > 2**40:
            raise Damaged(f"{_place(where)}: elements {offset}..{offset + count} lie beyond the {data.size} of the "
                          f"{dtype} pool")
        bad = self._bad_before.get(dtype) if finite else None
        if bad is not None and bad[offset + count] != bad[offset]:
            raise Damaged(f"{_place(where)}: holds a value that is not finite")
        return data[offset:offset + count].reshape(shape).copy()


def _place(where: tuple) -> str:
    """(label, field, indices...) as "object 12 (PHSpline) A[3]"."""
    label, *rest = where
    if not rest:
        return label
    return f"{label} {rest[0]}" + "".join(f"[{k!r}]" for k in rest[1:])


def _shape_ok(shape: tuple, spec: tuple) -> bool:
    if len(shape) != len(spec):
        return False
    for n, want in zip(shape, spec, strict=True):
        if want is None:
            continue
        if isinstance(want, tuple) and n not in want or isinstance(want, int) and n != want:
            return False
    return True


def _plain(value, depth: int) -> bool:
    """Whether ``value`` is JSON of at most ``depth`` levels of lists and objects (no non-finite numbers)."""
    if isinstance(value, str | bool) or value is None:
        return True
    if isinstance(value, int):
        return abs(value) <= INT_LIMIT
    if isinstance(value, float):
        return math.isfinite(value)
    if depth <= 0:
        return False
    if isinstance(value, list):
        return all(_plain(v, depth - 1) for v in value)
    if isinstance(value, dict):
        return all(_plain(v, depth - 1) for v in value.values())
    return False


def _shown(value) -> str:
    """A short description of a value read from a file, for a message."""
    if isinstance(value, str):
        return repr(value[:40] + "..." if len(value) > 40 else value)
    if isinstance(value, bool) or value is None:
        return str(value).lower() if value is not None else "null"
    if isinstance(value, int):
        return str(value) if abs(value) < 10**20 else f"an integer of {len(str(abs(value)))} digits"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return f"an object of {len(value)} fields"
    return type(value).__name__


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if isinstance(exc, PlannerError) else f"{type(exc).__name__}: {text}"
