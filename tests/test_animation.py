"""The animation: the drawing follows the rows, the arrow is the contact force, the contact colour its
temperature, the cursor the row's time; a GIF of 200 frames; `mechsim animate` and [output] animation."""
import math

import numpy as np
import pytest
from matplotlib import colormaps
from PIL import Image

from mechsim.scenarios.loader import build_mechanism, load
from mechsim.scenarios.output.animation import Animator, frame_rows
from mechsim.mechanisms.drawing import TEMPERATURE_MAP
from mechsim.scenarios.runner import run


@pytest.fixture(scope="module")
def geneva():
    sc = load("geneva-lc1", ["duration='1.5 s'", "output_step='2 ms'"])
    return run(sc), build_mechanism(sc.si)


def _arrow(drawing):
    return np.array([drawing.arrow.U[0], drawing.arrow.V[0]]), drawing.arrow.get_offsets()[0]


def test_frames_spread_evenly_over_the_run(geneva):
    result, _ = geneva
    t = result.timeseries["t_s"].to_numpy()
    rows = frame_rows(result.timeseries, 200)
    assert len(rows) == 200 and rows[0] == 0 and rows[-1] == len(t) - 1
    np.testing.assert_allclose(t[rows], np.linspace(t[0], t[-1], 200), atol=2e-3)   # one output step


def test_geneva_arrow_is_the_normal_force_and_the_pin_colours_with_temperature(geneva):
    result, mech = geneva
    df = result.timeseries
    anim = Animator(result, mech, frames=10)
    d = anim.drawing
    g = mech.geometry
    peak = int(np.argmax(np.abs(df["contact_force_N"].to_numpy())))
    d.update(df.iloc[peak])
    vec, at = _arrow(d)
    row = df.iloc[peak]
    theta = row["crank_angle_rad"]
    pin = 1e3 * np.array([g.centre_distance - g.crank_radius * math.cos(theta), g.crank_radius * math.sin(theta)])
    np.testing.assert_allclose(at, pin, rtol=1e-12)
    f = np.abs(df["contact_force_N"].to_numpy())
    typical = np.percentile(f[f > 0], 99)                              # the arrow's nominal force
    nominal = 0.45 * g.crank_radius * 1e3
    np.testing.assert_allclose(np.hypot(*vec), min(abs(row["contact_force_N"]) / typical, 1.6) * nominal, rtol=1e-12)
    assert abs(vec @ pin) < 1e-9 * np.hypot(*vec) * np.hypot(*pin)     # across the slot (the pin is on its line)
    assert _cross(pin, vec) * row["contact_force_N"] > 0             # N > 0 turns the wheel forward
    colour = colormaps[TEMPERATURE_MAP](d.temperature(row["temp_contact_C"]))
    np.testing.assert_allclose(d.pin.get_facecolor(), colour)
    dwell = int(np.flatnonzero(df["mode"].to_numpy() == "dwell")[0])
    d.update(df.iloc[dwell])
    assert np.hypot(*_arrow(d)[0]) == 0.0
    # the wheel polygon turns with the wheel angle: a slot's centre line follows psi
    assert np.allclose(d.wheel.get_xy()[0], _rot(d.wheel_shape[0], df["wheel_angle_rad"].iloc[dwell]))


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _rot(p, a):
    return np.array([p[0] * math.cos(a) - p[1] * math.sin(a), p[0] * math.sin(a) + p[1] * math.cos(a)])


def test_cursor_follows_the_frames_and_frames_change(geneva):
    result, mech = geneva
    anim = Animator(result, mech, frames=6)
    frames = list(anim.frames())
    assert len(frames) == 6
    assert anim.cursors[0].get_xdata()[0] == result.timeseries["t_s"].iloc[anim.rows[-1]]
    assert all(np.any(a != b) for a, b in zip(frames[:-1], frames[1:]))


@pytest.mark.parametrize("name, overrides", [("rolling-a-speed", ["duration='2 s'"]),
                                             ("chain-mech1-kinematic", ["duration='3 s'"])])
def test_other_mechanisms_animate_with_the_force_arrow(name, overrides):
    sc = load(name, overrides)
    result, mech = run(sc), build_mechanism(sc.si)
    anim = Animator(result, mech, frames=4)
    assert len(list(anim.frames())) == 4
    row = result.timeseries.iloc[anim.rows[-1]]
    vec, at = _arrow(anim.drawing)
    if name.startswith("rolling"):     # at the contact point, along the normal towards the disc centre
        pts = mech.points([row["crank_angle_rad"], row["coupler_angle_rad"], row["rolling_angle_rad"]])
        np.testing.assert_allclose(at, pts["P"] * 1e3, rtol=1e-9)
        n = (pts["B0"] - pts["P"]) / np.hypot(*(pts["B0"] - pts["P"]))
        assert abs(_cross(n, vec)) <= 1e-9 * max(np.hypot(*vec), 1e-300)
    else:                              # at B, along the coupler
        B = np.array([row["joint_B_x_m"], row["joint_B_y_m"]]) * 1e3
        np.testing.assert_allclose(at, B, rtol=1e-12)


def test_output_animation_writes_a_gif_of_200_frames(tmp_path):
    from typer.testing import CliRunner
    from mechsim.scenarios.cli import app
    out = tmp_path / "run"
    r = CliRunner().invoke(app, ["animate", "rolling-a-speed", "--out", str(out), "--quiet", "--set",
                                 "output.plots=false", "--set", "duration='2 s'"])
    assert r.exit_code == 0, r.output
    with Image.open(out / "animation.gif") as im:
        assert im.n_frames == 200 and im.size[0] > im.size[1] > 300
