"""Record, then assert: tolerance files written from the errors a test session measured
(``pytest --mbh-record``, :mod:`mbh._harness.testing.plugin`).

A recorded tolerance is the session's margin (``--mbh-record-margin``, default
:data:`mbh._harness.testing.plugin.RECORD_MARGIN`) times the measured value, rounded up to two
significant digits and never below the quantity's floor (:data:`FLOORS`: below it a figure is
round-off, which differs across CPUs and BLAS builds).  Per case, under
``[SCENARIO.ADAPTER.METHOD.dt."STEP"]`` (the format of :mod:`mbh._harness.testing.tolerances`):

* ``status``: the status measured;
* for an ``ok`` case with samples, ``outputs``: every scenario output's
  max |y − y_ref| (as ``atol``), ``constraint_violation``: the largest of
  :func:`~mbh._harness.testing.tolerances.constraint_violation_series`, and ``energy_error``: the
  largest of :func:`~mbh._harness.testing.tolerances.energy_error_series` (when the scene has an
  energy scale).

Writing a file keeps its entries for other cases and replaces those of the cases recorded (its
comments are not kept: the file is rewritten).  Cases that differ in their duration alone share
one table, holding the looser of each value.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from mbh._harness.common.status import CaseStatus
from mbh._harness.model.scenario import read_toml
from mbh._harness.testing.cases import SessionCase, ToleranceError, step_text
from mbh._harness.testing.tolerances import (ENTRY_KEYS, CaseTolerance, Tolerances,
                                             constraint_violation_series, energy_error_series)

#: The smallest tolerance recorded per quantity: output errors (the output's unit: rad, m …),
#: constraint violation (m) and energy error (fraction of the energy scale).
FLOORS = {"outputs": 1e-11, "constraint_violation": 1e-11, "energy_error": 1e-10}
#: Keys TOML writes bare; any other key is quoted.
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def rounded_up(value: float) -> float:
    """``value`` (> 0) rounded up to two significant digits: 5.83e-7 → 5.9e-7."""
    exponent = math.floor(math.log10(value)) - 1
    digits = math.ceil(round(value / 10.0 ** exponent, 9))
    return float(f"{digits}e{exponent}")


def _tolerance(measured: float, margin: float, floor: float) -> float:
    return max(rounded_up(margin * measured) if measured > 0 else floor, floor)


def measured_errors(case: SessionCase) -> dict:
    """What ``case`` measured, in the shape of a tolerance entry: ``status``, and for an ``ok``
    case with samples ``outputs`` (name → max |y − y_ref|, when the scene has a reference),
    ``constraint_violation`` and ``energy_error`` (when the scene has an energy scale)."""
    measured: dict = {"status": case.status}
    if case.status != CaseStatus.OK or case.trajectory.n_samples == 0:
        return measured
    if case.reference is not None:
        measured["outputs"] = {
            output.name: float(np.max(np.abs(case.output(output.name)[1]
                                              - case.reference_output(output.name))))
            for output in case.mechanism.outputs}
    measured["constraint_violation"] = float(np.max(constraint_violation_series(case)))
    try:
        measured["energy_error"] = float(np.max(energy_error_series(case)))
    except AssertionError:  # no reference or no energy scale: nothing to hold it to
        pass
    return measured


def recorded_entry(measured: dict, margin: float) -> dict:
    """The tolerance entry for :func:`measured_errors`' ``measured``: each value × ``margin``,
    rounded up, at least its floor (:data:`FLOORS`)."""
    entry: dict = {"status": measured["status"]}
    if "outputs" in measured:
        entry["outputs"] = {name: {"atol": _tolerance(error, margin, FLOORS["outputs"])}
                            for name, error in measured["outputs"].items()}
    for key in ("constraint_violation", "energy_error"):
        if key in measured:
            entry[key] = _tolerance(measured[key], margin, FLOORS[key])
    return entry


def _looser(first: dict, second: dict, where: str) -> dict:
    """One entry holding both: the larger of each value (the statuses must agree)."""
    if first["status"] != second["status"]:
        raise ToleranceError(f"{where}: two recorded cases of this scenario, adapter, method and "
                             f"step ended {first['status']} and {second['status']}; one "
                             f"tolerance table cannot hold both (record them in different files)")
    merged = dict(first)
    for key, value in second.items():
        if key == "outputs":
            outputs = dict(first.get("outputs", {}))
            for name, tolerance in value.items():
                atol = max(tolerance["atol"], outputs.get(name, {}).get("atol", 0.0))
                outputs[name] = {"atol": atol}
            merged["outputs"] = outputs
        elif key != "status":
            merged[key] = max(value, first.get(key, value))
    return merged


class ToleranceRecording:
    """The tolerances a session records, by file, written at its end (:meth:`write`).

    Parameters
    ----------
    margin : float
        Recorded tolerance / measured value (> 1).
    """

    def __init__(self, margin: float):
        if not (math.isfinite(margin) and margin > 1):
            raise ToleranceError(f"--mbh-record-margin: expected a number > 1, got {margin!r}")
        self.margin = margin
        self.files: dict[Path, dict[tuple[str, str, str, str], dict]] = {}

    def record(self, path: Path, case: SessionCase) -> CaseTolerance:
        """Record ``case``'s tolerances for the file ``path``; returns the tolerance a recording
        session asserts: the measured status alone."""
        spec = case.spec
        key = (spec.scenario, spec.adapter, spec.method, step_text(spec.dt))
        entry = recorded_entry(measured_errors(case), self.margin)
        if path not in self.files:
            _existing(path)  # a file with mistakes is named now, in the test, not at the end
        entries = self.files.setdefault(path, {})
        if key in entries:
            entry = _looser(entries[key], entry, f"{path}: {'.'.join(key[:3])}.dt.{key[3]}")
        entries[key] = entry
        return CaseTolerance(status=case.status, source=f"{path}: being recorded")

    def write(self) -> list[Path]:
        """Write every file recorded into, keeping the entries of cases not recorded; returns
        the files written."""
        for path, entries in self.files.items():
            document = _existing(path)
            for (scene, adapter, method, step), entry in entries.items():
                table = document.setdefault(scene, {}).setdefault(adapter, {})
                table.setdefault(method, {}).setdefault("dt", {})[step] = entry
            path.write_text(_header(self.margin) + dumps(document), encoding="utf-8")
        return list(self.files)


def _existing(path: Path) -> dict:
    """The tolerance document at ``path``, validated (:class:`Tolerances`); {} when there is
    none."""
    if not path.exists():
        return {}
    Tolerances(path)
    return read_toml(path)[1]


def _header(margin: float) -> str:
    floors = ", ".join(f"{key} {value:g}" for key, value in FLOORS.items())
    return (f"# Recorded by pytest --mbh-record: each tolerance is {margin:g} x the value the "
            f"session measured,\n# rounded up to two digits; floors: {floors}.\n"
            f"# Format: docs/formats/tolerances.md.\n\n")


def _key(name: str) -> str:
    """A TOML key: bare when it may be, quoted when not or when it reads as a number (a step)."""
    return name if _BARE_KEY.fullmatch(name) and not name[0].isdigit() else json.dumps(name)


def _value(value) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


def _entry_lines(path: tuple[str, ...], entry: dict) -> list[str]:
    """``[path]`` and the entry's keys, then its per-step tables."""
    keys = [f"{key} = {_value(entry[key])}" for key in ENTRY_KEYS
            if key != "dt" and key in entry]
    lines = [f"[{'.'.join(map(_key, path))}]", *keys, ""] if keys else []
    for step, override in entry.get("dt", {}).items():
        lines += _entry_lines((*path, "dt", step), override)
    return lines


def dumps(document: dict) -> str:
    """A tolerance document (scenario → adapter → method → entry) as TOML text."""
    lines = []
    for scene, adapters in document.items():
        for adapter, methods in adapters.items():
            for method, entry in methods.items():
                lines += _entry_lines((scene, adapter, method), entry)
    return "\n".join(lines)
