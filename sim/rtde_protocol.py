"""RTDE wire format (protocol versions 1 and 2): package header, field types, packing of data packages.

A package is ``>HB`` (uint16 size including the 3-byte header, uint8 type) then its payload, big-endian,
IEEE doubles. The package types and field types below are those of Universal Robots' RTDE guide as
ur_rtde 1.6.5 (src/rtde.cpp, include/ur_rtde/rtde.h) sends and parses them. What differs between the protocol
versions (`PROTOCOL_VERSIONS`), as UR's C++ client library reads and writes them (``src/rtde/``): in version 1
the output setup request has no frequency (outputs come every control period) and its answer, like every output
data package, no recipe id; a text message is ``uint8 level`` then the text, and goes from the controller to
the client only.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

HEADER = struct.Struct(">HB")
HEADER_SIZE = HEADER.size

# package types (ASCII letters)
REQUEST_PROTOCOL_VERSION = ord("V")  # 86
GET_URCONTROL_VERSION = ord("v")  # 118
TEXT_MESSAGE = ord("M")  # 77
DATA_PACKAGE = ord("U")  # 85
SETUP_OUTPUTS = ord("O")  # 79
SETUP_INPUTS = ord("I")  # 73
START = ord("S")  # 83
PAUSE = ord("P")  # 80

PACKAGE_TYPES = frozenset(
    {REQUEST_PROTOCOL_VERSION, GET_URCONTROL_VERSION, TEXT_MESSAGE, DATA_PACKAGE, SETUP_OUTPUTS, SETUP_INPUTS,
     START, PAUSE}
)

#: The protocol versions the controller speaks; a connection speaks version 1 until the client asks for another.
PROTOCOL_VERSIONS = (1, 2)

# text message levels
EXCEPTION, ERROR, WARNING, INFO = 0, 1, 2, 3

#: Field type name -> struct code (big-endian, without the leading '>').
TYPE_CODES = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
#: Number of scalars each type packs.
TYPE_WIDTH = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}


def package(kind: int, payload: bytes = b"") -> bytes:
    """One package: header (size, type) + payload."""
    return HEADER.pack(HEADER_SIZE + len(payload), kind) + payload


def text_message(message: str, source: str = "RTDE", level: int = ERROR, protocol: int = 2) -> bytes:
    """An 'M' package: protocol version 2: uint8 length + message, uint8 length + source, uint8 warning level;
    version 1: uint8 level + message (no source)."""
    m = message.encode("utf-8", "replace")[:255]
    if protocol == 1:
        return package(TEXT_MESSAGE, bytes([level]) + m)
    s = source.encode("utf-8", "replace")[:255]
    return package(TEXT_MESSAGE, bytes([len(m)]) + m + bytes([len(s)]) + s + bytes([level]))


@dataclass(frozen=True)
class Recipe:
    """One output or input recipe of a connection.

    Attributes
    ----------
    recipe_id : int
        The id the controller assigned (1, 2, ... per connection; 0 = refused).
    names : tuple of str
        Field names in the client's order.
    types : tuple of str
        RTDE type names, one per field (``NOT_FOUND`` / ``IN_USE`` where refused).
    frequency : float
        Output recipes only: packages per second (Hz).
    """

    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]
    frequency: float = 0.0

    @property
    def ok(self) -> bool:
        """Every field was accepted."""
        return all(t in TYPE_CODES for t in self.types)

    @property
    def struct(self) -> struct.Struct:
        """The packed layout of the fields (after the recipe id byte)."""
        return struct.Struct(">" + "".join(TYPE_CODES[t] for t in self.types))


def flatten(types: tuple[str, ...], values: list) -> list:
    """Values of ``types`` (vectors as sequences) flattened to the scalars ``struct`` expects."""
    out: list = []
    for t, v in zip(types, values, strict=True):
        if t in TYPE_WIDTH:
            out.extend(v)
        else:
            out.append(v)
    return out


def unflatten(types: tuple[str, ...], scalars: tuple) -> list:
    """Inverse of :func:`flatten`: vectors regrouped as tuples."""
    out: list = []
    i = 0
    for t in types:
        w = TYPE_WIDTH.get(t)
        if w:
            out.append(tuple(scalars[i : i + w]))
            i += w
        else:
            out.append(scalars[i])
            i += 1
    return out
