"""Numbers in text and numbers from stored values, one way each.

* :func:`format_number`: a number as short text for tables, summaries and the command line
  (``3`` significant digits; ``-`` for a missing value);
* :func:`as_float`: a stored, frame or JSON value as a finite float, or None;
* :func:`float_or_nan`: a frame cell as a float for plotting and arithmetic (NaN when missing).
"""

from __future__ import annotations

import math

__all__ = ["as_float", "float_or_nan", "format_number", "is_missing"]


def is_missing(value) -> bool:
    """None, NaN or pandas' NA."""
    if value is None:
        return True
    try:
        return bool(value != value)  # NaN and pd.NA (whose != is NA, truthiness raises)
    except TypeError:
        return True


def format_number(value, digits: int = 3) -> str:
    """``value`` with ``digits`` significant digits (``f"{value:.3g}"``); ``"-"`` when it is
    missing (None, NaN, pandas' NA)."""
    return "-" if is_missing(value) else f"{value:.{digits}g}"


def as_float(value) -> float | None:
    """A finite float from a stored value (None, NaN, ±inf, pandas' NA, the string "NaN" and
    anything that is not a number → None)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def float_or_nan(value) -> float:
    """A float from a frame cell: None, NaN and pandas' NA → NaN, anything else ``float(value)``."""
    return math.nan if is_missing(value) else float(value)
