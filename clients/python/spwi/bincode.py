"""bincode 2's standard configuration, the part spwi's messages use.

Integers wider than a byte are variable-length: a value below 251 is one byte;
otherwise a marker (251, 252, 253) then the value in 2, 4 or 8 little-endian bytes.
``f32`` is 4 little-endian IEEE 754 bytes. Options are a ``0x00``/``0x01`` byte.
Sequences and strings carry their length as a variable-length ``u64``.
"""

from __future__ import annotations

import math
import struct

_MARKERS = {251: 2, 252: 4, 253: 8}
_WIDTH_BYTES = {"u16": 2, "u32": 4, "u64": 8}


class DecodeError(ValueError):
    """The bytes are not a message of the kind expected: what is wrong, where."""


class Writer:
    def __init__(self) -> None:
        self.out = bytearray()

    def u8(self, v: int) -> None:
        if not 0 <= v <= 0xFF:
            raise ValueError(f"{v} does not fit a byte")
        self.out.append(v)

    def varint(self, v: int, width: str = "u64") -> None:
        limit = 1 << (8 * _WIDTH_BYTES[width])
        if not 0 <= v < limit:
            raise ValueError(f"{v} does not fit a {width}")
        if v < 251:
            self.out.append(v)
        elif v < 1 << 16:
            self.out.append(251)
            self.out += struct.pack("<H", v)
        elif v < 1 << 32:
            self.out.append(252)
            self.out += struct.pack("<I", v)
        else:
            self.out.append(253)
            self.out += struct.pack("<Q", v)

    def f32(self, v: float) -> None:
        if not math.isfinite(v):
            raise ValueError(f"{v} is not finite")
        try:
            self.out += struct.pack("<f", v)
        except OverflowError:
            raise ValueError(f"{v} does not fit an f32") from None

    def raw(self, b: bytes) -> None:
        self.out += b


class Reader:
    def __init__(self, data: bytes) -> None:
        self.data = memoryview(data)
        self.pos = 0

    def take(self, n: int) -> bytes:
        if self.pos + n > len(self.data):
            raise DecodeError(f"the message ends at byte {len(self.data)}, {n} more bytes expected at {self.pos}")
        b = bytes(self.data[self.pos : self.pos + n])
        self.pos += n
        return b

    def u8(self) -> int:
        return self.take(1)[0]

    def varint(self, width: str = "u64") -> int:
        first = self.u8()
        if first < 251:
            return first
        n = _MARKERS.get(first)
        if n is None or n > _WIDTH_BYTES[width]:
            raise DecodeError(f"byte {first} at {self.pos - 1} does not start a {width}")
        return int.from_bytes(self.take(n), "little")

    def f32(self) -> float:
        return struct.unpack("<f", self.take(4))[0]

    def remaining(self) -> int:
        return len(self.data) - self.pos
