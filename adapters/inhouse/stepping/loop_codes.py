"""The integer codes of the compiled loops (:mod:`~mbh._adapters.inhouse.stepping.compiled`,
:mod:`~mbh._adapters.inhouse.stepping.compiled_multistep`): why a loop stopped, where each member
of the model tuple sits, which stabilisation it runs and where each cost counter is kept.

These are numba constants, folded into the compiled code; they are not the case statuses
(``ok``, ``failed``, …), which :mod:`~mbh._adapters.inhouse.stepping.compiled_stepper` derives
from them.  Read by numba code, so this module names numba, and its text is part of the kernels'
fingerprint (:mod:`mbh._harness.common.kernel_cache`).
"""

RUNNING, DIVERGED_NONFINITE, DIVERGED_LIMIT, FAILED_LINALG, FAILED_NEWTON, FAILED_RANK, \
    REPARTITION = range(7)

#: The members of the model tuple the compiled loop reads, by name: the Baumgarte gains (α, β),
#: the constraint rows, the constraint kernels' arguments, the force kernels' arguments, the
#: sparsity arrays of Φ_q, the generated functions, and whether the generated steps run
#: (:func:`_generated_run`: only when every function the formulation calls was generated, so that
#: a step never computes its stages twice).  That is a flag and not a second tuple of the
#: functions: converting a generated function into a call's argument costs ~2.5 µs (numba asks
#: Python for its address), 12 µs a tuple of five.  numba folds these module constants into the
#: tuple's indexing, so the names cost nothing; a named tuple in their place made the generated
#: loop's step 2–3 % slower (docs/measurements.md, "Named model tuple").  Last, the right-hand
#: side kernel's entry (:class:`~mbh._adapters.inhouse.stepping.native_call.NativeEntry`), which
#: the loops call through its address rather than linking its code into each of them.
GAINS, ROWS, CONSTRAINT_ARGS, DYNAMICS_ARGS, SPARSITY, GENERATED, GENERATED_STEPS, \
    RIGHT_HAND_SIDE = range(8)

#: What :func:`_generated_run` returns when one of its functions declined a call of the next step
#: (a guard, or :data:`~mbh._adapters.inhouse.codegen.generated.NEVER`): nothing of that step was kept, the
#: full step runs instead.
DECLINED = -1

#: Stabilisation codes of :func:`~.compiled.run_samples`.
PLAIN, PROJECTED, PARTITIONED = range(3)

#: Index of each cost counter in the ``counters`` array of :func:`~.compiled.run_samples`
#: (KERNEL_CALLS: right-hand sides the generated function left to the kernel, :mod:`.generated`;
#: STEP_ENDS: steps ended by ``direct``'s projection or by ρ̂ for placed passages,
#: STEP_END_KERNELS: those of them a generated part left to the kernels, near a singular position
#: where the kernels' solve is the truncated SVD).
(RHS_EVALS, JACOBIAN_EVALS, FACTORIZATIONS, NEWTON_ITERATIONS, KERNEL_CALLS, STEP_ENDS,
 STEP_END_KERNELS) = range(7)
#: Length of the ``counters`` array.
COUNTERS = 7
