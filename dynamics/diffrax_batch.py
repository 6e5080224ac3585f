"""Many cases of one model structure on the diffrax backend: one vmapped, compiled segment solve per round.

Each case is a lane with its own parameter tuple, state, mode and output times (`diffrax_backend.Lane`, the
same loop state and per-segment post-processing as `diffrax_backend.simulate_with`). Every round, ONE call of
`jax.vmap` over the compiled segment solve advances every unfinished lane to its own next guard crossing or
output-chunk end: diffrax's Event stops each lane at its own root inside the vmapped while-loop, and the mode
number k is a traced argument, so lanes in different modes share the call. Then the Python transition step
(`apply_transition`) runs per lane. Finished lanes are masked with t0 = t1 (their solve takes no step).

Under vmap the while-loop runs until its slowest lane has finished, so one round costs about the longest
lane's segment; lanes whose events fall far apart in time wait for each other. See docs/sweeps.md, 'Batching'.

Requirements: every case has the same derived model (same `derive` key: mechanism structure, formulation,
drive kind, state extension) and the same diffrax options (solver, tolerances). The result of each lane
equals `diffrax_backend.simulate` of that case (the same arithmetic per lane, up to vmap's reordering).
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from mechsim.mechanisms.base import Mechanism

from mechsim.dynamics.diffrax_backend import DiffraxOptions, Lane, _args, _make_solve, default_options
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.hybrid import Trajectory, prepare
from mechsim.dynamics.jax_model import JaxModel, jax_model
from mechsim.dynamics.model import StateExtension
from mechsim.dynamics.settings import SolverSettings

import jax  # noqa: E402


@dataclass
class _Batched:
    fn: object
    compile_time: float
    compile_cpu_time: float
    model: object


_CACHE: dict[tuple, _Batched] = {}
#: the latest batch: lanes, rounds (vmapped calls), compile_time_s (0 if cached), solve_time_s
last_batch: dict = {}


def compiled_batch_solve(model, o: DiffraxOptions, lanes: int) -> tuple[_Batched, JaxModel, bool]:
    """The vmapped segment solve for `lanes` lanes (AOT-compiled once per model structure, options and batch
    size); True if it was compiled by this call."""
    key = (id(model), o, lanes)
    hit = _CACHE.get(key)
    if hit is not None and hit.model is model:
        return hit, jax_model(model), False
    wall, cpu = _time.perf_counter(), _time.process_time()
    jmod = jax_model(model)
    one = _args(0, 0.0, 1.0, np.zeros(jmod.nz), np.zeros(len(model.parameter_names)),
                np.ones(jmod.ng_max, bool), np.ones(o.rows(jmod.nz)), 1e-3)
    example = tuple(np.stack([a] * lanes) for a in one)
    fn = jax.jit(jax.vmap(_make_solve(jmod, o))).lower(*example).compile()
    entry = _Batched(fn, _time.perf_counter() - wall, _time.process_time() - cpu, model)
    _CACHE[key] = entry
    return entry, jmod, True


def simulate_batch(mech_list: Sequence[Mechanism], drive_list: Sequence[Drive], settings: SolverSettings,
                   t_end_list: Sequence[float], dt_out: float, angle0_list: Sequence[float],
                   speed0_list: Sequence[float], ext_list: Sequence[StateExtension | None] | None = None,
                   ext_initial_list: Sequence | None = None, options: DiffraxOptions | None = None,
                   t0: float = 0.0) -> list[Trajectory]:
    """Integrate every case (same derived model structure) with one vmapped solve per round; a Trajectory per
    case, as `diffrax_backend.simulate` would return it.

    Statistics per lane are that lane's own (segments, steps, events); compile_time_s is the batch compilation
    divided by the number of lanes, and solve_time_s the batch's solve time divided likewise (the lanes share
    every call); the same keys as a single run, so per-case tables keep their format. The batch's own figures
    (lanes, rounds, compile and solve time) are in `last_batch`.
    """
    n = len(mech_list)
    if not n:
        return []
    o = options or default_options(settings)
    ext_list = list(ext_list) if ext_list is not None else [None] * n
    ext_initial_list = list(ext_initial_list) if ext_initial_list is not None else [None] * n
    lanes = []
    for mech, drive, t_end, a0, s0, ext, x0 in zip(mech_list, drive_list, t_end_list, angle0_list, speed0_list,
                                                    ext_list, ext_initial_list, strict=True):
        start = prepare(mech, drive, settings, t_end, dt_out, a0, s0, ext, x0, t0)
        lanes.append(Lane(o, mech, settings, start, t0, t_end))
    model = lanes[0].model
    if any(lane.model is not model for lane in lanes):
        raise ValueError("simulate_batch: the cases do not share one derived model structure (derive key); "
                         "group them by structure first")
    entry, jmod, fresh = compiled_batch_solve(model, o, n)
    compile_time = entry.compile_time if fresh else 0.0
    compile_cpu = entry.compile_cpu_time if fresh else 0.0
    solve0 = _time.perf_counter()
    rounds = 0
    while not all(lane.done for lane in lanes):
        rounds += 1
        per_lane = []
        for lane in lanes:
            if lane.done:       # masked: t0 = t1, the solve takes no step; its outputs are ignored
                args, n_chunk = lane.segment_args(jmod)
                args = args[:2] + (args[1],) + args[3:]
                per_lane.append((args, 0))
            else:
                per_lane.append(lane.segment_args(jmod))
        batched = tuple(np.stack(col) for col in zip(*(a for a, _ in per_lane)))
        out = jax.device_get(entry.fn(*batched))
        for j, lane in enumerate(lanes):
            if not lane.done:
                lane.after_segment(jmod, {key: val[j] for key, val in out.items()}, per_lane[j][1])
    solve = _time.perf_counter() - solve0
    for lane in lanes:
        lane.stats["compile_time_s"] = compile_time / n
        lane.stats["compile_cpu_time_s"] = compile_cpu / n
        lane.stats["compilations"] = 1 if fresh else 0
        lane.stats["solve_time_s"] = solve / n
    last_batch.update(lanes=n, rounds=rounds, compile_time_s=compile_time, solve_time_s=solve)
    return [lane.trajectory() for lane in lanes]
