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
from numba import carray, cfunc, njit, types
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


def _cast_to(pointer_type):
    """(signature, codegen) of an intrinsic reading an address (an int64) as a typed pointer."""
    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))
    return pointer_type(types.int64), codegen


@intrinsic
def float_pointer(typingctx, address):
    """The address (an int64) as a double*."""
    return _cast_to(types.CPointer(types.float64))


@intrinsic
def int_pointer(typingctx, address):
    """The address (an int64) as an int64*."""
    return _cast_to(types.CPointer(types.int64))


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


@intrinsic
def ida_set_real(typingctx, address, mem, value):
    """An IDA setter `int f(void *mem, sunrealtype value)` (IDASetInitStep, IDASetStopTime) called through its
    address."""
    i64, i32 = ir.IntType(64), ir.IntType(32)
    fnty = ir.FunctionType(i32, [i64, ir.DoubleType()])

    def codegen(context, builder, signature, args):
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, list(args[1:]))
    return types.int32(types.int64, types.int64, types.float64), codegen


@intrinsic
def ida_reinit(typingctx, address, mem, t0, yy, yp):
    """IDAReInit(mem, t0, yy, yp) called through its address."""
    i64, i32 = ir.IntType(64), ir.IntType(32)
    fnty = ir.FunctionType(i32, [i64, ir.DoubleType(), i64, i64])

    def codegen(context, builder, signature, args):
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, list(args[1:]))
    return types.int32(types.int64, types.int64, types.float64, types.int64, types.int64), codegen


@intrinsic
def ida_get_long(typingctx, address, mem, out):
    """An IDA getter `int f(void *mem, long *out)` (IDAGetNumSteps, ...) called through its address, writing to the
    address `out`."""
    i64, i32 = ir.IntType(64), ir.IntType(32)
    fnty = ir.FunctionType(i32, [i64, i64])

    def codegen(context, builder, signature, args):
        fn = builder.inttoptr(args[0], fnty.as_pointer())
        return builder.call(fn, list(args[1:]))
    return types.int32(types.int64, types.int64, types.int64), codegen


def _segment(addresses, mem, t0, first_step, t_stop, t_out, tret_address, yy, yp, y_view, yp_view, tret, rows_t,
             rows_y, rows_yp, counts_address, count_size):
    """One segment of `IdaCompiledBackend.integrate` in one call: IDAReInit at t0 from the state the vectors yy, yp
    hold, IDASetInitStep and IDASetStopTime, `advance` over t_out, then IDA's counters read into the C longs
    (count_size bytes each) at counts_address. `addresses`: those of IDASolve, IDAReInit, IDASetInitStep,
    IDASetStopTime, then of the counters' getters. Returns (flag, rows written); where a setter fails, (its flag,
    -1 - its place among the three); without output times, (0, 0) before calling IDA."""
    if t_out.size == 0:
        return 0, 0
    flag = ida_reinit(addresses[1], mem, t0, yy, yp)
    if flag < 0:
        return flag, -1
    flag = ida_set_real(addresses[2], mem, first_step)
    if flag < 0:
        return flag, -2
    flag = ida_set_real(addresses[3], mem, t_stop)
    if flag < 0:
        return flag, -3
    flag, k = advance(addresses[0], mem, t_out, tret_address, yy, yp, y_view, yp_view, tret, rows_t, rows_y,
                      rows_yp)
    for i in range(4, addresses.size):
        ida_get_long(addresses[i], mem, counts_address + (i - 4) * count_size)
    return flag, k


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


def _read_rows(addresses, mem, yy, yp, tret_address, y_view, yp_view, p_view, tret, t0, y0, yp0, p, first_step,
               bounds, rows_t, rows_y, rows_yp, written):
    """Many re-integrations on one IDA memory, each as `IdaCompiledBackend.read` runs one: reading i starts from
    (t0[i], y0[i], yp0[i]) with parameters p[i] and first step first_step[i] (IDAReInit, IDASetInitStep, and the
    stop time its last instant), and fills rows bounds[i, 0] to bounds[i, 2]: the first up to bounds[i, 1] (its
    instants within round-off of t0) with the start itself, the others at the instants rows_t holds there
    (`advance` on those rows). `addresses` are those of IDASolve, IDAReInit,
    IDASetInitStep and IDASetStopTime. written[i]: the instants IDA reached, or -1 where it failed (a negative
    flag), -2 where a setter failed."""
    solve, reinit, init_step, stop_time = addresses[0], addresses[1], addresses[2], addresses[3]
    n = y_view.size
    for i in range(t0.size):
        a, b, c = bounds[i, 0], bounds[i, 1], bounds[i, 2]
        for r in range(a, b):
            for j in range(n):
                rows_y[r, j] = y0[i, j]
                rows_yp[r, j] = yp0[i, j]
        for j in range(n):
            y_view[j] = y0[i, j]
            yp_view[j] = yp0[i, j]
        for j in range(p_view.size):
            p_view[j] = p[i, j]
        if (ida_reinit(reinit, mem, t0[i], yy, yp) < 0 or ida_set_real(init_step, mem, first_step[i]) < 0
                or ida_set_real(stop_time, mem, rows_t[c - 1]) < 0):
            written[i] = -2
            continue
        flag, k = advance(solve, mem, rows_t[b:c], tret_address, yy, yp, y_view, yp_view, tret, rows_t[b:c],
                          rows_y[b:c], rows_yp[b:c])
        written[i] = -1 if flag < 0 else k


def _cached_in_the_user_cache_folder(py_func, decorate=None):
    """`njit(cache=True)` (or `decorate`) with numba's cache in mechsim's user-cache folder (dynamics/user_cache.py,
    numba/) instead of beside this module, like the compiled callbacks: one folder holds what mechsim compiles.
    numba picks the folder when the function is decorated, so its setting is changed only for this decoration; a
    folder that cannot be written falls back to numba's own choice."""
    import numba
    from mechsim.dynamics.user_cache import cache_dir
    before = numba.config.CACHE_DIR
    if not before:                    # a NUMBA_CACHE_DIR the user set is kept
        numba.config.CACHE_DIR = str(cache_dir() / "numba")
    try:
        return (decorate or njit(cache=True))(py_func)
    finally:
        numba.config.CACHE_DIR = before


advance = _cached_in_the_user_cache_folder(_advance)
read_rows = _cached_in_the_user_cache_folder(_read_rows)
segment = _cached_in_the_user_cache_folder(_segment)


#: the signature of the loop's entry points: (int64 arguments, float64 arguments) -> 0; results written into the
#: int64 arguments' last slots. C-callable, so that a caller needs no numba (compiled_model.loop_entries)
ENTRY = types.int32(types.CPointer(types.int64), types.CPointer(types.float64))


def _segment_entry(ints, reals):
    """`segment` on arrays given by address. ints: addresses (of IDASolve, ...) and their count, mem, t_out and its
    count, tret_address, yy, yp, y_view and its size, yp_view, tret, rows_t and its count, rows_y, rows_yp,
    counts_address, count_size, then (flag, rows written) are written to ints[18], ints[19]. reals: t0, first_step,
    t_stop."""
    n_out, ny, n_rows = ints[4], ints[9], ints[13]
    flag, k = segment(carray(int_pointer(ints[0]), (ints[1],)), ints[2], reals[0], reals[1], reals[2],
                      carray(float_pointer(ints[3]), (n_out,)), ints[5], ints[6], ints[7],
                      carray(float_pointer(ints[8]), (ny,)), carray(float_pointer(ints[10]), (ny,)),
                      carray(float_pointer(ints[11]), (1,)), carray(float_pointer(ints[12]), (n_rows,)),
                      carray(float_pointer(ints[14]), (n_rows, ny)), carray(float_pointer(ints[15]), (n_rows, ny)),
                      ints[16], ints[17])
    ints[18] = flag
    ints[19] = k
    return 0


def _read_rows_entry(ints, reals):
    """`read_rows` on arrays given by address. ints: addresses and their count, mem, yy, yp, tret_address, y_view
    and its size, yp_view, p_view and its size, tret, the readings' t0 and their count, y0, yp0, p, first_step,
    bounds, written, rows_t and its count, rows_y, rows_yp. reals: not read."""
    ny, n_p, n, n_rows = ints[7], ints[10], ints[13], ints[21]
    read_rows(carray(int_pointer(ints[0]), (ints[1],)), ints[2], ints[3], ints[4], ints[5],
              carray(float_pointer(ints[6]), (ny,)), carray(float_pointer(ints[8]), (ny,)),
              carray(float_pointer(ints[9]), (n_p,)), carray(float_pointer(ints[11]), (1,)),
              carray(float_pointer(ints[12]), (n,)), carray(float_pointer(ints[14]), (n, ny)),
              carray(float_pointer(ints[15]), (n, ny)), carray(float_pointer(ints[16]), (n, n_p)),
              carray(float_pointer(ints[17]), (n,)), carray(int_pointer(ints[18]), (n, 3)),
              carray(float_pointer(ints[20]), (n_rows,)), carray(float_pointer(ints[22]), (n_rows, ny)),
              carray(float_pointer(ints[23]), (n_rows, ny)), carray(int_pointer(ints[19]), (n,)))
    return 0


def native_entries() -> tuple:
    """(the segment entry, the read_rows entry): numba's C callbacks, compiled, or loaded from numba's cache (in
    mechsim's user-cache folder, or where numba.config.CACHE_DIR points: compiled_model.loop_entries)."""
    entry = cfunc(ENTRY, cache=True)
    return (_cached_in_the_user_cache_folder(_segment_entry, entry),
            _cached_in_the_user_cache_folder(_read_rows_entry, entry))
