"""numba intrinsics that read the data pointer of a SUNDIALS serial vector or dense matrix inside compiled code.

A SUNDIALS object is a struct whose first member points to its content; the content of a serial N_Vector and of
a dense SUNMatrix holds the data pointer at a byte offset that `sundials_c.Sundials` measures at load time
(it depends on the library's index type). The offsets are constants of the generated code, and part of the key
under which compiled callbacks are cached (`compiled_model.py`).
"""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from mechsim.dynamics.sundials_c import sundials


def _data_pointer(builder, obj, offset: int):
    byte_pp = ir.PointerType(ir.PointerType(ir.IntType(8)))
    content = builder.load(builder.bitcast(obj, byte_pp))
    slot = builder.gep(content, [ir.Constant(ir.IntType(64), offset)])
    return builder.load(builder.bitcast(slot, ir.PointerType(ir.PointerType(ir.DoubleType()))))


@intrinsic
def vector_data(typingctx, nvector):
    """double* data of a serial N_Vector (N_VGetArrayPointer, inlined)."""
    offset = sundials().vector_data_offset

    def codegen(context, builder, signature, args):
        return _data_pointer(builder, args[0], offset)
    return types.CPointer(types.float64)(types.voidptr), codegen


@intrinsic
def matrix_data(typingctx, matrix):
    """double* data (column-major) of a dense SUNMatrix (SUNDenseMatrix_Data, inlined)."""
    offset = sundials().matrix_data_offset

    def codegen(context, builder, signature, args):
        return _data_pointer(builder, args[0], offset)
    return types.CPointer(types.float64)(types.voidptr), codegen
