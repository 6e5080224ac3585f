"""Cycle averaging (thermal.averaging = "cycle") for the design sensitivities: the traced cycle-averaged bulk of a
DAE run's turn read on its window's solution (`dense_turn`, `dense_bulk_samples`), and at a prescribed speed the
periodic turn's rows at their last time in the run (`cycle_temperatures`, `cycle_bulk_samples`)
(docs/sensitivity.md, "Cycle averaging")."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pandas as pd


#: the columns of the cycle-averaged bulk besides the mechanism's contact columns (`ParameterMap.contact_columns`,
#: the contact of every row of the turn: its heat input, the ripple): the drive angle and the energies at the turn's
#: ends (the cycle means), the heat rate of every row
CYCLE_COLUMNS = ("crank_angle_rad", "heat_generated_J", "heat_pin_J", "friction_power_W")


def cycle_window(plan):
    """The plan of a cycle-averaged scenario's mechanics window, resolved: the very run that cycle averaging
    averages (the runner integrates `plan.mechanics_duration`; `plan` as scenarios/runner.py `settled` gives it),
    with the DAE's bulk and bookkeeping states on every row and no periodic continuation."""
    return dataclasses.replace(plan, thermal=dataclasses.replace(plan.thermal, averaging="resolved"))


def _network(system, xp=np) -> dict:
    return {"capacity": xp.asarray(system.capacity), "conductance": xp.asarray(system.dense_conductance()),
            "source": xp.asarray(system.source), "input_matrix": xp.asarray(system.input_matrix)}


def cycle_temperatures(plan, df: pd.DataFrame) -> dict | None:
    """The contact temperature and flash rise of the periodic turn's rows at their last time in the run
    (docs/sensitivity.md, "Cycle averaging"): the rows inside the last full turn of the mechanics window (`df`,
    the run of `cycle_window(plan)`), each at its last repetition t_k + m_k P <= duration (m_k per row,
    thermal/cycle.py `last_repetitions`: the rows the run's continuation writes there), with the cycle-averaged bulk
    there (thermal/cycle_exact.py) under the row's flash rise and Blok share. The bulk's mean response rises
    monotonically from ambient, so a row's last repetition is its hottest and the largest of these is the run's
    reported peak. None without a full turn. Keys: rows (indices into df), t_s, temp_contact_C, temp_flash_rise_K,
    temp_contact_previous_C (one repetition earlier: the jump where a row's last repetition leaves the run),
    layout, period, duration, bulk, share (the inner rows' Blok share), row_inputs (every row's network input, rows x
    inputs; None without bulk states)."""
    from mechsim.thermal.contact_row import KELVIN
    from mechsim.thermal.cycle_exact import TurnLayout, turn_bulk, turn_ends
    setup, mech = plan.thermal.setup, plan.mechanism
    t = df["t_s"].to_numpy(float)
    angle = df["crank_angle_rad"].to_numpy(float)
    duration = float(plan.scenario.si["duration"])
    layout = TurnLayout.of(t, angle, duration)
    if layout is None:
        return None
    inner, edges, data = layout.inner, layout.edges, layout.data()
    flash = df["temp_flash_rise_K"].to_numpy(float)[inner]
    share = df["heat_share_pin"].to_numpy(float)[inner]
    a, b = turn_ends(data["t_edges"], data["targets"], angle[edges])
    bulk = previous = None
    u = None
    if setup.system is None:
        base_pin = base_wheel = setup.temp_ambient
        contact_previous = share * base_pin + (1.0 - share) * base_wheel + flash - KELVIN
    else:
        u = setup.extension.inputs_numeric(mech.contact_state(df))[0].T

        def at(periods):
            return turn_bulk({**data, "periods": periods}, angle[edges], df["heat_generated_J"].to_numpy(float)[edges],
                             df["heat_pin_J"].to_numpy(float)[edges], u[edges], u[layout.padded],
                             _network(setup.system), start)[0][layout.pad:]
        # the network's states around the turn's start (the table keeps the bulk ones as temp_bulk_<body>_C; the
        # 1-D mesh, whose cells it drops, is not cycle-averaged)
        start = np.column_stack([df[name[:-2] + "_C"].to_numpy(float)[edges] + KELVIN
                                 for name in setup.system.state_names])
        bulk, previous = at(data["periods"]), at(data["periods"] - 1.0)
        names = list(setup.system.state_names)
        pin, wheel = names.index("temp_bulk_pin_K"), names.index("temp_bulk_wheel_K")
        base_pin, base_wheel = bulk[:, pin], bulk[:, wheel]
        contact_previous = share * previous[:, pin] + (1.0 - share) * previous[:, wheel] + flash - KELVIN
    return {"rows": inner, "t_s": t[inner] + layout.periods * (b - a), "period": float(b - a), "layout": layout,
            "t_start": float(a), "share": share, "row_inputs": u,
            "duration": duration, "temp_flash_rise_K": flash, "bulk": bulk,
            "temp_contact_C": share * base_pin + (1.0 - share) * base_wheel + flash - KELVIN,
            "temp_contact_previous_C": contact_previous}


def closed_form_turn(plan, turn: dict) -> dict:
    """At a prescribed speed the run is the closed form's (thermal/plan.py: the motion exact at any time, its
    two-turn window, the network's input exact between the contact's switches), while the derivatives follow the
    DAE with the speed as a constraint over that same window, the same output rows and turn, with the cycle bulk of
    the input linear between rows (`cycle_temperatures`, thermal/cycle_exact.py). `turn` with its contact
    temperatures (and their previous repetitions, and times) replaced by the closed-form run's own at the same rows
    and repetitions: its window run, the same flash rise and Blok share columns, and its cycle bulk
    (`ThermalPlan.cycle_bulk`, the run's `bulk_response`) at t_k + m_k P. So the table's value is the run's
    reported peak; the traced ones stay as `traced_temp_contact_C` (they differ by the input's linear interpolation
    between rows across the contact's switches: docs/sensitivity.md, "Cycle averaging")."""
    from mechsim.scenarios import runner
    from mechsim.thermal.contact_row import KELVIN
    window = runner.execute(cycle_window(plan))
    if window.failure is not None:
        raise ValueError(f"the closed-form window failed: {window.failure.message()}")
    df = window.timeseries
    t = df["t_s"].to_numpy(float)
    layout = turn["layout"]
    rows_t = layout.t[turn["rows"]]
    idx = np.clip(np.searchsorted(t, rows_t), 0, len(t) - 1)
    step = float(plan.scenario.si["output_step"])
    if not np.all(np.abs(t[idx] - rows_t) <= 1e-9 * step):
        raise ValueError("the closed-form window's rows are not the DAE window's")
    flash = df["temp_flash_rise_K"].to_numpy(float)[idx]
    share = df["heat_share_pin"].to_numpy(float)[idx]
    setup = plan.thermal.setup
    out = dict(turn, traced_temp_contact_C=turn["temp_contact_C"], traced_t_s=turn["t_s"])
    if setup.system is None:
        return out
    names = list(setup.system.state_names)
    pin, wheel = names.index("temp_bulk_pin_K"), names.index("temp_bulk_wheel_K")
    m = np.asarray(layout.periods)
    _, out["inputs"], _ = plan.thermal._window_states(df)
    out["share"] = share
    times, bulk = plan.thermal.cycle_bulk(df, rows_t, m)
    _, previous = plan.thermal.cycle_bulk(df, rows_t, m - 1)
    out.update(t_s=times, temp_contact_C=share * bulk[:, pin] + (1.0 - share) * bulk[:, wheel] + flash - KELVIN,
               temp_contact_previous_C=share * previous[:, pin] + (1.0 - share) * previous[:, wheel] + flash - KELVIN)
    return out


def switch_kernel(plan, turn: dict, t_row: float, t_e: float, at: tuple[float, float] | None = None) -> np.ndarray:
    """d(contact temperature of the turn's row at t_row, at its last repetition T = t_k + m_k P) / d(heat input
    impulse at t_e), per network input (K/J): the ripple's response to delta(t - t_e) - 1/P (the ripple is the
    response to the input less its period mean, thermal/cycle.py `bulk_response`). In modal coordinates
    y = V^-1 C^-1 B e_j of A = -C^-1 K the periodic response is y (e^(x r)/(1 - e^x) + 1/x), x = lambda P,
    r = ((t - t_e) mod P)/P; the ripple at T is that at T less e^(lambda T) times that at 0; the contact
    temperature weighs the pin's and the wheel's bulk by the row's Blok share (docs/sensitivity.md, "Cycle
    averaging"). `at` = (T, share): an instant between the rows (a located peak's) and its share instead of the row's."""
    from mechsim.thermal.cycle_exact import modes
    system = plan.thermal.setup.system
    C, K, B = np.asarray(system.capacity), np.asarray(system.dense_conductance()), np.asarray(system.input_matrix)
    lam, V, Vinv = modes(C, K)
    k = int(np.argmin(np.abs(turn["layout"].t[turn["rows"]] - t_row)))
    T, P, share = float(turn["t_s"][k]), float(turn["period"]), float(turn["share"][k])
    if at is not None:
        T, share = map(float, at)
    names = list(system.state_names)
    weight = np.zeros(system.size)
    weight[names.index("temp_bulk_pin_K")], weight[names.index("temp_bulk_wheel_K")] = share, 1.0 - share
    x = lam * P

    def periodic(t):
        r = np.mod(t - t_e, P) / P
        return (-np.expm1(x) + x * np.exp(x * r)) / (x * -np.expm1(x))
    y = Vinv @ (B / C[:, None])
    return weight @ (V @ ((periodic(T) - np.exp(lam * T) * periodic(0.0))[:, None] * y))


def switch_correction(plan, turn: dict, t_row: float, events, delta: float = 1e-6,
                      at: tuple[float, float] | None = None) -> np.ndarray:
    """The derivative the turn's input linear between rows leaves out, per scaled value, of the contact temperature
    of the turn's row at t_row, where the run's input is exact (`closed_form_turn`), as the events of the turn move:
    at an entry or exit the run's input jumps, at a slip reversal its slope does (|slip speed|), and the run
    integrates it across the event where the interpolation spans the event's row interval [t_i, t_i + h] with the
    rows' values. Moving the input by dt_e in time moves the run's integral over that interval by
    (u(t_i) - u(t_i + h)) dt_e and the interpolation's by -(h/2)(u'(t_i) + u'(t_i + h)) dt_e, so the run's
    bulk moves by `switch_kernel` D dt_e more, D = u(t_i) - u(t_i + h) + (h/2)(u'(t_i) + u'(t_i + h)) (a jump
    du = u(t_e-) - u(t_e+) gives D = du, a kink of slopes -c, c at alpha = t_e - t_i gives D = c (2 alpha - h);
    zero to O(h^3) where the input is smooth). The slopes are the run's input's one-sided differences (step
    `delta`) away from the event. Left out: the change of the input's shape at a fixed distance from the event,
    on the part of the interval the two integrate differently (docs/sensitivity.md, "Cycle averaging").
    events: the traced path's (t, dt per scaled value); `at` as `switch_kernel`'s."""
    layout = turn["layout"]
    a, P = float(turn["t_start"]), float(turn["period"])
    n_in = np.asarray(plan.thermal.setup.system.input_matrix).shape[1]

    def u(t):
        return np.asarray(turn["inputs"](np.asarray(t, float)))[:n_in]
    out = 0.0
    for e in events:
        if not a < e.t < a + P:
            continue
        i = int(np.searchsorted(layout.t, e.t, side="right") - 1)
        t0, t1 = float(layout.t[i]), float(layout.t[i + 1])
        v = u([t0 - delta, t0, t1, t1 + delta])
        D = v[:, 1] - v[:, 2] + 0.5 * (t1 - t0) * ((v[:, 1] - v[:, 0]) + (v[:, 3] - v[:, 2])) / delta
        out = out + float(switch_kernel(plan, turn, t_row, e.t, at) @ D) * np.asarray(e.dt, float)
    return np.asarray(out)


def turn_peak(turn: dict, column: str, t_row: float) -> tuple[float, float]:
    """(value, time) of the periodic turn's row at t_row at its last time in the run: the value from the run's own
    columns and the cycle bulk in numpy (`cycle_temperatures`), so that it is the run's reported peak itself (the
    traced pass, which integrates the path anew, gives its derivative and agrees with it to its tolerance)."""
    k = int(np.argmin(np.abs(turn["layout"].t[turn["rows"]] - t_row)))
    return float(turn[column][k]), float(turn["t_s"][k])


def period_gradient(turn: dict, by_time: dict) -> np.ndarray:
    """dP per scaled value of the turn's period P = b - a, its ends where the drive angle passes its targets, linear
    between the rows around them (thermal/cycle_exact.py `turn_ends`): da = -h (dphi_i (1 - w) + dphi_(i+1) w) /
    (phi_(i+1) - phi_i), the implicit-function rule on the interpolated angle (docs/sensitivity.md, "Cycle
    averaging"); the rows' times are fixed output times. by_time: the traced samples, which hold the rows around
    the turn's ends with the drive angle's gradient wherever the cycle bulk is traced."""
    layout = turn["layout"]
    t = layout.t
    ends = []
    for k, i in enumerate((layout.ia, layout.ib)):
        s0, s1 = by_time[float(t[i])], by_time[float(t[i + 1])]
        p0, p1 = s0.values["crank_angle_rad"], s1.values["crank_angle_rad"]
        w = (layout.targets[k] - p0) / (p1 - p0)
        ends.append(-(t[i + 1] - t[i]) * (np.asarray(s0.grads["crank_angle_rad"]) * (1.0 - w)
                                          + np.asarray(s1.grads["crank_angle_rad"]) * w) / (p1 - p0))
    return ends[1] - ends[0]


def row_repetition(turn: dict, t_row: float) -> tuple[int, float, float, float]:
    """(m, P, time, jump) of the periodic turn's row at t_row (`cycle_temperatures`): its whole periods to its last
    repetition in the run, the period, that repetition's time, and the contact temperature's rise from the previous
    repetition (one period's rise of the bulk)."""
    layout = turn["layout"]
    k = int(np.argmin(np.abs(layout.t[turn["rows"]] - t_row)))
    return (int(layout.periods[k]), float(turn["period"]), float(turn["t_s"][k]),
            float(turn["temp_contact_C"][k] - turn["temp_contact_previous_C"][k]))


def repetition_crosses_end(q: str, wrt: list[str], relative: list[bool], m: int, P: float, time: float, jump: float,
                           duration: float, period_grad: np.ndarray, change: float):
    """A warning where the peak's instant t_w + m P (t_w held in the periodic turn, m whole periods after it, P the
    period) crosses the run's end within the stated change of a value (d(t_w + m P) = m dP): there the last repetition
    leaves the run (or one more enters), m changes and the value jumps by one period's rise of the bulk (`jump`, the
    difference to the previous repetition, stated); the derivative is that at a fixed m."""
    leave, enter = duration - time, time + P - duration      # both >= 0
    found = {}
    for key, d in zip(wrt, period_grad):
        if d != 0:
            need = min(leave / (m * abs(d)) if m > 0 else np.inf, enter / ((m + 1) * abs(d)))
            if need < change:
                found[key] = need
    if not found:
        return None
    rel = dict(zip(wrt, relative))
    return (f"{q}: the last repetition of its instant in the run (t = {time:.6g} s, {leave:.3g} s before the end) "
            f"crosses the run's end within the stated change, where the value jumps by about {jump:.2g} K (one "
            "period's rise of the bulk; the derivative is that at a fixed repetition): "
            + ", ".join(f"{key} " + (f"{d * 100:.2g}%" if rel[key] else f"{d:.2g} (absolute)")
                        for key, d in found.items()))


def repetition_trend(m: int, P: float, jump: float, period_grad: np.ndarray) -> np.ndarray:
    """The trend of the cycle-averaged run's peak across repetitions less its derivative, per scaled value
    (docs/sensitivity.md, "A thermal sizing"): the peak rides on the bulk's rise at its last repetition
    t_w + m P <= duration, which a change dP of the period moves by m dP; each time it crosses the run's end one
    repetition more (or less) is in the run and the peak jumps by the bulk's rise over a period, dT_P (`jump`). So the
    peak is a sawtooth in any value that moves the period, whose teeth have the derivative's slope and whose trend
    adds -dT_P m dP / P: what a change of more than a few teeth sees."""
    return -jump * m * np.asarray(period_grad, dtype=float) / P


def event_row_trend(plan, turn: dict, t_row: float, events) -> np.ndarray:
    """The trend of the cycle-averaged run's peak across the output rows the turn's events cross, less its
    derivative, per scaled value (docs/sensitivity.md, "A thermal sizing"). The run's turn input is linear between
    its output rows (a motor drive's DAE window), so where it jumps at an event (a Geneva's entry and exit) the input
    integral at fixed row modes does not follow the event, and each time the event crosses a row that row changes
    mode and the bulk jumps by about one row's heat: a sawtooth whose teeth have the derivative's slope and whose
    trend is the exact input's, the translated jump du dt_e through `switch_kernel` (the mean over the event's place
    in its row interval of `switch_correction`'s D is du; a kink such as the slip reversal has du = 0, its D averages
    to zero). du = u(t_e-) - u(t_e+), each side extrapolated linearly from the two rows on that side. events: the
    traced path's (t, dt per scaled value)."""
    u, t = turn["row_inputs"], turn["layout"].t
    a, P = float(turn["t_start"]), float(turn["period"])
    out = 0.0
    for e in events if u is not None else ():
        if not a < e.t < a + P:
            continue
        i = int(np.searchsorted(t, e.t, side="right") - 1)
        if i < 1 or i + 2 >= len(t):
            continue
        left = u[i] + (u[i] - u[i - 1]) * (e.t - t[i]) / (t[i] - t[i - 1])
        right = u[i + 1] + (u[i + 1] - u[i + 2]) * (t[i + 1] - e.t) / (t[i + 2] - t[i + 1])
        out = out + float(switch_kernel(plan, turn, t_row, e.t) @ (left - right)) * np.asarray(e.dt, float)
    return np.asarray(out)


_CYCLE_FNS: dict = {}


def _input_fn(ext, distribution: str, pmap):
    """(x, cols, engaged) -> the network's inputs (rows x inputs) from the mechanism's contact columns and the heat
    rate at each row (`ParameterMap.contact_row`, thermal/coupling.py `heat_inputs`), zero where not engaged."""
    import jax.numpy as jnp

    from mechsim.thermal.coupling import heat_inputs
    nc = len(pmap.contact_columns)

    def inputs(x, cols, engaged):
        contact = {**pmap.contact_row([cols[:, i] for i in range(nc)], x["R"], jnp), "heat_rate": cols[:, nc]}
        u, _, _ = heat_inputs(contact, x.__getitem__, ext.inputs, distribution, jnp)
        return jnp.where(engaged[:, None], jnp.stack(u, axis=1), 0.0)
    return inputs


def _jitted_bulk(kind: str, ext, distribution: str, pmap, bulk_of):
    """(fn, fresh): fn(x, dx, data) -> (bulk, its jvp along the leading axis of dx) of `bulk_of(x, data, network,
    inputs)` (inputs: `_input_fn`, the heat input from the contact columns), jitted once per kind, network,
    distribution and contact row (`_CYCLE_FNS`); fresh says whether it was made now (its first call compiles)."""
    import jax
    import jax.numpy as jnp

    B = np.asarray(ext.system.input_matrix)
    key = (kind, ext.structure_key(), B.tobytes(), pmap.contact_row, pmap.contact_columns)
    fn = _CYCLE_FNS.get(key)
    if fn is not None:
        return fn, False
    inputs = _input_fn(ext, distribution, pmap)

    def bulk(x, data):
        network = {"capacity": x["capacity"], "conductance": x["conductance"], "source": x["source"],
                   "input_matrix": jnp.asarray(B)}
        return bulk_of(x, data, network, inputs)

    def both(x, dx, data):
        return bulk(x, data), jax.vmap(lambda d: jax.jvp(lambda y: bulk(y, data), (x,), (d,))[1])(dx)
    fn = _CYCLE_FNS[key] = jax.jit(both)
    return fn, True


def _cycle_bulk_fn(ext, distribution: str, pmap):
    """`_jitted_bulk` of the cycle-averaged bulk as a function of the traced values x (thermal/cycle_exact.py
    `turn_bulk`, the heat input of each row by thermal/coupling.py `heat_inputs`); the turn's rows are padded, so a
    new design needs no new one. The columns are the mechanism's contact columns and the heat rate
    (`_input_columns`)."""
    import jax.numpy as jnp

    from mechsim.thermal.cycle_exact import turn_bulk

    def bulk_of(x, data, network, inputs):
        return turn_bulk(data, x["angle"], x["gen"], x["pin"], inputs(x, x["cols_edges"], data["engaged_edges"]),
                         inputs(x, x["cols_inner"], data["engaged_inner"]), network, x["start"], jnp)[0]
    return _jitted_bulk("rows", ext, distribution, pmap, bulk_of)


def _network_parameters(plan, seed, model, n: int, primal: dict, tangent: dict) -> None:
    """Add to primal/tangent (n tangents, padded) the heat share's parameters, the contact radius R and the network's
    capacity, conductance and source from the model's parameters, checked to be the run's network."""
    from mechsim.dynamics.sensitivity import SensitivityUnavailable
    from mechsim.thermal.coupling import SHARE_PARAMETERS
    ext = plan.thermal.setup.extension
    sysm = ext.system
    names = list(model.parameter_names)
    values = {**plan.mechanism.parameter_values(), **ext.parameter_values()}

    def parameter(name):
        return values[name], np.pad(seed.dp[names.index(name)], (0, n - seed.n))
    for name in SHARE_PARAMETERS + ("R",):
        primal[name], tangent[name] = parameter(name)
    size = sysm.size
    for key, prefix, shape in (("capacity", "th_C_", (size,)), ("conductance", "th_K_", (size, size)),
                               ("source", "th_s_", (size,))):
        x, dx = np.zeros(shape), np.zeros(shape + (n,))
        for idx in np.ndindex(*shape):
            name = prefix + "_".join(map(str, idx))
            if name in values:
                x[idx], dx[idx] = parameter(name)
        primal[key], tangent[key] = x, dx
    reference = _network(sysm)
    for key in ("capacity", "conductance", "source"):
        if not np.allclose(primal[key], reference[key], rtol=1e-13, atol=0.0):
            raise SensitivityUnavailable(f"the network's {key} from the model's parameters is not the run's")


def cycle_bulk_samples(plan, df: pd.DataFrame, turn: dict, by_time: dict, seed, model, samples: list,
                        stats: dict) -> None:
    """Replace the bulk temperatures (values, gradients) of the samples at the turn's rows by the cycle-averaged ones:
    thermal/cycle_exact.py `turn_bulk` evaluated in jax on the run's rows and pushed forward (jvp) along the traced
    columns of every row of the turn (the drive angle, the energies and the network's states at its ends, the contact
    that makes the heat input) and the network's and heat share's parameters. The jax evaluation must give the numpy one
    (to 1e-9 K), as the row formulas must give the run's columns."""
    import jax.numpy as jnp

    from mechsim.dynamics.sensitivity import COLUMNS, SensitivityUnavailable
    from mechsim.thermal.contact_row import KELVIN
    setup = plan.thermal.setup
    ext, sysm, layout = setup.extension, setup.system, turn["layout"]
    t = layout.t
    # tangents padded with zero columns to a multiple of COLUMNS, as the path's pass pads them: the compiled bulk
    # (`_cycle_bulk_fn`) then serves any number of values up to that (its shapes include the tangents' number)
    n_used = seed.n
    n = COLUMNS * -(-n_used // COLUMNS)
    engaged = df["mode"].to_numpy() == "engaged"
    def columns(cols, rows, contact=True):
        """The run's columns (primal) and the samples' gradients (tangent, rows x columns x n) at `rows`; with
        `contact`, rows without contact get 1 and no gradient (their heat input is masked to zero)."""
        x = np.ones((len(rows), len(cols)))
        dx = np.zeros((len(rows), len(cols), n))
        for r, i in enumerate(rows):
            if engaged[i] or not contact:
                x[r] = [float(df[c].iloc[i]) for c in cols]
                dx[r, :, :n_used] = [by_time[float(t[i])].grads[c] for c in cols]
        return x, dx

    primal, tangent = {}, {}
    edges = layout.edges
    for key, col in (("angle", "crank_angle_rad"), ("gen", "heat_generated_J"), ("pin", "heat_pin_J")):
        x, dx = columns([col], edges, contact=False)
        primal[key], tangent[key] = x[:, 0], dx[:, 0]
    pmap = plan.mechanism.parameter_map()
    inputs = pmap.contact_columns + ("friction_power_W",)
    # the network's states at the turn's ends (the table keeps them as temp_bulk_<body>_C, the path by their names)
    primal["start"] = np.column_stack([df[name[:-2] + "_C"].to_numpy(float)[edges] + KELVIN
                                       for name in sysm.state_names])
    tangent["start"] = np.zeros(primal["start"].shape + (n,))
    for r, i in enumerate(edges):
        tangent["start"][r, :, :n_used] = [by_time[float(t[i])].grads[name] for name in sysm.state_names]
    primal["cols_edges"], tangent["cols_edges"] = columns(inputs, edges)
    primal["cols_inner"], tangent["cols_inner"] = columns(inputs, layout.padded)
    _network_parameters(plan, seed, model, n, primal, tangent)
    data = {**layout.data(), "engaged_edges": engaged[edges], "engaged_inner": engaged[layout.padded]}
    x = {k: jnp.asarray(v, jnp.float64) for k, v in primal.items()}
    dx = {k: jnp.moveaxis(jnp.asarray(v, jnp.float64), -1, 0) for k, v in tangent.items()}
    fn, fresh = _cycle_bulk_fn(ext, setup.section["distribution"], pmap)
    wall = time.perf_counter()
    value, grads = fn(x, dx, data)
    if fresh:            # compiled on its first call (with a first evaluation of ~0.2 s): counted as compilation
        stats["compile_time_s"] += time.perf_counter() - wall
    value, grads = np.asarray(value)[layout.pad:], np.asarray(grads)[:n_used, layout.pad:]   # (n, rows, states)
    if not np.all(np.abs(value - turn["bulk"]) <= 1e-9 * np.maximum(1.0, np.abs(turn["bulk"]))):
        raise SensitivityUnavailable("the traced cycle-averaged bulk is not the one the quantity is read from "
                                     f"(difference {np.max(np.abs(value - turn['bulk'])):.2e} K)")
    state_names = list(sysm.state_names)
    inner = t[layout.inner]
    for s in samples:
        # a sample between the turn's rows (a located peak's instant) reads the bulk linearly between the rows
        # around it, at their last repetitions: the bulk is smooth there, so the error is O(h^2) of its curvature
        k = int(np.clip(np.searchsorted(inner, s.t), 1, len(inner) - 1))
        w = float(np.clip((s.t - inner[k - 1]) / (inner[k] - inner[k - 1]), 0.0, 1.0))
        for name in ("temp_bulk_pin_K", "temp_bulk_wheel_K"):
            j = state_names.index(name)
            s.values[name] = float((1 - w) * value[k - 1, j] + w * value[k, j])
            s.grads[name] = (1 - w) * grads[:, k - 1, j] + w * grads[:, k, j]



def event_crosses_turn_row(q: str, wrt: list[str], relative: list[bool], turn: dict, events, change: float):
    """A warning where an event inside the periodic turn moves past an output row within the stated change of a
    value: that row's heat input (the turn's input is linear between rows) then changes mode, and the cycle-averaged
    bulk jumps by about one row's heat (the run's reported temperatures with it); the derivative holds up to there."""
    t = turn["layout"].t
    inner = t[turn["layout"].inner]
    rel = dict(zip(wrt, relative))
    found = {}
    for e in events:
        if not inner[0] <= e.t <= inner[-1]:
            continue
        gap = float(np.min(np.abs(inner - e.t)))
        for key, d in zip(wrt, e.dt):
            if d != 0 and gap / abs(d) < min(change, found.get(key, (np.inf,))[0]):
                found[key] = (gap / abs(d), e.kind, e.t)
    if not found:
        return None
    return (f"{q}: an event of the periodic turn crosses an output row within the stated change, where the turn's "
            "heat input (linear between rows) and with it the cycle-averaged bulk jump by about one row's heat: "
            + ", ".join(f"{key} " + (f"{d * 100:.2g}%" if rel[key] else f"{d:.2g} (absolute)")
                        + f" ('{kind}' at t = {te:.6g} s)" for key, (d, kind, te) in found.items()))


# ------------------------------------------------------------------------------ the turn read on the solution
#: the traced turn's pieces are padded to a multiple of this (zero-length pieces at its end), its instants to a
#: multiple of SAMPLES_PAD, so that one compilation serves the designs near one another
PIECES_PAD = 256
SAMPLES_PAD = 8


def dense_turn(run_plan) -> dict | None:
    """The periodic turn of a cycle-averaged DAE run as the run reads it on its window's solution (thermal/plan.py
    `ThermalPlan._read_input`, docs/sensitivity.md "Cycle averaging"): its ends a, b where the drive passes its start
    angle, the pieces its heat input is read on (fixed by the turn and its events, `input_pieces`) with their
    Gauss-Legendre nodes, and the window's columns read there and at the ends (the primal values of the traced
    bulk: the run's own). None where the window cannot be read or holds no full turn. `sample_times`: the instants
    the sensitivity pass must sample (the ends, then every node)."""
    from mechsim.scenarios import runner
    from mechsim.thermal.plan import input_nodes, input_pieces
    got = runner.read_window(run_plan)
    if got is None:
        return None
    thermal, window = got
    solution = thermal.cycle_solution(window)
    if solution is None or "input" not in solution:
        return None
    a, P = solution["means"].t_start, solution["means"].period
    readings = thermal.dense
    edges, lo, hi = input_pieces(a, P, readings.breaks)
    x = input_nodes()
    rel = edges - a
    nodes = a + (rel[:-1, None] + np.diff(rel)[:, None] * x[None, :])        # as `_read_input` reads them
    ends = np.array([a, a + P])
    return {"thermal": thermal, "solution": solution, "t_start": a, "period": P, "edges": edges, "lo": lo, "hi": hi,
            "node_offsets": x, "nodes": nodes, "frame": readings.memo[("frame", a, P)],
            "ends_frame": readings.read(ends), "duration": float(run_plan.scenario.si["duration"]),
            "sample_times": [float(t) for t in ends] + [float(t) for t in nodes.ravel()]}


def _dense_bulk_fn(ext, distribution: str, pmap):
    """`_jitted_bulk` of `dense_turn_bulk` (thermal/cycle_exact.py) with the input from the contact columns at the
    nodes."""
    import jax.numpy as jnp

    from mechsim.thermal.cycle_exact import dense_turn_bulk

    def bulk_of(x, data, network, inputs):
        pieces, nodes = data["piece_shape"].shape
        u = inputs(x, x["cols"], data["engaged"]).reshape(pieces, nodes, -1)
        return dense_turn_bulk(x, data, network, u, jnp)[0]
    return _jitted_bulk("dense", ext, distribution, pmap, bulk_of)


def dense_bulk_samples(plan, turn: dict, by_time: dict, seed, model, samples: list, periods: dict, events,
                       stats: dict) -> None:
    """Replace the bulk temperatures (values, gradients) of `samples` (instants t_w of the periodic turn, each
    standing for t_w + m P, m = periods[t_w]) by the cycle-averaged bulk of the turn read on the solution
    (`dense_turn`, thermal/cycle_exact.py `dense_turn_bulk`), pushed forward (jvp) along the total derivatives of what
    it is made of: the turn's ends, da = -dphi(a)/phi'(a) (the implicit-function rule on the drive angle, read on
    the traced path at a); the energies and the network's states there, dX(a) = X_p(a) + X'(a) da; the pieces'
    ends, each fixed between two cuts (the turn's ends and its events, whose times' derivatives the path gives) so
    moving with them; the contact columns at every node, moving with its piece, X_p + X' dt_node; and the network's
    and heat share's parameters. The primal values are the run's own readings; the jax evaluation must give the
    run's cycle-averaged bulk (`ThermalPlan.cycle_states`) at t_w + m P (to 1e-9 relative)."""
    import jax.numpy as jnp

    from mechsim.dynamics.sensitivity import COLUMNS, SensitivityUnavailable
    from mechsim.thermal.cycle_exact import lagrange_monomials
    setup = plan.thermal.setup
    ext, sysm = setup.extension, setup.system
    n_used = seed.n
    n = COLUMNS * -(-n_used // COLUMNS)
    a, P = turn["t_start"], turn["period"]

    def grad(s, c):
        return np.pad(np.asarray(s.grads[c], float), (0, n - n_used))
    ends = [by_time[t] for t in turn["sample_times"][:2]]
    d_ends = [-grad(s, "crank_angle_rad") / s.rates["crank_angle_rad"] for s in ends]
    # the cuts' derivatives: the turn's ends and the events between them (the traced path's, matched by time)
    cuts = {a: d_ends[0], a + P: d_ends[1]}
    for c in np.unique(np.concatenate([turn["lo"], turn["hi"]])):
        if float(c) in cuts:
            continue
        e = min(events, key=lambda ev: abs(ev.t - c), default=None)
        if e is None or abs(e.t - c) > 1e-6 * P:
            raise SensitivityUnavailable(f"no traced event at the turn's break t = {c:.9g} s")
        cuts[float(c)] = np.pad(np.asarray(e.dt, float), (0, n - n_used))
    edges, lo, hi = turn["edges"], turn["lo"], turn["hi"]
    w = ((edges - lo) / (hi - lo))[:, None]
    d_edges = np.array([cuts[float(x)] for x in lo]) * (1 - w) + np.array([cuts[float(x)] for x in hi]) * w
    xo = turn["node_offsets"][None, :, None]
    d_nodes = (d_edges[:-1, None, :] * (1 - xo) + d_edges[1:, None, :] * xo).reshape(-1, n)
    pmap = plan.mechanism.parameter_map()
    names = pmap.contact_columns + ("friction_power_W",)
    frame = turn["frame"]
    node_t = turn["sample_times"][2:]
    cols = frame[list(names)].to_numpy(float)
    # each column's gradient plus its rate times the node's motion, all nodes at once (grad(s, c) + rate d_node)
    at_nodes = [by_time[t] for t in node_t]
    d_cols = np.zeros(cols.shape + (n,))
    for j, c in enumerate(names):
        d_cols[:, j, :n_used] = np.array([s.grads[c] for s in at_nodes], dtype=float)
        d_cols[:, j] += np.array([s.rates[c] for s in at_nodes], dtype=float)[:, None] * d_nodes
    engaged = frame["mode"].to_numpy() == "engaged"
    primal, tangent = {"ends": np.array([a, a + P]), "cols": np.where(engaged[:, None], cols, 1.0)}, {}
    tangent["ends"] = np.array(d_ends)
    tangent["cols"] = np.where(engaged[:, None, None], d_cols, 0.0)
    at_ends = turn["ends_frame"]
    for key, col in (("gen", "heat_generated_J"), ("pin", "heat_pin_J")):
        primal[key] = at_ends[col].to_numpy(float)
        tangent[key] = np.array([grad(s, col) + s.rates[col] * d for s, d in zip(ends, d_ends)])
    state_names = list(sysm.state_names)
    primal["start"] = at_ends[state_names].to_numpy(float)[0]
    tangent["start"] = np.array([grad(ends[0], c) + ends[0].rates[c] * d_ends[0] for c in state_names])
    primal["edges"], tangent["edges"] = edges, d_edges
    _network_parameters(plan, seed, model, n, primal, tangent)
    # padding: zero-length pieces at b, the instants repeated
    pieces, nodes = turn["nodes"].shape
    extra = PIECES_PAD * -(-pieces // PIECES_PAD) - pieces
    primal["edges"] = np.concatenate([edges, np.full(extra, edges[-1])])
    tangent["edges"] = np.concatenate([d_edges, np.repeat(d_edges[-1:], extra, axis=0)])
    primal["cols"] = np.concatenate([primal["cols"], np.ones((extra * nodes, cols.shape[1]))])
    tangent["cols"] = np.concatenate([tangent["cols"], np.zeros((extra * nodes,) + d_cols.shape[1:])])
    times = np.array([s.t for s in samples], float)
    m = np.array([periods[s.t] for s in samples], float)
    count = SAMPLES_PAD * -(-len(times) // SAMPLES_PAD)
    data = {"weights": np.polynomial.legendre.leggauss(nodes)[1] / 2,
            "lagrange": lagrange_monomials(turn["node_offsets"]),
            "piece": np.clip(np.searchsorted(edges, np.resize(times, count), side="right") - 1, 0, pieces - 1),
            "times": np.resize(times, count), "periods": np.resize(m, count),
            "engaged": np.concatenate([engaged, np.zeros(extra * nodes, bool)]),
            "piece_shape": np.zeros((pieces + extra, nodes))}
    x = {k: jnp.asarray(v, jnp.float64) for k, v in primal.items()}
    dx = {k: jnp.moveaxis(jnp.asarray(v, jnp.float64), -1, 0) for k, v in tangent.items()}
    fn, fresh = _dense_bulk_fn(ext, setup.section["distribution"], pmap)
    wall = time.perf_counter()
    value, grads = fn(x, dx, {k: jnp.asarray(v) for k, v in data.items()})
    if fresh:
        stats["compile_time_s"] += time.perf_counter() - wall
    value, grads = np.asarray(value)[:len(times)], np.asarray(grads)[:n_used, :len(times)]
    run = plan.thermal.cycle_states(turn["solution"], times + m * P)
    if not np.all(np.abs(value - run) <= 1e-9 * np.maximum(1.0, np.abs(run))):
        raise SensitivityUnavailable("the traced cycle-averaged bulk is not the run's "
                                     f"(difference {np.max(np.abs(value - run)):.2e} K)")
    previous = plan.thermal.cycle_states(turn["solution"], times + (m - 1) * P)
    turn["period_grad"] = (d_ends[1] - d_ends[0])[:n_used]
    turn.setdefault("rises", {})
    for k, s in enumerate(samples):
        rise = {}
        for name in ("temp_bulk_pin_K", "temp_bulk_wheel_K"):
            j = state_names.index(name)
            s.values[name], s.grads[name] = float(value[k, j]), grads[:, k, j]
            rise[name] = float(value[k, j] - previous[k, j])
        turn["rises"][s.t] = rise


def dense_jump(turn: dict, sample) -> float:
    """The contact temperature's rise from the previous repetition of the periodic turn's instant `sample` (traced,
    with its bulk from `dense_bulk_samples` and its contact temperature from the row's formulas): the bulk's rise over
    one period weighted by the Blok share, T_c = gamma T_pin + (1 - gamma) T_wheel + dT_flash (thermal/plan.py)."""
    from mechsim.thermal.contact_row import KELVIN
    pin, wheel = sample.values["temp_bulk_pin_K"], sample.values["temp_bulk_wheel_K"]
    gamma = (sample.values["temp_contact_C"] + KELVIN - sample.values["temp_flash_rise_K"] - wheel) / (pin - wheel)
    rise = turn["rises"][sample.t]
    return float(gamma * rise["temp_bulk_pin_K"] + (1.0 - gamma) * rise["temp_bulk_wheel_K"])
