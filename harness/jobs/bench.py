"""``mbh bench``: the speed figures, measured side by side in one run and printed as ratios.

Five parts (each a function returning plain rows, so the CLI prints them and tests can call them
on tiny inputs):

* :func:`front_rows` — the in-house Pareto front against the best engine's: from the cases of the
  ``bench`` campaign (every adapter's candidate methods on every shipped scene over a ladder
  of steps), the fastest ``ok`` case reaching each accuracy level on the main output, in-house
  versus every engine (:func:`mbh._harness.report.summary.front_ratio_table`, also in the report).
* :func:`overhead_rows` — each adapter's time per step in :meth:`Adapter.simulate` over its bare
  loop (:meth:`Adapter.bare_loop`: the same steps with no samples and no checks), measured
  interleaved, best of ``repeats``; and the state read-back time per sample
  (:attr:`Trajectory.read_back_s`), which is outside ``wall_time_s``.
* :func:`fallback_rows` — per shipped scene, the right-hand sides the in-house generated loop
  handed back to the generic kernels (``kernel_calls`` / ``rhs_evals``) and the run's note saying
  why (a function not generated, a guard that failed).
* :func:`scaling_rows` — cost per simulated second of each adapter's ``best`` on the N-four-bar
  family, and the fitted exponent of cost ∝ N^p from N = 4 to the largest N run.
* :func:`reference_rows` — the reference build times: the stored cost of each route and the same
  route timed now (in-house fixed-step routes and the compiled neutral routes alike).

Nothing here is asserted: times depend on the machine; only ratios measured in one run are meant
to be read.
"""

from __future__ import annotations

import time

import numpy as np

from mbh._adapters import adapter_names, get_adapter
from mbh._adapters.base import UnsupportedCase
from mbh._harness.model import scenario
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.timegrid import sample_times

#: Scenarios of the overhead and fallback measurements: every shipped scene.
SCENES = tuple(scenario.scenario_names())
#: The generated loop of the fallback table: the in-house ``best`` formulation and integrator.
FALLBACK_METHOD = "rk4+direct:loop=generated"
#: Members of the N-four-bar family in the scaling table; the exponent is fitted from N = 4 on.
SCALING_N = (1, 2, 4, 8, 16, 32, 64)
SCALING_FIT_FROM = 4


def _simulate(adapter, model, mech, method: str, dt: float, t_end: float):
    return adapter.simulate(model, method, dt, t_end, sample_times(dt, t_end, mech.sample_step))


def overhead_rows(adapters=None, scenarios=SCENES, methods=("default", "best"),
                  dt: float = 1e-3, t_end: float = 4.0, repeats: int = 5) -> list[dict]:
    """Adapter time per step over bare-loop time per step, per adapter, scenario and method.

    Returns
    -------
    list of dict
        ``adapter, scenario, method, adapter_us_per_step, bare_us_per_step, ratio,
        read_back_us_per_sample, note`` (µs; ratio dimensionless; None where not measured).
    """
    rows = []
    for name in adapters or adapter_names():
        adapter = get_adapter(name)
        for scene in scenarios:
            mech = scenario.load(scene)
            try:
                model = adapter.build(mech)
            except UnsupportedCase as error:
                rows.append(_overhead_row(name, scene, "-", note=str(error)))
                continue
            steps = int(round(t_end / dt))
            for method in methods:
                rows.append(_measure_overhead(adapter, model, mech, method, dt, t_end, steps,
                                              repeats))
    return rows


def _overhead_row(adapter, scene, method, adapter_us=None, bare_us=None, read_back_us=None,
                  note=""):
    ratio = adapter_us / bare_us if adapter_us and bare_us else None
    return {"adapter": adapter, "scenario": scene, "method": method,
            "adapter_us_per_step": adapter_us, "bare_us_per_step": bare_us, "ratio": ratio,
            "read_back_us_per_sample": read_back_us, "note": note}


def _measure_overhead(adapter, model, mech, method, dt, t_end, steps, repeats) -> dict:
    simulated, bare, read_back = [], [], []
    for _ in range(repeats):  # interleaved, so that machine load disturbs both alike
        run = _simulate(adapter, model, mech, method, dt, t_end)
        if run.status != CaseStatus.OK or run.steps != steps:
            return _overhead_row(adapter.name, mech.name, method,
                                 note=f"run {run.status}: {run.reason}")
        simulated.append(run.wall_time_s / run.steps)
        read_back.append(run.read_back_s / max(run.n_samples, 1))
        try:
            bare.append(adapter.bare_loop(model, method, dt, steps) / steps)
        except UnsupportedCase as error:
            return _overhead_row(adapter.name, mech.name, method, 1e6 * min(simulated),
                                 read_back_us=1e6 * min(read_back), note=str(error))
    return _overhead_row(adapter.name, mech.name, method, 1e6 * min(simulated), 1e6 * min(bare),
                         1e6 * min(read_back))


def fallback_rows(scenarios=SCENES, method: str = FALLBACK_METHOD, dt: float = 1e-4,
                  t_end: float = 1.0) -> list[dict]:
    """Right-hand sides the generated loop handed back to the kernels, per scene: a run of
    ``method`` for ``t_end`` s (at most the scene's duration) at ``dt``.

    Returns
    -------
    list of dict
        ``scenario, status, kernel_calls, rhs_evals, fraction, note`` (fraction = kernel_calls /
        rhs_evals; note: the run's notes on generated functions, "" when every call was served).
    """
    adapter = get_adapter("inhouse")
    rows = []
    for scene in scenarios:
        mech = scenario.load(scene)
        run = _simulate(adapter, adapter.build(mech), mech, method, dt, min(t_end, mech.duration))
        kernel, calls = run.counters.get("kernel_calls"), run.counters.get("rhs_evals")
        rows.append({"scenario": scene, "status": run.status, "kernel_calls": kernel,
                     "rhs_evals": calls,
                     "fraction": kernel / calls if kernel is not None and calls else None,
                     "note": "; ".join(note for note in run.notes if "generat" in note)})
    return rows


def scaling_rows(adapters=None, members=SCALING_N, dt: float = 1e-3,
                 t_end: float = 0.5) -> tuple[list[dict], dict]:
    """Cost per simulated second of each adapter's ``best`` on ``n_fourbar@N``.

    Returns
    -------
    rows : list of dict
        ``adapter, N, status, s_per_sim_s`` (None when the run did not end ``ok``).
    exponents : dict
        adapter → fitted p of cost ∝ N^p over the ``ok`` members with N ≥ 4 (None: < 2 points).
    """
    rows = []
    for name in adapters or adapter_names():
        adapter = get_adapter(name)
        for n in members:
            mech = scenario.load(f"n_fourbar@{n}")
            try:
                model = adapter.build(mech)
            except UnsupportedCase as error:
                rows.append({"adapter": name, "N": n, "status": CaseStatus.UNSUPPORTED,
                             "s_per_sim_s": None, "note": str(error)})
                continue
            run = _simulate(adapter, model, mech, "best", dt, t_end)
            rows.append({"adapter": name, "N": n, "status": run.status,
                         "s_per_sim_s": (run.wall_time_s / t_end if run.status == CaseStatus.OK
                                         else None),
                         "note": run.reason})
    return rows, {name: _exponent([r for r in rows if r["adapter"] == name])
                  for name in adapters or adapter_names()}


def _exponent(rows: list[dict]) -> float | None:
    """Least-squares slope of log(cost) over log(N) for N ≥ :data:`SCALING_FIT_FROM`."""
    points = [(r["N"], r["s_per_sim_s"]) for r in rows
              if r["s_per_sim_s"] and r["N"] >= SCALING_FIT_FROM]
    if len(points) < 2:
        return None
    n, cost = np.log(np.array(points, dtype=float)).T
    return float(np.polyfit(n, cost, 1)[0])


def reference_rows(live: bool = True) -> list[dict]:
    """Per shipped scenario and route: the stored build time, and (``live``) the time of the same
    route run now on the reference grid (s)."""
    from mbh._harness.references.build import _run_route, reference_grid, reference_info, routes

    rows = []
    for name in scenario.scenario_names():
        mech = scenario.load(name)
        info = reference_info(mech)
        for label, route in zip("AB", routes(mech)):
            stored = info[f"route_{label.lower()}_cost"]["wall_time_s"]
            now = None
            if live:
                began = time.perf_counter()
                _run_route(mech, tuple(route), reference_grid(mech))
                now = time.perf_counter() - began
            rows.append({"scenario": name, "route": f"{label}: {route[0]} dt={route[1]:g}",
                         "stored_s": stored, "now_s": now})
    return rows
