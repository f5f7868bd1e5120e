"""Messages to bytes and back, and to the JSON of the golden vectors.

A payload is the protocol version (a ``u16``) followed by the message, both in
bincode 2's standard configuration. The layout comes from each dataclass's annotated
fields (``messages``): one walker writes, one reads, one renders JSON, so the three
cannot disagree. Decoding refuses what a robot refuses: another version, trailing
bytes, a payload over 256 kB, a float that is not finite, an id that is not one, a
message that fails ``validate()``, and a message whose ``robot`` is not the key's.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from enum import Enum
from functools import lru_cache
from typing import Any, Optional, Union

from . import keys
from .bincode import DecodeError, Reader, Writer
from .messages import (
    MAX_MESSAGE_BYTES,
    PROTOCOL_VERSION,
    BallotsMsg,
    DecisionMsg,
    DetectionFrame,
    EmbeddingMsg,
    Fixed,
    HistoryMsg,
    Invalid,
    MapMsg,
    Station,
    TruthMsg,
    VoteMsg,
    check_id,
)

Message = Union[DetectionFrame, EmbeddingMsg, VoteMsg, DecisionMsg, BallotsMsg, MapMsg, HistoryMsg, TruthMsg]

TOPICS: dict[str, type] = {
    "detections": DetectionFrame,
    "embedding": EmbeddingMsg,
    "ballots": BallotsMsg,
    "map": MapMsg,
    "history": HistoryMsg,
    "vote": VoteMsg,
    "decision": DecisionMsg,
    "truth": TruthMsg,
}
"""The message each topic carries (``truth`` under ``world/``, the rest under ``robot/<id>/``)."""


@lru_cache(maxsize=None)
def _fields(cls: type) -> list[tuple[str, Any]]:
    hints = typing.get_type_hints(cls, include_extras=True)
    return [(f.name, hints[f.name]) for f in dataclasses.fields(cls)]


def _json_name(name: str) -> str:
    return name[:-1] if name.endswith("_") else name


def _split(t: Any) -> tuple[Any, tuple]:
    """(the bare type, its Annotated metadata)."""
    if typing.get_origin(t) is typing.Annotated:
        return t.__origin__, t.__metadata__
    return t, ()


def _optional_of(t: Any) -> Optional[Any]:
    if typing.get_origin(t) is Union:
        args = [a for a in typing.get_args(t) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(t)) == 2:
            return args[0]
    return None


def _write(w: Writer, t: Any, v: Any, path: str) -> None:
    bare, meta = _split(t)
    try:
        if (inner := _optional_of(bare)) is not None:
            if v is None:
                w.u8(0)
            else:
                w.u8(1)
                _write(w, inner, v, path)
        elif "f32" in meta:
            w.f32(float(v))
        elif any(m in meta for m in ("u16", "u32", "u64")):
            w.varint(int(v), next(m for m in meta if m in ("u16", "u32", "u64")))
        elif "id" in meta:
            check_id(v, path)
            _write_bytes(w, v.encode())
        elif bare is str:
            _write_bytes(w, v.encode())
        elif bare is bytes:
            _write_bytes(w, bytes(v))
        elif isinstance(bare, type) and issubclass(bare, Station):
            w.u8(int(Station(v)))
        elif isinstance(bare, type) and issubclass(bare, Enum):
            w.varint(list(bare).index(bare(v)), "u32")
        elif dataclasses.is_dataclass(bare):
            for name, ft in _fields(bare):
                _write(w, ft, getattr(v, name), f"{path}.{_json_name(name)}" if path else _json_name(name))
        elif typing.get_origin(bare) is list:
            (item,) = typing.get_args(bare)
            fixed = next((m.n for m in meta if isinstance(m, Fixed)), None)
            if fixed is None:
                w.varint(len(v))
            elif len(v) != fixed:
                raise Invalid(path, f"has {len(v)} values, expected {fixed}")
            for x in v:
                _write(w, item, x, path)
        else:
            raise TypeError(f"{path}: no wire format for {t!r}")
    except (ValueError, TypeError) as e:
        if isinstance(e, Invalid):
            raise
        raise Invalid(path, str(e)) from None


def _write_bytes(w: Writer, b: bytes) -> None:
    w.varint(len(b))
    w.raw(b)


def _read(r: Reader, t: Any, path: str) -> Any:
    bare, meta = _split(t)
    if (inner := _optional_of(bare)) is not None:
        tag = r.u8()
        if tag > 1:
            raise DecodeError(f"{path}: option tag {tag} (0 or 1)")
        return _read(r, inner, path) if tag else None
    if "f32" in meta:
        x = r.f32()
        if not math.isfinite(x):
            raise DecodeError(f"{path}: {x} is not finite")
        return x
    for width in ("u16", "u32", "u64"):
        if width in meta:
            return r.varint(width)
    if bare in (str, bytes):
        n = r.varint()
        if n > r.remaining():
            raise DecodeError(f"{path}: {n} bytes claimed, {r.remaining()} left")
        raw = r.take(n)
        if bare is bytes:
            return raw
        try:
            s = raw.decode()
        except UnicodeDecodeError:
            raise DecodeError(f"{path}: not UTF-8") from None
        if "id" in meta:
            try:
                check_id(s, path)
            except Invalid as e:
                raise DecodeError(str(e)) from None
        return s
    if isinstance(bare, type) and issubclass(bare, Station):
        b = r.u8()
        try:
            return Station(b)
        except ValueError:
            raise DecodeError(f"{path}: no station {b}") from None
    if isinstance(bare, type) and issubclass(bare, Enum):
        i = r.varint("u32")
        variants = list(bare)
        if i >= len(variants):
            raise DecodeError(f"{path}: no {bare.__name__} variant {i}")
        return variants[i]
    if dataclasses.is_dataclass(bare):
        values = {}
        for name, ft in _fields(bare):
            values[name] = _read(r, ft, f"{path}.{_json_name(name)}" if path else _json_name(name))
        return bare(**values)
    if typing.get_origin(bare) is list:
        (item,) = typing.get_args(bare)
        n = next((m.n for m in meta if isinstance(m, Fixed)), None)
        if n is None:
            n = r.varint()
            if n > r.remaining():  # every element takes at least a byte
                raise DecodeError(f"{path}: {n} elements claimed, {r.remaining()} bytes left")
        return [_read(r, item, path) for _ in range(n)]
    raise TypeError(f"{path}: no wire format for {t!r}")


def encode(msg: Message) -> bytes:
    """The payload of ``msg``: version, then the message. Raises ``Invalid`` (naming the
    field) for a message a robot would refuse."""
    msg.validate()
    w = Writer()
    w.varint(PROTOCOL_VERSION, "u16")
    _write(w, type(msg), msg, "")
    if len(w.out) > MAX_MESSAGE_BYTES:
        raise Invalid("", f"{len(w.out)} bytes, at most {MAX_MESSAGE_BYTES}")
    return bytes(w.out)


def decode_as(cls: type, payload: bytes) -> Message:
    """``payload`` as a message of ``cls``; raises ``DecodeError`` or ``Invalid``."""
    if len(payload) > MAX_MESSAGE_BYTES:
        raise DecodeError(f"{cls.__name__}: {len(payload)} bytes, at most {MAX_MESSAGE_BYTES}")
    r = Reader(payload)
    version = r.varint("u16")
    if version != PROTOCOL_VERSION:
        raise DecodeError(f"{cls.__name__}: protocol version {version}, this client speaks {PROTOCOL_VERSION}")
    msg = _read(r, cls, "")
    if r.remaining():
        raise DecodeError(f"{cls.__name__}: {r.remaining()} trailing bytes")
    msg.validate()
    return msg


def decode(key: str, payload: bytes) -> Message:
    """The message published on ``key`` (its topic names the type). A message on a
    robot's key must name that robot."""
    topic = keys.parse(key)
    if topic is None:
        raise DecodeError(f"{key}: not a spwi key expression with a payload")
    cls = TOPICS[topic.topic]
    msg = decode_as(cls, payload)
    if topic.robot is not None and msg.robot != topic.robot:
        raise DecodeError(f"{key}: the {cls.__name__} names robot {msg.robot}")
    return msg


def to_json(value: Any) -> Any:
    """The JSON value of a message as the golden vectors render it: field names as on
    the wire, stations as numbers, other enums by name, ``None`` as null."""
    if dataclasses.is_dataclass(value):
        return {_json_name(f.name): to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Station):
        return int(value)
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, bytes):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [to_json(x) for x in value]
    return value


def from_json(cls: type, value: Any) -> Any:
    """The inverse of ``to_json``: a value of type ``cls`` from its JSON."""
    bare, _ = _split(cls)
    if value is None:
        return None
    if (inner := _optional_of(bare)) is not None:
        return from_json(inner, value)
    if dataclasses.is_dataclass(bare):
        return bare(**{name: from_json(ft, value[_json_name(name)]) for name, ft in _fields(bare)})
    if bare is bytes:
        return bytes(value)
    if isinstance(bare, type) and issubclass(bare, Enum):
        return bare(value)
    if typing.get_origin(bare) is list:
        (item,) = typing.get_args(bare)
        return [from_json(item, x) for x in value]
    return value
