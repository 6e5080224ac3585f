"""Per-call cost of the IDA residual and Jacobian: generated plain Python vs a jax.jit of the same expressions.

docs/architecture.md measured ~3 us for plain scalar Python against ~11 us for one jitted JAX call from Python; this
measures ours side by side in one process and reports the ratio. Run: python benchmarks/residual_cost.py
"""
from __future__ import annotations

import timeit

import numpy as np


def measure() -> list[dict]:
    """Per-call times (us) of the generated residual and Jacobian and of a jax.jit residual, per formulation."""
    import jax
    import sympy as sp

    jax.config.update("jax_enable_x64", True)
    from mechsim.dynamics.drives import Drive
    from mechsim.dynamics.model import derive
    from mechsim.mechanisms.geneva.model import Geneva
    from mechsim.mechanisms.geneva.kinematics import GenevaGeometry

    mech = Geneva(GenevaGeometry(0.075, 4, 0.004, 0.004), 0.02, 1.5626e-3, 7.0, 0.15)
    results = []
    for formulation in ("index1", "index2"):
        model = derive(mech, formulation, False)
        mf = model.modes["engaged"]
        values = {**mech.parameter_values(), **Drive("motor", stall_torque=40, no_load_speed=8).parameter_values(0.0),
                  "baumgarte_alpha": 10.0, "baumgarte_beta": 10.0}
        p = tuple(values[n] for n in model.parameter_names)
        y, yp, out = np.random.default_rng(0).normal(size=(3, mf.ny))
        J = np.zeros((mf.ny, mf.ny))
        n = 20000
        t_res = min(timeit.repeat(lambda: mf.residual(0.1, y, yp, out, p), number=n, repeat=5)) / n
        t_jac = min(timeit.repeat(lambda: mf.jacobian(0.1, y, yp, None, 10.0, J, p), number=n, repeat=5)) / n
        # the same residual rows lambdified to jax and jitted (the peer docs/architecture.md measured)
        rows = _rows_from_source(mf, model, mech, formulation)
        import jax.numpy as jnp
        raw = sp.lambdify(rows[0], rows[1], modules="jax")
        f = jax.jit(lambda *a: jnp.stack([jnp.asarray(r, dtype=jnp.float64) for r in raw(*a)]))
        args = (0.1, *y, *yp, *p)
        f(*args)[0].block_until_ready()
        t_jax = min(timeit.repeat(lambda: np.asarray(f(*args)), number=2000, repeat=5)) / 2000
        results.append(dict(formulation=formulation, states=mf.ny, residual_us=t_res * 1e6, jacobian_us=t_jac * 1e6,
                            jax_jit_residual_us=t_jax * 1e6, ratio_jax_over_generated=t_jax / t_res))
    return results


def main() -> None:
    for r in measure():
        print(f"{r['formulation']}: ny = {r['states']}; generated residual {r['residual_us']:.2f} us, "
              f"Jacobian {r['jacobian_us']:.2f} us; jax.jit residual {r['jax_jit_residual_us']:.2f} us; "
              f"ratio jax/generated = {r['ratio_jax_over_generated']:.1f}")


def _rows_from_source(mf, model, mech, formulation):
    """Rebuild the residual rows symbolically (same derivation as dynamics/model.py)."""
    import sympy as sp

    from mechsim.dynamics.formulation import differentiate_constraints, mechanical_residual
    s = mf.symbolic
    q, v, lam, params = s["q"], s["v"], s["lam"], s["params"]
    qp = [sp.Symbol(f"qp_{c}", real=True) for c in mech.coordinates]
    vp = [sp.Symbol(f"vp_{c}", real=True) for c in mech.coordinates]
    mu = [sp.Symbol(f"mu_{i}", real=True) for i in range(len(lam))] if formulation == "index2" else []
    cd = differentiate_constraints(list(s["constraints"].phi), s["t"], q, v, vp)
    by = dict(zip(model.parameter_names, params))
    rows = mechanical_residual(formulation, s["mass"], s["force"], cd, q, v, qp, vp, lam, mu,
                               (by["baumgarte_alpha"], by["baumgarte_beta"]))
    W = [sp.Symbol(f"W_{n}", real=True) for n in s["work_names"]]
    Wp = [sp.Symbol(f"Wp_{n}", real=True) for n in s["work_names"]]
    rows += [Wp[i] - s["powers"][n] for i, n in enumerate(s["work_names"])]
    lamp = [sp.Symbol(f"lamp_{i}", real=True) for i in range(len(lam))]
    mup = [sp.Symbol(f"mup_{i}", real=True) for i in range(len(mu))]
    args = [s["t"], *q, *v, *lam, *mu, *W, *qp, *vp, *lamp, *mup, *Wp, *params]
    return args, rows


if __name__ == "__main__":
    main()
