"""One campaign case → one flat result row (scalars only) and its trajectory.

:func:`run_spec` runs a :class:`~mbh._harness.run.spec.CaseSpec` the one way every caller does
(:func:`mbh._harness.run.case.run_case`: build → simulate → the stick's verdict → metrics), against the
scenario's verified reference when there is one, repeats the timed run, and flattens everything a
report needs into one tidy row: the stick's metrics, the status with its reason and failure time,
wall times (the median over the repetitions, per simulated second and per step), the engine's cost
counters, the model size the engine carried (:meth:`mbh._adapters.base.Adapter.model_size`) and the
versions.  Nested values (counters, notes, the list of wall times, package versions) are JSON
strings, so every column holds str, float, int, bool or None.

Columns: ``case_id, scenario, scenario_hash, adapter, adapter_version, method, dt, t_end,
repetitions, status, reason, failure_time, accurate, main_output, main_output_error, wall_time_s,
wall_time_per_sim_s, wall_time_per_step_s, wall_times_s, steps, rhs_evals, counters, notes,
n_coordinates, n_constraint_equations, n_redundant_equations, model_notes, reference, packages``,
every scalar of :func:`mbh._harness.measure.metrics.case_metrics` (``samples``, ``final_time``,
``max_constraint_violation``, ``max_velocity_violation``, ``max_energy_error_J``,
``max_energy_error_rel``, ``max_joint_gap_m`` …), and per scenario output ``error_<output>``
(max |y − y_ref|, rad, rad/s or m) and ``final_<output>`` (its value at the last sample).
"""

from __future__ import annotations

import json
import statistics
from dataclasses import dataclass

import numpy as np
import scipy

from mbh._adapters import AdapterLoadError, resolve_adapter
from mbh._adapters.base import Adapter, UnsupportedCase, blame, describe
from mbh._harness.common.status import CaseStatus
from mbh._harness.model import scenario
from mbh._harness.run.spec import CaseSpec, main_output
from mbh._harness.run.case import CaseResult, run_case, simulate_case
from mbh._harness.common.jsonout import dumps
from mbh._harness.measure.metrics import constraint_violations
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.references.build import ReferenceBuildError, reference_trajectory
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.measure.verdict import Bounds

def packages(adapter: Adapter) -> str:
    """JSON of the versions that produced a row: numpy, scipy, the engine and, for a third-party
    adapter, the package providing it (``adapter_package``: ``"NAME VERSION"``)."""
    versions = {"numpy": np.__version__, "scipy": scipy.__version__, "engine": adapter.version()}
    if adapter.package:
        versions["adapter_package"] = adapter.package
    return json.dumps(versions, sort_keys=True)


def _load_reference(mech: Mechanism) -> tuple[Trajectory | None, str]:
    """The verified reference and the ``reference`` column: ``"verified"`` or ``"none: why"``."""
    try:
        return reference_trajectory(mech), "verified"
    except ReferenceBuildError as error:
        return None, f"none: {' '.join(str(error).split())}"


def _model_size(adapter: Adapter, mech: Mechanism, method: str) -> dict:
    """The model-size columns of ``method``'s model; None with the reason as the note when the
    engine cannot build."""
    try:
        size = adapter.method_model_size(adapter.build(mech), method)
    except UnsupportedCase as error:
        size = _no_size(f"not built: {error}")
    except Exception as error:  # noqa: BLE001 — the run's row already says why (rule 6)
        size = _no_size(f"not built: {blame(adapter.source, 'build or method_model_size', error)}")
    return {"n_coordinates": size["coordinates"],
            "n_constraint_equations": size["constraint_equations"],
            "n_redundant_equations": size["redundant_equations"],
            "model_notes": size["notes"]}


def _no_size(notes: str) -> dict:
    return {"coordinates": None, "constraint_equations": None, "redundant_equations": None,
            "notes": notes}


def _spec_columns(spec: CaseSpec) -> dict:
    return {"case_id": spec.case_id, "scenario": spec.scenario, "adapter": spec.adapter,
            "method": spec.method, "dt": spec.dt, "t_end": spec.t_end,
            "repetitions": spec.repetitions}


def _blank_metrics(mech: Mechanism) -> dict:
    """Every float metric column of ``mech``'s rows, NaN (a case without samples)."""
    nan = float("nan")
    blank = {"final_time": nan, "max_energy_error_J": nan, "max_energy_error_rel": nan,
             **constraint_violations(mech, Trajectory.empty(len(mech.bodies)))}
    for output in mech.outputs:
        blank[f"error_{output.name}"] = nan
        blank[f"final_{output.name}"] = nan
    return blank


def _metric_columns(metrics: dict, mech: Mechanism) -> dict:
    """case_metrics flattened: scalars as they are, nested values as JSON or per-output columns;
    metrics a run without samples lacks are NaN."""
    row = _blank_metrics(mech) | {
        key: value for key, value in metrics.items()
        if key not in ("counters", "notes", "outputs", "output_errors", "wall_time_s")}
    row["counters"] = dumps(metrics["counters"], indent=None)
    row["notes"] = dumps(metrics["notes"], indent=None)
    for name, value in metrics.get("output_errors", {}).items():
        row[f"error_{name}"] = value
    for name, value in metrics.get("outputs", {}).items():
        row[f"final_{name}"] = value
    return row


@dataclass(frozen=True)
class CaseWork:
    """The work a worker process does for one spec: :func:`run_spec`, returning
    ``(row, trajectory)``.

    Picklable (module-level class of plain fields), so it can be sent to worker processes.  It
    lives here, not with the campaign runner, because unpickling it imports its module in every
    case's process: the runner's module imports the result store (pandas, pyarrow), which no case
    needs (0.37 s a case).

    Attributes
    ----------
    bounds : Bounds
    accuracy : float
    adapters : tuple of (str, type or Adapter)
        Adapters given as a class or an instance rather than registered, by the name their cases
        carry; each reaches the workers by pickle (a class by its importable name).
    """

    bounds: Bounds
    accuracy: float
    adapters: tuple[tuple[str, type[Adapter] | Adapter], ...] = ()

    def __call__(self, spec: CaseSpec) -> tuple[dict, Trajectory | None]:
        outcome = run_spec(spec, self.bounds, self.accuracy,
                           adapter=dict(self.adapters).get(spec.adapter))
        return outcome.row, outcome.trajectory


def run_spec(spec: CaseSpec, bounds: Bounds, accuracy: float, mech: Mechanism | None = None,
             adapter: type[Adapter] | Adapter | None = None) -> CaseResult:
    """Run one case and flatten it into a row.

    Parameters
    ----------
    spec : CaseSpec
    bounds : Bounds
        The verdict's bounds.
    accuracy : float
        Threshold on the main output's error (rad or m) for the ``accurate`` column.
    mech : Mechanism, optional
        The scene, when it was built in Python (:mod:`mbh._harness.model.builder`); loaded from
        ``spec.scenario`` otherwise.
    adapter : Adapter subclass or instance, optional
        The adapter of ``spec.adapter`` when it is not registered under that name
        (:func:`mbh._adapters.resolve_adapter`); the registered adapter otherwise.

    Returns
    -------
    CaseResult
        With ``row`` set (see the module docstring).  Never raises for engine trouble: that is
        the row's status.  An adapter that cannot be loaded or constructed
        (:class:`mbh._adapters.AdapterLoadError`), and an exception raised outside the engine's run
        (the adapter's ``version()``, measuring the run), give status ``failed`` with the error as
        the reason (and empty ``metrics``); a third-party adapter's reason names it and its
        package.
    """
    mech = scenario.load(spec.scenario) if mech is None else mech
    reference, reference_column = _load_reference(mech)
    try:
        adapter = resolve_adapter(spec.adapter if adapter is None else adapter)
    except AdapterLoadError as error:
        return _failed(spec, mech, str(error), reference_column)
    try:
        version = adapter.version()
    except Exception as error:  # noqa: BLE001 — the adapter's own code: named in the reason
        return _failed(spec, mech, blame(adapter.source, "version()", error), reference_column)
    try:
        result = run_case(adapter, mech, spec.method, spec.dt, spec.t_end, reference, bounds)
        walls = [result.trajectory.wall_time_s]
        for _ in range(spec.repetitions - 1):
            walls.append(simulate_case(adapter, mech, spec.method, spec.dt, spec.t_end).wall_time_s)
        size = _model_size(adapter, mech, spec.method)
    except Exception as error:  # noqa: BLE001 — a failure to measure is a result
        return _failed(spec, mech, describe(error), reference_column)
    trajectory, metrics = result.trajectory, result.metrics
    main = main_output(mech)
    error = metrics.get("output_errors", {}).get(main, float("nan"))
    wall = statistics.median(walls)
    row = {
        **_spec_columns(spec),
        "scenario_hash": mech.content_hash, "adapter_version": version,
        **_metric_columns(metrics, mech),
        "accurate": None if reference is None else bool(
            trajectory.status == CaseStatus.OK and error <= accuracy),
        "main_output": main, "main_output_error": error,
        "wall_time_s": wall, "wall_time_per_sim_s": wall / spec.t_end,
        "wall_time_per_step_s": wall / trajectory.steps if trajectory.steps else float("nan"),
        "wall_times_s": json.dumps(walls),
        **size,
        "reference": reference_column, "packages": packages(adapter),
    }
    return CaseResult(trajectory, metrics, row)


def _failed(spec: CaseSpec, mech: Mechanism, reason: str, reference_column: str) -> CaseResult:
    """A ``failed`` case without samples or metrics, its row saying ``reason``."""
    row = error_row(spec, CaseStatus.FAILED, reason) | {"reference": reference_column}
    return CaseResult(Trajectory.empty(len(mech.bodies), status=CaseStatus.FAILED, reason=reason,
                                       failure_time=0.0), {}, row)


def error_row(spec: CaseSpec, status: str, reason: str) -> dict:
    """A row for a case that produced no outcome (``crashed``, ``timeout``): the same columns as
    :func:`run_spec`'s, metrics NaN, counts and model size None."""
    nan = float("nan")
    row = {**_spec_columns(spec), "scenario_hash": None, "adapter_version": None,
           "status": status, "reason": reason, "failure_time": None, "accurate": False,
           "main_output": None, "main_output_error": nan, "wall_time_s": nan,
           "wall_time_per_sim_s": nan, "wall_time_per_step_s": nan, "wall_times_s": "[]",
           "steps": None, "rhs_evals": None, "counters": "{}", "notes": "[]", "samples": 0,
           "n_coordinates": None, "n_constraint_equations": None, "n_redundant_equations": None,
           "model_notes": "", "reference": None, "packages": None}
    try:
        mech = scenario.load(spec.scenario)
    except scenario.ScenarioError:
        return row
    return row | _blank_metrics(mech) | {"scenario_hash": mech.content_hash,
                                         "main_output": main_output(mech)}
