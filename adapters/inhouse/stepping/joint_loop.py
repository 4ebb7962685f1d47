"""The in-house stepper of the joint-coordinate model on its compiled loop
(:mod:`~mbh._adapters.inhouse.stepping.compiled_joint`): the whole run of (θ, θ̇) through every
sample time in one compiled call, no Python per step, for the explicit one-step methods and
Adams–Bashforth ab1–ab5 with ``none``, ``baumgarte`` and ``direct`` (:func:`joint_loop_unsupported`
says why another method does not run there; it runs on the Python loop,
:class:`~mbh._adapters.inhouse.stepping.joint_stepper.JointStepper`).  With ``loop=generated``
or ``auto`` the right-hand side is the function generated for the mechanism
(:func:`~mbh._adapters.inhouse.codegen.generated.joint_function`) wherever it accepts a call;
``direct``'s projection stays on the kernels.

The formulation object is built as on the Python loop (θ₀, the gains of ``auto``, the
projection's cut, the notes), so both loops integrate the same equations with the same
arithmetic.  The first :meth:`JointLoopStepper._step_to` integrates through every sample step
and keeps (θ, θ̇) there; each read expands the kept state to the absolute body states by the
formulation's ``expand`` (g(θ), B θ̇), as the Python loop reads its current state.

Failures get the Python loop's status and reason: a state that is not finite or leaves the
divergence limit is worded as :meth:`mbh._adapters.integrators.base.Integrator.step` words it; a
step whose solve raised is taken again on the Python loop (from the start to that step, left out
of the wall time and noted), whose exception gives the reason, as
:class:`~mbh._adapters.integrators.base.Integrator` words it.
"""

from __future__ import annotations

import time

import numpy as np

from mbh._adapters.base import RunFailure, RunGrid
from mbh._adapters.inhouse.bodies.states import body_states
from mbh._adapters.inhouse.codegen import generated
from mbh._adapters.inhouse.stepping import (compiled_joint, compiled_multistep, kernel_step,
                                            loop_codes, on_demand)
from mbh._adapters.inhouse.stepping.compiled_stepper import AUTO_MIN_CALLS, hand_back_note
from mbh._adapters.inhouse.stepping.driver import FormulationStepper
from mbh._adapters.inhouse.stepping.joint_stepper import JointStepper
from mbh._adapters.inhouse.stepping.native_call import VECTOR, NativeEntry
from mbh._adapters.inhouse.formulations.joint_rhs import acceleration_kernel
from mbh._adapters.integrators import integrator_class
from mbh._adapters.integrators.multistep import LinearMultistep
from mbh._adapters.integrators.nystrom import NystromIntegrator
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

#: The treatments the compiled joint-coordinate loop runs.
JOINT_LOOP_TREATMENTS = ("none", "baumgarte", "direct")
#: What the announcements of the first compilations say to expect, s: on Bricard from an empty
#: cache, after the reduced kernel and the start's pivots (29 s), Adams–Bashforth's loop took 8 s
#: and the joint right-hand side it calls through its address 15 s (benchmarks/compile_cost.py,
#: 2-core machine, 2026-11-30); rk4+direct's loop, with the projection's solves, 16 s in a
#: warm-up.
JOINT_RIGHT_HAND_SIDE_S, JOINT_LOOP_S = 15.0, 16.0
#: The run's note on its loop.
COMPILED_NOTE = "joint coordinates stepped on their compiled loop (one compiled call a run)"
#: The note of a run whose right-hand side was generated for its mechanism.
GENERATED_NOTE = ("joint right-hand side generated for this mechanism (straight-line code traced "
                  "from the kernel; the kernel serves the calls it declines)")


def joint_loop_unsupported(integrator_name: str, treatment: str) -> str | None:
    """Why ``integrator_name+treatment`` in joint coordinates has no compiled loop, or None."""
    method_class = integrator_class(integrator_name)
    if treatment not in JOINT_LOOP_TREATMENTS:
        return (f"the compiled joint-coordinate loop runs {', '.join(JOINT_LOOP_TREATMENTS)}, "
                f"not {treatment}")
    explicit_multistep = (issubclass(method_class, LinearMultistep)
                          and method_class.beta[0] == 0.0)
    if issubclass(method_class, NystromIntegrator) or explicit_multistep:
        return None
    return (f"the compiled joint-coordinate loop runs the explicit one-step methods and "
            f"ab1–ab5, not {integrator_name}")


def joint_loop(integrator_name: str, treatment: str, loop: str) -> str | None:
    """The loop a joint-coordinate run of ``integrator_name+treatment`` takes for its ``loop``
    parameter (:data:`~mbh._adapters.inhouse.formulations.joint_coordinates.JOINT_LOOPS`):
    ``"generated"`` (the compiled loop with a generated right-hand side; ``auto`` too),
    ``"compiled"`` or ``"python"``; None when that loop does not run it (``generated`` or
    ``compiled`` for a method :func:`joint_loop_unsupported` names)."""
    runs_compiled = joint_loop_unsupported(integrator_name, treatment) is None
    if loop == "python":
        return "python"
    if loop == "auto":
        return "generated" if runs_compiled else "python"
    if loop in ("generated", "compiled") and runs_compiled:
        return loop
    return None


class JointLoopStepper(FormulationStepper):
    """One fixed-step run in joint coordinates on the compiled loop.

    Parameters
    ----------
    mech : Mechanism
    formulation_class : type
        :class:`~mbh._adapters.inhouse.formulations.joint_coordinates.JointNone`,
        ``JointBaumgarte`` or ``JointDirect``.
    integrator_name : str
        A method :func:`joint_loop_unsupported` accepts.
    integrator_params, formulation_params : dict
        Resolved parameters of each part (``divergence_limit`` is the integrator's).
    grid : RunGrid
    loop : str
        The method's ``loop`` (``auto``, ``generated`` or ``compiled``): whether the right-hand
        side is generated for the mechanism, and whether a run of fewer than
        :data:`~.compiled_stepper.AUTO_MIN_CALLS` right-hand sides may compile it.
    """

    def __init__(self, mech: Mechanism, formulation_class, integrator_name: str,
                 integrator_params: dict, formulation_params: dict, grid: RunGrid,
                 loop: str = "auto"):
        super().__init__(mech, formulation_class, formulation_params, grid)
        self._python = (mech, formulation_class, integrator_name, integrator_params,
                        formulation_params, grid)
        formulation = self.formulation
        theta, rate = formulation.reduce(*self._start_state)
        method_class = integrator_class(integrator_name)
        if issubclass(method_class, LinearMultistep):
            method = compiled_multistep.method_arguments(method_class, integrator_params,
                                                         theta.size)
            dispatcher = compiled_joint.run_adams_bashforth_samples
            calls_per_step = 1
        else:
            method = kernel_step.step_tableau(method_class.tableau)
            dispatcher = compiled_joint.run_one_step_samples
            calls_per_step = method[0].shape[0]
        params = formulation.params
        projection = ((float(params["proj_tol"]), int(params["proj_max_iter"]),
                       float(formulation.cut))
                      if formulation.corrects and formulation.closure.m else None)
        self._limit = float(integrator_params["divergence_limit"])
        self._counters = np.zeros(loop_codes.COUNTERS, dtype=np.int64)
        times = np.append(grid.sample_times, grid.t_end)
        steps = np.rint(times / grid.dt).astype(np.int64)
        targets = np.unique(steps)
        #: Sample time (s) → its step, round(t / dt); step → row of the kept states.
        self._step_of_time = dict(zip(times.tolist(), steps.tolist()))
        self._rows = dict(zip(targets.tolist(), range(targets.size)))
        self._theta_out = np.empty((targets.size, theta.size))
        self._rate_out = np.empty((targets.size, theta.size))
        #: The counters after each target's step: the cost up to the sample the run is at.
        self._counters_out = np.zeros((targets.size, loop_codes.COUNTERS), dtype=np.int64)
        #: The right-hand side kernel the loop calls (:mod:`.native_call`), resolved before it.
        right_hand_side = NativeEntry(acceleration_kernel,
                                      (theta, rate, 0.0, *formulation.kernel_args), VECTOR)

        def loop_args(function) -> tuple:
            """The loop's arguments with ``function`` the right-hand side it asks first."""
            return (theta, rate, 0.0, grid.dt, 0, targets, method,
                    (*formulation.kernel_args, function, right_hand_side), projection,
                    self._limit, self._counters, self._theta_out, self._rate_out,
                    self._counters_out)

        function, notes = generated.NEVER, []
        if loop != "compiled":
            # As the absolute model's auto: a short run compiles no new function, unless the
            # loop itself is to be compiled (seconds more on a minute).
            compile_new = (loop == "generated"
                           or grid.steps(grid.t_end) * calls_per_step >= AUTO_MIN_CALLS
                           or not on_demand.is_ready(dispatcher, loop_args(function)))
            function, notes = generated.joint_function(formulation, theta, rate, compile_new)
        self._generated = function is not generated.NEVER
        self._args = loop_args(function)
        self._entry = on_demand.entry(dispatcher, self._args, "the joint-coordinate loop",
                                      JOINT_LOOP_S)
        on_demand.resolve(right_hand_side, "the joint-coordinate right-hand side",
                          JOINT_RIGHT_HAND_SIDE_S)
        #: (θ, θ̇, done, status, reached) of the run's call, once made.
        self._end: tuple | None = None
        #: Row of the kept states the run is at (None: the end of the call, after a failure).
        self._row: int | None = 0
        self.notes[1:1] = [COMPILED_NOTE, *notes]  # beside the model note, before the treatment's
        if self._generated:
            self.notes.insert(2, GENERATED_NOTE)

    # -- stepping ------------------------------------------------------------------------------
    def _step_to(self, t: float) -> None:
        target = self._step_of_time.get(t)
        if target is None:
            target = self.grid.steps(t)
        if self._end is None:
            self._end = self._entry(*self._args)
        row = self._rows.get(target)
        if row is None:
            raise ValueError(f"t = {t:g} s is not a sample time of this run")
        _, _, done, status, reached = self._end
        if row >= reached:
            self.steps, self.t_good = done, done * self.grid.dt
            self._row = None  # the counters at the failure: the whole call's
            raise RunFailure(*self._failure(status, done))
        self._row, self.steps, self.t_good = row, target, target * self.grid.dt

    def _failure(self, status: int, done: int) -> tuple[CaseStatus, str]:
        """(status, reason) of the loop's failure code in step ``done + 1``, as the Python loop
        words it."""
        if status == loop_codes.DIVERGED_LIMIT:
            return CaseStatus.DIVERGED, f"state norm exceeds divergence_limit={self._limit:g}"
        if status == loop_codes.DIVERGED_NONFINITE:
            return CaseStatus.DIVERGED, "non-finite state"
        return self._python_failure(done)

    def _python_failure(self, done: int) -> tuple[CaseStatus, str]:
        """The failure of step ``done + 1`` on the Python loop (the same steps, so the same
        exception): its status and reason; the time is left out of the run's wall time."""
        began = time.perf_counter()
        answer = (CaseStatus.FAILED, "a solve failed in the compiled joint-coordinate loop "
                                     "(the Python loop did not repeat it)")
        replay = JointStepper(*self._python)
        try:
            replay._step_to((done + 1) * self.grid.dt)
        except RunFailure as failure:
            if replay.steps == done:
                answer = (failure.status, failure.reason)
        took = time.perf_counter() - began
        self.untimed_s += took
        self.notes.append(f"the failing step was taken again on the Python loop for its reason "
                          f"({took:.3g} s, left out of the wall time)")
        return answer

    def run(self, grid: RunGrid, n_bodies: int):
        """:meth:`Stepper.run`, with the note of the right-hand sides the generated function
        handed back to the kernel (:func:`~.compiled_stepper.hand_back_note`)."""
        trajectory = super().run(grid, n_bodies)
        note = hand_back_note(int(self._counters[loop_codes.KERNEL_CALLS]),
                              int(self._counters[loop_codes.RHS_EVALS]))
        if self._generated and note:
            trajectory.notes.append(note)
        return trajectory

    # -- reading -------------------------------------------------------------------------------
    def _states(self, t: float) -> BodyStates:
        if self.steps == 0:
            return body_states(self.layout, *self._start_state)
        if self._row is None:  # after a failure: the call's last good state, after step done
            theta, rate = self._end[0], self._end[1]
        else:
            theta, rate = self._theta_out[self._row], self._rate_out[self._row]
        return body_states(self.layout, *self.formulation.expand(self.t_good, theta, rate))

    def counters(self) -> dict:
        """The cost up to the state the run is at: the counters kept with the sample read last
        (the call ran on to the end, or to its failure, which the Python loop would not have
        reached if the run stopped at that sample), or the whole call's after a failure."""
        own = self.formulation.counters
        spent = self._counters if self._row is None else self._counters_out[self._row]
        return {"rhs_evals": int(spent[loop_codes.RHS_EVALS]),
                "jacobian_evals": own["jacobian_evals"] + int(spent[loop_codes.JACOBIAN_EVALS]),
                "factorizations": own["factorizations"] + int(spent[loop_codes.FACTORIZATIONS]),
                "newton_iterations": own["newton_iterations"]
                + int(spent[loop_codes.NEWTON_ITERATIONS]),
                "repartitions": 0, "passages": 0,
                "kernel_calls": int(spent[loop_codes.KERNEL_CALLS])}
