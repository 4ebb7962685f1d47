"""Generated kernels: what the compiled loop computes at every stage and step, traced for one
formulation into straight-line code.

The generic kernels (:func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`, the projection's
Φ, Φ_q and minimum-norm corrections, the conditioning indicator ρ̂) loop over tables of
primitives, bodies and matrix entries.  :func:`compiled_function` runs one of them once on
symbols (:mod:`mbh._adapters.inhouse.codegen.tracing`) with the formulation's rows, gains, projection cut and
tables fixed, and compiles what it recorded as a numba ``cfunc`` of :data:`SIGNATURE`::

    accepted = function(q, v, t, out)     # q, v (n,), t s; writes into out

It returns 1 with ``out`` the kernel's result to the bit, or 0 (``out`` unspecified) where one of
the kernel's branches on data goes the other way than at the traced state (a guard: a pivot, the
certificate of a Cholesky solve); the compiled loop (:mod:`mbh._adapters.inhouse.stepping.compiled`) then calls
the kernel.  :func:`functions` makes the set the loop needs (:data:`ACCELERATION` …), with
:data:`NEVER` (always 0: the kernel) where one cannot be made: a trace over
:data:`MAX_OPERATIONS`, a kernel path through LAPACK (the banded solves of planar systems with
30 rows or more, the SVD of a system without a certificate at the start) — each with a note.

The joint-coordinate model's right-hand side (:data:`JOINT_ACCELERATION`,
:func:`joint_function`) is generated the same way from
:func:`~mbh._adapters.inhouse.formulations.joint_rhs.acceleration_kernel`, traced on the closure
(:func:`_traced_inputs`), for its compiled loop (:mod:`mbh._adapters.inhouse.stepping.compiled_joint`).

A generated right-hand side is several times faster than the kernel (figures:
docs/measurements.md, section "In-house step cost").  The cost is the first compilation, seconds
per function, paid once per formulation and machine: the source goes to an entry of
:mod:`mbh._adapters.inhouse.codegen.generated_store` named by its hash, where numba caches the compiled
function next to it.  The trace itself (0.01–0.3 s per function on the shipped scenes, more for
a large one that passes :data:`MAX_OPERATIONS`) is paid once too: the store remembers which entry,
or which reason for none, a trace's inputs gave (:func:`trace_key`), and a later run with the same
inputs loads that entry (its source checked against its name) without tracing.

The traced state is the formulation's start, its coordinates moved by ~1e-6 and its velocities
by ~1 in a fixed pseudo-random direction, so that no entry is zero there by the start's symmetry
alone; close enough to the start for the guards on pivots and certificates to hold along a run.
"""

from __future__ import annotations

import hashlib
import sys
import warnings

import numpy as np
from numba import cfunc, types
from numba.core.errors import NumbaExperimentalFeatureWarning

from mbh._adapters.inhouse.bodies import bodykin, kernels, tree_pass
from mbh._adapters.inhouse.codegen import generated_store, tracing
from mbh._adapters.inhouse.formulations import dynamics, joint_rhs, mass_and_forces
from mbh._adapters.inhouse.numerics import banded, linalg
from mbh._harness.common import waits
from mbh._harness.common.digest import feed
from mbh._harness.common.kernel_cache import kernel_fingerprint

# The compiled loop takes the generated functions as first-class function values, a numba
# feature still labelled experimental (a warning at every compilation that types one); the tests
# cover its use here.
warnings.filterwarnings("ignore", message="First-class function type feature is experimental",
                        category=NumbaExperimentalFeatureWarning)

#: ``accepted(q, v, t, out)`` of every generated function.
SIGNATURE = types.int64(types.float64[::1], types.float64[::1], types.float64,
                        types.float64[::1])

#: Generated source lines compiled a second, about (the announcement's estimate): measured
#: 6,000–8,000 on functions of 5,000–19,000 lines (docs/speed.md), ~0.3 s for a short one.
LINES_PER_SECOND = 6000
#: Traces with more operations are not compiled (the kernel runs instead).  Set when numba
#: compiled ~1,000 straight-line operations a second (a mechanism of tens of bodies would have
#: waited minutes); compiling is 6–8× faster now (:mod:`~mbh._adapters.inhouse.codegen.straight_line`),
#: but the trace itself, in Python, grows with it, and larger traces were not measured.
MAX_OPERATIONS = 20_000


@cfunc(SIGNATURE, cache=True)
def _never(q, v, t, out):
    """The kernel for every call."""
    return 0


NEVER = _never


class NotGenerated(RuntimeError):
    """No generated function for this formulation: the trace passed :data:`MAX_OPERATIONS`, the
    kernel took a path that cannot be traced (LAPACK: the banded solves, the truncated SVD of a
    system without a certificate at the traced state), or the source did not compile."""


class NotTraceable(NotGenerated):
    """No generated function for a reason that holds whenever the same inputs are traced (the
    operation limit, a kernel path through LAPACK): the reason :func:`compiled_function`
    remembers.  Any other failure of a trace is not remembered."""


#: The generated functions, by their index in :func:`functions`' tuple (all of
#: :data:`SIGNATURE`; ``out`` as given):
#:
#: * ACCELERATION — q̈ (n,) of :func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`;
#: * RESIDUAL_SIZE — max |Φ| over the formulation's rows, out[0];
#: * POSITION_CORRECTION — q − Φ_q⁺Φ (n,), one iteration of the position projection (Rouvinen 2003, eq. 127,
#:   :func:`~mbh._adapters.inhouse.numerics.banded.min_norm_correction`);
#: * VELOCITY_CORRECTION — q̇ − Φ_q⁺Φ_q q̇ (n,) and ρ̂ in out[n], the velocity projection (Rouvinen 2003
#:   eq. 137) and the conditioning indicator of the placed passages
#:   (:func:`~mbh._adapters.inhouse.numerics.banded.min_norm_correction_and_indicator`);
#: * INDICATOR — ρ̂ alone, out[0] (:func:`~mbh._adapters.inhouse.numerics.banded.conditioning_indicator`);
#: * JOINT_ACCELERATION — θ̈ (n_θ,) of the joint-coordinate model
#:   (:func:`~mbh._adapters.inhouse.formulations.joint_rhs.acceleration_kernel`), its inputs θ, θ̇
#:   in the places of q, q̇ (:func:`joint_function`; the absolute loops' tuple stops before it).
(ACCELERATION, RESIDUAL_SIZE, POSITION_CORRECTION, VELOCITY_CORRECTION, INDICATOR,
 JOINT_ACCELERATION) = range(6)
#: The part of a generated module that compiles its straight-line function (``{name}``):
#: numba's ``cfunc`` of :data:`SIGNATURE` that calls ``{name}_emitted``, the intrinsic
#: :func:`~mbh._adapters.inhouse.codegen.straight_line.straight_line` makes of
#: ``{name}_operations`` (Python calls the latter; the cfunc is for compiled callers).
#: Everything before it is plain Python (:func:`declines_at_start` runs it).
_COMPILED_PART = """

{name}_emitted = straight_line({name}_operations)


@cfunc(SIGNATURE, cache=True)
def {name}(q, v, t, out):
    return {name}_emitted(q, v, t, out)
"""
_NAMES = ("acceleration", "residual_size", "position_correction", "velocity_correction",
          "indicator", "joint_acceleration")


def kernel_outputs(which: int, formulation, q, v, t) -> list:
    """What function ``which`` computes, by the kernels: on symbols (q, v object arrays) its
    trace, on numbers the result the generated function must reproduce."""
    if which == JOINT_ACCELERATION:
        return list(joint_rhs.acceleration_kernel(q, v, t, *formulation.kernel_args))
    rows = np.ascontiguousarray(formulation.rows)
    constraint_args = formulation.constraints.kernel_args
    sparsity_arrays = formulation.constraints.sparsity.arrays
    if which == ACCELERATION:
        alpha, beta = (float(x) for x in formulation.gains)
        return list(dynamics.index1_acceleration(q, v, t, alpha, beta, rows, constraint_args,
                                                 formulation.dynamics.kernel_args,
                                                 sparsity_arrays))
    if which == RESIDUAL_SIZE:  # kernel_step._max_abs: the largest of 0 and every |Φ_i|
        return [tracing.maximum([0.0, *(abs(x) for x in
                                       kernels.phi(q, t, constraint_args)[rows])])]
    jacobian = kernels.jacobian(q, t, constraint_args)[rows]
    if which == POSITION_CORRECTION:
        residual = kernels.phi(q, t, constraint_args)[rows]
        return list(q - banded.min_norm_correction(jacobian, residual, formulation.cut,
                                                   sparsity_arrays))
    if which == VELOCITY_CORRECTION:
        correction, indicator = banded.min_norm_correction_and_indicator(
            jacobian, banded.pattern_matvec(jacobian, sparsity_arrays[0], v), formulation.cut,
            sparsity_arrays)
        return [*(v - correction), indicator]
    return [banded.conditioning_indicator(jacobian, sparsity_arrays)]


def traced_state(q0: np.ndarray, v0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The state the functions are traced at (see the module notes): the start (q0, v0) with its
    coordinates moved by ~1e-6 and its velocities by ~1 in a fixed pseudo-random direction."""
    rng = np.random.default_rng(20261126)
    return q0 + 1e-6 * rng.standard_normal(q0.size), v0 + rng.standard_normal(v0.size)


def _traced_inputs(which: int, formulation, q0: np.ndarray,
                   v0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where function ``which`` is traced: :func:`traced_state`, its coordinates put back onto
    the closure for :data:`JOINT_ACCELERATION` (``formulation.on_closure``): off it by 1e-6, the
    range-space matrix of redundant closure rows is not null to round-off in their directions,
    and the trace would take the truncated SVD, which it cannot follow, where every run's states,
    on the closure, take the pivoted Cholesky."""
    q, v = traced_state(q0, v0)
    if which == JOINT_ACCELERATION:
        q = formulation.on_closure(q)
    return q, v


def declines_at_start(which: int, source: str, q0: np.ndarray, v0: np.ndarray) -> bool:
    """Whether generated function ``which`` of module ``source`` declines a call at the start's
    coordinates q0 (with the traced velocities, so that no velocity is zero by the start alone),
    run as plain Python before anything is compiled.  The traced state lies ~1e-6 off the
    constraints, the start on them: where that decides a guard (a pivot of a range-space solve
    that is zero on the constraints, as where equations are redundant), the function would hand
    back nearly every call of a run, and compiling it would cost seconds to minutes for
    nothing."""
    name = _NAMES[which]
    plain = source.split(_COMPILED_PART.format(name=name))[0]
    namespace: dict = {}
    exec(compile(plain, f"<generated {name}>", "exec"), namespace)
    out = np.zeros(2 * q0.size + 2)
    return namespace[f"{name}_operations"](np.array(q0, dtype=float),
                                           traced_state(q0, v0)[1], 0.0, out) == 0


def function_source(which: int, formulation, q0: np.ndarray, v0: np.ndarray) -> str:
    """The Python source of generated function ``which`` (:data:`ACCELERATION` …) of
    ``formulation`` (its rows, gains α, β, projection cut, constraint and dynamics tables), traced
    near the start (q0, v0) (see the module notes).

    Raises
    ------
    NotGenerated
        When the trace passes :data:`MAX_OPERATIONS` or meets a branch it cannot follow.
    """
    q, v = _traced_inputs(which, formulation, q0, v0)
    graph = tracing.Graph(limit=MAX_OPERATIONS)
    name = _NAMES[which]
    try:
        with tracing.tracing([kernels, mass_and_forces, dynamics, linalg, bodykin, banded,
                              joint_rhs, tree_pass]):
            out = kernel_outputs(which, formulation, graph.inputs("q", q), graph.inputs("v", v),
                           graph.scalar("t", 0.0))
    except tracing.LimitReached:
        raise NotTraceable(f"the trace takes more than {MAX_OPERATIONS} operations") from None
    except tracing.Untraceable as error:
        raise NotTraceable(f"the kernels' path at the start cannot be traced: "
                           f"{type(error).__name__}: {error}") from None
    except Exception as error:  # noqa: BLE001 — an unforeseen branch; the kernel runs instead
        raise NotGenerated(f"the kernels' path at the start cannot be traced: "
                           f"{type(error).__name__}: {error}") from None
    return tracing.function_source(graph, f"{name}_operations", ("q", "v", "t"), out)


class NotCompiled(NotGenerated):
    """The function was asked for only if already compiled (``compile_new=False``), and is not."""


def trace_key(which: int, formulation, q0: np.ndarray, v0: np.ndarray) -> str | None:
    """SHA-256 (hex) of everything the trace of function ``which`` reads
    (:func:`kernel_outputs`, :func:`function_source`): the kernels' and the tracer's code
    (:func:`~mbh._harness.common.kernel_cache.kernel_fingerprint`, which covers this module), ``which``,
    the formulation's rows, gains, projection cut, constraint and dynamics tables and sparsity
    pattern, and the start (q0, v0).  None when an input is of a kind it cannot digest (the
    function is then traced every time)."""
    digest = hashlib.sha256(kernel_fingerprint().encode())
    try:
        if which == JOINT_ACCELERATION:  # its kernel's arguments: tree, dynamics, closure, …
            feed(digest, (which, formulation.kernel_args, q0, v0))
            return digest.hexdigest()
        feed(digest, (which, formulation.rows, formulation.gains,
                      getattr(formulation, "cut", None),  # projected formulations only
                      formulation.constraints.kernel_args,
                      formulation.constraints.sparsity.arrays,
                      formulation.dynamics.kernel_args, q0, v0))
    except TypeError:
        return None
    return digest.hexdigest()


def module_name(source: str) -> str:
    """The module name of a generated source: made of its hash."""
    return "mbh_" + hashlib.sha256(source.encode()).hexdigest()[:24]


def _traced_source(key: str | None, which: int, formulation, q0: np.ndarray,
                   v0: np.ndarray) -> str:
    """The module source of generated function ``which``, traced now; what the trace gave (the
    module's name, or why there can be none: :class:`NotTraceable`) is remembered under ``key``."""
    try:
        body = function_source(which, formulation, q0, v0)
    except NotTraceable as error:
        if key:
            generated_store.remember(key, {"not_generated": str(error)})
        raise
    source = ("# Generated by adapters/inhouse/codegen/generated.py for one formulation.  Do not edit;\n"
              "# delete freely (it is made again when needed).\n"
              "import numpy as np\nfrom numba import cfunc\n\n"
              "from mbh._adapters.inhouse.codegen.generated import SIGNATURE\n"
              "from mbh._adapters.inhouse.codegen.straight_line import straight_line\n\n\n"
              + body + _COMPILED_PART.format(name=_NAMES[which]))
    if key:
        generated_store.remember(key, {"module": module_name(source)})
    return source


def compiled_function(which: int, formulation, q0: np.ndarray, v0: np.ndarray,
                      compile_new: bool = True):
    """Generated function ``which`` of ``formulation``, compiled (a ``cfunc`` of
    :data:`SIGNATURE`), from numba's cache when this source was compiled before
    (:mod:`mbh._adapters.inhouse.codegen.generated_store`: a damaged entry is compiled again).  A trace whose
    inputs were traced before (:func:`trace_key`) is not repeated: its remembered entry is loaded
    when its source still matches its name, and a remembered reason for none is raised again.

    Raises
    ------
    NotGenerated
        When the trace passes :data:`MAX_OPERATIONS` or meets a branch it cannot follow, or the
        source does not compile (a fault of the generator, which the tests look for).
    """
    key = trace_key(which, formulation, q0, v0)
    memo = (generated_store.remembered(key) if key else None) or {}
    if "not_generated" in memo:
        raise NotGenerated(str(memo["not_generated"]))
    name = memo.get("module")
    module = sys.modules.get(name) if isinstance(name, str) else None
    if module is None:
        source = generated_store.entry_source(name) if isinstance(name, str) else None
        if source is None or module_name(source) != name:  # no memo; its entry gone or damaged
            source = _traced_source(key, which, formulation, q0, v0)
            name = module_name(source)
            module = sys.modules.get(name)
        if module is None:
            if not generated_store.is_compiled(name) and declines_at_start(which, source, q0,
                                                                            v0):
                reason = ("its guards decline at the start, where a pivot of its solves "
                          "differs from the traced state's (as where equations are redundant): "
                          "it would hand back nearly every call, so it is not compiled")
                if key:
                    generated_store.remember(key, {"not_generated": reason})
                raise NotGenerated(reason)
            module = _load(name, source, compile_new, which)
    return getattr(module, _NAMES[which])


def _load(name: str, source: str, compile_new: bool, which: int):
    """Module ``name`` of ``source`` from the store (:func:`generated_store.load`); a compilation
    is announced (:mod:`mbh._harness.common.waits`) with its estimate (:data:`LINES_PER_SECOND`)."""
    if not compile_new and not generated_store.is_compiled(name):
        raise NotCompiled("not compiled yet")
    lines = source.count("\n")
    try:
        return generated_store.load(name, source, announce=waits.said(
            f"compiling the generated {_NAMES[which].replace('_', ' ')} of this mechanism, "
            f"{lines} lines", "once on this machine", max(1.0, lines / LINES_PER_SECOND)))
    except generated_store.GeneratedCacheSettingError:
        raise
    except Exception as error:  # noqa: BLE001 — a generator fault must not end the run
        raise NotGenerated(f"{generated_store.entry_folder(name)} does not compile: "
                           f"{type(error).__name__}: {str(error)[:300]}") from None


#: The tuple of :func:`functions` with nothing generated: the kernels for every call (the
#: compiled loop with ``loop=compiled``).
NOTHING = (NEVER,) * JOINT_ACCELERATION


def functions(formulation, q0: np.ndarray, v0: np.ndarray, wanted,
              compile_new: bool = True) -> tuple[tuple, list[str]]:
    """The compiled loop's generated functions for ``formulation``: a tuple indexed by
    :data:`ACCELERATION` …, the compiled function for each index in ``wanted`` that can be made
    (with ``compile_new`` False: that was compiled before, by any run on this machine) and
    :data:`NEVER` elsewhere, and one note per reason some were not, starting "not generated"."""
    made, missing = list(NOTHING), {}
    for which in wanted:
        try:
            made[which] = compiled_function(which, formulation, q0, v0, compile_new)
        except NotGenerated as error:
            missing.setdefault(str(error), []).append(_NAMES[which].replace("_", " "))
    notes = [f"not generated: {', '.join(names)} ({reason}); the generic kernels serve them"
             for reason, names in missing.items()]
    return tuple(made), notes


def joint_function(formulation, theta0: np.ndarray, rate0: np.ndarray,
                   compile_new: bool = True) -> tuple:
    """The generated :data:`JOINT_ACCELERATION` of a joint-coordinate ``formulation``
    (:class:`~mbh._adapters.inhouse.formulations.joint_coordinates.JointCoordinates`) started at
    (θ₀, θ̇₀), and the run's notes: (function, notes), with :data:`NEVER` and a note starting
    "not generated" where it cannot be made (as :func:`functions`)."""
    made, missing = NEVER, []
    try:
        made = compiled_function(JOINT_ACCELERATION, formulation, theta0, rate0, compile_new)
    except NotGenerated as error:
        missing.append(f"not generated: joint acceleration ({error}); the joint-coordinate "
                       "kernel serves it")
    return made, missing
