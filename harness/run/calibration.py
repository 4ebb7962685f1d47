"""A run's machine-speed figure (:mod:`mbh._harness.common.machine_speed`), measured where the run
has a core to spare, so that it costs the run no time of its own:

* locally, while the warm template starts (its imports keep one core busy and leave this process
  idle): in the campaign's own process;
* otherwise (the template already runs, cold workers, a Dask cluster): as the first case of the
  run's execution (:data:`CALIBRATION`, :class:`WithCalibration`), in a worker process of its own
  beside the other cases.

Either way it runs beside one busy core.  The run stores the figure with the workload that measured
it (:meth:`mbh._harness.store.runs.RunStore.set_calibration`; :func:`store_figure`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from mbh._harness.common.machine_speed import machine_speed_s, workload_name
from mbh._harness.common.status import CaseStatus
from mbh._harness.run.spec import CaseSpec

#: The calibration case's identity for the executor (its row is not stored with the cases).
CALIBRATION = CaseSpec("calibration", "machine-speed", "solve_ivp+lu", 1.0, 1.0)


def calibration_work(spec: CaseSpec) -> tuple[dict, None]:
    """The executor's work for :data:`CALIBRATION`: a row with status ``ok``, the figure as
    ``wall_time_s`` (s) and the ``workload`` that measured it; no trajectory."""
    return ({"case_id": spec.case_id, "status": CaseStatus.OK, "reason": "",
             "wall_time_s": machine_speed_s(), "workload": workload_name()}, None)


@dataclass(frozen=True)
class WithCalibration:
    """The work of an execution whose specs include :data:`CALIBRATION`: :func:`calibration_work`
    for it, ``work`` for every other spec.  Picklable when ``work`` is."""

    work: Callable

    def __call__(self, spec):
        return calibration_work(spec) if spec == CALIBRATION else self.work(spec)


def store_figure(store, row: dict, say) -> None:
    """Store the figure of :data:`CALIBRATION`'s ``row`` in ``store`` (a
    :class:`~mbh._harness.store.runs.RunStore`); a calibration that did not end ``ok`` is reported
    through ``say`` and leaves the run without a figure."""
    seconds = row.get("wall_time_s")
    measured = seconds is not None and math.isfinite(seconds) and seconds > 0
    if row.get("status") == CaseStatus.OK and measured:
        store.set_calibration(seconds, row.get("workload"))
    else:
        say(f"mbh: calibration case ended {row.get('status')} ({row.get('reason')}); this run "
            f"has no machine-speed figure")
