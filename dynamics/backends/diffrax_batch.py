"""Many cases of one model structure on the diffrax backend: one vmapped, compiled segment solve per round.

Each case is a lane: its own run of THE hybrid loop (`hybrid.hybrid_loop`, a generator that asks for one
segment at a time), with its own parameter tuple, state, mode and output times. Every round, ONE call of
`jax.vmap` over the compiled segment solve advances every unfinished lane to its own next guard crossing or
output-chunk end: diffrax's Event stops each lane at its own root inside the vmapped while-loop, and the mode
number k is a traced argument, so lanes in different modes share the call. Each lane's outputs become a
`Segment` (`DiffraxBackend.segment`) sent back into its loop, which applies the transition and asks for the
next segment. Finished lanes are masked with t0 = t1 (their solve takes no step).

Under vmap the while-loop runs until its slowest lane has finished, so one round costs about the longest
lane's segment; lanes whose events fall far apart in time wait for each other. See docs/sweeps.md, 'Batching'.

Requirements: every case has the same derived model (same `derive` key: mechanism structure, formulation,
drive kind, state extension) and the same diffrax options (solver, tolerances). The result of each lane
equals `hybrid.simulate` of that case on the diffrax segment loop (the same arithmetic per lane, up to vmap's
reordering).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from mechsim.mechanisms.base import Mechanism

from mechsim.dynamics.backends.diffrax_backend import (DiffraxBackend, DiffraxOptions, compile_key, make_solve,
                                                       segment_arguments)
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.hybrid import Trajectory, hybrid_loop, prepare
from mechsim.dynamics.jax_model import JaxModel, jax_model
from mechsim.dynamics.model import StateExtension
from mechsim.dynamics.programs import kept_key, program
from mechsim.dynamics.traced import compile_ahead
from mechsim.dynamics.settings import SolverSettings

import jax  # noqa: E402


@dataclass
class _Batched:
    fn: object
    compile_time: float
    compile_cpu_time: float


#: the latest batch: lanes, rounds (vmapped calls), compile_time_s (0 if cached), solve_time_s, and calls_time_s: the
#: part of the solve inside the vmapped calls, their outputs fetched (the rest is the lanes' hybrid loops in Python)
last_batch: dict = {}


def compiled_batch_solve(model, o: DiffraxOptions, lanes: int) -> tuple[_Batched, JaxModel, bool]:
    """The vmapped segment solve for `lanes` lanes (AOT-compiled once per model structure, options and batch
    size); True if it was compiled by this call."""
    # the vmapped segment solve does not depend on compiled_run (which picks the single run's loop): a sweep with it
    # on or off shares one compilation
    def build() -> _Batched:
        wall, cpu = _time.perf_counter(), _time.process_time()
        jmod = jax_model(model)
        one = segment_arguments(0, 0.0, 1.0, np.zeros(jmod.nz), np.zeros(len(model.parameter_names)),
                                np.ones(jmod.ng_max, bool), np.ones(o.rows(jmod.nz)), 1e-3, (o.rtol, o.atol))
        example = tuple(np.stack([a] * lanes) for a in one)
        fn = compile_ahead("diffrax_batch_solve", kept_key(model, (compile_key(o), lanes)),
                           lambda: jax.jit(jax.vmap(make_solve(jmod, o))), example)
        return _Batched(fn, _time.perf_counter() - wall, _time.process_time() - cpu)
    entry, fresh = program("diffrax_batch_solve", model, (compile_key(o), lanes), build)
    return entry, jax_model(model), fresh


def simulate_batch(mech_list: Sequence[Mechanism], drive_list: Sequence[Drive], settings: SolverSettings,
                   t_end_list: Sequence[float], dt_out: float, angle0_list: Sequence[float],
                   speed0_list: Sequence[float], ext_list: Sequence[StateExtension | None] | None = None,
                   ext_initial_list: Sequence | None = None, options: DiffraxOptions | None = None,
                   t0: float = 0.0) -> list[Trajectory]:
    """Integrate every case (same derived model structure) with one vmapped solve per round; a Trajectory per
    case, as `hybrid.simulate` on the diffrax segment loop would return it.

    Statistics per lane are that lane's own (segments, steps, events); compile_time_s is the batch compilation
    divided by the number of lanes, and solve_time_s the batch's solve time divided likewise (the lanes share
    every call); the same keys as a single run, so per-case tables keep their format. The batch's own figures
    (lanes, rounds, compile and solve time, the solve's time inside the vmapped calls) are in `last_batch`.
    """
    n = len(mech_list)
    if not n:
        return []
    backend = DiffraxBackend(settings, options)
    o = backend.o
    ext_list = list(ext_list) if ext_list is not None else [None] * n
    ext_initial_list = list(ext_initial_list) if ext_initial_list is not None else [None] * n
    starts = [prepare(mech, drive, settings, t_end, dt_out, a0, s0, ext, x0, t0)
              for mech, drive, t_end, a0, s0, ext, x0 in zip(mech_list, drive_list, t_end_list, angle0_list,
                                                              speed0_list, ext_list, ext_initial_list, strict=True)]
    model = starts[0].model
    if any(start.model is not model for start in starts):
        raise ValueError("simulate_batch: the cases do not share one derived model structure (derive key); "
                         "group them by structure first")
    entry, jmod, fresh = compiled_batch_solve(model, o, n)
    compile_time = entry.compile_time if fresh else 0.0
    compile_cpu = entry.compile_cpu_time if fresh else 0.0
    solve0 = _time.perf_counter()
    loops = [hybrid_loop(mech, start, settings, backend, t0, t_end)
             for mech, start, t_end in zip(mech_list, starts, t_end_list)]
    requests: list = [None] * n
    results: list[Trajectory | None] = [None] * n
    idle = segment_arguments(0, t0, t0, np.zeros(jmod.nz), np.zeros(len(model.parameter_names)),
                             np.zeros(jmod.ng_max, bool), np.full(o.rows(jmod.nz), t0), 1e-3, (o.rtol, o.atol))
    masked: list = [idle] * n       # a finished lane's last call with t1 = t0 (it takes no step)
    for j, loop in enumerate(loops):
        requests[j] = _advance(loop, None, results, j)
    rounds, calls = 0, 0.0
    while any(r is not None for r in requests):
        rounds += 1
        per_lane = []
        for j, request in enumerate(requests):
            if request is None:
                per_lane.append((masked[j], 0))
            else:
                args, n_chunk = backend.arguments(request, jmod)
                masked[j] = args[:2] + (args[1],) + args[3:6] + (np.full_like(args[6], args[1]),) + args[7:]
                per_lane.append((args, n_chunk))
        batched = tuple(np.stack(col) for col in zip(*(a for a, _ in per_lane)))
        call0 = _time.perf_counter()
        out = jax.device_get(entry.fn(*batched))
        calls += _time.perf_counter() - call0
        for j, request in enumerate(requests):
            if request is not None:
                seg = backend.segment(request, jmod, {key: val[j] for key, val in out.items()}, per_lane[j][1])
                requests[j] = _advance(loops[j], seg, results, j)
    solve = _time.perf_counter() - solve0
    for traj in results:
        traj.stats["compile_time_s"] = compile_time / n
        traj.stats["compile_cpu_time_s"] = compile_cpu / n
        traj.stats["compilations"] = 1 if fresh else 0
        traj.stats["solve_time_s"] = solve / n
    last_batch.update(lanes=n, rounds=rounds, compile_time_s=compile_time, solve_time_s=solve, calls_time_s=calls)
    return results


def _advance(loop, segment, results: list, j: int):
    """Send a lane's segment into its loop (None: start it); the next request, or None with the lane's
    Trajectory stored in results[j] when the loop has finished."""
    try:
        return next(loop) if segment is None else loop.send(segment)
    except StopIteration as done:
        results[j] = done.value
        return None
