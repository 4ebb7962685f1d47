"""Compile a generated function's straight-line source without numba's per-statement typing.

A generated function (:mod:`~mbh._adapters.inhouse.codegen.generated`) is thousands of lines of
one form, written by :func:`~mbh._adapters.inhouse.codegen.tracing.function_source`::

    x12 = x3 * x7                      # + - * /, unary -, abs, np.sqrt, np.sin, np.cos, max
    x13 = q[4]                         # an entry of an input array, or the scalar t
    if not (x12 > 0.0):                # a guard: the call is declined
        return 0
    out[0] = x12
    return 1

numba compiled it like any function, typing and lowering each statement through its generic
machinery: ~1.3 ms a line (a spatial mechanism's 7,354-line acceleration took 9.2 s; a profile put
a third of the time in type inference and another third in lowering).  Every value here is a
float64, so none of that inference is needed.  :func:`straight_line` gives an intrinsic that
emits the function's operations directly, each through the lowering numba itself registers for
that operation on float64 (``context.get_function``; numba's own ``do_minmax`` for ``max``), so
the instructions are those numba would have emitted for the same source; numba's cfunc that
calls the intrinsic (same signature, same cache) is optimised by LLVM as before.  Python calls
the function itself.  The numbers are the same to the bit
(``tests/adapters/inhouse/test_straight_line.py``; the generated functions' tests compare them
with the kernels they were traced from).
"""

from __future__ import annotations

import ast
import inspect
import operator
import textwrap

import numpy as np
from numba.core import cgutils, types
from numba.core.typing import signature
from numba.cpython.builtins import do_minmax
from numba.extending import intrinsic

_F8 = types.float64
#: Python operators and calls of the generated source → what numba lowers them as.
_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv}
_COMPARE = {ast.Gt: operator.gt, ast.GtE: operator.ge, ast.Lt: operator.lt, ast.LtE: operator.le,
            ast.Eq: operator.eq, ast.NotEq: operator.ne}
_CALLS = {"abs": abs, "np.sqrt": np.sqrt, "np.sin": np.sin, "np.cos": np.cos}
#: Constants the source names rather than writes.
_NAMED_CONSTANTS = {"np.nan": np.nan, "np.inf": np.inf}


class NotStraightLine(ValueError):
    """The function has a statement or an expression outside the form above."""


def straight_line(function):
    """A numba intrinsic that compiles to the operations of ``function`` (a generated function
    of the form above, defined in a file; 1-D float64 arrays q, v, out and a float64 t, returning
    0 or 1): a compiled function calls it where it would call ``function``; Python calls
    ``function``.  Its source is read and parsed only when a caller is compiled.

    The operations are emitted once, into the caller.  Compiled as an ``inline="always"``
    overload of ``function`` instead, numba emitted them four times for one cfunc (three
    compilations of the overload's implementation, two of them while typing the call, and once
    inlined in the caller): a 19,192-line acceleration compiled in 4.05 s instead of 2.38 s, its
    calls the same to the bit and as fast (3.53 and 3.48 µs, side by side).  An overload not
    inlined compiles once too, but its implementation is a function of its own whose symbol
    (this module's closure and a counter) recurs in the cached code of other generated modules:
    a process that loads two of them runs one's operations for the other's."""

    def operations(typingctx, q, v, t, out):
        def codegen(context, builder, sig, args):
            try:
                return _Emitter(context, builder, sig, args).run(_statements(function))
            except NotStraightLine as error:  # name the file: the line alone says little
                raise NotStraightLine(f"{function.__code__.co_filename}, {error}") from None
        return types.int64(q, v, t, out), codegen

    operations.__name__ = f"{function.__name__}_emitted"
    return intrinsic(operations)


def _statements(function) -> list[ast.stmt]:
    """The statements of ``function``'s body, numbered by the lines of its file."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
    ast.increment_lineno(tree, function.__code__.co_firstlineno - 1)  # the file's line numbers
    definition = tree.body[0]
    if not isinstance(definition, ast.FunctionDef):
        raise NotStraightLine(f"{function.__qualname__} is not a plain function")
    return definition.body


class _Emitter:
    """Emits one generated function's statements into the intrinsic's caller."""

    def __init__(self, context, builder, sig, args):
        self.context, self.builder = context, builder
        names = ("q", "v", "t", "out")
        self.arrays = {name: (ty, context.make_array(ty)(context, builder, value))
                       for name, ty, value in zip(names, sig.args, args)
                       if isinstance(ty, types.Array)}
        self.values = {name: value for name, ty, value in zip(names, sig.args, args)
                       if not isinstance(ty, types.Array)}
        self.implementations = {}

    def implementation(self, key, result, arity):
        """numba's lowering of ``key`` on ``arity`` float64 operands, giving ``result``."""
        found = self.implementations.get((key, arity))
        if found is None:
            found = self.context.get_function(key, signature(result, *(_F8,) * arity))
            self.implementations[(key, arity)] = found
        return found

    def run(self, statements):
        builder = self.builder
        declined = builder.append_basic_block("declined")
        for statement in statements:
            if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
                target = statement.targets[0]
                if isinstance(target, ast.Name):
                    self.values[target.id] = self.expression(statement.value)
                    continue
                if isinstance(target, ast.Subscript):
                    builder.store(self.expression(statement.value), self.element(target))
                    continue
            elif isinstance(statement, ast.If) and _returns(statement.body, 0) \
                    and not statement.orelse:
                passed = builder.append_basic_block("passed")
                builder.cbranch(self.condition(statement.test), declined, passed)
                builder.position_at_end(passed)
                continue
            elif _returns([statement], 1):
                accepted = builder.basic_block
                merged = builder.append_basic_block("merged")
                builder.branch(merged)
                builder.position_at_end(declined)
                builder.branch(merged)
                builder.position_at_end(merged)
                result = builder.phi(self.context.get_value_type(types.int64))
                result.add_incoming(self.context.get_constant(types.int64, 1), accepted)
                result.add_incoming(self.context.get_constant(types.int64, 0), declined)
                return result
            raise NotStraightLine(f"line {statement.lineno}: {ast.unparse(statement)}")
        raise NotStraightLine("no final 'return 1'")

    def element(self, subscript: ast.Subscript):
        """Pointer to ``array[i]`` for a constant i."""
        if not (isinstance(subscript.value, ast.Name) and subscript.value.id in self.arrays
                and isinstance(subscript.slice, ast.Constant)):
            raise NotStraightLine(f"line {subscript.lineno}: {ast.unparse(subscript)}")
        ty, array = self.arrays[subscript.value.id]
        index = self.context.get_constant(types.intp, int(subscript.slice.value))
        return cgutils.get_item_pointer(self.context, self.builder, ty, array, [index])

    def condition(self, test):
        """The i1 that is true where the call is declined: ``not (a op b)`` or ``(a op b)``."""
        negated = isinstance(test, ast.UnaryOp) and isinstance(test.op, ast.Not)
        compare = test.operand if negated else test
        if not (isinstance(compare, ast.Compare) and len(compare.ops) == 1
                and type(compare.ops[0]) in _COMPARE):
            raise NotStraightLine(f"line {test.lineno}: {ast.unparse(test)}")
        operands = [self.expression(compare.left), self.expression(compare.comparators[0])]
        outcome = self.implementation(_COMPARE[type(compare.ops[0])], types.boolean, 2)(
            self.builder, operands)
        return self.builder.not_(outcome) if negated else outcome

    def expression(self, node):
        """The float64 value of ``node``."""
        if isinstance(node, ast.Name) and node.id in self.values:
            return self.values[node.id]
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return self.context.get_constant(_F8, float(node.value))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub) \
                and isinstance(node.operand, ast.Constant):  # -1.5 is a constant in Python too
            return self.context.get_constant(_F8, -float(node.operand.value))
        if isinstance(node, ast.Attribute) and ast.unparse(node) in _NAMED_CONSTANTS:
            return self.context.get_constant(_F8, _NAMED_CONSTANTS[ast.unparse(node)])
        if isinstance(node, ast.Subscript):
            return self.builder.load(self.element(node))
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            operands = [self.expression(node.left), self.expression(node.right)]
            return self.implementation(_BINARY[type(node.op)], _F8, 2)(self.builder, operands)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return self.implementation(operator.neg, _F8, 1)(
                self.builder, [self.expression(node.operand)])
        if isinstance(node, ast.Call) and ast.unparse(node.func) == "max" and node.args:
            operands = [self.expression(x) for x in node.args]  # numba's own max of floats
            return do_minmax(self.context, self.builder, [_F8] * len(operands), operands,
                             operator.gt)
        if isinstance(node, ast.Call) and ast.unparse(node.func) in _CALLS and not node.keywords:
            operands = [self.expression(x) for x in node.args]
            return self.implementation(_CALLS[ast.unparse(node.func)], _F8, len(operands))(
                self.builder, operands)
        raise NotStraightLine(f"line {node.lineno}: {ast.unparse(node)}")


def _returns(statements, value: int) -> bool:
    """Whether ``statements`` is ``return <value>``."""
    return (len(statements) == 1 and isinstance(statements[0], ast.Return)
            and isinstance(statements[0].value, ast.Constant)
            and statements[0].value.value == value)
