"""A run's calibration case on a Dask cluster: the machine-speed workload
(:mod:`harness.common.machine_speed`) in a worker process of its own, as every case runs there,
whose figure the run stores (:meth:`harness.store.runs.RunStore.set_calibration`).  A local run
measures the figure in its own process instead (:func:`harness.run.campaign.run_campaign`).
"""

from __future__ import annotations

from harness.common.machine_speed import machine_speed_s, workload_name
from harness.run.spec import CaseSpec

#: The calibration case's identity for the executor (its row is not stored with the cases).
CALIBRATION = CaseSpec("calibration", "machine-speed", "solve_ivp+lu", 1.0, 1.0)


def calibration_work(spec: CaseSpec) -> tuple[dict, None]:
    """The executor's work for :data:`CALIBRATION`: a row with status ``ok``, the figure as
    ``wall_time_s`` (s) and the ``workload`` that measured it; no trajectory."""
    return ({"case_id": spec.case_id, "status": "ok", "reason": "",
             "wall_time_s": machine_speed_s(), "workload": workload_name()}, None)
