"""Run one in-house case: a formulation (stabilisation strategy) integrated by one method from the
assembled initial state, sampled into a :class:`~harness.trajectory.Trajectory`.

Fixed-step methods take round(t_end/dt) steps and are sampled after step round(t_s/dt); adaptive
methods are sampled through their dense output.  A failed or diverged integrator ends the run with
the samples reached so far.
"""

from __future__ import annotations

import time

import numpy as np

from adapters.inhouse.constraints import layout_of
from adapters.integrators import RUNNING, make_integrator
from adapters.inhouse.kinematics import assemble
from adapters.inhouse.states import trajectory_from_coordinates
from adapters.inhouse.stabilisation import Formulation
from harness.model import Mechanism
from harness.trajectory import Trajectory

_INTEGRATOR_COUNTERS = {"rhs_evals": "nfev", "jacobian_evals": "njev", "factorizations": "nlu",
                        "newton_iterations": "n_newton"}


class _Run:
    """Mutable state of one run: the current integrator, its predecessors' costs, the samples."""

    def __init__(self, mech: Mechanism, formulation: Formulation, integrator_name: str,
                 integrator_params: dict, dt: float):
        self.mech = mech
        self.layout = layout_of(mech)
        self.formulation = formulation
        self.integrator_name = integrator_name
        self.integrator_params = integrator_params
        self.dt = dt
        self.times: list[float] = []
        self.samples: list[tuple[np.ndarray, np.ndarray]] = []
        self.spent = dict.fromkeys(_INTEGRATOR_COUNTERS, 0)
        self.steps = 0
        self.wall = 0.0
        self.integrator = None

    def start(self, t: float, q_full: np.ndarray, v_full: np.ndarray) -> None:
        """(Re)start the integrator from a full state, keeping the cost of the previous one."""
        if self.integrator is not None:
            self._bank()
        q, v = self.formulation.reduce(q_full, v_full)
        self.integrator = make_integrator(self.integrator_name, self.formulation, t, q, v, self.dt,
                                          **self.integrator_params)

    def _bank(self) -> None:
        for key, attribute in _INTEGRATOR_COUNTERS.items():
            self.spent[key] += getattr(self.integrator, attribute)
        self.steps += self.integrator.n_steps

    def step(self) -> str:
        began = time.perf_counter()
        status = self.integrator.step()
        self.wall += time.perf_counter() - began
        return status

    def repartition_if_needed(self) -> None:
        """Choose the integrated coordinates again when the formulation asks (partitioning)."""
        q, v = self.full_state()
        if self.formulation.needs_repartition(q):
            self.formulation.choose_partition(q)
            self.start(self.integrator.t, q, v)

    def full_state(self, t=None, q=None, v=None):
        integrator = self.integrator
        if t is None:
            t, q, v = integrator.t, integrator.q, integrator.v
        return self.formulation.expand(t, q, v)

    def record(self, t: float, q_full: np.ndarray, v_full: np.ndarray) -> None:
        """Keep a sample; body states are computed for the whole run at the end."""
        self.times.append(t)
        self.samples.append((np.array(q_full, dtype=float), np.array(v_full, dtype=float)))

    def trajectory(self) -> Trajectory:
        self._bank()
        integrator = self.integrator
        status = "ok" if integrator.status == RUNNING else integrator.status
        counters = {key: self.spent[key] + self.formulation.counters.get(key, 0)
                    for key in self.spent}
        counters["repartitions"] = getattr(self.formulation, "repartitions", 0)
        return trajectory_from_coordinates(
            self.layout, self.times, [q for q, _ in self.samples], [v for _, v in self.samples],
            status=status, reason=integrator.failure_reason or "",
            failure_time=integrator.failure_time, wall_time_s=self.wall, steps=self.steps,
            counters=counters, notes=list(self.formulation.notes))


def simulate(mech: Mechanism, formulation_class, integrator_name: str, integrator_params: dict,
             formulation_params: dict, dt: float, t_end: float, sample_times) -> Trajectory:
    """Integrate ``mech`` from its assembled state and sample it.

    Parameters
    ----------
    formulation_class : type[Formulation]
    integrator_name : str
        A name from :func:`adapters.integrators.integrator_names`.
    dt : float
        Fixed step, or first-step hint of an adaptive method, s.
    t_end : float
        s.
    sample_times : ndarray, shape (k,)
        Increasing times in [0, t_end], s.
    """
    assembly = assemble(mech)
    formulation = formulation_class(mech, assembly.q, dt, **formulation_params)
    formulation.start(assembly.q, assembly.v)
    formulation.warm_up(assembly.q, assembly.v)
    run = _Run(mech, formulation, integrator_name, integrator_params, dt)
    run.start(0.0, assembly.q, assembly.v)
    samples = np.asarray(sample_times, dtype=float)
    if samples.size and samples[0] == 0.0:
        run.record(0.0, assembly.q, assembly.v)
        samples = samples[1:]
    if run.integrator.adaptive:
        _integrate_adaptive(run, t_end, samples)
    else:
        _integrate_fixed(run, t_end, samples)
    return run.trajectory()


def _integrate_fixed(run: _Run, t_end: float, samples: np.ndarray) -> None:
    wanted = {int(round(t / run.dt)): t for t in samples}
    for k in range(1, int(round(t_end / run.dt)) + 1):
        if run.step() != RUNNING:
            return
        if k in wanted:
            run.record(wanted[k], *run.full_state())
        run.repartition_if_needed()


def _integrate_adaptive(run: _Run, t_end: float, samples: np.ndarray) -> None:
    pending = list(samples)
    while pending:
        if run.step() != RUNNING:
            return
        integrator = run.integrator
        while pending and pending[0] <= integrator.t:
            t = pending.pop(0)
            run.record(t, *run.full_state(t, *integrator.dense(t)))
        run.repartition_if_needed()
