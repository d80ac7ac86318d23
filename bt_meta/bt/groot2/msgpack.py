"""MessagePack encoding of JSON-like values, byte for byte as nlohmann::json's ``to_msgpack`` writes them.

Groot2's BLACKBOARD reply is BehaviorTree.CPP's blackboard dump converted by nlohmann::json 3.11; writing the same
bytes (smallest integer form, float32 when the double survives the round trip, map keys sorted) keeps our replies
comparable with BehaviorTree.CPP's. A tiny encoder of our own avoids a dependency for ~60 lines.

Offers:

* :func:`packb` -- ``None``, ``bool``, ``int``, ``float``, ``str``, lists and string-keyed dicts -> bytes
"""

from __future__ import annotations

import struct
from typing import Any

_FLOAT_MAX = 3.4028234663852886e38


def _length(prefix_small: int, small_limit: int, codes: tuple[int, int, int], n: int) -> bytes:
    """Header for a str/array/map of length n: a fix form below ``small_limit``, else 8/16/32-bit (str only 8)."""
    if n < small_limit:
        return bytes([prefix_small | n])
    code8, code16, code32 = codes
    if code8 and n <= 0xFF:
        return bytes([code8, n])
    if n <= 0xFFFF:
        return bytes([code16]) + struct.pack(">H", n)
    return bytes([code32]) + struct.pack(">I", n)


def _int(value: int) -> bytes:
    if value >= 0:
        if value < 128:
            return bytes([value])
        for code, fmt, limit in ((0xCC, ">B", 0xFF), (0xCD, ">H", 0xFFFF), (0xCE, ">I", 0xFFFFFFFF)):
            if value <= limit:
                return bytes([code]) + struct.pack(fmt, value)
        return b"\xcf" + struct.pack(">Q", value)
    if value >= -32:
        return struct.pack(">b", value)
    for code, fmt, low in ((0xD0, ">b", -(1 << 7)), (0xD1, ">h", -(1 << 15)), (0xD2, ">i", -(1 << 31))):
        if value >= low:
            return bytes([code]) + struct.pack(fmt, value)
    return b"\xd3" + struct.pack(">q", value)


def _float(value: float) -> bytes:
    # nlohmann writes float32 when the value is in float range and survives the cast (never for NaN or inf).
    if -_FLOAT_MAX <= value <= _FLOAT_MAX:
        single = struct.unpack(">f", struct.pack(">f", value))[0]
        if single == value:
            return b"\xca" + struct.pack(">f", value)
    return b"\xcb" + struct.pack(">d", value)


def packb(value: Any) -> bytes:
    """Encode ``value``; raises ``TypeError`` for anything JSON cannot hold."""
    if value is None:
        return b"\xc0"
    if value is True:
        return b"\xc3"
    if value is False:
        return b"\xc2"
    if isinstance(value, int):
        if not -(1 << 63) <= value < (1 << 64):
            raise TypeError(f"integer {value} does not fit MessagePack")
        return _int(value)
    if isinstance(value, float):
        return _float(value)
    if isinstance(value, str):
        raw = value.encode("utf-8")
        return _length(0xA0, 32, (0xD9, 0xDA, 0xDB), len(raw)) + raw
    if isinstance(value, (list, tuple)):
        return _length(0x90, 16, (0, 0xDC, 0xDD), len(value)) + b"".join(packb(item) for item in value)
    if isinstance(value, dict):
        if not all(isinstance(key, str) for key in value):
            raise TypeError("MessagePack maps here have string keys only")
        keys = sorted(value, key=lambda key: key.encode("utf-8"))
        body = b"".join(packb(key) + packb(value[key]) for key in keys)
        return _length(0x80, 16, (0, 0xDE, 0xDF), len(value)) + body
    raise TypeError(f"cannot encode {type(value).__name__} as MessagePack")
