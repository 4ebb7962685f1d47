"""Generated kernels (adapters/inhouse/codegen/generated.py, tracing.py): the traced straight-line
functions against the generic kernels they were traced from, and when ``loop=auto`` makes them.

Bounds: a generated function makes its kernel's floating-point operations on the same operands
in the same order (only exact identities folded), so it returns the kernel's numbers; measured on
this machine (2026-11-26) the largest difference over every shipped scene, all five functions and
the states below is 0.0.  The bound, 1e-13 relative to the largest |q̈|, leaves room for a build that
evaluates an elementary function (sqrt, sin, cos) differently in the two compiled functions, and
is far below any method's error.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, reject, settings
from hypothesis import strategies as st
from numba import cfunc, njit

from mbh._adapters import get_adapter
from mbh._adapters.base import RunFailure, RunGrid
from mbh._adapters.inhouse.codegen import generated, generated_store, tracing
from mbh._adapters.inhouse.formulations import dynamics, mass_and_forces
from mbh._adapters.inhouse.stepping import compiled_stepper, on_demand
from mbh._adapters.inhouse.stepping.compiled_stepper import hand_back_note, step_end_note
from mbh._harness.model import scenario
from mbh._harness.neutral.assembly import AssemblyError
from mbh._harness.testing.strategies import aligned_mechanisms, mechanisms
from mbh._harness.model.timegrid import sample_times
from tests.helpers import LARGE_TRACES, PATH_BOUND, parallel_revolute_fourbar

RELATIVE_BOUND = 1e-13

EXAMPLE_KERNEL = '''
import numpy as np

def kernel(x):
    root = np.sqrt(x[0])
    return root * x[1] if root > 1.0 else x[1]
'''


def test_exact_identities_fold_and_repeated_operations_are_recorded_once():
    graph = tracing.Graph()
    x, y = graph.inputs("q", [2.0, 3.0])
    assert x * 0.0 == 0.0 and 0.0 * y == 0.0  # plain zeros: no symbol, so no guard either
    assert (x * 1.0) is x and (x + 0.0) is x and (x - 0.0) is x and (x / 1.0) is x
    assert not graph.guards
    first, second = x * y, x * y
    assert first.index == second.index and first.value == 6.0
    negated = 0.0 - x
    assert negated.value == -2.0 and graph.nodes[negated.index][0] == "neg"
    assert len(graph.nodes) == 4  # x, y, x·y, −x


def test_zero_over_a_symbol_folds_to_the_kernels_signed_zero_while_the_sign_holds():
    graph = tracing.Graph()
    x, y = graph.inputs("q", [2.0, -3.0])
    over_x, over_y, negative_over_x = 0.0 / x, 0.0 / y, -0.0 / x
    assert [math.copysign(1.0, z) for z in (over_x, over_y, negative_over_x)] == [1.0, -1.0, -1.0]
    assert not isinstance(0.0 / x, tracing.Symbol) and len(graph.nodes) == 2
    assert [(node, compare, outcome) for node, compare, _, outcome in graph.guards] == \
        [(x.index, "gt", True), (y.index, "lt", True)]  # each once, though 0/x was traced twice
    namespace = {}
    exec("import numpy as np\n"
         + tracing.function_source(graph, "f", ("q",), [over_x, over_y, x + y]), namespace)
    out = np.zeros(3)
    for q, accepted in (([5.0, -1.0], 1), ([-5.0, -1.0], 0), ([0.0, -1.0], 0),
                        ([np.nan, -1.0], 0), ([5.0, 1.0], 0)):
        assert namespace["f"](np.array(q), out) == accepted
        if accepted:  # the kernel's own 0/x, bit for bit (its sign too)
            assert out[0] == 0.0 / q[0] and math.copysign(1.0, out[0]) == 1.0
            assert math.copysign(1.0, out[1]) == math.copysign(1.0, 0.0 / q[1])


def test_a_guard_hands_the_call_back_when_the_branch_goes_the_other_way():
    module = types.ModuleType("example_kernel")
    exec(EXAMPLE_KERNEL, module.__dict__)
    graph = tracing.Graph()
    with tracing.tracing([module]):
        traced = module.kernel(graph.inputs("q", [4.0, 3.0]))
    assert [(compare, other, outcome) for _, compare, other, outcome in graph.guards] == \
        [("gt", 1.0, True)]
    namespace = {}
    exec("import numpy as np\n" + tracing.function_source(graph, "f", ("q",), [traced]),
         namespace)  # the source alone, run as plain Python
    out = np.zeros(1)
    assert namespace["f"](np.array([9.0, 2.0]), out) == 1 and out[0] == 6.0
    assert namespace["f"](np.array([0.25, 2.0]), out) == 0  # √0.25 < 1: the other branch


def test_a_trace_past_its_limit_stops():
    graph = tracing.Graph(limit=3)
    x, y = graph.inputs("q", [2.0, 3.0])
    x * y
    with pytest.raises(tracing.LimitReached):
        x + y


@njit
def _call(function, q, v, t, out):
    return function(q, v, t, out)


def _states(name: str, method: str, count: int = 10):
    """The formulation of ``method`` on scene ``name`` and (t, q, q̇) at the start and at ``count``
    sample times of 0.2 s of its own run on the generic kernels (``loop=compiled``)."""
    mech, adapter = scenario.load(name), get_adapter("inhouse")
    dt = mech.sample_step / 10 if mech.sample_step < 1e-2 else 1e-3
    t_end = 200 * dt
    spec, params = adapter.method_spec(f"{method}:loop=compiled")
    stepper = adapter._start(mech, spec, params,
                             RunGrid(dt, t_end, sample_times(dt, t_end, t_end / count), True))
    states = [(0.0, *stepper._start_state)]
    for t in stepper.grid.sample_times[1:]:
        try:
            stepper._step_to(float(t))
        except RunFailure:  # stiff_fourbar diverges at this step: its states up to there
            break
        states.append((float(t), stepper.q.copy(), stepper.v.copy()))
    return stepper.formulation, stepper._start_state, states


#: Each generated function with a formulation that uses it.
FUNCTIONS = [(generated.ACCELERATION, "rk4+direct"), (generated.ACCELERATION, "rk4+baumgarte"),
             (generated.RESIDUAL_SIZE, "rk4+direct"), (generated.POSITION_CORRECTION, "rk4+direct"),
             (generated.VELOCITY_CORRECTION, "rk4+direct"), (generated.INDICATOR, "rk4+none")]


@pytest.mark.parametrize("which, method", FUNCTIONS)
@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.slow)
                                  if name in LARGE_TRACES else name
                                  for name in scenario.scenario_names()])
def test_each_generated_function_computes_what_its_kernels_compute(name, which, method):
    """At the start and ten states along 0.2 s of the formulation's own run, every guard holds
    (measured) and the result is the kernels'; Bricard's trace is too large."""
    formulation, start, states = _states(name, method)
    try:
        function = generated.compiled_function(which, formulation, *start)
    except generated.NotGenerated:
        assert name == "bricard"
        return
    for t, q, v in states:
        expected = np.asarray(generated.kernel_outputs(which, formulation, q, v, t))
        out = np.empty(q.size + 1)
        assert _call(function, q, v, t, out) == 1
        scale = max(np.abs(expected).max(), np.finfo(float).tiny)
        assert np.abs(out[:expected.size] - expected).max() <= RELATIVE_BOUND * scale


def test_the_source_is_the_same_every_time():
    """The source names its numba cache: a trace that varied would compile again each run."""
    formulation, start, _ = _states("fourbar", "rk4+direct", count=1)
    assert generated.function_source(generated.ACCELERATION, formulation, *start) == \
        generated.function_source(generated.ACCELERATION, formulation, *start)


def test_a_short_run_compiles_nothing_new_and_a_long_one_does(tmp_path, monkeypatch):
    """``loop=auto`` (the default): 100 rk4 steps (400 right-hand sides, below AUTO_MIN_CALLS)
    take the kernels until the functions exist; 300 steps compile them; then short runs load
    them.  Gains no other test traces, so no other test compiles this right-hand side."""
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    mech, adapter = scenario.load("fourbar"), get_adapter("inhouse")
    method = "rk4+baumgarte:alpha=7,beta=7"

    def run(t_end):
        return adapter.simulate(mech, method, 1e-3, t_end, sample_times(1e-3, t_end, 0.1))

    # The kernels' loop compiled first: else a short run compiles the generated functions, the
    # cheaper of the two (test_a_short_run_where_the_kernels_loop_is_not_compiled_...).
    adapter.simulate(mech, "rk4+baumgarte:loop=compiled", 1e-3, 1e-3, np.zeros(1))
    first = run(0.1)
    assert first.counters["kernel_calls"] == first.counters["rhs_evals"] == 400
    # (ρ̂'s function does not depend on the gains: another test may have compiled it already.)
    assert any(note.startswith("not generated: acceleration") and "(not compiled yet)" in note
               for note in first.notes), first.notes
    compiled_marks = f"*/*/{generated_store.USED}"  # <toolchain>/<entry>/used
    assert not list(tmp_path.glob(compiled_marks))
    long = run(0.3)
    assert long.counters["kernel_calls"] == 0 and list(tmp_path.glob(compiled_marks))
    again = run(0.1)
    assert again.counters["kernel_calls"] == 0
    # Two paths to the same numbers (measured equal to the bit): bounded as tests/
    # test_compiled_path.py bounds its paths, not by one machine's bits.
    assert np.abs(again.position - first.position).max() <= PATH_BOUND


def test_a_short_run_where_the_kernels_loop_is_not_compiled_compiles_the_generated_functions(
        tmp_path, monkeypatch):
    """On a machine where the kernels' loop was never compiled (a minute or more), a short run
    compiles the generated functions (seconds) and runs on them alone."""
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    monkeypatch.setattr(on_demand, "is_ready", lambda dispatcher, args: False)
    run = get_adapter("inhouse").simulate(scenario.load("fourbar"),
                                          "rk4+baumgarte:alpha=6,beta=6", 1e-3, 0.05,
                                          sample_times(1e-3, 0.05))
    assert run.status == "ok" and run.counters["kernel_calls"] == 0 < run.counters["rhs_evals"]
    assert list(tmp_path.glob(f"*/*/{generated_store.USED}"))


def _asked_loops(monkeypatch) -> list[str]:
    """The names of the compiled loops the stepper asks :func:`on_demand.entry` for, in order."""
    asked = []
    entry = on_demand.entry

    def recording(dispatcher, args, *announcement):
        asked.append(dispatcher.py_func.__name__)
        return entry(dispatcher, args, *announcement)

    monkeypatch.setattr(compiled_stepper.on_demand, "entry", recording)
    return asked


def test_a_run_the_generated_steps_serve_never_asks_for_the_kernels_loop(monkeypatch):
    """rk4+direct on the four-bar: every step on the generated functions, so the run asks for the
    generated steps' loop alone, and the kernels' loop, a minute or more of compiling on a new
    machine, is never made."""
    asked = _asked_loops(monkeypatch)
    run = get_adapter("inhouse").simulate(scenario.load("fourbar"), "rk4+direct:loop=generated",
                                          1e-3, 0.2, sample_times(1e-3, 0.2))
    assert run.status == "ok" and run.counters["kernel_calls"] == 0
    assert asked == ["run_generated_samples"]


def test_a_run_the_generated_steps_hand_over_is_the_full_loops_run_to_the_bit(monkeypatch):
    """The double four-bar with rk4+baumgarte: the generated steps hand the run over to the full
    loop at its first placed passage (~0.7 s), which then goes on to the end.  The states and
    counters are those of the full loop run from the start (which runs the same generated steps
    inside it), to the bit: the hand-over repeats no operation and skips none."""
    mech, adapter = scenario.load("double_fourbar"), get_adapter("inhouse")
    method, times = "rk4+baumgarte:loop=generated", sample_times(1e-2, 1.5)
    asked = _asked_loops(monkeypatch)
    handed = adapter.simulate(mech, method, 1e-2, 1.5, times)
    assert asked == ["run_generated_samples", "run_samples"]
    init = compiled_stepper.CompiledStepper.__init__

    def full_loop_only(self, *args, **kwargs):
        init(self, *args, **kwargs)
        if self._generated_entry is not None:
            self._generated_entry = None
            self._full_entry()

    monkeypatch.setattr(compiled_stepper.CompiledStepper, "__init__", full_loop_only)
    whole = adapter.simulate(mech, method, 1e-2, 1.5, times)
    assert handed.status == whole.status == "ok"
    assert handed.counters["passages"] > 0 and handed.counters == whole.counters
    np.testing.assert_array_equal(handed.position, whole.position)
    np.testing.assert_array_equal(handed.velocity, whole.velocity)


def test_a_function_whose_guards_decline_at_the_start_is_not_compiled(tmp_path, monkeypatch):
    """A four-bar drawn in space with four parallel revolutes (three redundant equations): ρ̂,
    traced off the constraints, takes the plain Cholesky factorisation there, whose pivot is
    zero on them, so the function would hand back every call (its right-hand side's trace passes
    MAX_OPERATIONS: flat bodies take the augmented mass form).  ρ̂'s source is checked at the
    start before anything is compiled, and the note says why the kernels serve it."""
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    run = get_adapter("inhouse").simulate(parallel_revolute_fourbar(),
                                          "rk4+baumgarte:loop=generated", 1e-3, 0.05,
                                          sample_times(1e-3, 0.05))
    assert run.status == "ok" and run.counters["passages"] == 0
    assert any(note.startswith("not generated: indicator (its guards decline at the start")
               for note in run.notes), run.notes
    compiled_sources = [path.read_text() for mark in tmp_path.glob(f"*/*/{generated_store.USED}")
                        for path in mark.parent.glob("*.py")]
    assert not [text for text in compiled_sources if "def indicator(" in text]


@settings(max_examples=5, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(mech=mechanisms())
def test_generated_functions_on_drawn_mechanisms_compute_what_the_kernels_compute(mech):
    """Mechanisms the generator was not written around (trees and ladders, planar and spatial,
    loads, any declaration order; harness/testing/strategies.py): the right-hand side and the velocity
    projection at the start and at a nearby state 1e-3 away in q and q̇, where their guards hold
    or the call is handed back (returns 0, never a different number)."""
    adapter = get_adapter("inhouse")
    spec, params = adapter.method_spec("rk4+direct:loop=compiled")
    try:
        stepper = adapter._start(mech, spec, params, RunGrid(1e-3, 1e-3, np.zeros(1), True))
    except AssemblyError:
        reject()
    formulation, (q0, v0) = stepper.formulation, stepper._start_state
    rng = np.random.default_rng(7)
    states = [(0.0, q0, v0), (0.01, q0 + 1e-3 * rng.standard_normal(q0.size),
                            v0 + 1e-3 * rng.standard_normal(v0.size))]
    for which in (generated.ACCELERATION, generated.VELOCITY_CORRECTION):
        try:
            function = generated.compiled_function(which, formulation, q0, v0)
        except generated.NotGenerated as error:
            event(f"not generated: {str(error)[:40]}")
            continue
        for t, q, v in states:
            expected = np.asarray(generated.kernel_outputs(which, formulation, q, v, t))
            out = np.empty(q.size + 1)
            if _call(function, q, v, t, out) == 0:
                event("a guard handed the call back")
                continue
            scale = max(np.abs(expected).max(), np.finfo(float).tiny)
            assert np.abs(out[:expected.size] - expected).max() <= RELATIVE_BOUND * scale


# --- Hand-backs are noted; starts of exact zeros and symmetry -----------------------------------

@cfunc(generated.SIGNATURE)
def _declines(q, v, t, out):
    """A generated right-hand side whose guard always fails."""
    return 0


def test_a_run_whose_guards_hand_calls_back_says_so_with_the_fraction(monkeypatch):
    """Every call handed back (a stand-in whose guard always fails): the kernels serve all 400
    right-hand sides of 100 rk4 steps and the run's notes give the count and the fraction."""
    def functions(formulation, q0, v0, wanted, compile_new=True):
        return (_declines, *generated.NOTHING[1:]), []

    monkeypatch.setattr(generated, "functions", functions)
    run = get_adapter("inhouse").simulate(scenario.load("fourbar"), "rk4+direct:loop=generated",
                                          1e-3, 0.1, sample_times(1e-3, 0.1))
    assert run.status == "ok" and run.counters["kernel_calls"] == run.counters["rhs_evals"] == 400
    assert "generated functions handed back 400 of 400 right-hand sides (100 %) to the kernels" \
        in " ".join(run.notes)


def test_a_run_handed_back_now_and_then_is_the_kernels_run_to_the_bit(monkeypatch):
    """The generated projection declines its first call in every third step (the step's time in
    the first third of a 3 ms period), after the step's new state was written: the flat generated
    loop hands those steps to the full path from the old state and takes the kernels' fresh
    state back.  The states, written into the loop's two slots in turn, must be those of the
    kernels alone (a loop writing over the state it stepped from fails this)."""
    made = {}

    def functions(formulation, q0, v0, wanted, compile_new=True):
        real, notes = original(formulation, q0, v0, wanted, compile_new)
        residual_size = real[generated.RESIDUAL_SIZE]

        @cfunc(generated.SIGNATURE)
        def sometimes(q, v, t, out):
            if (t * 1000.0) % 3.0 < 1.0:
                return 0
            return residual_size(q, v, t, out)

        made["sometimes"] = sometimes  # kept alive for the run
        functions = list(real)
        functions[generated.RESIDUAL_SIZE] = sometimes
        return tuple(functions), notes

    original = generated.functions
    mech = scenario.load("fourbar")
    times = sample_times(1e-3, 0.2)
    kernels = get_adapter("inhouse").simulate(mech, "rk4+direct:loop=compiled", 1e-3, 0.2, times)
    monkeypatch.setattr(generated, "functions", functions)
    mixed = get_adapter("inhouse").simulate(mech, "rk4+direct:loop=generated", 1e-3, 0.2, times)
    assert mixed.status == kernels.status == "ok"
    assert mixed.counters == kernels.counters | {"kernel_calls": mixed.counters["kernel_calls"]}
    np.testing.assert_array_equal(mixed.position, kernels.position)
    np.testing.assert_array_equal(mixed.velocity, kernels.velocity)


def test_the_hand_back_note_is_absent_when_every_call_was_served():
    assert hand_back_note(0, 8000) is None
    assert "handed back 75879 of 80000 right-hand sides (94.8 %)" in hand_back_note(75879, 80000)
    assert step_end_note(0, 1000) is None
    assert "the projection or ρ̂ of 72 of 1007 steps (7.15 %)" in step_end_note(72, 1007)


def test_a_run_whose_projection_is_handed_back_says_so_with_the_fraction(monkeypatch):
    """The generated velocity correction declines every call (a stand-in): each of the 100 steps
    ends on the kernels' projection, the right-hand sides stay generated, and the notes say so."""
    def functions(formulation, q0, v0, wanted, compile_new=True):
        real, notes = original(formulation, q0, v0, wanted, compile_new)
        made = list(real)
        made[generated.VELOCITY_CORRECTION] = _declines
        return tuple(made), notes

    original = generated.functions
    monkeypatch.setattr(generated, "functions", functions)
    run = get_adapter("inhouse").simulate(scenario.load("fourbar"), "rk4+direct:loop=generated",
                                          1e-3, 0.1, sample_times(1e-3, 0.1))
    assert run.status == "ok" and run.counters["kernel_calls"] == 0
    notes = " ".join(run.notes)
    assert "handed back the projection or ρ̂ of 100 of 100 steps (100 %) to the kernels" in notes
    assert "right-hand sides" not in notes


def test_a_run_through_a_singular_position_notes_the_projections_the_kernels_served():
    """The double four-bar's first singular passage (~0.7 s): near it the projection's
    certificate fails and the kernels' truncated SVD serves those steps.  Measured (2026-11-27,
    rk4+direct at 1e-2 s, 1 s): 7 of 101 steps; the note must give a count, neither none nor
    all."""
    mech = scenario.load("double_fourbar")
    run = get_adapter("inhouse").simulate(mech, "rk4+direct:loop=generated", 1e-2, 1.0,
                                          sample_times(1e-2, 1.0))
    assert run.status == "ok"
    [note] = [note for note in run.notes if "projection or ρ̂" in note]
    handed, total = (int(word) for word in note.split(" steps ")[0].split()[-3::2])
    assert 0 < handed < total


def _generated_and_kernel_runs(mech):
    """rk4+direct at dt 1e-3 s for 0.25 s on the generated loop and on the kernels alone."""
    adapter = get_adapter("inhouse")
    model = adapter.build(mech)
    return [adapter.simulate(model, f"rk4+direct:loop={loop}", 1e-3, 0.25,
                             sample_times(1e-3, 0.25, 0.05)) for loop in ("generated", "compiled")]


def _check_generated_serves(mech):
    """The generated loop's right-hand sides served (kernel_calls ≤ 1 % of rhs_evals) or a note
    saying why not; the same trajectory as the kernels' (PATH_BOUND)."""
    fast, kernels = _generated_and_kernel_runs(mech)
    assert fast.status == kernels.status and fast.steps == kernels.steps
    why = [note for note in fast.notes if note.startswith("not generated: acceleration")]
    assert why or fast.counters["kernel_calls"] <= fast.counters["rhs_evals"] // 100, fast.notes
    event("not generated" if why else "generated")
    assert np.abs(fast.position - kernels.position).max() <= PATH_BOUND
    assert np.abs(fast.velocity - kernels.velocity).max() <= PATH_BOUND


@settings(max_examples=3, derandomize=True, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(mech=aligned_mechanisms())
def test_generated_loops_serve_starts_of_exact_zeros_and_symmetry(mech):
    """A few chains of mbh._harness.testing.strategies.aligned_mechanisms (identity orientations, axes
    and springs along coordinate axes): measured, their guards hand back no call."""
    try:
        _check_generated_serves(mech)
    except AssemblyError:
        reject()


@pytest.mark.slow
@settings(max_examples=24, derandomize=True, deadline=None, database=None,
          suppress_health_check=list(HealthCheck))
@given(mech=st.one_of(aligned_mechanisms(), mechanisms()))
def test_generated_loops_serve_drawn_mechanisms(mech):
    """24 drawn mechanisms, planar and spatial, random poses and starts of exact zeros, springs
    (stiffness to 1e5 N/m), slender bars: served, or a note names why not."""
    try:
        _check_generated_serves(mech)
    except AssemblyError:
        reject()


def test_a_slender_spatial_body_is_traced_through_the_augmented_mass_form():
    """A spatial pendulum of two bars, one slender (no moment about its own y axis): the block
    solve refuses its mass block, the M̃ form (Cholesky, no LAPACK) serves, and its generated
    function returns the kernel's numbers at the start and along the run."""
    mech = _slender_pendulum()
    formulation, start = _formulation(mech)
    nc, masses, inertias = formulation.dynamics.kernel_args[:3]
    assert not mass_and_forces._inertia_certified(masses[1], inertias[1], dynamics.ACCELERATION_CUT)
    function = generated.compiled_function(generated.ACCELERATION, formulation, *start)
    rng = np.random.default_rng(3)
    for t in (0.0, 0.1, 0.2):
        q = start[0] + 1e-3 * rng.standard_normal(start[0].size)
        v = start[1] + rng.standard_normal(start[1].size)
        expected = np.asarray(generated.kernel_outputs(generated.ACCELERATION, formulation, q,
                                                       v, t))
        out = np.empty(q.size)
        assert _call(function, q, v, t, out) == 1
        assert np.abs(out - expected).max() <= RELATIVE_BOUND * np.abs(expected).max()


def _slender_pendulum():
    """Two 1 m bars along x in the identity orientation: a revolute about z at the origin, a
    spherical joint at (1, 0, 0); the second bar slender about y (no moment about y)."""
    bar = {"mass": 1.0, "euler313_deg": [0.0, 0.0, 0.0]}
    return scenario.from_document({
        "kind": "spatial", "duration": 1.0, "gravity": [0.0, 0.0, -9.81],
        "bodies": [{**bar, "name": "upper", "inertia": [0.01, 0.08, 0.08],
                    "position": [0.5, 0.0, 0.0]},
                   {**bar, "name": "lower", "inertia": [0.08, 0.0, 0.08],
                    "position": [1.5, 0.0, 0.0]}],
        "joints": [{"name": "pivot", "type": "revolute", "body1": "ground", "body2": "upper",
                    "location": [0.0, 0.0, 0.0], "axis": [0.0, 0.0, 1.0]},
                   {"name": "ball", "type": "spherical", "body1": "upper", "body2": "lower",
                    "location": [1.0, 0.0, 0.0]}],
        "initial": {"driver": "pivot", "value": 0.0, "rate": 1.0},
        "outputs": {"angle": {"kind": "joint_angle", "joint": "pivot"}}},
        "slender_pendulum", "tests/adapters/inhouse/test_generated.py")


def _formulation(mech):
    """The rk4+direct formulation of ``mech`` and its start (q0, q̇0)."""
    adapter = get_adapter("inhouse")
    spec, params = adapter.method_spec("rk4+direct:loop=compiled")
    stepper = adapter._start(mech, spec, params, RunGrid(1e-3, 1e-3, np.zeros(1), True))
    return stepper.formulation, stepper._start_state


def test_the_cholesky_form_of_the_augmented_mass_solve_matches_lu():
    """M̃ = LLᵀ with W = L⁻¹Φ_qᵀ against the LU solve of M̃ [Q, Φ_qᵀ] it replaced, on the slender
    pendulum at its start with a random velocity.  Measured difference (2026-11-27): 3.5e-15
    on accelerations up to 9.81; bound 1e-11 as for the block solve
    (tests/adapters/inhouse/test_compiled_path.py)."""
    formulation, (q, _) = _formulation(_slender_pendulum())
    constraints = formulation.constraints
    jacobian = constraints.jacobian(q, 0.0)
    r = np.random.default_rng(0).normal(size=q.size)
    v = r - np.linalg.pinv(jacobian) @ (jacobian @ r)
    mass, force = mass_and_forces.mass_and_forces_kernel(q, v, *formulation.dynamics.kernel_args)
    gamma = constraints.gamma(q, v, 0.0)
    no_pivots = np.empty(0, np.int64)
    cholesky = dynamics.augmented_mass_acceleration(mass, jacobian, force, gamma,
                                                    dynamics.ACCELERATION_CUT, no_pivots)
    rho = np.trace(mass) / np.sum(jacobian * jacobian)
    lu = dynamics._lu_mass_acceleration(mass + rho * jacobian.T @ jacobian, jacobian, force,
                                        gamma, dynamics.ACCELERATION_CUT, no_pivots)
    assert np.abs(cholesky - lu).max() <= 1e-11
