"""Shared fixtures: the seed geometry (docs/theory.md §G0) and helpers to build scenarios in memory."""
import atexit
import copy
import os
import secrets
import shutil
import tempfile
import tomllib

import numpy as np
import pytest

from mechsim.mechanisms.geneva.kinematics import GenevaGeometry
from mechsim.scenarios.loader import builtin_text


#: the user-cache folder this process made for the session (removed at its exit), None when one was given
_OWN_CACHE: str | None = None


def pytest_configure(config):
    """One fuzz seed for the whole run (the xdist workers inherit it), new each run unless MECHSIM_FUZZ_SEED is
    set (tests/test_fuzz_scenarios.py)."""
    os.environ.setdefault("MECHSIM_FUZZ_SEED", str(secrets.randbelow(2**32)))
    # the default backend compiles no callbacks of its own during the tests: a run's backend then never depends on
    # how far a background compilation had got (tests/test_ida_compiled.py tests that compilation by itself)
    os.environ.setdefault("MECHSIM_BACKGROUND_COMPILE", "0")
    # mechsim's user cache (derivations, compiled callbacks and their ready marks, units) fresh for the session, as
    # on a clean machine, unless MECHSIM_CACHE_DIR is set: the default backend's choice (ida-compiled where a
    # model's callbacks are cached and marked ready) must not follow what this machine ran before
    global _OWN_CACHE
    if "MECHSIM_CACHE_DIR" not in os.environ:
        _OWN_CACHE = tempfile.mkdtemp(prefix="mechsim-test-cache-")
        os.environ["MECHSIM_CACHE_DIR"] = _OWN_CACHE
        # removed at exit, after what the session's own exit handlers write there (the unit cache's flush is
        # registered later, and atexit runs the last registered first)
        atexit.register(shutil.rmtree, _OWN_CACHE, True)
    config.pluginmanager.register(xdist_schedule.Schedule(config), "mechsim-xdist-schedule")


def pytest_addoption(parser):
    xdist_schedule.addoption(parser)


def pytest_terminal_summary(terminalreporter):
    """The fuzz's case count and seed, where a fuzz test ran (in this process or an xdist worker)."""
    ran = [r for kind in ("passed", "failed") for r in terminalreporter.stats.get(kind, [])
           if getattr(r, "when", "call") == "call"
           and getattr(r, "nodeid", "").split("::")[0].endswith("test_fuzz_scenarios.py")]
    if not ran:
        return
    from test_fuzz_scenarios import FUZZ_EXAMPLES       # tests/ is on the path, as for cli_helpers
    seed = os.environ["MECHSIM_FUZZ_SEED"]
    terminalreporter.write_line(f"scenario fuzzing: {FUZZ_EXAMPLES} generated cases, seed {seed} "
                                f"(MECHSIM_FUZZ_SEED={seed} repeats them)")


@pytest.fixture(scope="session")
def seed_geometry():
    """Seed geometry: r = 75 mm, n = 4, R = 4 mm, l = 4 mm (docs/theory.md §G0)."""
    return GenevaGeometry(crank_radius=0.075, slots=4, pin_radius=0.004, thickness=0.004)


@pytest.fixture
def lc1_raw():
    """The built-in geneva-lc1 scenario as a dict, to modify in a test."""
    return copy.deepcopy(tomllib.loads(builtin_text("geneva-lc1")))


def wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def assert_wheel_matches_closed_form(geometry, df, crank_speed, rel=1e-6):
    """Wheel angle, speed and acceleration of a run at constant crank speed against docs/theory.md §G1's closed
    forms, each to `rel` of its peak; the crank keeps the prescribed speed."""
    import mechsim.mechanisms.geneva.kinematics as gk
    cf = gk.constant_speed_motion(geometry, df["crank_angle_rad"].to_numpy(), crank_speed)
    for key, col in [("wheel_angle", "wheel_angle_rad"), ("wheel_speed", "wheel_speed_rad_s"),
                     ("wheel_accel", "wheel_accel_rad_s2")]:
        scale = np.max(np.abs(cf[key]))
        assert np.max(np.abs(df[col].to_numpy() - cf[key])) <= rel * scale, key
    np.testing.assert_allclose(df["crank_speed_rad_s"], crank_speed, rtol=1e-9)


@pytest.fixture(scope="module")
def m1():
    """El-Shakery Mech 1 (3 sprockets), docs/theory.md §K1.3."""
    from mechsim.mechanisms.chain.dwell import MECH1, ChainDwellMechanism
    return ChainDwellMechanism(MECH1)


@pytest.fixture(scope="module")
def m2():
    """El-Shakery Mech 2 (4 sprockets), docs/theory.md §K1.3."""
    from mechsim.mechanisms.chain.dwell import MECH2, ChainDwellMechanism
    return ChainDwellMechanism(MECH2)


def richardson_central(evaluate, p: float, h: float) -> dict:
    """d(quantity)/dp for every quantity evaluate(value) returns: central differences with relative steps h and
    h/2, Richardson-extrapolated (error O(h^4) instead of O(h^2))."""
    diffs = {}
    for step in (h, h / 2):
        plus, minus = evaluate(p * (1 + step)), evaluate(p * (1 - step))
        diffs[step] = {q: (plus[q] - minus[q]) / (2 * p * step) for q in plus}
    return {q: (4 * diffs[h / 2][q] - diffs[h][q]) / 3 for q in diffs[h]}


def assert_matches_finite_differences(part, ref0: dict, fd: dict, p: float, key: str, value_rel: float,
                                      floor: float, worst: dict) -> None:
    """Each quantity's value equals the finite differences' nominal run to value_rel, and its elasticity
    (p/y) dy/dp that of the finite difference to 1e-4 relative, or `floor` absolute where that is larger (a
    derivative that is zero to the differences' own accuracy). Exact zeros must be exact in both.
    `worst` collects the relative deviations of the derivatives that are not near zero."""
    for q in ref0:
        assert part.loc[q, "value"] == pytest.approx(ref0[q], rel=value_rel)
        d = part.loc[q, "derivative"]
        if ref0[q] == 0.0:                 # no friction, no heat: exactly zero, and so its derivatives
            assert d == 0.0 and fd[q] == 0.0, (q, key, d, fd[q])
            continue
        e, e_fd = p / ref0[q] * d, p / ref0[q] * fd[q]
        assert abs(e - e_fd) <= 1e-4 * abs(e_fd) + floor, (q, key, d, fd[q])
        if abs(e_fd) > 100 * floor:
            worst[q] = max(worst.get(q, 0.0), abs(d - fd[q]) / abs(fd[q]))



def value_setting(si: dict, key: str, value: float, unit: str) -> str:
    """--set of one value in SI (`unit`, '' for a plain number); a list entry ('mechanism.sprockets[1][0]') sets its
    whole list with that entry replaced and the others as the scenario gives them (the loader sets lists whole)."""
    def quoted(v):
        return f'"{v!r} {unit}"' if unit else repr(v)
    if "[" not in key:
        return f"{key}={quoted(value)}"
    name, *idx = key.split("[")
    idx = [int(i.rstrip("]")) for i in idx]
    entries = [list(e) if isinstance(e, list) else e for e in si["mechanism"][name.split(".")[1]]]
    node = entries
    for i in idx[:-1]:
        node = node[i]
    node[idx[-1]] = value

    def text(e):
        return "[" + ", ".join(text(x) for x in e) + "]" if isinstance(e, list) else quoted(e)
    return f"{name}={text(entries)}"


def locating(plan, columns=()):
    """The runner's plan whose run locates the peaks of only the mechanism's `columns` (and, as ever, the thermal
    model's): for finite differences that read a few peaks. Each column's extrema are located on their own
    (scenarios/peaks.py), so those read are the full run's, bit for bit; what is skipped is locating the others and
    reading their approaches to the events, most of a run's time at rtol 1e-12. The timeseries and events are the
    run's."""
    import dataclasses
    mech = copy.copy(plan.mechanism)
    mech.peak_columns = tuple(c for c in mech.peak_columns if c in columns)
    return dataclasses.replace(plan, mechanism=mech)


def run_locating(scenario, columns=()):
    """`mechsim.run(scenario)` (a loaded Scenario) locating the peaks of only the mechanism's `columns` (`locating`)."""
    from mechsim.scenarios import runner
    return runner.execute(locating(runner.plan(scenario), columns))


def located_peak(result, column: str, side: str | None = None) -> float:
    """The run's located peak of `column` as `mechsim sensitivity` reports it: the extremum of larger magnitude
    (summary.json peaks, `abs_max`), signed (docs/theory.md §K5); side 'max' or 'min' picks one (where the two are
    equal in magnitude, a symmetric motion, the larger may be either from one run to the next)."""
    entry = result.summary["peaks"][column]
    return float(entry[side or entry["abs_max"]["side"]]["value"])


def peaks_match_finite_differences(name: str, table, wrt: list, fd_sets: list, steps: dict, si: dict,
                                   value_rel: float, floor: float) -> dict:
    """Every peak of the sensitivity `table` against Richardson central differences of `mechsim.run(name)` with
    `fd_sets`: differences of the runs' located peaks (`located_peak`), with the relative step steps[key] for each key of `wrt` (set in SI, the table's `wrt_unit`); returns the
    largest relative deviation per quantity (`assert_matches_finite_differences`)."""
    import mechsim
    from mechsim.scenarios.studies.sensitivity import PEAKS
    peaks = [q for q in dict.fromkeys(table["quantity"]) if q in PEAKS]
    # the side the table differentiates (its value's sign), so that a tie of max and -min reads the same side
    sides = {q: "max" if table.loc[table["quantity"] == q, "value"].iloc[0] >= 0 else "min" for q in peaks}

    def at_rows(sets):
        r = run_locating(mechsim.load(name, set=sets), [PEAKS[q] for q in peaks])
        assert r.failure is None, r.failure.message()
        return {q: located_peak(r, PEAKS[q], sides[q]) for q in peaks}
    ref0 = at_rows(fd_sets)
    worst: dict = {}
    for key in wrt:
        part = table[table["wrt"] == key].set_index("quantity")
        p, unit = float(part["parameter"].iloc[0]), part["wrt_unit"].iloc[0]
        fd = richardson_central(lambda value: at_rows(fd_sets + [value_setting(si, key, value, unit)]), p, steps[key])
        assert_matches_finite_differences(part, ref0, fd, p, key, value_rel, floor, worst)
    return worst

# the xdist schedule, derived from the durations and compiled programs the suite records (tests/xdist_schedule.py)
import xdist_schedule  # noqa: E402

# one persistent jax compilation cache per session (tests/jax_cache.py), before any test imports jax
import jax_cache  # noqa: E402

jax_cache.share()


def pytest_unconfigure(config):
    jax_cache.remove()


def assert_peaks_bracket_rows(runs: dict, columns, rel: float) -> None:
    """Every run's located max of each column is at least, and its min at most, the column's output rows (a
    located extremum of the continuous solution is never below a sample of it), up to `rel` of the column's size."""
    import numpy as np
    for step, r in runs.items():
        for col in columns:
            rows = r.timeseries[col].to_numpy(float)
            entry = r.summary["peaks"][col]
            scale = rel * max(1.0, float(np.nanmax(np.abs(rows))))
            assert entry["max"]["value"] >= np.nanmax(rows) - scale, (col, step)
            assert entry["min"]["value"] <= np.nanmin(rows) + scale, (col, step)
