"""The straight-line compiler of generated functions (adapters/inhouse/codegen/straight_line.py):
a compiled call returns what the Python function returns, to the bit, for every construct the
tracer writes; anything else is refused with its line."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from numba import cfunc, njit

from mbh._adapters.inhouse.codegen.generated import SIGNATURE
from mbh._adapters.inhouse.codegen.straight_line import NotStraightLine, straight_line

#: Every construct of tracing.function_source: inputs and t, the four operators on values and
#: constants, unary minus, abs, np.sqrt/sin/cos, max over values and constants, the named
#: constants, guards of both polarities with a comparison each way, outputs.
EVERY_CONSTRUCT = '''
import numpy as np


def f(q, v, t, out):
    x0 = q[0]
    x1 = q[1]
    x2 = v[0]
    x3 = t
    x4 = x0 * x1
    x5 = x4 + -1.5
    x6 = 2.0 - x2
    x7 = x5 / x6
    x8 = -x7
    x9 = abs(x8)
    if not (x9 > 0.0):
        return 0
    x10 = np.sqrt(x9)
    x11 = np.sin(x3) * np.cos(x0)
    x12 = max(x10, x11, 0.25, x4)
    if (x2 >= 3.0):
        return 0
    x13 = x12 - np.inf
    out[0] = x12
    out[1] = x11 / x10
    out[2] = x13
    out[3] = np.nan
    out[4] = 0.0
    return 1
'''


def module_from(folder, name: str, source: str):
    path = folder / f"{name}.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@njit
def call(function, q, v, t, out):
    return function(q, v, t, out)


def test_a_compiled_call_returns_the_python_result_to_the_bit(tmp_path):
    module = module_from(tmp_path, "mbh_test_every_construct", EVERY_CONSTRUCT)
    emitted = straight_line(module.f)
    compiled = cfunc(SIGNATURE)(lambda q, v, t, out: emitted(q, v, t, out))
    rng = np.random.default_rng(7)
    accepted = declined = 0
    for trial in range(300):
        q, v = rng.standard_normal(2) * 10.0 ** rng.integers(-3, 3), rng.standard_normal(1) * 3
        if trial == 0:
            q[:] = [0.0, 0.0]  # x4 = 0: x9 = |-1.5 / (2 - v)| stays positive
        t = float(rng.standard_normal())
        expected, got = np.full(5, 7.0), np.full(5, 7.0)
        result = module.f(q, v, t, expected)
        assert call(compiled, q, v, t, got) == result
        if result:
            accepted += 1
            assert got.tobytes() == expected.tobytes()
        else:
            declined += 1
    assert accepted > 100 and declined > 10  # both exits taken (measured: 245 and 55)


@pytest.mark.parametrize("statement", ["x1 = x0 ** 2.0", "while x0 > 0.0: x0 = x0 - 1.0",
                                       "x1 = np.exp(x0)", "x1 = q[x0]"])
def test_a_statement_outside_the_form_is_refused_with_its_file_and_line(tmp_path, statement):
    source = textwrap.dedent(f'''
        import numpy as np


        def g(q, v, t, out):
            x0 = q[0]
            {statement}
            out[0] = x0
            return 1
        ''')
    module = module_from(tmp_path, f"mbh_test_refused_{abs(hash(statement))}", source)
    emitted = straight_line(module.g)
    with pytest.raises(Exception) as raised:
        cfunc(SIGNATURE)(lambda q, v, t, out: emitted(q, v, t, out))
    assert isinstance(raised.value, NotStraightLine) or "NotStraightLine" in str(raised.value)
    assert f"{module.__file__}, line 7: " in str(raised.value)  # the file and line of the source


#: A generated module as mbh._adapters.inhouse.codegen.generated writes it, long enough for LLVM
#: not to inline its operations into their caller: ``scale`` differs between modules, every name
#: is the same.
CACHED_MODULE = """
import numpy as np
from numba import cfunc

from mbh._adapters.inhouse.codegen.generated import SIGNATURE
from mbh._adapters.inhouse.codegen.straight_line import straight_line


def acceleration_operations(q, v, t, out):
    x0 = q[0]
{chain}
    out[0] = x0 * {scale}
    out[1] = x{length}
    return 1


acceleration_emitted = straight_line(acceleration_operations)


@cfunc(SIGNATURE, cache=True)
def acceleration(q, v, t, out):
    return acceleration_emitted(q, v, t, out)
"""
#: Statements of the chain in :data:`CACHED_MODULE`.
CHAIN = 2000


def test_two_cached_modules_of_the_same_names_keep_their_own_operations(tmp_path):
    """Each module compiled and cached by a process of its own, then both loaded into one: a
    compiled function whose symbol recurred in both caches would run one module's operations
    for the other's."""
    chain = "\n".join(f"    x{i + 1} = x{i} * 0.5 + v[0]" for i in range(CHAIN))
    names = {"mbh_test_cached_two": 2.0, "mbh_test_cached_three": 3.0}
    for name, scale in names.items():
        source = CACHED_MODULE.format(chain=chain, scale=scale, length=CHAIN)
        (tmp_path / f"{name}.py").write_text(source)
        subprocess.run([sys.executable, "-c", f"import {name}"], cwd=tmp_path, check=True,
                       env={**os.environ, "PYTHONPATH": str(tmp_path)})
    for name, scale in names.items():
        module = module_from(tmp_path, name, (tmp_path / f"{name}.py").read_text())
        assert module.acceleration._cache_hits, "compiled anew instead of loaded from its cache"
        out = np.zeros(2)
        assert call(module.acceleration, np.array([1.5]), np.zeros(1), 0.0, out) == 1
        assert out[0] == 1.5 * scale
