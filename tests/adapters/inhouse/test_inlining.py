"""Where the kernels' helpers are inlined (adapters/inhouse/numerics/inlining.py): into every
compiled caller except a kernel that Python calls by itself, compiled alone."""

from __future__ import annotations

from types import SimpleNamespace

from mbh._adapters.inhouse.bodies import bodykin, kernels
from mbh._adapters.inhouse.numerics.inlining import called_from_python, into_compiled_callers


def ir_of(function):
    """The part of numba's function IR the cost model reads."""
    return SimpleNamespace(func_id=SimpleNamespace(func=function))


def test_helpers_are_inlined_except_into_a_kernel_python_calls_alone():
    def loop():
        pass

    def entry():
        pass

    called_from_python(SimpleNamespace(py_func=entry))
    assert into_compiled_callers(None, ir_of(loop), None)
    assert not into_compiled_callers(None, ir_of(entry), None)


def test_the_start_kernels_are_marked_and_their_helpers_use_the_cost_model():
    """Φ, Φ_q and γ are what Python calls at a run's start (assembly, rank, ρ̂); compiled alone
    they took 2.4, 5.4 and 10.4 s with every helper inlined (measured 2026-11-29)."""
    for kernel in (kernels.phi, kernels.jacobian, kernels.gamma):
        assert not into_compiled_callers(None, ir_of(kernel.py_func), None), kernel
        assert kernel.targetoptions["inline"] is into_compiled_callers  # inlined into loops
    helpers = [value for module in (bodykin, kernels) for value in vars(module).values()
               if hasattr(value, "targetoptions") and "inline" in value.targetoptions]
    assert len(helpers) >= 19
    assert all(helper.targetoptions["inline"] is into_compiled_callers for helper in helpers)
