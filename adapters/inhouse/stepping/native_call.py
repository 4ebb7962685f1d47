"""A compiled kernel called from the compiled loops through its address, so that each loop's
code does not hold the kernel's code again.

numba compiles every ``@njit`` function into a library of its own, and a function that calls
another links the callee's whole library into its own and optimises and generates machine code
for all of it once more.  The right-hand sides
(:func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`,
:func:`~mbh._adapters.inhouse.formulations.joint_rhs.acceleration_kernel`, with their forces,
Jacobians, γ and solves) were linked into every loop and step above them, and on an empty cache
each compiled its copy again (docs/speed.md, "What a first run compiles").  Called here instead,
a loop holds an indirect call: :class:`NativeEntry` carries the kernel's address, found at run
time once the kernel is compiled or loaded, and :func:`call_native` calls it with numba's own
calling convention, so that an exception the kernel raises reaches the loop as a direct call's
would (a ``try`` in the loop catches it; outside one it leaves the loop).  It costs: runs that
take every right-hand side from the kernels stepped 2–6 % slower than with the linked kernel,
for a tenth less compiling (docs/speed.md, "The right-hand sides called through their address").

Typing keeps the address and the call in agreement: a :class:`NativeEntry`'s numba type is its
kernel's name, argument types and return type, and :func:`call_native` accepts only arguments of
exactly those types (else numba's ``TypingError`` when the loop is compiled); the address is the
kernel's compiled version for exactly those types (:meth:`NativeEntry.resolve`).  An entry not
yet resolved has the address 0, and a call then raises ``RuntimeError`` in the loop instead of
jumping there.
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.core.errors import TypingError
from numba.extending import (NativeValue, intrinsic, models, register_model, typeof_impl,
                             unbox)

#: What the right-hand side kernels return, q̈ or θ̈: a vector of float64 (numba types it of
#: any layout, since its branches return views and new arrays alike).
VECTOR = types.float64[:]


class NativeEntry:
    """The native entry of one compiled kernel for one set of argument types.

    Parameters
    ----------
    dispatcher : numba dispatcher
        The kernel (``@njit``).
    args : tuple
        Arguments of the types every call passes (their values are not kept).
    return_type : numba type
        What the kernel returns for them; :meth:`resolve` checks it against the compiled version.
    """

    def __init__(self, dispatcher, args: tuple, return_type):
        self.dispatcher = dispatcher
        self.argument_types = tuple(dispatcher.typeof_pyval(arg) for arg in args)
        self.return_type = return_type
        #: The compiled function's address, 0 until :meth:`resolve` (read at each loop call).
        self.address = 0
        self._overload = None  # keeps the library holding the code alive as long as the entry

    @property
    def name(self) -> str:
        function = self.dispatcher.py_func
        return f"{function.__module__}.{function.__qualname__}"

    def resolve(self, overload) -> None:
        """Point the entry at ``overload`` (the kernel's ``CompileResult`` for the entry's
        argument types), checking its types."""
        if (tuple(overload.signature.args) != self.argument_types
                or overload.signature.return_type != self.return_type):
            raise TypeError(f"{self.name} was compiled as {overload.signature}, the loops call it "
                            f"as {self.return_type}{self.argument_types}")
        self._overload = overload
        self.address = overload.library.get_pointer_to_function(overload.fndesc.llvm_func_name)


class NativeEntryType(types.Type):
    """numba's type of a :class:`NativeEntry`: the kernel's name and signature."""

    def __init__(self, function: str, argument_types: tuple, return_type):
        self.function, self.argument_types, self.return_type = (function, argument_types,
                                                                return_type)
        super().__init__(name=f"NativeEntry[{return_type}{function}{argument_types}]")

    @property
    def key(self):
        return self.function, self.argument_types, self.return_type


@typeof_impl.register(NativeEntry)
def _typeof_entry(value, context):
    return NativeEntryType(value.name, value.argument_types, value.return_type)


@register_model(NativeEntryType)
class _AddressModel(models.PrimitiveModel):
    """An entry is its address (64 bits) in compiled code."""

    def __init__(self, dmm, fe_type):
        super().__init__(dmm, fe_type, ir.IntType(64))


@unbox(NativeEntryType)
def _unbox_entry(typ, obj, c):
    address = c.pyapi.object_getattr_string(obj, "address")
    value = c.pyapi.long_as_longlong(address)
    c.pyapi.decref(address)
    return NativeValue(value, is_error=c.pyapi.c_api_error())


@intrinsic
def call_native(typingctx, entry, arguments):
    """``entry``'s kernel called with the tuple ``arguments`` (exactly its argument types);
    what it returns, or its exception raised in the caller."""
    if not isinstance(entry, NativeEntryType) or not isinstance(arguments, types.BaseTuple):
        return None
    if tuple(arguments) != entry.argument_types:
        raise TypingError(f"{entry.function} takes {entry.argument_types}, "
                          f"called with {tuple(arguments)}")

    def lower(context, builder, signature, values):
        address, packed = values
        with cgutils.if_unlikely(builder, cgutils.is_null(builder, address)):
            context.call_conv.return_user_exc(
                builder, RuntimeError, (f"{entry.function} called before it was resolved",))
        argument_types = entry.argument_types
        unpacked = [builder.extract_value(packed, i) for i in range(len(argument_types))]
        function_type = context.call_conv.get_function_type(entry.return_type, argument_types)
        function = builder.inttoptr(address, ir.PointerType(function_type))
        status, result = context.call_conv.call_function(builder, function, entry.return_type,
                                                         argument_types, unpacked)
        with cgutils.if_unlikely(builder, status.is_error):
            context.call_conv.return_status_propagate(builder, status)
        return result

    return entry.return_type(entry, arguments), lower
