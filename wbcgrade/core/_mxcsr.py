"""The x86-64 MXCSR register (flush-to-zero, denormals-are-zero) read and written from
compiled code; imported by :mod:`wbcgrade.core._cpu` when the core first computes (it
loads numba), not when the core is imported."""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from wbcgrade.core._jit import compiled


def _mxcsr_call(builder, name, ptr):
    fnty = ir.FunctionType(ir.VoidType(), [ir.PointerType(ir.IntType(8))])
    fn = cgutils.get_or_insert_function(builder.module, fnty, name)
    builder.call(fn, [builder.bitcast(ptr, ir.PointerType(ir.IntType(8)))])


@intrinsic

def _stmxcsr(typingctx):  # pragma: no cover - compiled
    def codegen(context, builder, sig, args):
        ptr = cgutils.alloca_once(builder, ir.IntType(32))
        _mxcsr_call(builder, "llvm.x86.sse.stmxcsr", ptr)
        return builder.load(ptr)

    return types.uint32(), codegen


@intrinsic

def _ldmxcsr(typingctx, value):  # pragma: no cover - compiled
    def codegen(context, builder, sig, args):
        ptr = cgutils.alloca_once_value(builder, args[0])
        _mxcsr_call(builder, "llvm.x86.sse.ldmxcsr", ptr)
        return context.get_dummy_value()

    return types.void(types.uint32), codegen


@compiled(cache=True)

def get_flags() -> int:  # pragma: no cover - compiled
    return _stmxcsr()


@compiled(cache=True)

def set_flags(value: int) -> None:  # pragma: no cover - compiled
    _ldmxcsr(value)
