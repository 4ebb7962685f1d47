"""Feeding structured values to a hash, so that two values digest alike only when they are alike:
the keys of the caches a computation's inputs name (a mechanism's data, a generated function's
trace)."""

from __future__ import annotations

import dataclasses

import numpy as np


def feed(digest, value) -> None:
    """Feed ``value`` to ``digest`` (a :mod:`hashlib` object) with its structure, types, shapes
    and bytes: dataclasses (field by field), numeric arrays, tuples and lists, mappings (by key,
    in sorted order), strings, numbers, booleans and None.

    Raises
    ------
    TypeError
        For any other value (an object array among them): it has no faithful digest here.
    """
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        digest.update(f"<{type(value).__name__}".encode())
        for item in dataclasses.fields(value):
            digest.update(item.name.encode())
            feed(digest, getattr(value, item.name))
        digest.update(b">")
    elif isinstance(value, np.ndarray) and value.dtype != object:
        digest.update(f"array {value.dtype.str} {value.shape}:".encode())
        digest.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (tuple, list)):
        digest.update(f"sequence {len(value)}:".encode())
        for item in value:
            feed(digest, item)
    elif isinstance(value, dict):
        digest.update(f"mapping {len(value)}:".encode())
        for key in sorted(value, key=str):
            feed(digest, key)
            feed(digest, value[key])
    elif value is None or isinstance(value, (bool, int, float, str, np.bool_, np.number)):
        digest.update(f"scalar {type(value).__name__} {value!r};".encode())
    else:
        raise TypeError(f"no digest for a value of type {type(value).__name__}")
