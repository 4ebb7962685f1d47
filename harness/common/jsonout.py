"""Strict JSON for every ``--json`` output (RFC 8259: no NaN or Infinity tokens).

Non-finite floats are written as the strings ``"NaN"``, ``"Infinity"`` and ``"-Infinity"``
(:data:`NON_FINITE`): the value stays in its field, a strict parser accepts the document, and
Python's ``float()`` reads each string back to the same value.  NumPy scalars become Python
numbers and NumPy arrays nested lists; anything else JSON cannot hold raises TypeError.
"""

from __future__ import annotations

import json
import math

import numpy as np

#: How each non-finite float is encoded.
NON_FINITE = {"nan": "NaN", "inf": "Infinity", "-inf": "-Infinity"}


def encode_float(value: float) -> float | str:
    """``value`` itself when finite, otherwise its :data:`NON_FINITE` string."""
    return value if math.isfinite(value) else NON_FINITE[repr(float(value))]


def to_jsonable(value):
    """A copy of ``value`` made of dicts, lists, str, int, finite float, bool and None only.

    Raises
    ------
    TypeError
        For an object JSON cannot represent (the message names its type).
    """
    if isinstance(value, dict):
        return {str(key): to_jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float):
        return encode_float(value)
    if value is None or isinstance(value, (str, int, bool)):
        return value
    raise TypeError(f"cannot write a {type(value).__name__} as JSON: {value!r}")


def dumps(value, indent: int | None = 2) -> str:
    """Strict JSON text of ``value`` (see the module docstring for the encoding)."""
    return json.dumps(to_jsonable(value), indent=indent, allow_nan=False)
