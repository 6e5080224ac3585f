"""One re-initialisation for every path (`consistent.reinitialise`, numpy and JAX): the Python loop's projection
to round-off (numpy), the compiled run's three Gauss-Newton steps on the padded constraints and the sensitivity
pass's one step (JAX) land on the same consistent state, and the velocity law is Newton's impact law in the
kinetic-energy metric (docs/theory.md §K4)."""
import jax.numpy as jnp
import numpy as np
import pytest

from mechsim.dynamics.consistent import project_positions, project_velocities, reinitialise
from mechsim.dynamics.backends.diffrax_run import GN_ITERATIONS, padded_constraint_parts
from mechsim.dynamics.drives import Drive
from mechsim.dynamics.hybrid import parameter_tuple
from mechsim.dynamics.jax_model import jax_model
from mechsim.dynamics.model import derive
from mechsim.mechanisms.geneva.kinematics import GenevaGeometry
from mechsim.mechanisms.geneva.model import Geneva
from mechsim.mechanisms.rolling.model import Bodies, RollingPairFourBar
from mechsim.mechanisms.rolling.sets import make


def _geneva():
    return Geneva(GenevaGeometry(0.075, 4, 0.004, 0.004), 0.02, 1.5626e-3, friction=0.15), 0.3, 5.0


def _rolling():
    kin = make("A")
    mech = RollingPairFourBar(kin, Bodies.uniform(kin, 0.2, 0.3, 0.5, 0.1), driven_link="crank")
    return mech, float(kin.solve(np.array([0.0]), 1).theta2[0]), 1.0


@pytest.mark.parametrize("make_mech", [_geneva, _rolling], ids=["geneva", "rolling"])
def test_numpy_and_jax_paths_agree_on_a_consistent_state(make_mech):
    """From a state 1e-5 off the constraints with a random velocity: the compiled run's three steps land on the
    numpy projection's (q, v) to round-off (1e-14: the steps converge quadratically, 1e-5 -> 1e-10 -> round-off;
    measured 2e-16), the sensitivity pass's one step within |dq|^2 times the constraints' curvature (1e-10 for a
    curvature up to 1; measured 5e-13 Geneva, 5e-12 rolling pair); Phi = 0 and G v + Phi_t = 0 there;
    the velocity change is M^-1 G^T times an impulse (the kinetic-energy metric); e = 1 reverses G v and keeps
    the kinetic energy."""
    mech, angle, speed = make_mech()
    drive = Drive("torque", torque=1.0)
    model = derive(mech, "index1", False, None)
    jmod = jax_model(model)
    init = mech.initial_state(angle, speed)
    values = {**mech.parameter_values(), **init.updates, **drive.parameter_values(0.0, 0.0),
              "baumgarte_alpha": 1.0, "baumgarte_beta": 1.0}
    mf = model.modes[init.mode]
    p = parameter_tuple(model, values)
    q_c = project_positions(mf, 0.0, init.q, p)
    rng = np.random.default_rng(7)
    q0 = q_c + 1e-5 * rng.normal(size=len(q_c))
    v0 = speed * rng.normal(size=len(q_c))
    q_np = project_positions(mf, 0.0, q0, p)
    v_np, impact = project_velocities(mf, 0.0, q_np, v0, p)
    k = jmod.index(init.mode)
    jm = jmod.modes[k]
    parts = padded_constraint_parts(jmod)
    pj = jnp.asarray(p)
    padded = reinitialise(lambda q, v: parts(k, 0.0, q, v, pj), jnp.asarray(q0), jnp.asarray(v0), xp=jnp,
                          steps=GN_ITERATIONS)
    one = reinitialise(lambda q, v: jm.constraint_parts(0.0, q, v, pj) + (None,), jnp.asarray(q0),
                       jnp.asarray(v0), xp=jnp, steps=1)
    scale_v = np.max(np.abs(v0))
    for (q, v), tol in ((padded, 1e-14), (one, 1e-10)):
        np.testing.assert_allclose(np.asarray(q), q_np, rtol=0, atol=tol)
        np.testing.assert_allclose(np.asarray(v), v_np, rtol=0, atol=tol * scale_v)
    # on the constraints, position and velocity, to round-off
    assert np.max(np.abs(np.asarray(mf.phi(0.0, q_np, p), float))) <= 1e-14
    assert np.max(np.abs(np.asarray(mf.phi_dot(0.0, q_np, v_np, p), float))) <= 1e-12 * scale_v
    # kinetic-energy metric: M (v0 - v) = G^T mu for some impulse mu, so it never raises the energy
    M = np.atleast_2d(np.asarray(mf.mass(q_np, p), float))
    G = np.atleast_2d(np.asarray(mf.G(0.0, q_np, p), float))
    mu = np.linalg.lstsq(G.T, M @ (v0 - v_np), rcond=None)[0]
    np.testing.assert_allclose(G.T @ mu, M @ (v0 - v_np), rtol=0, atol=1e-12 * np.max(np.abs(M @ v0)))
    assert impact.energy_after <= impact.energy_before
    # Newton's law with e = 1 from a consistent position: G v reversed, energy kept
    v_e, elastic = project_velocities(mf, 0.0, q_np, v0, p, restitution=1.0)
    rel = np.asarray(mf.phi_dot(0.0, q_np, v0, p), float).ravel()
    np.testing.assert_allclose(np.asarray(mf.phi_dot(0.0, q_np, v_e, p), float).ravel(), -rel, rtol=0,
                               atol=1e-12 * scale_v)
    assert elastic.energy_after == pytest.approx(elastic.energy_before, rel=1e-12)
