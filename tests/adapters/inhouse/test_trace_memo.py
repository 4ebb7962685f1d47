"""The remembered traces of the generated functions (adapters/inhouse/codegen/generated.py,
``trace_key``; generated_store.py, ``remember``): a trace is made once per set of inputs, a later
call with the same inputs loads the remembered entry (or raises the remembered reason) without
tracing, a damaged entry is traced again, and the key changes with every input of the trace."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pytest
from numba import njit

from mbh._adapters import get_adapter
from mbh._adapters.base import RunGrid
from mbh._adapters.inhouse.codegen import generated, generated_store
from mbh._harness.model import scenario
from mbh._harness.model.timegrid import sample_times


@pytest.fixture
def store(tmp_path, monkeypatch):
    """An empty store of generated functions, none loaded in this process."""
    monkeypatch.setenv("MBH_GENERATED_DIR", str(tmp_path))
    forget_loaded_modules(monkeypatch)
    return tmp_path


def start(name: str = "fourbar", method: str = "rk4+direct"):
    """(formulation, q0, v0) of ``method`` on scene ``name``, nothing generated."""
    mech, adapter = scenario.load(name), get_adapter("inhouse")
    spec, params = adapter.method_spec(f"{method}:loop=compiled")
    stepper = adapter._start(mech, spec, params, RunGrid(1e-3, 0.01, sample_times(1e-3, 0.01, 0.01),
                                                         True))
    return (stepper.formulation, *stepper._start_state)


def forget_loaded_modules(monkeypatch) -> None:
    """As in a new process: no generated module loaded."""
    for name in [name for name in sys.modules if name.startswith("mbh_")]:
        monkeypatch.delitem(sys.modules, name)


def no_tracing(monkeypatch) -> list:
    """Record every trace instead of making it (a call that needs one then fails)."""
    calls = []

    def refuse(*args):
        calls.append(args)
        raise AssertionError("traced again")

    monkeypatch.setattr(generated, "function_source", refuse)
    return calls


@njit
def _call(function, q, v, t, out):
    return function(q, v, t, out)


def residual_size(function, q: np.ndarray, v: np.ndarray) -> float:
    out = np.zeros(1)
    assert _call(function, q, v, 0.0, out) == 1
    return float(out[0])


def test_a_trace_is_remembered_and_its_entry_loaded_without_tracing(store, monkeypatch):
    formulation, q0, v0 = start()
    first = generated.compiled_function(generated.RESIDUAL_SIZE, formulation, q0, v0)
    key = generated.trace_key(generated.RESIDUAL_SIZE, formulation, q0, v0)
    name = generated_store.remembered(key)["module"]
    assert generated_store.is_compiled(name)

    forget_loaded_modules(monkeypatch)
    calls = no_tracing(monkeypatch)
    again = generated.compiled_function(generated.RESIDUAL_SIZE, formulation, q0, v0)
    assert not calls and name in sys.modules
    q = q0 + 1e-3
    assert residual_size(again, q, v0) == residual_size(first, q, v0)  # the same function


def test_a_remembered_reason_for_no_function_is_raised_again_without_tracing(store, monkeypatch):
    formulation, q0, v0 = start()
    monkeypatch.setattr(generated, "MAX_OPERATIONS", 10)
    with pytest.raises(generated.NotGenerated, match="more than 10 operations") as first:
        generated.compiled_function(generated.ACCELERATION, formulation, q0, v0)
    calls = no_tracing(monkeypatch)
    with pytest.raises(generated.NotGenerated) as again:
        generated.compiled_function(generated.ACCELERATION, formulation, q0, v0)
    assert str(again.value) == str(first.value) and not calls


def test_an_entry_whose_source_no_longer_matches_its_name_is_traced_again(store, monkeypatch):
    formulation, q0, v0 = start()
    first = generated.compiled_function(generated.RESIDUAL_SIZE, formulation, q0, v0)
    key = generated.trace_key(generated.RESIDUAL_SIZE, formulation, q0, v0)
    name = generated_store.remembered(key)["module"]
    source = generated_store.entry_folder(name) / f"{name}.py"
    source.write_text(source.read_text()[:200])  # cut short
    forget_loaded_modules(monkeypatch)
    again = generated.compiled_function(generated.RESIDUAL_SIZE, formulation, q0, v0)
    assert generated.module_name(source.read_text()) == name  # written again whole
    q = q0 + 1e-3
    assert residual_size(again, q, v0) == residual_size(first, q, v0)


def test_a_garbled_memo_is_ignored(store):
    formulation, q0, v0 = start()
    key = generated.trace_key(generated.RESIDUAL_SIZE, formulation, q0, v0)
    generated_store.remember(key, {"module": "x"})
    (next(store.glob(f"*/{key}.trace"))).write_text("{not json")
    assert generated_store.remembered(key) is None
    function = generated.compiled_function(generated.RESIDUAL_SIZE, formulation, q0, v0)
    assert residual_size(function, q0, v0) >= 0.0
    assert generated_store.remembered(key)["module"].startswith("mbh_")


def test_a_failure_of_the_trace_other_than_its_limits_is_not_remembered(store, monkeypatch):
    """An unforeseen error in a trace (here one made up) may not recur: the next call traces again."""
    formulation, q0, v0 = start()

    def failing(*args):
        raise FloatingPointError("made up")

    monkeypatch.setattr(generated, "kernel_outputs", failing)
    with pytest.raises(generated.NotGenerated, match="FloatingPointError: made up"):
        generated.compiled_function(generated.RESIDUAL_SIZE, formulation, q0, v0)
    assert generated_store.remembered(
        generated.trace_key(generated.RESIDUAL_SIZE, formulation, q0, v0)) is None


def _copy(formulation, **changes) -> SimpleNamespace:
    """The inputs of a trace of ``formulation`` as a plain object, with ``changes``."""
    fields = dict(rows=formulation.rows, gains=formulation.gains, cut=formulation.cut,
                  constraint_args=formulation.constraints.kernel_args,
                  sparsity=formulation.constraints.sparsity.arrays,
                  dynamics_args=formulation.dynamics.kernel_args) | changes
    return SimpleNamespace(
        rows=fields["rows"], gains=fields["gains"], cut=fields["cut"],
        constraints=SimpleNamespace(kernel_args=fields["constraint_args"],
                                    sparsity=SimpleNamespace(arrays=fields["sparsity"])),
        dynamics=SimpleNamespace(kernel_args=fields["dynamics_args"]))


def _changed_array_in(arguments: tuple) -> tuple:
    """``arguments`` with the first non-empty float array's first entry moved by one ulp."""
    items = list(arguments)
    for index, item in enumerate(items):
        if isinstance(item, np.ndarray) and item.dtype.kind == "f" and item.size:
            moved = item.copy()
            moved.flat[0] = np.nextafter(moved.flat[0], np.inf)
            items[index] = moved
            return tuple(items)
        if isinstance(item, tuple):
            changed = _changed_array_in(item)
            if changed != item:
                items[index] = changed
                return tuple(items)
    return arguments


def test_the_key_changes_with_every_input_of_the_trace():
    formulation, q0, v0 = start("slider_crank", "rk4+direct")
    which = generated.ACCELERATION
    key = generated.trace_key(which, formulation, q0, v0)
    assert key == generated.trace_key(which, _copy(formulation), q0.copy(), v0.copy())
    moved = np.nextafter(q0[0], np.inf)
    variants = {
        "which": (generated.RESIDUAL_SIZE, _copy(formulation), q0, v0),
        "rows": (which, _copy(formulation, rows=formulation.rows[:-1]), q0, v0),
        "gains": (which, _copy(formulation, gains=tuple(g + 1.0 for g in formulation.gains)),
                  q0, v0),
        "cut": (which, _copy(formulation, cut=formulation.cut * 2 + 1e-9), q0, v0),
        "constraint tables": (which, _copy(formulation, constraint_args=_changed_array_in(
            formulation.constraints.kernel_args)), q0, v0),
        "dynamics tables": (which, _copy(formulation, dynamics_args=_changed_array_in(
            formulation.dynamics.kernel_args)), q0, v0),
        "q0": (which, _copy(formulation), np.concatenate([[moved], q0[1:]]), v0),
        "v0": (which, _copy(formulation), q0, v0 + 1.0),
    }
    for what, arguments in variants.items():
        assert generated.trace_key(*arguments) != key, what
    assert _changed_array_in(formulation.constraints.kernel_args) is not \
        formulation.constraints.kernel_args


def test_an_input_it_cannot_digest_gives_no_key():
    formulation, q0, v0 = start()
    # an object has no faithful digest (harness/common/digest.py; a mapping has one)
    assert generated.trace_key(generated.ACCELERATION,
                               _copy(formulation, gains=object()), q0, v0) is None
