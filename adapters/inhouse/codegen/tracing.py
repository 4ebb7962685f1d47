"""Straight-line code from the compiled kernels: run a kernel's Python source once on symbols,
record every floating-point operation it makes, and write them out as one branch-free function.

The generic kernels (:mod:`~mbh._adapters.inhouse.bodies.kernels`,
:mod:`~mbh._adapters.inhouse.formulations.mass_and_forces`, :mod:`~mbh._adapters.inhouse.formulations.dynamics`,
:mod:`~mbh._adapters.inhouse.numerics.linalg`) loop over tables of primitives, bodies and matrix entries; most
of their time goes to that bookkeeping (indices, branches on the kind of a row, zero fills,
products with zeros).  Run on symbols instead of numbers (:class:`Symbol`), with the tables as
plain constants, the same Python source leaves only the arithmetic of one mechanism: a graph of
operations on the inputs q, q̇ and t, with products by constant zeros and ones folded away and
repeated subexpressions computed once.  A :class:`Graph` records it while the kernels run on its
symbols within :func:`tracing`; :func:`function_source` writes it out as Python source for numba.

*Same numbers.*  Every recorded operation is the one the kernel makes, on the same operands in
the same order, so the generated function returns the kernel's result to the bit wherever the
kernel's own arithmetic is finite, up to the sign of a zero.  Only exact identities are folded
(x·0 = 0, x·1 = x, x ± 0 = x, 0 − x = −x, x/1 = x, operations on two constants, and 0/x = ±0
under a guard that x keeps its traced sign); they can turn a −0 into +0 or back, which no later
sum or product sees, and a NaN or an infinity reaching a folded product would differ, which the
caller's divergence check catches anyway.  The 0/x rule keeps the structural zeros of a sparse
matrix constant through its factorisation: a Cholesky factor's entry below a zero of the matrix
is 0/l_jj, and without the rule every later product with it was recorded (on Andrews' squeezer
the range-space solve took 2,878 operations of the acceleration's 3,687; with it 1,030).

*Guards.*  A kernel's branches on data (a Cholesky pivot that must be positive, a certificate
bound) are taken during the trace as the traced values take them, at a generic state chosen by
the caller.  (The skips of exact zeros, :func:`~mbh._adapters.inhouse.numerics.linalg.skippable`, decide
nothing and are not guarded: a traced entry is never skipped.)  A foreign function (LAPACK)
cannot be traced and stops the trace (:class:`Untraceable`).  Each such comparison becomes a guard: the generated function
re-tests it and returns 0 (not written) when it comes out the other way, so the caller falls back
to the kernel itself.  A generated function therefore never returns a result the kernel would
not, only sometimes none.

This is partial evaluation (Y. Futamura, "Partial evaluation of computation process — an
approach to a compiler-compiler", 1971) of the kernels with respect to their constant tables,
done by tracing, as JAX traces numpy-like code into a graph (``jax.make_jaxpr``).
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import operator
import types

import numpy as np
from numba.core import types as numba_types
from numba.core.registry import CPUDispatcher

#: Operators a symbol records: name → (Python function, source template).
_BINARY = {"add": (operator.add, "{} + {}"), "sub": (operator.sub, "{} - {}"),
           "mul": (operator.mul, "{} * {}"), "div": (operator.truediv, "{} / {}")}
_UNARY = {"neg": (operator.neg, "-{}"), "abs": (abs, "abs({})"),
          "sqrt": (math.sqrt, "np.sqrt({})"), "sin": (math.sin, "np.sin({})"),
          "cos": (math.cos, "np.cos({})")}
_COMPARE = {"gt": (operator.gt, ">"), "ge": (operator.ge, ">="), "lt": (operator.lt, "<"),
            "le": (operator.le, "<="), "eq": (operator.eq, "=="), "ne": (operator.ne, "!=")}


class LimitReached(RuntimeError):
    """A trace passed its graph's ``limit`` of operations."""


class Graph:
    """The operations recorded by one trace (kernels run on its symbols within
    :func:`tracing`): nodes in the order they were made (each node's operands are earlier nodes
    or constants) and the guards on them.

    Attributes
    ----------
    limit : int or None
        Most nodes the graph takes; one more raises :class:`LimitReached`.
    nodes : list of tuple
        ``(op, operands)``: ``("input", (name, index))`` or an operator of ``_BINARY`` /
        ``_UNARY`` / ``"max"`` with operands that are node indices (int) or constants (float).
    guards : list of tuple
        ``(node, compare, other, outcome)``: the comparison ``node compare other`` (``other`` a
        node index or a float) came out ``outcome`` during the trace.
    """

    def __init__(self, limit: int | None = None):
        self.limit = limit
        self.nodes: list[tuple] = []
        self.values: list[float] = []
        self.guards: list[tuple] = []
        self._known: dict[tuple, int] = {}
        self._guarded: set[tuple] = set()

    def node(self, op: str, operands: tuple, value: float) -> "Symbol":
        if op != "input":  # node references are ints, constants floats
            operands = tuple(x if isinstance(x, Symbol) else float(x) for x in operands)
        key = (op, operands if op == "input" else tuple(_operand_key(x) for x in operands))
        index = self._known.get(key)
        if index is None:
            index = len(self.nodes)
            if self.limit is not None and index >= self.limit:
                raise LimitReached(f"more than {self.limit} operations")
            self.nodes.append((op, tuple(x.index if isinstance(x, Symbol) else x
                                         for x in operands)))
            self.values.append(value)
            self._known[key] = index
        return Symbol(self, index)

    def guard(self, node: int, compare: str, other, outcome: bool) -> None:
        """Record the guard ``node compare other`` came out ``outcome`` (once: a repeated one
        would only be tested again)."""
        key = (node, compare, _operand_key(other) if not isinstance(other, int) else other,
               outcome)
        if key not in self._guarded:
            self._guarded.add(key)
            self.guards.append((node, compare, other, outcome))

    def inputs(self, name: str, values) -> np.ndarray:
        """Symbols for the entries of the input array ``name`` (an object array), valued
        ``values`` during the trace."""
        return np.array([self.node("input", (name, i), float(x)) for i, x in enumerate(values)]
                        + [None], dtype=object)[:-1]

    def scalar(self, name: str, value: float) -> "Symbol":
        """A symbol for the scalar input ``name``, valued ``value`` during the trace."""
        return self.node("input", (name, None), float(value))


def _operand_key(x):
    if isinstance(x, Symbol):
        return ("n", x.index)
    return ("c", float(x).hex())  # keeps −0.0 apart from 0.0


def _value(x) -> float:
    return x.value if isinstance(x, Symbol) else x


def _binary(op: str, a, b):
    """a op b, folded when exact (see the module notes), else a recorded node."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return NotImplemented  # numpy then applies the operation entry by entry
    a_symbol, b_symbol = isinstance(a, Symbol), isinstance(b, Symbol)
    function = _BINARY[op][0]
    if not a_symbol and not b_symbol:
        return function(a, b)
    if op == "mul":
        if (not a_symbol and a == 0.0) or (not b_symbol and b == 0.0):
            return 0.0
        if not a_symbol and a == 1.0:
            return b
        if not b_symbol and b == 1.0:
            return a
    elif op == "add":
        if not a_symbol and a == 0.0:
            return b
        if not b_symbol and b == 0.0:
            return a
    elif op == "sub":
        if not b_symbol and b == 0.0:
            return a
        if not a_symbol and a == 0.0:
            return _unary("neg", b)
    elif op == "div":
        if not b_symbol and b == 1.0:
            return a
        if not a_symbol and a == 0.0 and _value(b) != 0.0 and not math.isnan(_value(b)):
            # 0 / x: the kernel's ±0 wherever x keeps its traced sign (a guard), so an entry
            # below a structural zero of a factorised matrix stays a constant (module notes)
            positive = _value(b) > 0.0
            b.graph.guard(b.index, "gt" if positive else "lt", 0.0, True)
            return a if positive else -a
    graph = a.graph if a_symbol else b.graph
    return graph.node(op, (a, b), function(_value(a), _value(b)))


def _unary(op: str, a):
    function = _UNARY[op][0]
    if not isinstance(a, Symbol):
        return function(a)
    return a.graph.node(op, (a,), function(a.value))


def _compare(op: str, a, b) -> bool:
    """The traced outcome of a op b, recorded as a guard when either side is a symbol."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return NotImplemented
    outcome = _COMPARE[op][0](_value(a), _value(b))
    if isinstance(a, Symbol):
        a.graph.guard(a.index, op, b.index if isinstance(b, Symbol) else float(b), outcome)
    elif isinstance(b, Symbol):
        mirrored = {"gt": "lt", "ge": "le", "lt": "gt", "le": "ge", "eq": "eq", "ne": "ne"}[op]
        b.graph.guard(b.index, mirrored, float(a), outcome)
    return outcome


class Symbol:
    """A traced float: a node of a :class:`Graph` and its value at the traced state."""

    __slots__ = ("graph", "index")
    __array_priority__ = 1000

    def __init__(self, graph: Graph, index: int):
        self.graph, self.index = graph, index

    @property
    def value(self) -> float:
        return self.graph.values[self.index]

    def __add__(self, other): return _binary("add", self, other)
    def __radd__(self, other): return _binary("add", other, self)
    def __sub__(self, other): return _binary("sub", self, other)
    def __rsub__(self, other): return _binary("sub", other, self)
    def __mul__(self, other): return _binary("mul", self, other)
    def __rmul__(self, other): return _binary("mul", other, self)
    def __truediv__(self, other): return _binary("div", self, other)
    def __rtruediv__(self, other): return _binary("div", other, self)
    def __neg__(self): return _unary("neg", self)
    def __pos__(self): return self
    def __abs__(self): return _unary("abs", self)
    def __gt__(self, other): return _compare("gt", self, other)
    def __ge__(self, other): return _compare("ge", self, other)
    def __lt__(self, other): return _compare("lt", self, other)
    def __le__(self, other): return _compare("le", self, other)
    def __eq__(self, other): return _compare("eq", self, other)
    def __ne__(self, other): return _compare("ne", self, other)
    __hash__ = object.__hash__

    def __float__(self):
        raise TypeError("a traced value has no number until the generated function runs")

    def __repr__(self):
        return f"Symbol(#{self.index} = {self.value!r})"


def maximum(values):
    """max of a sequence of floats and symbols as one recorded node (no guard: which entry is
    largest may change from call to call)."""
    items = list(np.asarray(values, dtype=object).ravel())
    symbols = [x for x in items if isinstance(x, Symbol)]
    if not symbols:
        return max(items)
    return symbols[0].graph.node("max", tuple(items), max(_value(x) for x in items))


def _elementwise(name):
    def apply(x):
        if isinstance(x, np.ndarray):
            return np.array([apply(item) for item in x.ravel()] + [None],
                            dtype=object)[:-1].reshape(x.shape)
        return _unary(name, x)
    return apply


def _object_array(fill):
    def make(shape, dtype=float):
        if dtype is not float and np.dtype(dtype).kind != "f":
            return np.zeros(shape, dtype=dtype)
        return np.full(shape, fill, dtype=object)
    return make


class _TracingNumpy(types.SimpleNamespace):
    """The ``np`` a traced module sees: float arrays become object arrays of floats and symbols,
    the elementary functions record nodes; everything else is numpy's."""

    def __getattr__(self, name):
        return getattr(np, name)


_TRACING_NUMPY = _TracingNumpy(
    zeros=_object_array(0.0), empty=_object_array(0.0), sqrt=_elementwise("sqrt"),
    sin=_elementwise("sin"), cos=_elementwise("cos"), max=maximum)


def _skippable(x) -> bool:
    """:func:`~mbh._adapters.inhouse.numerics.linalg.skippable` while tracing: only a constant zero is left
    out, a symbol is kept whatever its traced value (no guard: the kernel's skip of an exact zero
    changes no number, and a guard on it would fail whenever an entry's zeros differ from the
    traced state's)."""
    return not isinstance(x, Symbol) and x == 0.0


def _larger(a, b):
    """:func:`~mbh._adapters.inhouse.numerics.linalg.larger` while tracing: one max node, no
    guard (:func:`maximum`)."""
    return maximum([a, b])


#: Foreign functions a kernel may call: ctypes pointers and numba's declarations of them
#: (``types.ExternalFunction``, as :mod:`mbh._adapters.inhouse.numerics.banded` declares LAPACK's dpbtrf).
_FOREIGN = (ctypes._CFuncPtr, numba_types.ExternalFunction)


class Untraceable(RuntimeError):
    """The kernel called a foreign function (LAPACK through ctypes): its arithmetic cannot be
    recorded."""


def _untraceable(name: str):
    def refuse(*args):
        raise Untraceable(f"{name} is a foreign function: its arithmetic cannot be traced")
    return refuse


#: Compiled functions that tracing replaces by a version of its own rather than their source.
_TRACED_VERSIONS = {"skippable": _skippable, "larger": _larger}


@contextlib.contextmanager
def tracing(modules):
    """Within the block, ``modules`` compute on symbols: their ``np`` is the tracing one, every
    compiled function they call is its Python source (``py_func``) or its version in
    ``_TRACED_VERSIONS``, and a foreign function (``_FOREIGN``) raises :class:`Untraceable`."""
    saved = []
    try:
        for module in modules:
            for name, value in vars(module).items():
                if isinstance(value, CPUDispatcher):
                    saved.append((module, name, value))
                    setattr(module, name, _TRACED_VERSIONS.get(name, value.py_func))
                elif isinstance(value, _FOREIGN):  # LAPACK by pointer: never on symbols
                    saved.append((module, name, value))
                    setattr(module, name, _untraceable(name))
            saved.append((module, "np", module.np))
            module.np = _TRACING_NUMPY
        yield
    finally:
        for module, name, value in reversed(saved):
            setattr(module, name, value)


def function_source(graph: Graph, name: str, inputs: tuple[str, ...],
                    outputs: list) -> str:
    """Python source of ``def name(*inputs, out)``: the nodes the ``outputs`` (floats and symbols
    of ``graph``) and the guards need, each guard tested as soon as its operands exist; returns
    1 after writing ``out[i] = outputs[i]``, or 0 at the first guard that fails."""
    needed = set()
    pending = [x.index for x in outputs if isinstance(x, Symbol)]
    pending += [g[0] for g in graph.guards] + [g[2] for g in graph.guards
                                                if isinstance(g[2], int)]
    while pending:
        index = pending.pop()
        if index in needed:
            continue
        needed.add(index)
        op, operands = graph.nodes[index]
        if op != "input":
            pending.extend(x for x in operands if isinstance(x, int))
    guards_at: dict[int, list] = {}
    for node, compare, other, outcome in graph.guards:
        ready = max(node, other) if isinstance(other, int) else node
        guards_at.setdefault(ready, []).append((node, compare, other, outcome))
    lines = [f"def {name}({', '.join(inputs)}, out):"]
    for index in sorted(needed):
        op, operands = graph.nodes[index]
        lines.append(f"    x{index} = {_expression(op, operands)}")
        for node, compare, other, outcome in guards_at.get(index, ()):
            test = f"x{node} {_COMPARE[compare][1]} {_operand(other)}"
            lines.append(f"    if {'not ' if outcome else ''}({test}):\n        return 0")
    for i, x in enumerate(outputs):
        lines.append(f"    out[{i}] = {_operand(x.index if isinstance(x, Symbol) else float(x))}")
    lines.append("    return 1")
    return "\n".join(lines) + "\n"


def _operand(x) -> str:
    if isinstance(x, int):
        return f"x{x}"
    if math.isfinite(x):
        return repr(float(x))
    return "np.nan" if math.isnan(x) else ("np.inf" if x > 0 else "-np.inf")


def _expression(op: str, operands: tuple) -> str:
    if op == "input":
        return operands[0] if operands[1] is None else f"{operands[0]}[{operands[1]}]"
    if op == "max":
        return f"max({', '.join(_operand(x) for x in operands)})"
    template = (_BINARY.get(op) or _UNARY[op])[1]
    return template.format(*(_operand(x) for x in operands))
