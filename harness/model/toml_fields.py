"""Reading TOML files field by field, the way every input file of mbh is checked: the file read
as a document (:func:`read_toml`), and typed readers (:class:`_Collector`) that record a
:class:`Problem` naming the file and the field for each mistake instead of raising, so a file's
every mistake is reported at once.  Scenario, campaign and tolerance files are read with them.

The limits on numbers (:data:`LARGEST`, :data:`SMALLEST`) and names (:func:`name_problem`) are
those of docs/formats/scenario.md, "Limits".
"""

from __future__ import annotations

import json
import math
import sys
import tomllib
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["LARGEST", "SMALLEST", "Problem", "finite_number", "read_toml", "name_problem"]

#: Shortest length of a vector read with ``nonzero=True``.
_AXIS_TOL = 1e-9
#: Largest magnitude of any number in a file, and smallest mass or duration: the engines multiply
#: up to three such numbers (m·v², I·ω², r × F), and 1e100³ stays below the double range (1.8e308).
LARGEST = 1e100
SMALLEST = 1e-100
#: Unicode categories a name may not contain: control, format (e.g. right-to-left override,
#: zero-width space), surrogate, private-use, unassigned, line and paragraph separators.
_UNPRINTABLE = {"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"}


@dataclass(frozen=True)
class Problem:
    """One validation finding: ``file: field: message``."""

    file: str
    field: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}: {self.field}: {self.message}"


#: What :meth:`_Collector._given` returns for a required field that is missing.
_MISSING = object()


class _Collector:
    """Typed field readers that record a problem instead of raising."""

    def __init__(self, file: str):
        self.file = file
        self.problems: list[Problem] = []

    def add(self, field: str, message: str) -> None:
        self.problems.append(Problem(self.file, field, message))

    def unknown_keys(self, table: dict, allowed: set[str], path: str) -> None:
        for key in sorted(set(table) - allowed):
            self.add(_join(path, _key_text(key)),
                     f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def required(self, table: dict, key: str, path: str) -> Any:
        if key not in table:
            self.add(_join(path, key), "missing required field")
            return None
        return table[key]

    def _given(self, table: dict, key: str, path: str, default: Any) -> Any:
        """``table[key]`` if present (a None from a Python caller included: the typed readers
        name it), else ``default`` if not None, else :data:`_MISSING` with the problem added."""
        if key in table:
            return table[key]
        if default is not None:
            return default
        self.add(_join(path, key), "missing required field")
        return _MISSING

    def string(self, table: dict, key: str, path: str, default: str | None = None) -> str | None:
        value = self._given(table, key, path, default)
        if value is _MISSING:
            return None
        if not isinstance(value, str) or not value:
            self.add(_join(path, key), f"expected a non-empty string, got {value!r}")
            return None
        return value

    def name(self, table: dict, key: str, path: str, default: str | None = None) -> str | None:
        """A non-empty string fit to name something (see :func:`name_problem`)."""
        value = self.string(table, key, path, default)
        problem = None if value is None else name_problem(value)
        if problem:
            self.add(_join(path, key), problem)
            return None
        return value

    def number(self, table: dict, key: str, path: str, default: float | None = None,
               positive: bool = False, nonnegative: bool = False) -> float | None:
        value = self._given(table, key, path, default)
        if value is _MISSING:
            return None
        if not finite_number(value):
            self.add(_join(path, key), f"expected a finite number, got {value!r}")
            return None
        if abs(value) > LARGEST:
            self.add(_join(path, key), f"magnitude {value:g} exceeds the limit {LARGEST:g}")
            return None
        if positive and value <= 0:
            self.add(_join(path, key), f"must be > 0, got {value!r}")
            return None
        if positive and value < SMALLEST:
            self.add(_join(path, key), f"{value:g} is below the smallest allowed {SMALLEST:g}")
            return None
        if nonnegative and value < 0:
            self.add(_join(path, key), f"must be >= 0, got {value!r}")
            return None
        return float(value)

    def vector(self, table: dict, key: str, path: str, length: tuple[int, ...] = (3,),
               required: bool = True, nonzero: bool = False) -> np.ndarray | None:
        if key not in table:
            if required:
                self.add(_join(path, key), "missing required field")
            return None
        value = table[key]
        field = _join(path, key)
        if (not isinstance(value, list) or len(value) not in length
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            sizes = " or ".join(str(n) for n in length)
            self.add(field, f"expected a list of {sizes} numbers, got {value!r}")
            return None
        if not all(finite_number(v) for v in value):
            self.add(field, f"contains a non-finite value: {value!r}")
            return None
        array = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(array)):
            self.add(field, f"contains a non-finite value: {value!r}")
            return None
        if np.abs(array).max() > LARGEST:
            self.add(field, f"a magnitude exceeds the limit {LARGEST:g}: {value!r}")
            return None
        if nonzero and np.linalg.norm(array) < _AXIS_TOL:
            self.add(field, "zero-length vector")
            return None
        return array


def finite_number(value: Any) -> bool:
    """Whether ``value`` is a number (not a bool) that is finite as a double: TOML reads integers
    of any size, and one beyond the double range (±1.8e308) cannot become a float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    return abs(value) <= sys.float_info.max if isinstance(value, int) else math.isfinite(value)


def read_toml(path: Path) -> tuple[str, dict]:
    """The text of ``path`` and the TOML document it holds.

    Raises
    ------
    FileNotFoundError
        When there is no such file.
    ValueError
        When the file cannot be read or is not TOML; the message says why (``cannot read the
        file: ...`` or ``not valid TOML: ...``; tomllib raises ValueError for an integer of over
        4300 digits and RecursionError for arrays nested a few hundred deep).
    """
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise
    except UnicodeDecodeError as error:
        raise ValueError(f"not valid TOML: {error}") from None
    except (OSError, ValueError) as error:  # a folder, no permission, a NUL in the name
        raise ValueError(f"cannot read the file: {error}") from None
    try:
        return text, tomllib.loads(text)
    except ValueError as error:  # TOMLDecodeError, or an integer too long to convert
        raise ValueError(f"not valid TOML: {error}") from None
    except RecursionError:
        raise ValueError("not valid TOML: arrays or tables nested too deeply to read") from None


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a scenario, body, joint, force or output, or None.

    Names are printed in tables and messages, so they must be printable and not padded; markup,
    emoji and other printable characters are fine (every output escapes them).
    """
    bad = next((ch for ch in name if unicodedata.category(ch) in _UNPRINTABLE), None)
    if bad is not None:
        return (f"name {name!r} contains the unprintable character U+{ord(bad):04X} "
                f"({unicodedata.category(bad)}); names must be printable")
    if name != name.strip():
        return f"name {name!r} has leading or trailing whitespace"
    return None


def _missing(*values) -> bool:
    """True if any value is None (arrays compare element-wise, so ``None in`` cannot be used)."""
    return any(v is None for v in values)


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _key_text(key: str) -> str:
    """``key`` as TOML writes it: bare when it can be, else quoted, so that an empty, spaced or
    unprintable key still shows in the problem's field (``""``, not an empty field)."""
    bare = key.isascii() and key.replace("_", "").replace("-", "").isalnum()
    return key if bare else json.dumps(key)
