"""Tolerance assertions on harness cases, usable with or without pytest.

The pytest plugin (:mod:`mbh._harness.testing.plugin`) is a thin layer over what is here and over
:class:`mbh._harness.testing.cases.CaseRunner`, which runs the cases the assertions look at:

* assertion helpers (``assert_*``) that raise ``AssertionError`` with a message naming the case
  and, for series, the worst sample's time, the value, the reference, the difference and the
  tolerance; each hides its own frame from pytest tracebacks (``__tracebackhide__``);
* :class:`Tolerances`, a TOML table of tolerances keyed by scenario, adapter and method, and
  :func:`assert_within_tolerance`, which checks one case against its entry;

Tolerance file format (``"*"`` matches any scenario, adapter or method; the entries that match a
case are merged, the more specific ones over the less specific)::

    [fourbar.mujoco.best]                 # scenario . adapter . method (quote methods with
    status = "ok"                         # punctuation: [fourbar.inhouse."rk4+direct"])
    outputs = { crank_angle = { atol = 2e-6, rtol = 0.0 } }   # |y - y_ref| <= atol + rtol |y_ref|
    constraint_violation = 1e-6           # m, the largest joint gap (orientation residuals as
                                          # lever-length × angle), see mbh._harness.measure.metrics
    energy_error = 1e-5                   # |energy-balance error| / the energy scale
    order = [1.8, 2.2]                    # band of the measured convergence order
    [fourbar.mujoco.best.dt."1e-2"]       # optional: overrides for one step size (s)
    outputs = { crank_angle = { atol = 1e-3 } }

Every key is optional; ``status`` defaults to ``"ok"``.  A file with a mistake raises
:class:`ToleranceError` naming the file, the field and the problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mbh._harness.common.status import CaseStatus
from mbh._harness.run.spec import CaseSpec, main_output
from mbh._harness.testing.cases import ANY, SessionCase, ToleranceError, step_text
from mbh._harness.measure.energy import energy_balance, energy_scale
from mbh._harness.measure.metrics import lever_length, violation_series
from mbh._harness.model.toml_fields import finite_number, read_toml
from mbh._harness.model.trajectory import STATUSES

#: Keys a tolerance entry may hold.
ENTRY_KEYS = ("status", "outputs", "constraint_violation", "energy_error", "order", "dt")
#: Keys of one output's tolerance.
OUTPUT_KEYS = ("atol", "rtol")
#: Sample times given to an assertion match a sample within this, s.
TIME_MATCH = 1e-9


# --- assertions -----------------------------------------------------------------------------

def _sample_indices(result: SessionCase, times) -> np.ndarray:
    """Indices of the samples at ``times`` (s); all samples when None."""
    samples = result.trajectory.times
    if times is None:
        return np.arange(samples.size)
    wanted = np.atleast_1d(np.asarray(times, dtype=float))
    index = np.clip(np.searchsorted(samples, wanted - TIME_MATCH), 0, samples.size - 1)
    off = np.abs(samples[index] - wanted) > TIME_MATCH
    if np.any(off):
        raise ToleranceError(f"{result.describe()}: time {wanted[off][0]:g} s is not a sample "
                             f"time (samples every 10 ms from 0 to {samples[-1]:g} s)")
    return index


def _worst(excess: np.ndarray) -> int:
    """Index of the largest excess over the tolerance; a non-finite value counts as infinite."""
    return int(np.argmax(np.where(np.isfinite(excess), excess, np.inf)))


def _no_samples(result: SessionCase) -> None:
    __tracebackhide__ = True
    if result.trajectory.n_samples == 0:
        raise AssertionError(f"{result.describe()}: no samples to check "
                             f"({result.trajectory.reason})")


def assert_status(result: SessionCase, expected: str = CaseStatus.OK) -> None:
    """The case ended with status ``expected`` (:data:`mbh._harness.model.trajectory.STATUSES`)."""
    __tracebackhide__ = True
    if expected not in STATUSES:
        raise ToleranceError(f"expected status {expected!r} is not one of {', '.join(STATUSES)}")
    if result.status != expected:
        raise AssertionError(f"{result.describe()}: status {result.status}, expected {expected}; "
                             f"reason: {result.trajectory.reason or '-'} (failure time "
                             f"{result.trajectory.failure_time})")


def assert_close_to_reference(result: SessionCase, output: str | None = None, atol: float = 0.0,
                              rtol: float = 0.0, times=None) -> None:
    """|y(t) − y_ref(t)| <= atol + rtol·|y_ref(t)| at every sample (or at ``times``, s).

    Parameters
    ----------
    result : SessionCase
    output : str, optional
        A scenario output (default its main output); values in its unit (rad, m, rad/s, m/s).
    atol, rtol : float
        Absolute tolerance (the output's unit) and relative tolerance; not negative.
    times : sequence of float, optional
        Sample times to check, s (each a multiple of the 10 ms sample step).
    """
    __tracebackhide__ = True
    if not (atol >= 0 and rtol >= 0):
        raise ToleranceError(f"atol and rtol must be >= 0, got atol={atol!r}, rtol={rtol!r}")
    _no_samples(result)
    name = output or main_output(result.mechanism)
    sample_times, values = result.output(name)
    reference = result.reference_output(name)
    index = _sample_indices(result, times)
    difference = np.abs(values[index] - reference[index])
    tolerance = atol + rtol * np.abs(reference[index])
    outside = ~(difference <= tolerance)
    if not outside.any():
        return
    worst = _worst(difference - tolerance)
    at = index[worst]
    raise AssertionError(
        f"{result.describe()}: output {name} is not within tolerance of the reference\n"
        f"  worst at t = {sample_times[at]:g} s: value {values[at]:.10g}, reference "
        f"{reference[at]:.10g}, difference {difference[worst]:.3g} > tolerance "
        f"{tolerance[worst]:.3g} (atol {atol:g} + rtol {rtol:g} × |reference|)\n"
        f"  {int(outside.sum())} of {index.size} checked samples outside the tolerance")


def _series_below(result: SessionCase, what: str, series: np.ndarray, bound: float,
                  unit: str) -> None:
    __tracebackhide__ = True
    if not bound > 0:
        raise ToleranceError(f"{what} bound must be positive, got {bound!r}")
    outside = ~(series <= bound)
    if not outside.any():
        return
    worst = _worst(series - bound)
    raise AssertionError(
        f"{result.describe()}: {what} above its bound\n"
        f"  worst at t = {result.trajectory.times[worst]:g} s: value {series[worst]:.3g}{unit}, "
        f"reference 0, difference {series[worst]:.3g}{unit} > tolerance {bound:.3g}{unit}\n"
        f"  {int(outside.sum())} of {series.size} samples above the bound")


def constraint_violation_series(result: SessionCase) -> np.ndarray:
    """Per-sample position-level constraint violation, m, shape (n_samples,): the larger of the
    joint gap and the orientation residual × the lever length (the per-sample figure whose
    maximum is :func:`mbh._harness.measure.metrics.constraint_violations`' ``max_constraint_violation``)."""
    series = violation_series(result.mechanism, result.trajectory)
    return np.maximum(series["joint_gap_m"],
                      lever_length(result.mechanism) * series["orientation_rad"])


def energy_error_series(result: SessionCase) -> np.ndarray:
    """Per-sample |energy-balance error| / the energy scale, shape (n_samples,)
    (:func:`mbh._harness.measure.energy.energy_balance`, :func:`mbh._harness.measure.energy.energy_scale`)."""
    if result.reference is None:
        raise AssertionError(f"{result.describe()}: no verified reference, so no energy scale")
    scale = energy_scale(result.mechanism, result.reference)
    if scale is None:
        raise AssertionError(f"{result.describe()}: the scene has no energy scale (no motion, "
                             f"no gravity)")
    return np.abs(energy_balance(result.mechanism, result.trajectory, result.reference)) / scale


def assert_constraint_violation_below(result: SessionCase, bound: float) -> None:
    """The position-level constraint violation stays <= ``bound`` (m) at every sample
    (:func:`constraint_violation_series`)."""
    __tracebackhide__ = True
    _no_samples(result)
    _series_below(result, "constraint violation", constraint_violation_series(result), bound,
                  " m")


def assert_energy_error_below(result: SessionCase, bound: float) -> None:
    """|energy-balance error| / energy scale stays <= ``bound`` at every sample
    (:func:`energy_error_series`)."""
    __tracebackhide__ = True
    _no_samples(result)
    _series_below(result, "energy-balance error (relative to the energy scale)",
                  energy_error_series(result), bound, "")


def convergence_order(results: list[SessionCase], output: str | None = None) -> float:
    """Slope of log(max error) against log(dt) over ``results`` (least squares).

    Raises
    ------
    ToleranceError
        For fewer than two distinct steps, or cases of different scenario, adapter or method.
    """
    keys = {(r.spec.scenario, r.spec.adapter, r.spec.method) for r in results}
    steps = [r.spec.dt for r in results]
    if len(keys) != 1 or len(set(steps)) < 2:
        raise ToleranceError("a convergence order needs cases of one scenario, adapter and "
                             f"method at two or more step sizes, got {[r.label for r in results]}")
    errors = [_max_error(r, output) for r in results]
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


def _max_error(result: SessionCase, output: str | None) -> float:
    if result.trajectory.n_samples == 0:
        return math.nan
    return float(np.max(np.abs(result.output(output)[1] - result.reference_output(output))))


def assert_convergence_order(results: list[SessionCase], low: float, high: float,
                             output: str | None = None) -> None:
    """The measured order (:func:`convergence_order`) lies in [low, high]; every case ``ok``."""
    __tracebackhide__ = True
    for result in results:
        assert_status(result)
    order = convergence_order(results, output)
    if low <= order <= high:
        return
    first = results[0]
    name = output or main_output(first.mechanism)
    table = ", ".join(f"dt {step_text(r.spec.dt)} → {_max_error(r, output):.3g}"
                      for r in sorted(results, key=lambda r: r.spec.dt))
    raise AssertionError(
        f"cases {first.spec.scenario}-{first.spec.adapter}-{first.spec.method} (t_end "
        f"{first.spec.t_end:g} s): convergence order of {name} is {order:.3f}, outside "
        f"[{low:g}, {high:g}]\n  max error by step: {table}")


def assert_at_least_as_fast(result: SessionCase, other: SessionCase, factor: float = 1.0) -> None:
    """``result`` takes at most ``factor`` times ``other``'s calibrated wall time (each wall
    time divided by its session's machine-speed figure, so runs compare as ratios)."""
    __tracebackhide__ = True
    if not factor > 0:
        raise ToleranceError(f"factor must be positive, got {factor!r}")
    mine, theirs = result.calibrated_time, other.calibrated_time
    ratio = mine / theirs
    if ratio <= factor:
        return
    raise AssertionError(
        f"{result.describe()} is slower than {other.describe()}\n"
        f"  calibrated time {mine:.4g} against {theirs:.4g} (wall {result.wall_time_s:.4g} s / "
        f"{result.calibration():.4g} s and {other.wall_time_s:.4g} s / "
        f"{other.calibration():.4g} s): ratio {ratio:.3g} > tolerance {factor:g}")


# --- tolerance files ------------------------------------------------------------------------

@dataclass(frozen=True)
class OutputTolerance:
    """|y − y_ref| <= atol + rtol·|y_ref| (the output's unit)."""

    atol: float = 0.0
    rtol: float = 0.0


@dataclass(frozen=True)
class CaseTolerance:
    """The tolerances of one case (None: not checked).

    Attributes
    ----------
    status : str
        Expected status.
    outputs : dict
        Output name → :class:`OutputTolerance`.
    constraint_violation : float or None
        m.
    energy_error : float or None
        Relative to the energy scale.
    order : (float, float) or None
        Band of the convergence order.
    source : str
        Where it came from (file and matched entries), for messages.
    """

    status: str = CaseStatus.OK
    outputs: dict = field(default_factory=dict)
    constraint_violation: float | None = None
    energy_error: float | None = None
    order: tuple[float, float] | None = None
    source: str = ""


def assert_within_tolerance(result: SessionCase, tolerance: CaseTolerance) -> None:
    """Every tolerance of ``tolerance`` holds for ``result``: the status, then (for an
    expected ``ok``) each output, the constraint violation and the energy error."""
    __tracebackhide__ = True
    assert_status(result, tolerance.status)
    for name, output in tolerance.outputs.items():
        assert_close_to_reference(result, name, atol=output.atol, rtol=output.rtol)
    if tolerance.constraint_violation is not None:
        assert_constraint_violation_below(result, tolerance.constraint_violation)
    if tolerance.energy_error is not None:
        assert_energy_error_below(result, tolerance.energy_error)


def _same_step(step: float, dt: float) -> bool:
    """Whether a per-step table's ``step`` is the case's ``dt`` (s), to round-off."""
    return math.isclose(step, dt, rel_tol=1e-9)


class Tolerances:
    """A tolerance file (format in the module docstring), validated on load.

    Parameters
    ----------
    path : str or Path

    Raises
    ------
    ToleranceError
        Naming the file, the field and the problem, for the first mistake found.
    """

    def __init__(self, path):
        self.path = Path(path)
        try:
            _, document = read_toml(self.path)
        except FileNotFoundError:
            raise ToleranceError(f"{self.path}: no such tolerance file") from None
        except ValueError as error:
            raise ToleranceError(f"{self.path}: {error}") from None
        self.entries: dict[tuple[str, str, str], dict] = {}
        for scene, adapters in document.items():
            for adapter, methods in self._table(adapters, scene).items():
                for method, entry in self._table(methods, f"{scene}.{adapter}").items():
                    where = f"{scene}.{adapter}.{method}"
                    self.entries[(scene, adapter, method)] = self._entry(entry, where, True)

    def _fail(self, where: str, problem: str):
        raise ToleranceError(f"{self.path}: {where}: {problem}")

    def _table(self, value, where: str) -> dict:
        if not isinstance(value, dict):
            self._fail(where, f"expected a table (scenario.adapter.method), got {value!r}")
        return value

    def _checked_number(self, value, where: str, least: float = 0.0) -> float:
        if not finite_number(value) or value < least:
            self._fail(where, f"expected a finite number >= {least:g}, got {value!r}")
        return float(value)

    def _entry(self, entry, where: str, steps_allowed: bool) -> dict:
        entry = self._table(entry, where)
        checked = {}
        for key, value in entry.items():
            field_ = f"{where}.{key}"
            if key not in ENTRY_KEYS or (key == "dt" and not steps_allowed):
                allowed = [k for k in ENTRY_KEYS if steps_allowed or k != "dt"]
                self._fail(field_, f"unknown key (allowed: {', '.join(allowed)})")
            if key == "status":
                if value not in STATUSES:
                    self._fail(field_, f"expected one of {', '.join(STATUSES)}, got {value!r}")
                checked[key] = value
            elif key == "outputs":
                checked[key] = {name: self._output(spec, f"{field_}.{name}")
                                for name, spec in self._table(value, field_).items()}
            elif key == "order":
                if (not isinstance(value, list) or len(value) != 2
                        or self._checked_number(value[0], field_, -math.inf)
                        > self._checked_number(value[1], field_, -math.inf)):
                    self._fail(field_, f"expected [low, high] with low <= high, got {value!r}")
                checked[key] = (float(value[0]), float(value[1]))
            elif key == "dt":
                checked[key] = {self._step(step, f"{field_}.{step}"):
                                self._entry(sub, f"{field_}.{step}", False)
                                for step, sub in self._table(value, field_).items()}
            else:
                checked[key] = self._checked_number(value, field_, math.ulp(0.0))
        return checked

    def _output(self, spec, where: str) -> OutputTolerance:
        spec = self._table(spec, where)
        unknown = set(spec) - set(OUTPUT_KEYS)
        if unknown:
            self._fail(f"{where}.{sorted(unknown)[0]}",
                       f"unknown key (allowed: {', '.join(OUTPUT_KEYS)})")
        return OutputTolerance(**{key: self._checked_number(spec[key], f"{where}.{key}")
                                  for key in OUTPUT_KEYS if key in spec})

    def _step(self, text: str, where: str) -> float:
        try:
            step = float(text)
        except ValueError:
            step = math.nan
        if not (math.isfinite(step) and step > 0):
            self._fail(where, f"expected a step size in s as the key, e.g. \"1e-3\", got {text!r}")
        return step

    def for_case(self, spec: CaseSpec) -> CaseTolerance:
        """The merged tolerances of ``spec`` (module docstring: wildcards, then specific
        entries, then the entry's per-step overrides).

        Raises
        ------
        ToleranceError
            When no entry matches the case, or every entry that matches holds per-step tables
            only (a recorded file: ``pytest --mbh-record``) and none for the case's step.
        """
        matched = [key for key in self._candidates(spec) if key in self.entries]
        if not matched:
            raise ToleranceError(f"{self.path}: no tolerance entry matches "
                                 f"{spec.scenario}.{spec.adapter}.{spec.method} (entries: "
                                 f"{', '.join('.'.join(k) for k in self.entries) or 'none'})")
        if not any(self._applies(self.entries[key], spec.dt) for key in matched):
            steps = sorted({step for key in matched for step in self.entries[key]["dt"]})
            raise ToleranceError(f"{self.path}: no tolerance for {spec.scenario}.{spec.adapter}."
                                 f"{spec.method} at dt {step_text(spec.dt)} s: its entries hold "
                                 f"the steps {', '.join(map(step_text, steps))} s only")
        merged = CaseTolerance()
        for key in matched:
            entry = self.entries[key]
            merged = self._merge(merged, entry)
            for step, override in entry.get("dt", {}).items():
                if _same_step(step, spec.dt):
                    merged = self._merge(merged, override)
        return replace(merged, source=f"{self.path}: " + ", ".join(".".join(k) for k in matched))

    @staticmethod
    def _applies(entry: dict, dt: float) -> bool:
        """Whether ``entry`` holds a tolerance for a case of step ``dt`` (s): it has keys of its
        own, or a per-step table of that step."""
        return set(entry) != {"dt"} or any(_same_step(step, dt) for step in entry["dt"])

    @staticmethod
    def _merge(tolerance: CaseTolerance, entry: dict) -> CaseTolerance:
        changes = {key: value for key, value in entry.items() if key not in ("dt", "outputs")}
        outputs = {**tolerance.outputs, **entry.get("outputs", {})}
        return replace(tolerance, outputs=outputs, **changes)

    @staticmethod
    def _candidates(spec: CaseSpec) -> list[tuple[str, str, str]]:
        """Keys that match ``spec``, least specific first."""
        keys = [(s, a, m) for s in (ANY, spec.scenario) for a in (ANY, spec.adapter)
                for m in (ANY, spec.method)]
        return sorted(dict.fromkeys(keys), key=lambda key: sum(part != ANY for part in key))
