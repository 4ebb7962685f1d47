"""mbh._harness.common.kernel_opt_level: the kernels compile at LLVM level 2, a user's functions
at the level they would have had, and level 2 gives a kernel the same bits as level 3."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numba.core import config, event

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem
from mbh._harness.common import kernel_opt_level
from mbh._harness.model import scenario


class _SeenLevels(event.Listener):
    """numba's level at the start of each compilation (after :class:`KernelLevel`, registered
    first when the kernel packages were imported), by the compiled function's name."""

    def __init__(self):
        self.levels = {}

    def on_start(self, event_):
        self.levels[event_.data["dispatcher"].py_func.__name__] = int(config.OPT)

    def on_end(self, event_):
        pass


def _function_of(module: str, body):
    """``body`` as a function defined in ``module`` (numba reads ``__module__``)."""
    body.__module__ = module
    return body


@pytest.fixture
def seen():
    listener = _SeenLevels()
    with event.install_listener("numba:compile", listener):
        yield listener.levels


def test_a_kernel_compiles_at_level_2_and_a_users_function_at_its_own(seen, monkeypatch):
    monkeypatch.setattr(config, "OPT", config._OptLevel(3))

    def kernel_leaf(x):
        return x * 2.0

    kernel_leaf = njit(_function_of("mbh._adapters.inhouse.probe", kernel_leaf))

    def users(x):
        return kernel_leaf(x) + 1.0

    users = njit(_function_of("users_own_module", users))
    assert users(1.5) == 4.0
    assert seen == {"users": 3, "kernel_leaf": kernel_opt_level.LEVEL}
    assert int(config.OPT) == 3, "the user's level is back after the kernel's compilation"


def test_a_failed_kernel_compilation_puts_the_level_back(seen, monkeypatch):
    monkeypatch.setattr(config, "OPT", config._OptLevel(3))

    def broken(x):
        return x.no_such_attribute

    broken = njit(_function_of("mbh._harness.neutral.probe", broken))
    with pytest.raises(Exception, match="no_such_attribute"):
        broken(1.0)
    assert seen == {"broken": kernel_opt_level.LEVEL}
    assert int(config.OPT) == 3


def test_at_kernel_level_sets_the_level_inside_the_block_only(monkeypatch):
    monkeypatch.setattr(config, "OPT", config._OptLevel(3))
    with kernel_opt_level.at_kernel_level():
        assert int(config.OPT) == kernel_opt_level.LEVEL
    assert int(config.OPT) == 3


@pytest.mark.parametrize("level", [3, 0])
def test_a_kernel_compiled_at_another_level_gives_the_same_bits(level, monkeypatch):
    """Φ_q and γ of the spatial four-bar at 20 random states (Euler parameters, ball joints):
    compiled afresh at LEVEL and at ``level`` (no cache), the same bits, because numba compiles
    without fast-math and no LLVM level may then reorder a floating-point operation."""
    mech = scenario.load("fourbar_spatial")
    args = ConstraintSystem(mech).kernel_args
    rng = np.random.default_rng(7)
    states = [(rng.normal(size=7 * len(mech.bodies)), rng.normal(size=7 * len(mech.bodies)))
              for _ in range(20)]

    def compiled_at(opt):
        monkeypatch.setattr(kernel_opt_level, "LEVEL", opt)
        jacobian, gamma = (njit(kernel.py_func) for kernel in (kernels.jacobian, kernels.gamma))
        return ([jacobian(q, 0.1, args) for q, _ in states]
                + [gamma(q, v, 0.1, args) for q, v in states])

    ours, theirs = compiled_at(2), compiled_at(level)
    for mine, other in zip(ours, theirs):
        assert np.array_equal(mine, other)
