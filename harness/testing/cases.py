"""Harness cases for tolerance assertions (:mod:`mbh._harness.testing.tolerances`) and the pytest
plugin (:mod:`mbh._harness.testing.plugin`), run in the caller's process or, isolated, in a worker
process of their own.

* :class:`CaseRunner` runs cases (:func:`mbh._harness.run.row.run_spec`: the same build → simulate →
  verdict → metrics as a campaign) and keeps every finished case for the session, so a
  parametrized suite that asks for a case twice runs it once; it also loads references and runs
  the machine-speed workload (:mod:`mbh._harness.common.machine_speed`) once, for calibrated time
  ratios.  An isolated case runs as a campaign's does (:func:`mbh._harness.run.executor.run_isolated`):
  an engine that crashes or hangs gives a ``crashed`` or ``timeout`` case, the signal named in its
  reason, and the test session goes on;
* :func:`campaign_cases` and :func:`campaign_params`, a campaign file turned into (readable id,
  case) pairs and ``pytest.param`` objects for parametrized tests (ids like
  ``fourbar-mujoco-best-dt1e-3``), and :class:`Selection`, the command line's choice of scenarios
  and adapters.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from mbh._harness.model import scenario
from mbh._harness.run.case import CaseResult
from mbh._harness.run.spec import CaseSpec, load_campaign, main_output
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import ReferenceBuildError, reference_trajectory
from mbh._harness.model.timegrid import reference_indices
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.measure.verdict import DEFAULT_ACCURACY, DEFAULT_BOUNDS, Bounds
from mbh._harness.common.errors import MbhError
from mbh._harness.common.machine_speed import machine_speed_s

#: Key of a tolerance table (and of a :class:`Selection`) that matches every name.
ANY = "*"


class ToleranceError(MbhError, ValueError):
    """A tolerance file, or an assertion's arguments, that cannot be used; the message says
    which file or argument, which field and why."""


def case_spec(scenario_name: str, adapter: str, method: str, dt: float,
              t_end: float | None = None, repetitions: int = 1) -> CaseSpec:
    """A :class:`~mbh._harness.run.spec.CaseSpec` with the scenario's own duration unless ``t_end``
    (s) is given.  ``repetitions`` > 1 times the case that often (the median wall time)."""
    if t_end is None:
        t_end = scenario.load(scenario_name).duration
    return CaseSpec(scenario_name, adapter, method, float(dt), float(t_end), repetitions)


def step_text(dt: float) -> str:
    """A step size as short scientific text: 1e-3 → ``"1e-3"``, 5e-4 → ``"5e-4"``."""
    return np.format_float_scientific(dt, trim="-", exp_digits=1).replace("e+", "e")


def case_label(spec: CaseSpec) -> str:
    """The readable id of a case: ``fourbar-mujoco-best-dt1e-3``."""
    return f"{spec.scenario}-{spec.adapter}-{spec.method}-dt{step_text(spec.dt)}"


def campaign_cases(name_or_path, scenarios=None, adapters=None) -> list[tuple[str, CaseSpec]]:
    """(label, case) for every case of a campaign, in the campaign's order.

    Parameters
    ----------
    name_or_path : str or Path
        A shipped campaign name (``campaigns/<name>.toml``) or a campaign file.
    scenarios, adapters : iterable of str, optional
        Keep only these (default: all).

    Returns
    -------
    list of (str, CaseSpec)
        Labels are :func:`case_label`, with ``-t<t_end>`` appended where two cases would
        otherwise share one.

    Raises
    ------
    mbh._harness.run.spec.CampaignError
        For a campaign file with mistakes (every one named).
    """
    keep = Selection.of(scenarios, adapters)
    cases = [spec for spec in load_campaign(name_or_path).cases if keep.reason(spec) is None]
    labels = [case_label(spec) for spec in cases]
    shared = {label for label in labels if labels.count(label) > 1}
    return [(f"{label}-t{spec.t_end:g}" if label in shared else label, spec)
            for label, spec in zip(labels, cases)]


def campaign_params(name_or_path, scenarios=None, adapters=None) -> list:
    """A campaign's cases as ``pytest.param(case, id=label)`` for
    ``@pytest.mark.parametrize`` (:func:`campaign_cases`, same arguments; ids like
    ``fourbar-mujoco-best-dt1e-3``)."""
    import pytest  # here: the assertions and the runner are usable without pytest

    return [pytest.param(spec, id=label)
            for label, spec in campaign_cases(name_or_path, scenarios, adapters)]


@dataclass(frozen=True)
class Selection:
    """The scenarios and adapters a session runs (None: all), e.g. from ``--mbh-scenarios``."""

    scenarios: frozenset[str] | None = None
    adapters: frozenset[str] | None = None

    @classmethod
    def of(cls, scenarios=None, adapters=None) -> "Selection":
        """From iterables of names (None: all)."""
        return cls(None if scenarios is None else frozenset(scenarios),
                   None if adapters is None else frozenset(adapters))

    @classmethod
    def parse(cls, scenarios: str | None, adapters: str | None) -> "Selection":
        """From comma-separated lists (``"fourbar,slider_crank"``); None or empty: all.

        Raises
        ------
        ToleranceError
            Naming an unknown scenario or adapter and the known ones.
        """
        from mbh._adapters import adapter_names

        def names(text, known, option, is_known=None):
            is_known = is_known or known.__contains__
            chosen = [name.strip() for name in (text or "").split(",") if name.strip()]
            unknown = [name for name in chosen if not is_known(name)]
            if unknown:
                raise ToleranceError(f"{option}: unknown {', '.join(unknown)} (known: "
                                     f"{', '.join(known)})")
            return frozenset(chosen) if chosen else None
        return cls(names(scenarios, scenario.scenario_names(), "--mbh-scenarios",
                         scenario.is_scenario_name),
                   names(adapters, adapter_names(), "--mbh-adapters"))

    def reason(self, spec: CaseSpec) -> str | None:
        """Why ``spec`` is not selected, or None when it is."""
        if self.scenarios is not None and spec.scenario not in self.scenarios:
            return (f"scenario {spec.scenario} not selected (--mbh-scenarios "
                    f"{','.join(sorted(self.scenarios))})")
        if self.adapters is not None and spec.adapter not in self.adapters:
            return (f"adapter {spec.adapter} not selected (--mbh-adapters "
                    f"{','.join(sorted(self.adapters))})")
        return None


@dataclass
class SessionCase:
    """A case finished in this test session: its result with what the tolerance assertions
    need around it (the spec, the mechanism, the reference, the session's calibration).

    Attributes
    ----------
    spec : CaseSpec
    result : CaseResult
        The case's result (:func:`mbh._harness.run.row.run_spec`): the judged trajectory, sampled
        every 10 ms, and the campaign row (status, reason, errors, wall time…).
    mechanism : Mechanism
    reference : Trajectory or None
        The scenario's verified reference (None when it has none).
    calibration : callable
        Returns the session's calibration time, s (run once, on first use).
    """

    spec: CaseSpec
    result: CaseResult
    mechanism: Mechanism
    reference: Trajectory | None
    calibration: Callable[[], float] = field(repr=False)

    @property
    def row(self) -> dict:
        """The campaign row (:func:`mbh._harness.run.row.run_spec`)."""
        return self.result.row

    @property
    def trajectory(self) -> Trajectory:
        """The judged trajectory."""
        return self.result.trajectory

    @property
    def label(self) -> str:
        """:func:`case_label` of the case."""
        return case_label(self.spec)

    @property
    def status(self) -> str:
        return self.trajectory.status

    @property
    def wall_time_s(self) -> float:
        """The case's wall time, s (median over its repetitions)."""
        return float(self.row["wall_time_s"])

    @property
    def calibrated_time(self) -> float:
        """Wall time / the session's machine-speed figure (dimensionless)."""
        return self.wall_time_s / self.calibration()

    def describe(self) -> str:
        """``case fourbar-mujoco-best-dt1e-3 (t_end 0.5 s, status ok)``."""
        return f"case {self.label} (t_end {self.spec.t_end:g} s, status {self.status})"

    def _output_name(self, name: str | None) -> str:
        """``name``, else the main output; a mechanism without outputs must be given one."""
        name = name or main_output(self.mechanism)
        if name is None:
            raise ToleranceError(f"{self.describe()}: scenario {self.spec.scenario} declares no "
                                 "outputs, so there is no main output to compare: declare one")
        return name

    def output(self, name: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(sample times in s, output values) of output ``name`` (default the main output)."""
        name = self._output_name(name)
        if name not in {o.name for o in self.mechanism.outputs}:
            known = ", ".join(o.name for o in self.mechanism.outputs)
            raise ToleranceError(f"{self.describe()}: scenario {self.spec.scenario} has no "
                                 f"output {name!r} (outputs: {known})")
        return self.trajectory.times, output_series(self.mechanism, self.trajectory, name)

    def reference_output(self, name: str | None = None) -> np.ndarray:
        """The reference's output ``name`` at this case's sample times, shape (n_samples,)."""
        if self.reference is None:
            raise AssertionError(f"{self.describe()}: scenario {self.spec.scenario} has no "
                                 f"verified reference to compare with")
        name = self._output_name(name)
        values = output_series(self.mechanism, self.reference, name)
        return values[reference_indices(self.reference, self.trajectory.times)]


@dataclass(frozen=True)
class IsolatedWork:
    """What an isolated case's worker process does: :func:`mbh._harness.run.row.run_spec`, returning
    (row, the whole result) for :func:`mbh._harness.run.executor.run_isolated`.  Picklable."""

    bounds: Bounds
    accuracy: float

    def __call__(self, spec: CaseSpec) -> tuple[dict, CaseResult]:
        from mbh._harness.run.row import run_spec

        result = run_spec(spec, self.bounds, self.accuracy)
        return result.row, result


class CaseRunner:
    """Runs cases, in this process or isolated, and keeps them for the session.

    Parameters
    ----------
    bounds : Bounds
        The verdict's bounds (:mod:`mbh._harness.measure.verdict`).
    accuracy : float
        The ``accurate`` column's threshold on the main output's error, rad or m.
    """

    def __init__(self, bounds: Bounds = DEFAULT_BOUNDS, accuracy: float = DEFAULT_ACCURACY):
        self.bounds, self.accuracy = bounds, accuracy
        self._results: dict[str, SessionCase] = {}
        self._references: dict[str, Trajectory | None] = {}
        self._calibration_s: float | None = None
        self._workers = None  # the isolated cases' warm workers, started on first use

    @property
    def finished(self) -> dict[str, SessionCase]:
        """Every case run so far, by :attr:`CaseSpec.case_id`."""
        return dict(self._results)

    def reference(self, scenario_name: str) -> Trajectory | None:
        """The verified reference of a scenario (None when it has none), loaded once."""
        if scenario_name not in self._references:
            try:
                self._references[scenario_name] = reference_trajectory(
                    scenario.load(scenario_name))
            except ReferenceBuildError:
                self._references[scenario_name] = None
        return self._references[scenario_name]

    def calibration_s(self) -> float:
        """The session's machine-speed figure, s (:func:`~mbh._harness.common.machine_speed.machine_speed_s`,
        measured in this process on first call).  It times numpy and scipy only, not this
        project's code, so a calibrated time changes with the case, not with the harness."""
        if self._calibration_s is None:
            self._calibration_s = machine_speed_s()
        return self._calibration_s

    def run(self, spec: CaseSpec, isolated: bool = False) -> SessionCase:
        """The finished case ``spec`` (run now unless already run this session, in a worker
        process of its own when ``isolated``)."""
        if spec.case_id not in self._results:
            self.reference(spec.scenario)  # loaded once per session, not once per case
            result = self._isolated(spec) if isolated else self._in_process(spec)
            self._results[spec.case_id] = SessionCase(
                spec, result, scenario.load(spec.scenario), self.reference(spec.scenario),
                self.calibration_s)
        return self._results[spec.case_id]

    def _in_process(self, spec: CaseSpec) -> CaseResult:
        from mbh._harness.run.row import run_spec

        return run_spec(spec, self.bounds, self.accuracy)

    def _isolated(self, spec: CaseSpec) -> CaseResult:
        """``spec`` run in a worker process; a case that gave no result (crash, timeout) becomes
        an empty trajectory with the row's status and reason (the signal or exit code)."""
        from mbh._harness.run.executor import WorkerProcesses, run_isolated
        from mbh._harness.run.row import error_row

        if self._workers is None:
            self._workers = WorkerProcesses(warm=True)
        row, result = run_isolated(IsolatedWork(self.bounds, self.accuracy), spec, spec.timeout_s,
                                   error_row, self._workers)
        if result is not None:
            return result
        n_bodies = len(scenario.load(spec.scenario).bodies)
        return CaseResult(Trajectory.empty(n_bodies, status=row["status"], reason=row["reason"]),
                          {}, row)

    def case(self, scenario_name: str, adapter: str, method: str, dt: float,
             t_end: float | None = None, repetitions: int = 1,
             isolated: bool = False) -> SessionCase:
        """:meth:`run` of :func:`case_spec` (same arguments)."""
        return self.run(case_spec(scenario_name, adapter, method, dt, t_end, repetitions),
                        isolated)

    def steps(self, scenario_name: str, adapter: str, method: str, dts,
              t_end: float | None = None) -> list[SessionCase]:
        """One case per step size in ``dts`` (s): the input of :func:`assert_convergence_order`."""
        return [self.case(scenario_name, adapter, method, dt, t_end) for dt in dts]


