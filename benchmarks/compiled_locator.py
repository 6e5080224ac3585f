"""What a compiled locator of the peaks would cost on case A's diffrax run, and what it would miss (docs/benchmarks.md,
"A compiled locator, measured").

A measurement of a lever, not a way mechsim locates anything: from the compiled run's own step records (the
interpolant its rows and readings come from), every step's dense output sampled at K Chebyshev-Lobatto instants,
the peak columns read out in JAX (the tables' KKT solve, without the index-1 form's Baumgarte terms), the best
sample of each (window, max or min, column) taken, then refined by golden section between its neighbouring
samples. The trajectory is the bench's integration of case A (`hybrid.simulate`, the settings of
`mechsim bench`'s diffrax-Tsit5 at rtol 1e-5), the windows the run's periodic regime and its start-up as
`mechsim.run` found them. Printed: a warm `mechsim.run` of the same case (process CPU, median), the locator's parts
(its inputs gathered from the run, the sampling, the refinement), and each extremum against the one `mechsim.run`
reports.

    python benchmarks/compiled_locator.py [K] [golden-section iterations]
"""
from __future__ import annotations

import statistics
import sys
import time

import numpy as np

import mechsim
from mechsim.benchmarks.peer_bench import CASES

RUNS = 15
RTOL = 1e-5


def _run_and_trajectory():
    """(a warm `mechsim.run` of case A on diffrax: its median CPU over RUNS runs and its summary; the same
    integration's trajectory, as the bench runs it)."""
    from mechsim.benchmarks.bench import BenchConfig, make_problem
    from mechsim.benchmarks.peer_bench import METHODS
    from mechsim.dynamics import hybrid
    sc = mechsim.load("geneva-motor", set=list(CASES["A"]) + ["duration=5 s", "output_step=1 ms",
                                                              "output.plots=false", 'solver.backend="diffrax"',
                                                              f"solver.rtol={RTOL}", f"solver.atol={RTOL * 1e-2}"])
    result = mechsim.run(sc)
    run_s = _median_cpu(lambda: mechsim.run(sc), RUNS)
    problem = make_problem(BenchConfig(scenario="geneva-motor", duration=5.0, overrides=CASES["A"]))
    settings = METHODS["diffrax-Tsit5"].settings(problem, RTOL, RTOL * 1e-2)
    traj = hybrid.simulate(problem.mech, problem.drive, settings, problem.duration, problem.dt_out, problem.angle0,
                           problem.speed0)
    return run_s, result.summary, traj, problem.mech


def _median_cpu(f, n: int = 30) -> float:
    f()
    spent = []
    for _ in range(n):
        t = time.process_time()
        f()
        spent.append(time.process_time() - t)
    return statistics.median(spent)


def main(k: int = 8, iterations: int = 40) -> None:
    import jax
    import jax.numpy as jnp
    from mechsim.dynamics.backends.diffrax_run import ST_ACC, ST_SEG, ST_T0, interpolator
    from mechsim.dynamics.codegen import lambdify
    from mechsim.dynamics.jax_model import jax_model

    run_s, summary, traj, mech = _run_and_trajectory()
    peaks, regime = summary["peaks"], summary["regime"]
    columns = tuple(peaks)
    dense, model = traj.dense, traj.model
    jmod, names = jax_model(model), list(model.modes)
    interpolate = interpolator(dense.o, dense.entry.steps.record)
    theta = 0.5 - 0.5 * np.cos(np.pi * np.arange(k) / (k - 1))
    golden = 0.5 * (np.sqrt(5.0) - 1.0)

    def read_out(name):
        mf, jm = model.modes[name], jmod.modes[jmod.index(name)]
        s = mf.symbolic
        readouts = lambdify([s["t"], list(s["q"]), list(s["v"]), list(mech.symbols.a), list(s["lam"]), list(s["x"]),
                             list(s["params"])], s["readout_exprs"], "jax")

        def at(row, x, p, offset):           # (t, the peak columns) at x in [0, 1] of the step `row`
            t = row[ST_T0] + x * (row[ST_ACC] - row[ST_T0])
            q, v, _, ext = jm.split(interpolate(row, t))
            # the tables' KKT solve: the index-1 form's Baumgarte terms zero (c = -gamma exactly)
            a, lam = jm.kkt(t, q, v, ext, p.at[jm.alpha_index].set(0.0).at[jm.beta_index].set(0.0))
            cols = {}
            for i, c in enumerate(model.coordinates):
                cols[f"{c}_speed_rad_s"], cols[f"{c}_accel_rad_s2"] = v[i], a[i]
            cols.update(zip(mf.readout_names, (jnp.asarray(e, jnp.float64)
                                               for e in readouts(t, q, v, a, lam, ext, p))))
            return t, jnp.stack([jnp.asarray(cols.get(c, jnp.nan), jnp.float64) for c in columns])
        return at

    reads = [read_out(n) for n in names]
    sample = [jax.jit(jax.vmap(jax.vmap(r, in_axes=(None, 0, None, None)), in_axes=(0, None, 0, 0))) for r in reads]

    def switched(row, x, mode, p, offset):
        return jax.lax.switch(mode, reads, row, x, p, offset)
    sample_switched = jax.jit(jax.vmap(jax.vmap(switched, in_axes=(None, 0, None, None, None)),
                                       in_axes=(0, None, 0, 0, 0)))

    def refiner(at):
        def refine(row, p, offset, c, sense, a, b):
            def f(x):
                return sense * at(row, x, p, offset)[1][c]

            def narrow(_, ab):
                a, b = ab
                x1, x2 = b - golden * (b - a), a + golden * (b - a)
                left = f(x1) >= f(x2)
                return jnp.where(left, a, x1), jnp.where(left, x2, b)
            a, b = jax.lax.fori_loop(0, iterations, narrow, (a, b))
            t, v = at(row, 0.5 * (a + b), p, offset)
            return t, v[c]
        return jax.jit(jax.vmap(refine))
    refine = [refiner(r) for r in reads]

    def inputs():          # every taken step's record, its segment's mode, parameters and offset
        S, first = dense.segments, {}
        for n, g in enumerate(S):
            first.setdefault(g[2], n)
        taken = [np.asarray(st)[:n_st] for st, n_st in dense.buffers]
        rows = np.concatenate(taken)
        seg = np.concatenate([first.get(c, 0) + r[:, ST_SEG].astype(int) for c, r in enumerate(taken)])
        modes = np.array([names.index(S[s][4]) for s in seg.tolist()], dtype=np.int32)
        return (rows, modes, np.array([np.asarray(S[s][5], float) for s in seg.tolist()]),
                np.array([np.asarray(S[s][6], float) for s in seg.tolist()]))

    t_end = float(dense.segments[-1][1])
    windows = ((regime["from_t_s"], t_end), (float(dense.segments[0][0]), regime["from_t_s"]))
    rows, modes, params, offsets = inputs()
    groups = [np.flatnonzero(modes == m) for m in range(len(names))]

    def sampled():
        T, V = np.empty((len(rows), k)), np.empty((len(rows), k, len(columns)))
        for m, ix in enumerate(groups):
            if len(ix):
                t, v = sample[m](rows[ix], theta, params[ix], offsets[ix])
                T[ix], V[ix] = np.asarray(t), np.asarray(v)
        return T, V

    def targets(T, V):       # (window, sense, column, step, sample, its value times sense)
        out = []
        for w, (lo, hi) in enumerate(windows):
            inside = (T >= lo) & (T <= hi)
            for sense in (1.0, -1.0):
                F = np.where(inside[..., None] & ~np.isnan(V), sense * V, -np.inf).reshape(-1, len(columns))
                for c, best in enumerate(np.argmax(F, axis=0).tolist()):
                    out.append((w, sense, c, best // k, best % k, F[best, c]))
        return out

    def refined(T, found):
        out = {}
        for m in range(len(names)):
            mine = [x for x in found if modes[x[3]] == m]
            if not mine:
                continue
            j, at = np.array([x[3] for x in mine]), np.array([x[4] for x in mine])
            t, v = refine[m](rows[j], params[j], offsets[j], np.array([x[2] for x in mine]),
                             np.array([x[1] for x in mine]), theta[np.maximum(at - 1, 0)],
                             theta[np.minimum(at + 1, k - 1)])
            for x, tt, vv in zip(mine, np.asarray(t).tolist(), np.asarray(v).tolist()):
                out[x[:3]] = (vv, tt) if x[1] * vv > x[5] else (x[1] * x[5], float(T[x[3], x[4]]))
        return out

    T, V = sampled()
    found = targets(T, V)
    located = refined(T, found)
    parts = {"inputs gathered from the run (Python)": _median_cpu(inputs),
             f"sampling, {len(rows)} steps x {k} instants, one call per mode": _median_cpu(sampled),
             "the same under lax.switch on each step's mode, one call": _median_cpu(
                 lambda: [np.asarray(x) for x in sample_switched(rows, theta, modes, params, offsets)]),
             "best samples (numpy)": _median_cpu(lambda: targets(T, V)),
             f"golden section, {iterations} iterations, one call per mode": _median_cpu(lambda: refined(T, found))}
    print(f"case A on diffrax (rtol {RTOL:g}): a warm mechsim.run {run_s * 1e3:.2f} ms CPU (median of {RUNS}); "
          "the compiled locator's parts (median of 30):")
    for what, s in parts.items():
        print(f"  {what:62s} {s * 1e3:7.3f} ms")
    worst = 0.0
    for (w, sense, c), (value, t) in sorted(located.items()):
        entry = peaks[columns[c]]["startup"] if w else peaks[columns[c]]
        ref = entry["max" if sense > 0 else "min"]
        rel = abs(value - ref["value"]) / abs(ref["value"]) if ref["value"] else abs(value)
        if "constant" not in ref["at"]:
            worst = max(worst, rel)
        print(f"  {('periodic', 'start-up')[w]:8s} {'max' if sense > 0 else 'min'} {columns[c]:19s} "
              f"mechsim {ref['value']:+.12e} at t = {ref['t_s']:.9f} s ({ref['at'][:34]}); "
              f"locator {value:+.12e} at t = {t:.9f} s; relative {rel:.1e}")
    print(f"largest relative difference outside constant stretches: {worst:.2e}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
