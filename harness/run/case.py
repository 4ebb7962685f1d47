"""Run one case the one way every caller uses (``mbh simulate``, the seed table, campaigns):
build → simulate (engine output captured) → the stick's verdict → metrics."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from mbh._adapters.base import Adapter, UnsupportedCase, blame
from mbh._harness.common.status import CaseStatus
from mbh._harness.common.capture import captured_output, engine_note
from mbh._harness.measure.failure_label import label_failure
from mbh._harness.measure.metrics import case_metrics
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.topology import DisconnectedGraphError
from mbh._harness.model.timegrid import sample_times
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.measure.verdict import DEFAULT_BOUNDS, Bounds, judge

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class CaseResult:
    """One case's result: the judged trajectory, its metrics
    (:func:`mbh._harness.measure.metrics.case_metrics`) and, for a campaign case, its flat row.

    Attributes
    ----------
    trajectory : Trajectory
        The judged trajectory.
    metrics : dict
        :func:`~mbh._harness.measure.metrics.case_metrics` of the run; empty when the case failed
        before it was measured.
    row : dict or None
        The flat campaign row (:func:`mbh._harness.run.row.run_spec`); None from :func:`run_case`.
    """

    trajectory: Trajectory
    metrics: dict
    row: dict | None = None

    @property
    def status(self) -> CaseStatus:
        """The verdict (:class:`~mbh._harness.common.status.CaseStatus`, equal to its string:
        ``ok``, ``failed``, ``diverged``, ``unsupported``; docs/adapters.md)."""
        return self.trajectory.status

    @property
    def reason(self) -> str:
        """Why the case is not ``ok`` ('' when it is)."""
        return self.trajectory.reason

    def to_frame(self) -> pd.DataFrame:
        """The case's row as a one-row DataFrame, with the columns and types of a stored run's
        (:func:`mbh._harness.store.runs.load_run`) less those the store adds (``run_id``,
        ``trajectory_file``, ``reused_from``); raises ValueError for a result without a row."""
        if self.row is None:
            raise ValueError("this result has no row: mbh.run_case and campaigns give results "
                             "with rows")
        # Imported here: a case's process (forked from the warm template, or a fresh interpreter)
        # never needs pandas and pyarrow, whose import added 0.37 s to the template's start.
        from mbh._harness.store.rows import case_frame

        return case_frame(self.row)


def simulate_case(adapter: Adapter, mech: Mechanism, method: str, dt: float,
                  t_end: float) -> Trajectory:
    """The adapter's own run, with what its library printed kept in the notes.

    A mechanism the engine cannot build gives an ``unsupported`` trajectory; one whose build
    raises anything else, a ``failed`` one whose reason names a third-party adapter and its
    package (:func:`mbh._adapters.base.blame`).  Raises ValueError for a step or end time that does not
    fit the sample grid or the adapter (user input).
    """
    times = sample_times(dt, t_end, mech.sample_step)
    with captured_output() as printed:
        try:
            trajectory = adapter.simulate(_built(adapter, mech), method, dt, t_end, times)
        except UnsupportedCase as error:
            trajectory = Trajectory.empty(len(mech.bodies), status=CaseStatus.UNSUPPORTED,
                                          reason=str(error))
        except _BuildBroke as error:
            trajectory = Trajectory.empty(len(mech.bodies), status=CaseStatus.FAILED,
                                          reason=str(error), failure_time=0.0)
    note = engine_note(printed.text)
    if note:
        trajectory.notes = [*trajectory.notes, note]
    return trajectory


class _BuildBroke(Exception):
    """An adapter's ``build`` raised something other than UnsupportedCase; the message is the
    case's reason."""


def _built(adapter: Adapter, mech: Mechanism):
    """``adapter.build(mech)``; a mechanism the adapter cannot give a spanning tree (a body with
    no joints to ground, which the in-house engine and Exudyn run) is :class:`UnsupportedCase`;
    any other exception becomes :class:`_BuildBroke` (a third-party adapter and its package
    named, :func:`mbh._adapters.base.blame`)."""
    try:
        return adapter.build(mech)
    except UnsupportedCase:
        raise
    except DisconnectedGraphError as error:
        raise UnsupportedCase(f"{adapter.name} builds its model as a tree of joints from the "
                              f"ground: {error}") from error
    except Exception as error:  # noqa: BLE001 — a build that breaks is a result (rule 6)
        raise _BuildBroke(blame(adapter.source, "build", error)) from error


def run_case(adapter: Adapter, mech: Mechanism, method: str, dt: float, t_end: float,
             reference: Trajectory | None = None, bounds: Bounds = DEFAULT_BOUNDS) -> CaseResult:
    """Simulate one case, judge it (:func:`mbh._harness.measure.verdict.judge`), say where it failed
    (:func:`mbh._harness.measure.failure_label.label_failure`: at a singular configuration, on an
    overconstrained loop) and measure it.

    Parameters
    ----------
    adapter : Adapter
    mech : Mechanism
    method : str
        Adapter method string, ``NAME[:key=value,...]``.
    dt, t_end : float
        Step and end time, s.
    reference : Trajectory or None
        The verified reference (errors, energy scale, assembly branch); None skips those.
    bounds : Bounds
        The verdict's bounds.
    """
    trajectory = label_failure(
        mech, judge(mech, simulate_case(adapter, mech, method, dt, t_end), reference, bounds),
        reference)
    return CaseResult(trajectory, case_metrics(mech, trajectory, reference))
