"""numba pieces that talk to SUNDIALS from compiled code: the data pointer of a serial vector or dense matrix,
IDASolve called through its address, and the compiled loop over a segment's output times.

A SUNDIALS object is a struct whose first member points to its content; the content of a serial N_Vector and of
a dense SUNMatrix holds the data pointer at a byte offset that `sundials_c.Sundials` measures at load time
(it depends on the library's index type). The offsets are constants of the generated code, and part of the key
under which compiled callbacks are cached (`compiled_model.py`).
"""
from __future__ import annotations

from llvmlite import ir
import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from mechsim.dynamics.backends.sundials_c import sundials


def _data_pointer(offset: int):
    """(signature, codegen) of an intrinsic loading the double* at `offset` in a SUNDIALS object's content."""
    def codegen(context, builder, signature, args):
        byte_pp = ir.PointerType(ir.PointerType(ir.IntType(8)))
        content = builder.load(builder.bitcast(args[0], byte_pp))
        slot = builder.gep(content, [ir.Constant(ir.IntType(64), offset)])
        return builder.load(builder.bitcast(slot, ir.PointerType(ir.PointerType(ir.DoubleType()))))
    return types.CPointer(types.float64)(types.voidptr), codegen


@intrinsic
def vector_data(typingctx, nvector):
    """double* data of a serial N_Vector (N_VGetArrayPointer, inlined)."""
    return _data_pointer(sundials().vector_data_offset)


@intrinsic
def matrix_data(typingctx, matrix):
    """double* data (column-major) of a dense SUNMatrix (SUNDenseMatrix_Data, inlined)."""
    return _data_pointer(sundials().matrix_data_offset)


@intrinsic
def ida_solve(typingctx, address, mem, tout, tret, yy, yp, itask):
    """IDASolve(mem, tout, &tret, yy, yp, itask) called through its address (an integer), so that compiled code
    calling it holds no process-specific constant and numba can cache it."""
    i64, i32 = ir.IntType(64), ir.IntType(32)
    fnty = ir.FunctionType(i32, [i64, ir.DoubleType(), i64, i64, i64, i32])

    def codegen(context, builder, signature, args):
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, list(args[1:]))
    return types.int32(types.int64, types.int64, types.float64, types.int64, types.int64, types.int64,
                       types.int32), codegen


def _advance(solve_address, mem, t_out, tret_address, yy, yp, y_view, yp_view, tret, rows_t, rows_y, rows_yp):
    """IDASolve in IDA_NORMAL mode at each output time until the last one, a root (flag 2) or a failure (< 0);
    copies each row. Returns (last flag, rows written)."""
    flag = 0
    k = 0
    n = y_view.size
    while k < t_out.size:
        flag = ida_solve(solve_address, mem, t_out[k], tret_address, yy, yp, np.int32(1))
        if flag == 2 or flag < 0:
            break
        rows_t[k] = tret[0]
        for j in range(n):
            rows_y[k, j] = y_view[j]
            rows_yp[k, j] = yp_view[j]
        k += 1
        if flag == 1:          # IDA_TSTOP_RETURN: the end of the segment
            break
    return flag, k


def _cached_in_the_user_cache_folder(py_func):
    """`njit(cache=True)` with numba's cache in mechsim's user-cache folder (dynamics/user_cache.py, numba/) instead
    of beside this module, like the compiled callbacks: one folder holds what mechsim compiles. numba picks the
    folder when the function is decorated, so its setting is changed only for this decoration; a folder that
    cannot be written falls back to numba's own choice."""
    import numba
    from mechsim.dynamics.user_cache import cache_dir
    before = numba.config.CACHE_DIR
    if not before:                    # a NUMBA_CACHE_DIR the user set is kept
        numba.config.CACHE_DIR = str(cache_dir() / "numba")
    try:
        return njit(cache=True)(py_func)
    finally:
        numba.config.CACHE_DIR = before


advance = _cached_in_the_user_cache_folder(_advance)


def compile_advance() -> None:
    """Compile `advance` for the argument types `IdaCompiledBackend.integrate` passes (numba caches it on disk):
    a call with no output time, which returns before calling IDASolve."""
    advance(0, 0, np.zeros(0), 0, 0, 0, np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(0), np.zeros((0, 1)),
            np.zeros((0, 1)))
