"""The in-house stepper on the compiled path (:mod:`mbh._adapters.inhouse.stepping.compiled`): a whole run, or
for partitioning each stretch between two sample times, in a single compiled call, so no Python
runs per step.

Used for the fixed-step explicit one-step methods (euler, symplectic-euler, heun, rk4, rkn4, rk5,
rk8) with the ``none``, ``baumgarte``, ``direct`` and ``partition`` formulations, and for the
linear multistep methods (ab1–ab5, am1–am5, bdf1–bdf4: :mod:`mbh._adapters.inhouse.stepping.compiled_multistep`)
with ``none``, ``baumgarte`` and ``direct``, unless the method says ``loop=python``; every other
method runs on :class:`~mbh._adapters.inhouse.stepping.driver.InhouseStepper`.
With ``loop=auto`` (the default) or ``generated`` each stage's q̈, the projection's parts and ρ̂
come from functions generated for the formulation (:mod:`mbh._adapters.inhouse.codegen.generated`: the same
numbers, a step 3–4 times faster; :data:`LOOPS` says when ``auto`` compiles them), with
``loop=compiled`` from the generic kernels.
The formulation object is built as on the Python path (its rows, gains, projection cut, split and
notes are the compiled loop's inputs), so both paths integrate the same equations with the same
arithmetic.  Partitioning returns to Python only to choose a new split.

Every formulation but partitioning is read without side effects, so its whole run is one compiled
call (:func:`compiled.run_samples`): the first :meth:`CompiledStepper._step_to` integrates through
every sample time of the grid and keeps the states there, and the later calls hand them out (a
failure is raised at the first sample after it, as step-by-step stepping raises it): a call
costs ~16 µs of converting its arguments (12 µs of it the five generated functions, whose
addresses numba asks Python for; the ~65 arrays and numbers take 0.06–0.1 µs each), more than a
pendulum's ten steps between two samples.  Partitioning steps from sample to sample: reading its
state moves the Newton start of the dependent coordinates.

Where every function the formulation calls was generated, a run starts on the generated steps'
own loop (:func:`compiled.run_generated_samples`), which compiles in seconds; the full loop, with
the kernels' path for a step a generated function declines, goes on from where that one hands a
step over, and is compiled (a minute or more, once per machine) only when a run first does.

Every call goes to the compiled function directly (:func:`.on_demand.entry`), not through numba's
dispatcher, whose typing of the arguments cost ~0.3 ms a call: the model tuple holds the generated
functions, which numba types in Python.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mbh._adapters.base import RunFailure, RunGrid
from mbh._adapters.inhouse.stepping import (compiled, compiled_multistep, kernel_step,
                                            loop_codes, on_demand)
from mbh._adapters.inhouse.stepping.native_call import VECTOR, NativeEntry
from mbh._adapters.inhouse.formulations.dynamics import index1_acceleration
from mbh._adapters.inhouse.codegen import generated
from mbh._adapters.inhouse.stepping.driver import FormulationStepper
from mbh._adapters.inhouse.formulations.fold import Passages
from mbh._adapters.inhouse.formulations.partition import CoordinatePartitioning
from mbh._adapters.inhouse.formulations.stabilisation import (
    Baumgarte, DirectCorrection, NoStabilisation)
from mbh._adapters.inhouse.bodies.states import body_states
from mbh._adapters.integrators import integrator_class
from mbh._adapters.integrators.multistep import LinearMultistep
from mbh._adapters.integrators.newton import non_convergence
from mbh._adapters.integrators.nystrom import NystromIntegrator
from mbh._harness.common.status import CaseStatus
from mbh._harness.common import waits
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

#: Formulations with a compiled path and their stabilisation code in :func:`compiled.run_samples`.
COMPILED_FORMULATIONS = {NoStabilisation.name: loop_codes.PLAIN, Baumgarte.name: loop_codes.PLAIN,
                         DirectCorrection.name: loop_codes.PROJECTED,
                         CoordinatePartitioning.name: loop_codes.PARTITIONED}

#: The ``loop`` method parameter: which stepping path runs a method that has a compiled one
#: (``generated``: the compiled loop with functions generated for the formulation, compiled on
#: first use; ``auto``: the same, except that a run of fewer than :data:`AUTO_MIN_CALLS`
#: right-hand sides compiles none and takes only those compiled before; ``compiled``: the
#: compiled loop with the generic kernels; ``python``: the same arithmetic stepped from Python).
LOOPS = ("auto", "generated", "compiled", "python")

#: Below this many right-hand sides a run with ``loop=auto`` compiles no generated function: a
#: check or a smoke test of a new mechanism (tens to hundreds of steps) would wait seconds for a
#: compilation that saves it milliseconds.  Every run of the shipped campaigns is longer (the
#: shortest, the four-bar's 4 s at 1e-2 s with rk4, takes 1,600).
AUTO_MIN_CALLS = 1000


#: Formulations of the linear multistep methods' compiled path (:mod:`.compiled_multistep`):
#: not partitioning, whose restarts at a new split restart the history.
MULTISTEP_FORMULATIONS = (NoStabilisation.name, Baumgarte.name, DirectCorrection.name)


def has_compiled_path(integrator_name: str, formulation_name: str) -> bool:
    """True when ``integrator+formulation`` can run on the compiled path: an explicit one-step
    method with a formulation of :data:`COMPILED_FORMULATIONS`, or a linear multistep method
    with one of :data:`MULTISTEP_FORMULATIONS`."""
    method_class = integrator_class(integrator_name)
    if issubclass(method_class, LinearMultistep):
        return formulation_name in MULTISTEP_FORMULATIONS
    return (formulation_name in COMPILED_FORMULATIONS
            and issubclass(method_class, NystromIntegrator))


class CompiledStepper(FormulationStepper):
    """One fixed-step run of ``formulation_class`` by the Nyström tableau or the linear
    multistep method of ``integrator_name`` (:func:`has_compiled_path`).

    Parameters
    ----------
    mech : Mechanism
    formulation_class : type
        One of :data:`COMPILED_FORMULATIONS`' classes.
    integrator_name : str
        A :class:`~mbh._adapters.integrators.nystrom.NystromIntegrator` or
        :class:`~mbh._adapters.integrators.multistep.LinearMultistep` method.
    integrator_params, formulation_params : dict
        Resolved parameters of each part (``divergence_limit``, ``tol`` and ``max_iter`` are the
        integrator's).
    grid : RunGrid
    loop : str
        ``auto``, ``generated`` or ``compiled`` (:data:`LOOPS`).
    """

    def __init__(self, mech: Mechanism, formulation_class, integrator_name: str,
                 integrator_params: dict, formulation_params: dict, grid: RunGrid,
                 loop: str = LOOPS[0]):
        super().__init__(mech, formulation_class, formulation_params, grid)
        formulation = self.formulation
        self._code = COMPILED_FORMULATIONS[formulation_class.name]
        method_class = integrator_class(integrator_name)
        self._multistep = issubclass(method_class, LinearMultistep)
        #: The method's arguments of the compiled loop: a Nyström tableau, or a multistep method
        #: with its history and Newton state.
        if self._multistep:
            self._method = compiled_multistep.method_arguments(
                method_class, integrator_params, self._start_state[0].size)
            # At least one right-hand side a step, two for an implicit method (its iteration
            # evaluates once at least).
            calls_per_step = 1 if method_class.beta[0] == 0.0 else 2
        else:
            self._method = kernel_step.step_tableau(method_class.tableau)
            calls_per_step = method_class.tableau.c.size
        self.passages = Passages.of(formulation, method_class)
        params = formulation.params
        self._projection = ((float(params["proj_tol"]), int(params["proj_max_iter"]),
                             float(formulation.cut)) if self._code == loop_codes.PROJECTED
                            else (0.0, 0, 0.0))
        self._limit = float(integrator_params["divergence_limit"])
        self._counters = np.zeros(loop_codes.COUNTERS, dtype=np.int64)
        self._check_due = np.zeros(1, dtype=np.int64)
        self._partition = None
        self._restart(*self._start_state)
        self._samples: _Samples | None = None
        #: Row of ``_samples`` holding the current state (None: ``q``, ``v`` hold it).
        self._row: int | None = None
        #: Step index of every sample time and of the end, increasing (shape (k,)).
        times = np.append(grid.sample_times, grid.t_end)
        steps = np.rint(times / grid.dt).astype(np.int64)
        self._sample_steps = np.unique(steps)
        #: Sample time (s) → its step index, round(t / dt) as :meth:`RunGrid.steps` counts it:
        #: the lookup took ~50 ns a sample less than the division (pendulum, 1e-2 s).
        self._step_of_time = dict(zip(times.tolist(), steps.tolist()))
        #: Step index → row of the run's output when one call runs from the start through every
        #: sample (the common case): built here, outside the timed stepping (~35 µs for 1,001).
        self._rows_from_start = dict(zip(self._sample_steps.tolist(),
                                         range(self._sample_steps.size)))
        self._partitioned = self._code == loop_codes.PARTITIONED
        self._dispatcher = self._full_loop(method_class)
        #: The right-hand side kernel the full loops call (:mod:`.native_call`), compiled or
        #: loaded with the full loop (:meth:`_full_entry`).
        self._right_hand_side = self._kernel_entry()
        self._model = self._model_tuple(generated.NOTHING, False)  # the types of the real one
        wanted = self._wanted_functions()
        compile_new = (loop == "generated"
                       or grid.steps(grid.t_end) * calls_per_step >= AUTO_MIN_CALLS
                       or not on_demand.is_ready(self._dispatcher, self._full_args()))
        functions = (generated.NOTHING if loop == "compiled"
                     else self._generated_functions(wanted, compile_new))
        #: Whether the right-hand side was generated, and every function a step's end calls
        #: (the projection's parts, ρ̂): their hand-backs are noted.
        self._generated_parts = (functions[generated.ACCELERATION] is not generated.NEVER,
                                 len(wanted) > 1 and all(functions[which] is not generated.NEVER
                                                         for which in wanted[1:]))
        every_one = all(functions[which] is not generated.NEVER for which in wanted)
        self._model = self._model_tuple(functions, every_one)
        # Compile (or load from numba's cache) and find the compiled functions outside the timed
        # stepping: the generated steps' own loop where it can serve (every function the
        # formulation calls generated, a one-step method without partitioning), else the full
        # loop; the full loop behind the generated steps only when they hand a step over
        # (_full_entry).
        self._entry = self._generated_entry = None
        if every_one and not self._multistep and not self._partitioned:
            self._generated_entry = on_demand.entry(
                compiled.run_generated_samples, self._generated_args(self._full_args()),
                "the generated steps' loop", on_demand.GENERATED_LOOP_S)
        else:
            self._full_entry()

    def _full_loop(self, method_class):
        """The numba dispatcher of the full compiled loop of this method and formulation."""
        if not self._multistep:
            return compiled.run_samples
        return (compiled_multistep.run_explicit_samples if method_class.beta[0] == 0.0
                else compiled_multistep.run_samples)

    def _model_tuple(self, functions: tuple, every_one: bool) -> tuple:
        """The compiled loop's model (:data:`loop_codes.GAINS` …) with the generated
        ``functions``; ``every_one``: every function the formulation calls generated."""
        formulation = self.formulation
        return (np.asarray(formulation.gains, dtype=float),
                np.ascontiguousarray(formulation.rows), formulation.constraints.kernel_args,
                formulation.dynamics.kernel_args, formulation.constraints.sparsity.arrays,
                functions, every_one, self._right_hand_side)

    def _kernel_entry(self) -> NativeEntry:
        """The entry of :func:`index1_acceleration` for the arguments
        :func:`~.kernel_step.kernel_acceleration` passes it from the model, not yet resolved."""
        formulation = self.formulation
        n = self._start_state[0].size
        return NativeEntry(index1_acceleration,
                           (np.zeros(n), np.zeros(n), 0.0, 0.0, 0.0,
                            np.ascontiguousarray(formulation.rows),
                            formulation.constraints.kernel_args, formulation.dynamics.kernel_args,
                            formulation.constraints.sparsity.arrays), VECTOR)

    def _full_args(self) -> tuple:
        """Arguments of the full loop from the start (types as every call's)."""
        return (self._steps_args(0) if self._partitioned
                else self._samples_args(np.zeros(0, np.int64)))

    def _full_entry(self):
        """The full loop's compiled function, compiled now (or loaded) if it is not yet, with the
        right-hand side kernel it calls (:attr:`_right_hand_side`): inside a run, when the
        generated steps first hand a step over, that time is left out of the run's wall time
        (:attr:`untimed_s`), as it was when the loop was always loaded before the run, and a
        compilation (a wait that is said, :mod:`mbh._harness.common.waits`) is noted."""
        if self._entry is None:
            began = time.perf_counter()
            self._entry = on_demand.entry(self._dispatcher, self._full_args(),
                                          "the in-house kernels' loop", on_demand.FULL_LOOP_S)
            on_demand.resolve(self._right_hand_side, "the in-house kernels' right-hand side",
                              on_demand.RIGHT_HAND_SIDE_S)
            if self._generated_entry is not None:
                took = time.perf_counter() - began
                self.untimed_s += took
                if took >= waits.QUIET_BELOW_S:
                    self.notes.append(
                        f"the generated steps handed step {self.steps + 1} over to the kernels' "
                        f"loop, compiled then ({took:.3g} s, left out of the wall time)")
        return self._entry

    def _wanted_functions(self) -> list[int]:
        """The generated functions the loop calls for this formulation (:mod:`.generated`): the
        right-hand side always, the projection's parts for ``direct``, ρ̂ for ``none`` and
        ``baumgarte`` with placed passages on."""
        wanted = [generated.ACCELERATION]
        if self._code == loop_codes.PROJECTED:
            wanted += [generated.RESIDUAL_SIZE, generated.POSITION_CORRECTION,
                       generated.VELOCITY_CORRECTION]
        elif self._code == loop_codes.PLAIN and self.passages.arrays[0][0] > 0.0:
            wanted.append(generated.INDICATOR)
        return wanted

    def _generated_functions(self, wanted: list[int], compile_new: bool) -> tuple:
        """The ``wanted`` generated functions; with ``compile_new`` False only those compiled
        before; a note for each that could not be had."""
        made, notes = generated.functions(self.formulation, *self._start_state, wanted,
                                          compile_new)
        self.notes.extend(notes)
        return made

    # -- the integrated state ----------------------------------------------------------------
    def _restart(self, q_full: np.ndarray, v_full: np.ndarray) -> None:
        """Integrated state from a full one; a (new) split's state for partitioning."""
        formulation = self.formulation
        if self._code != loop_codes.PARTITIONED:
            self.q, self.v = q_full.copy(), v_full.copy()
            if self._partition is None:
                self._partition = _no_partition()
            return
        independent = np.ascontiguousarray(formulation.independent)
        dependent = np.ascontiguousarray(formulation.dependent)
        params = formulation.params
        self._partition = (independent, dependent, np.array(q_full, dtype=float),
                           np.zeros((dependent.size, independent.size)),
                           np.zeros(1, dtype=np.int64), float(params["newton_tol"]),
                           int(params["newton_max_iter"]), float(params["cond_ratio"]),
                           np.zeros(3))
        self.q, self.v = q_full[independent].copy(), v_full[independent].copy()

    def _full(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Full (q, q̇) of the integrated state at its time ``t``: for every formulation but
        partitioning the stored sample the last :meth:`_step_to` reached (row ``_row`` of the
        call's output), else (q, v)."""
        if self._code != loop_codes.PARTITIONED:
            if self._row is None:
                return self.q, self.v
            return self._samples.q[self._row], self._samples.v[self._row]
        return kernel_step.expand(self.q, self.v, t, self._model[loop_codes.ROWS],
                               self._model[loop_codes.CONSTRAINT_ARGS],
                               self._partition, self._counters)

    # -- stepping ------------------------------------------------------------------------------
    def _steps_args(self, last: int) -> tuple:
        """Arguments of :func:`compiled.run_samples` from the integrated state to step ``last``
        alone (partitioning)."""
        return (self.q, self.v, 0.0, self.grid.dt, self.steps, np.array([last]), self._method,
                self._model, self._code, self._projection, self._partition, self._check_due,
                self._limit, self.passages.arrays, self._counters, np.empty((1, self.q.size)),
                np.empty((1, self.v.size)))

    def _run(self, last: int):
        """(q, v, done, status) of :func:`compiled.run_samples` from the integrated state to step
        ``last``."""
        return self._full_entry()(*self._steps_args(last))[:4]

    def _step_to(self, t: float) -> None:
        target = self._step_of_time.get(t)
        if target is None:
            target = self.grid.steps(t)
        if not self._partitioned:
            samples = self._samples
            row = None if samples is None else samples.rows.get(target)
            if row is None or row >= samples.reached:  # _Samples.row, inline: once a sample
                row = self._run_to(target)
            self._row, self.steps, self.t_good = row, target, target * self.grid.dt
            return
        while True:
            self.q, self.v, self.steps, status = self._run(target)
            self.t_good = self.steps * self.grid.dt
            if status != loop_codes.REPARTITION:
                break
            self._repartition()
        if status != loop_codes.RUNNING:
            raise RunFailure(*self._failure(status))

    def _run_to(self, target: int) -> int:
        """The row of step ``target``'s state after a new call of the compiled loop from the last
        integrated state; raises the failure that ended the run before that step."""
        samples = self._samples
        if samples is None or not samples.failed_before(target):
            samples = self._samples = self._run_samples(self._targets_from(target))
            row = samples.row(target)
            if row is not None:
                return row
        self._fail_at_end(samples)

    def _targets_from(self, target: int) -> np.ndarray:
        """Step indices of ``target`` and of every later sample time and the end, shape (k,)."""
        later = self._sample_steps[np.searchsorted(self._sample_steps, target):]
        return later if later.size and later[0] == target else np.insert(later, 0, target)

    def _samples_args(self, targets: np.ndarray) -> tuple:
        """Arguments of :func:`compiled.run_samples` from the last integrated state through every
        step of ``targets``, with fresh output rows."""
        q, v, first = (self.q, self.v, self.steps) if self._samples is None \
            else self._samples.end[:3]
        if targets.size and targets[0] < first:
            raise ValueError(f"step {targets[0]} was passed without its state being kept "
                             f"(the run is at step {first})")
        return (q, v, 0.0, self.grid.dt, first, targets, self._method, self._model, self._code,
                self._projection, self._partition, self._check_due, self._limit,
                self.passages.arrays, self._counters, np.empty((targets.size, q.size)),
                np.empty((targets.size, v.size)))

    def _run_samples(self, targets: np.ndarray) -> _Samples:
        """Integrate from the last integrated state through every step of ``targets`` in one
        call."""
        args = self._samples_args(targets)
        q_out, v_out = args[-2:]
        if self._generated_entry is None:
            q, v, done, status, reached = self._full_entry()(*args)
        else:
            q, v, done, status, reached = self._generated_entry(*self._generated_args(args))
            if status == loop_codes.DECLINED:  # the full loop goes on from the step handed over
                self.steps = done
                q, v, done, status, more = self._full_entry()(
                    *self._continued_args(args, q, v, done, reached))
                reached += more
        from_start = (targets.size == self._sample_steps.size
                      and targets[0] == self._sample_steps[0])  # then the same steps
        rows = (self._rows_from_start if from_start
                else dict(zip(targets.tolist(), range(targets.size))))
        return _Samples(rows, reached, q_out, v_out, (q, v, done, status))

    @staticmethod
    def _generated_args(args: tuple) -> tuple:
        """Arguments of :func:`compiled.run_generated_samples` from those of
        :func:`compiled.run_samples` (:meth:`_samples_args`)."""
        (q, v, t0, dt, first, targets, tableau, model, code, projection, _, _, limit, passage,
         counters, q_out, v_out) = args
        return (q, v, t0, dt, first, targets, tableau, model[loop_codes.GENERATED], code,
                projection, limit, passage, counters, q_out, v_out)

    @staticmethod
    def _continued_args(args: tuple, q: np.ndarray, v: np.ndarray, done: int,
                        reached: int) -> tuple:
        """Arguments of :func:`compiled.run_samples` (:meth:`_samples_args`) that go on from the
        state (q, q̇) after step ``done`` through the targets of ``args`` from ``reached`` on,
        into the same output rows."""
        _, _, t0, dt, _, targets, *method_to_counters, q_out, v_out = args
        return (q, v, t0, dt, done, targets[reached:], *method_to_counters, q_out[reached:],
                v_out[reached:])

    def _fail_at_end(self, samples: _Samples) -> None:
        """Make the last good state of ``samples`` current and raise the failure that ended it."""
        self._row = None
        self.q, self.v, self.steps, status = samples.end
        self.t_good = self.steps * self.grid.dt
        raise RunFailure(*self._failure(status))

    def _repartition(self) -> None:
        """Choose the split again at the current state (the Python path's choice) and restart."""
        q_full, v_full = self._full(self.t_good)
        self.formulation.choose_partition(q_full)
        self._restart(q_full, v_full)
        self._check_due[0] = 0

    def _failure(self, status: int) -> tuple[CaseStatus, str]:
        """(status, reason) of a failure code, worded as the Python path words it."""
        failure = self._partition[8]
        if status == loop_codes.DIVERGED_LIMIT:
            return CaseStatus.DIVERGED, f"state norm exceeds divergence_limit={self._limit:g}"
        if status == loop_codes.DIVERGED_NONFINITE:
            return CaseStatus.DIVERGED, "non-finite state"
        if status == loop_codes.FAILED_NEWTON and self._multistep:
            tol, max_iter, _ = self._method[2]  # method_arguments' (tol, max_iter, slow rate)
            reached = (self.steps + 1) * self.grid.dt
            return CaseStatus.FAILED, "StepFailure: " + non_convergence(max_iter, tol, reached)
        if status == loop_codes.FAILED_NEWTON:
            return CaseStatus.FAILED, ("StepFailure: dependent coordinates did not converge "
                                       f"(max |Φ| = {failure[1]:.3g}) at t = {failure[2]:g}")
        if status == loop_codes.FAILED_RANK:
            rows = self._model[loop_codes.ROWS].size
            return CaseStatus.FAILED, ("StepFailure: constraint Jacobian lost rank "
                                       f"({int(failure[1])} < {rows}): singular configuration")
        return CaseStatus.FAILED, "LinAlgError: a factorisation failed in the compiled step"

    # -- reading -------------------------------------------------------------------------------
    def run(self, grid: RunGrid, n_bodies: int):
        """:meth:`Stepper.run`, with notes of the right-hand sides and of the step ends
        (projections, ρ̂) the generated functions handed back to the kernels
        (:func:`hand_back_note`, :func:`step_end_note`)."""
        trajectory = super().run(grid, n_bodies)
        counters = self._counters
        accelerations, step_ends = self._generated_parts
        notes = [hand_back_note(int(counters[loop_codes.KERNEL_CALLS]),
                                int(counters[loop_codes.RHS_EVALS])) if accelerations else None,
                 step_end_note(int(counters[loop_codes.STEP_END_KERNELS]),
                               int(counters[loop_codes.STEP_ENDS])) if step_ends else None]
        trajectory.notes.extend(note for note in notes if note)
        return trajectory

    def _states(self, t: float) -> BodyStates:
        if self.steps == 0:
            return body_states(self.layout, *self._start_state)
        return body_states(self.layout, *self._full(self.t_good))

    def counters(self) -> dict:
        own = self.formulation.counters
        return {"rhs_evals": int(self._counters[loop_codes.RHS_EVALS]),
                "jacobian_evals": own["jacobian_evals"]
                + int(self._counters[loop_codes.JACOBIAN_EVALS]),
                "factorizations": own["factorizations"]
                + int(self._counters[loop_codes.FACTORIZATIONS]),
                "newton_iterations": own["newton_iterations"]
                + int(self._counters[loop_codes.NEWTON_ITERATIONS]),
                "kernel_calls": int(self._counters[loop_codes.KERNEL_CALLS]),
                "repartitions": getattr(self.formulation, "repartitions", 0),
                "passages": int(self.passages.count[0])}


def hand_back_note(kernel_calls: int, rhs_evals: int) -> str | None:
    """The note of a run whose generated right-hand side handed ``kernel_calls`` of its
    ``rhs_evals`` calls back to the kernels (None for none): one of its guards (a pivot or a
    certificate bound of its solves, :mod:`.generated`) came out otherwise than at the traced
    state, so the kernel served those calls at the kernel's cost."""
    if kernel_calls == 0:
        return None
    return (f"generated functions handed back {kernel_calls} of {rhs_evals} right-hand sides "
            f"({100.0 * kernel_calls / rhs_evals:.3g} %) to the kernels: a guard of the "
            f"generated right-hand side (a pivot or a certificate bound of its solves) came out "
            f"otherwise than at the traced start")


def step_end_note(kernel_ends: int, step_ends: int) -> str | None:
    """The note of a run whose generated projection or ρ̂ handed ``kernel_ends`` of its
    ``step_ends`` step ends back to the kernels (None for none): a certificate of their solve
    failed, as it does near a singular position, where the kernels' solve is the truncated SVD
    (LAPACK, which cannot be generated), so those steps ran on the kernels' path at its cost."""
    if kernel_ends == 0:
        return None
    return (f"generated functions handed back the projection or ρ̂ of {kernel_ends} of "
            f"{step_ends} steps ({100.0 * kernel_ends / step_ends:.3g} %) to the kernels: a "
            f"certificate of their solve failed (near a singular position the kernels solve by "
            f"the truncated SVD, which cannot be generated)")


@dataclass(frozen=True)
class _Samples:
    """States of one :func:`compiled.run_samples` call.

    Attributes
    ----------
    rows : dict
        Step index → row of ``q`` and ``v``, for every target of the call.  Reaching a sample is
        one lookup and no array made (the row is cut out when the state is read): the per-sample
        Python is a large part of the in-house cost at large steps (a pendulum at 1e-2 s spent
        0.63 ms on its 1,001 samples against 1.05 ms on its 1,000 steps before;
        docs/measurements.md, "In-house step cost").
    reached : int
        Targets reached: rows from ``reached`` on are unset.
    q, v : ndarray, shape (k, n)
        The integrated state after each target of the call (rows from ``reached`` on unset).
    end : tuple
        (q, v, done, status) of the call: the last good state, its step and why it stopped.
    """

    rows: dict
    reached: int
    q: np.ndarray
    v: np.ndarray
    end: tuple

    def row(self, target: int) -> int | None:
        """The row of step ``target``'s state, or None when the call did not reach it."""
        row = self.rows.get(target)
        return row if row is not None and row < self.reached else None

    def failed_before(self, target: int) -> bool:
        """Whether the call ended in a failure before step ``target``."""
        return self.end[3] != loop_codes.RUNNING and target > self.end[2]


def _no_partition() -> tuple:
    """The (unused) partition state of the other formulations, typed as :func:`kernel_step.expand`
    expects it."""
    empty = np.zeros(0, dtype=np.int64)
    return (empty, empty, np.zeros(0), np.zeros((0, 0)), np.zeros(1, dtype=np.int64), 0.0, 0, 0.0,
            np.zeros(3))
