"""The library's conveniences (docs/api.md): a chosen column plotted against time or folded per drive cycle,
a saved folder read back into the same Result, an existing folder refused with FileExistsError, a Scenario
edited (`set`), written (`to_toml`) and read by key, short reprs, a sweep with workers from a script without a
`__main__` guard, a built-in name that wins over a folder of the same name, and a bare number's unit hint in the
field's usual unit."""
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

import mechsim
from mechsim.scenarios.studies.sizing import SizingResult

SHORT = {"duration": "0.8 s", "output_step": "2 ms"}


@pytest.fixture(scope="module")
def lc1():
    return mechsim.run(mechsim.load("geneva-lc1", set=SHORT))


def _lines(fig):
    return {line.get_gid(): line for ax in fig.axes for line in ax.get_lines()}


def test_plot_a_column_draws_its_values_against_time(lc1):
    fig = lc1.plot("contact_force_N")
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    line = _lines(fig)["contact_force_N"]
    np.testing.assert_array_equal(line.get_xdata(), lc1["t_s"].to_numpy())
    np.testing.assert_array_equal(line.get_ydata(), lc1.timeseries["contact_force_N"].to_numpy())
    # two columns of one unit share a panel; a second unit gets its own
    assert len(lc1.plot(["crank_speed_rad_s", "wheel_speed_rad_s"]).axes) == 1
    assert len(lc1.plot(["crank_speed_rad_s", "contact_force_N"]).axes) == 2


def test_plot_against_angle_folds_per_crank_turn(lc1):
    """x="angle": one line per cycle at the crank angle within its turn (degrees from the cycle's start, the
    mechanism's DriveCycle), like the CLI's *_vs_angle figures; the folded x spans less than one turn."""
    cycle = lc1.mechanism.drive_cycle()
    fig = lc1.plot(["crank_speed_rad_s", "wheel_speed_rad_s"], x="angle")
    lines = {gid: ln for gid, ln in _lines(fig).items() if gid.startswith("wheel_speed_rad_s#")}
    assert lines
    x = np.concatenate([ln.get_xdata() for ln in lines.values()])
    y = np.concatenate([ln.get_ydata() for ln in lines.values()])
    angle = lc1.timeseries[cycle.column].to_numpy()
    k = np.floor((angle - cycle.start) / cycle.period + 1e-12)
    k[-1] = k[-2] if k[-1] != k[-2] else k[-1]
    np.testing.assert_allclose(x, np.degrees(angle - k * cycle.period), rtol=0, atol=1e-9)
    np.testing.assert_array_equal(y, lc1.timeseries["wheel_speed_rad_s"].to_numpy())
    assert math.degrees(cycle.start) - 1e-9 <= x.min() and x.max() <= math.degrees(cycle.start + cycle.period)


def test_plot_names_an_unknown_column_and_lists_the_columns(lc1):
    with pytest.raises(KeyError) as err:
        lc1.plot(["contact_force_N", "contact_forse_N"])
    assert "'contact_forse_N'" in str(err.value) and "wheel_speed_rad_s" in str(err.value)
    assert "(did you mean contact_force_N?)" in str(err.value)               # the likely column
    with pytest.raises(KeyError, match=r"\(did you mean motion_vs_time\?\)"):      # or figure
        lc1.plot("motion_vs_tme")
    with pytest.raises(KeyError, match=r"\(did you mean wheel_speed_rad_s\?\)"):
        lc1["wheel_sped_rad_s"]
    with pytest.raises(KeyError, match="no column 'nope'"):
        lc1["nope"]
    pd.testing.assert_series_equal(lc1["contact_force_N"], lc1.timeseries["contact_force_N"])
    assert sorted(lc1.plot("motion_vs_time")) == ["motion_vs_time"]       # the CLI's figures by name, as before


def test_open_reads_back_what_save_wrote(lc1, tmp_path):
    folder = lc1.save(tmp_path / "r", plots=False)
    back = mechsim.open(folder)
    pd.testing.assert_frame_equal(back.timeseries, lc1.timeseries)
    pd.testing.assert_frame_equal(back.events, lc1.events, check_dtype=False)   # CSV: 0.0 reads back as 0
    assert back.summary["peaks"] == lc1.summary["peaks"] and back.scenario == lc1.scenario
    assert back.success and back.mechanism.name == "geneva"
    assert back.plot("contact_force_N").axes                       # a reopened result plots like a fresh one
    with pytest.raises(FileExistsError, match="force=True"):
        lc1.save(folder)
    lc1.save(folder, force=True, plots=False)                       # force replaces mechsim's own folder
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(FileExistsError, match="not written by mechsim"):
        lc1.save(tmp_path / "mine", force=True)
    with pytest.raises(ValueError, match="is not a mechsim result folder"):
        mechsim.open(tmp_path / "mine")
    with pytest.raises(FileNotFoundError):
        mechsim.open(tmp_path / "absent")


def test_scenario_set_to_toml_and_keys(tmp_path):
    sc = mechsim.load("geneva-lc1", set=SHORT)
    assert sc["mechanism.crank_radius"] == pytest.approx(0.075) and sc["duration"] == pytest.approx(0.8)
    wider = sc.set({"mechanism.crank_radius": "80 mm"})
    assert wider["mechanism.crank_radius"] == pytest.approx(0.080) and sc["mechanism.crank_radius"] == 0.075
    assert sc.set(["load.wheel_torque=3 N*m"])["load.wheel_torque"] == pytest.approx(3.0)
    with pytest.raises(mechsim.ScenarioError) as err:                # validated like load
        sc.set({"mechanism.crank_radius": "80 kg"})
    assert err.value.field == "mechanism.crank_radius"
    with pytest.raises(KeyError, match="mechanism.crank_radius"):    # an unknown key lists the section's keys
        sc["mechanism.crank_radus"]
    with pytest.raises(KeyError, match=r"\(did you mean mechanism\.crank_radius\?\)"):      # and the likely one
        sc["mechanism.crank_radus"]
    path = tmp_path / "wider.toml"
    path.write_text(wider.to_toml())
    again = mechsim.load(path)
    assert again.si == wider.si and again.raw == wider.raw


def test_reprs_fit_a_screen(lc1):
    sc = mechsim.load("chain-mech2-torque")
    sized = SizingResult(design=sc, values={"mechanism.crank_radius": 0.07}, objective="peak_contact_force_N",
                         objective_value=212.5, constraints=[{"constraint": "temp_contact_peak_C <= 80",
                                                              "value": 80.0, "active": True}],
                         bounds=[], history=pd.DataFrame({"iteration": range(12)}),
                         summary={"scenario": "geneva-lc1", "design": [{"key": "mechanism.crank_radius",
                                                                        "unit": "m"}], "big": list(range(10**4))})
    for obj in (lc1, sc, mechsim.load("geneva-lc1"), sized):
        text = repr(obj)
        assert len(text.splitlines()) <= 20 and max(map(len, text.splitlines())) <= 120, text
    assert "mechanism.crank_radius = 0.07 m" in repr(sized) and "(active)" in repr(sized)


def test_sweep_with_workers_in_a_script_without_a_main_guard(tmp_path):
    """forkserver workers import the main script again; at its top level that would start the sweep again in
    each worker and kill the pool. The pool starts its workers without the script instead: every case runs."""
    script = tmp_path / "plain.py"
    script.write_text(textwrap.dedent("""\
        import mechsim
        table = mechsim.sweep("geneva-lc1", vary={"load.wheel_torque": "0,7 N*m"},
                              set={"duration": "0.5 s", "output_step": "5 ms"}, workers=2)
        print("cases", len(table), "ok", int(table["success"].sum()), table.attrs["exit_code"])
        """))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    out = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.split() == ["cases", "2", "ok", "2", "0"], out.stdout + out.stderr[-2000:]


def test_guard_detection_reads_the_script(tmp_path):
    from mechsim.scenarios.studies.sweep.execute import _inside_main_guard
    script = tmp_path / "s.py"
    script.write_text("import x\nx.sweep()\nif __name__ == '__main__':\n    x.sweep()\n"
                      "if '__main__' == __name__:\n    x.sweep()\nelse:\n    x.sweep()\n"
                      "if __name__ != '__main__':\n    x.sweep()\n")
    assert [_inside_main_guard(str(script), line) for line in (2, 4, 6, 8, 10)] == [False, True, True, False, False]


def test_a_builtin_name_wins_over_a_folder_of_that_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "chain-mech2-torque").mkdir()                        # e.g. `--out chain-mech2-torque`
    assert mechsim.load("chain-mech2-torque").source == "built-in:chain-mech2-torque"
    with pytest.raises(mechsim.ScenarioError, match="is a folder"):  # "./name" forces the path
        mechsim.load("./chain-mech2-torque")
    (tmp_path / "geneva-lc1").write_text(mechsim.load("geneva-lc1", set={"duration": "3 s"}).to_toml())
    assert mechsim.load("geneva-lc1").si["duration"] == 3.0         # a file is a file


@pytest.mark.parametrize("key, value, hint", [("mechanism.crank_radius", 75, '"75 mm"'),
                                              ("mechanism.crank_radius", "75", '"75 mm"'),
                                              ("thermal.ambient_temperature", 20, '"20 degC"'),
                                              ("duration", 2, '"2 s"'),
                                              ("initial.crank_angle", 30, '"30 deg" or "30 rad"')])
def test_a_bare_number_is_hinted_in_the_fields_usual_unit(key, value, hint):
    with pytest.raises(mechsim.ScenarioError) as err:
        mechsim.load("geneva-lc1", set={key: value})
    assert err.value.field == key and str(err.value).endswith(f"needs a unit, e.g. {hint}")


def test_a_key_of_another_variant_is_refused_and_a_switched_variant_drops_the_files_own():
    """A drive key that the drive's type does not read (a speed on a motor, a torque on a prescribed speed) changed
    nothing before: the run was the same to the bit. It is refused naming the key and the type it needs. Switching
    the type by an override drops the file's keys of the old type, so `--set drive.type=motor` with the motor's
    curve runs without removing drive.speed by hand; the thermal models' keys and the rolling pair's profile
    variants behave the same way, and so does a prescribed drive's unused initial speed."""
    for name, key, value, needs in (("geneva-motor", "drive.speed", "200 rad/s", "speed"),
                                    ("geneva-motor", "drive.torque", "5 N*m", "torque"),
                                    ("geneva-lc1", "drive.stall_torque", "40 N*m", "motor")):
        with pytest.raises(mechsim.ScenarioError) as err:
            mechsim.load(name, set={key: value})
        assert err.value.field == key and f"applies only with drive.type = '{needs}'" in str(err.value)
    motor = mechsim.load("geneva-lc1", set=["drive.type=motor", "drive.stall_torque=40 N*m",
                                            "drive.no_load_speed=8 rad/s"])
    assert "speed" not in motor.raw["drive"] and motor.si["drive"]["speed"] is None
    assert mechsim.load("geneva-lc1").raw["drive"]["speed"]           # the file's own value, untouched
    assert motor.si["initial"]["crank_speed"] == 5.34                   # the motor starts at the file's speed
    # a prescribed drive turns at its speed from t = 0: another initial speed is refused, and a new drive speed
    # takes the file's initial speed (equal to the old one) with it
    with pytest.raises(mechsim.ScenarioError, match=r"^initial\.crank_speed: 3\.0 rad/s would be ignored"):
        mechsim.load("geneva-lc1", set=["initial.crank_speed=3 rad/s"])
    faster = mechsim.load("geneva-lc1", set=["drive.speed=51 rpm"])
    assert "crank_speed" not in faster.raw["initial"] and faster.si["drive"]["speed"] == pytest.approx(51 * np.pi / 30)
    assert mechsim.load("geneva-lc1", set=["drive.speed=51 rpm", "initial.crank_speed=51 rpm"]).si["initial"][
        "crank_speed"] == faster.si["drive"]["speed"]
    with pytest.raises(mechsim.ScenarioError, match=r"^drive\.speed: applies only with drive\.type = 'speed'"):
        mechsim.load("geneva-lc1", set=["drive.type=motor", "drive.speed=5 rad/s", "drive.stall_torque=40 N*m",
                                        "drive.no_load_speed=8 rad/s"])
    # the thermal keys by the models that read them (a key outside a model's set left every thermal column of a
    # geneva-lc1 run the same to the bit under that model)
    for name, key, value, needs in (("geneva-motor", "thermal.conductivity", "30 W/(m*K)", "'flash' or 'lumped' or '1d'"),
                                    ("geneva-lc1", "thermal.mesh_growth", 1.5, "'1d'")):
        with pytest.raises(mechsim.ScenarioError) as err:
            mechsim.load(name, set={key: value})
        assert err.value.field == key and f"applies only with thermal.model = {needs};" in str(err.value)
    # the material's elastic constants are the compliant contact's too, whatever the thermal model
    assert mechsim.load("geneva-motor", set={"thermal.E": "150 GPa"}).si["thermal"]["E"] == 150e9
    flash = mechsim.load("geneva-lc1", set=["thermal.convection_pin=30 W/(m^2*K)"]).set(["thermal.model=flash"])
    assert flash.si["thermal"]["model"] == "flash" and "convection_pin" not in flash.raw["thermal"]
    from mechsim.scenarios.loader import apply_overrides, read_raw
    circle = read_raw("rolling-a-speed")[0]
    assert circle["mechanism"]["profile"] == "circle" and {"fixed_radius", "profile_centre"} <= set(circle["mechanism"])
    switch = ["mechanism.profile=line", "mechanism.line_point=[0, -2]"]
    line = apply_overrides(circle, switch)["mechanism"]
    assert not {"fixed_radius", "profile_centre"} & set(line) and line["disc_radius"] == circle["mechanism"]["disc_radius"]


def test_a_closed_form_run_says_the_solver_settings_are_not_its():
    """A prescribed speed runs in closed form, thermal states included (exact in time), so no [solver] setting moves
    a number of it: the tables of two runs with other tolerances, formulation and backend are the same to the bit,
    and the run's `why` (the console's first line) says the settings are unused."""
    base = ["duration=0.6 s", "output.plots=false"]
    a = mechsim.run(mechsim.load("geneva-lc1", set=base))
    b = mechsim.run(mechsim.load("geneva-lc1", set=base + ["solver.rtol=1e-4", "solver.formulation=index1",
                                                           "solver.backend=diffrax"]))
    assert a.summary["model"]["method"] == b.summary["model"]["method"] == "closed-form"
    assert "the [solver] settings are unused; solver.method = 'dae' integrates it" in a.summary["model"]["why"]
    pd.testing.assert_frame_equal(a.timeseries, b.timeseries, check_exact=True)


def test_a_solver_setting_the_backend_does_not_read_is_warned():
    """A DAE run on IDA's index-2 form reads neither the Baumgarte gains nor diffrax's solver: given, they leave the
    table the same to the bit, and the run warns that each is unused (console and summary.json). On diffrax, the
    formulation and IDA's Jacobian and multiplier tolerance are the unused ones; a default value is never named."""
    from mechsim.dynamics.settings import SolverSettings
    base = ["duration=0.3 s", "output.plots=false"]
    a = mechsim.run(mechsim.load("geneva-motor", set=base))
    b = mechsim.run(mechsim.load("geneva-motor", set=base + ["solver.baumgarte_alpha=20", "solver.diffrax_solver=Dopri5"]))
    pd.testing.assert_frame_equal(a.timeseries, b.timeseries, check_exact=True)
    unused = [w for w in b.summary["warnings"] if " is unused on backend " in w]
    assert [w.split(" = ")[0] for w in unused] == ["solver.diffrax_solver", "solver.baumgarte_alpha"]
    assert not [w for w in a.summary["warnings"] if " is unused on backend " in w]
    diffrax = SolverSettings(backend="diffrax", formulation="index1", jacobian="fd", multiplier_atol=1e3,
                             baumgarte_alpha=20.0, diffrax_solver="Dopri5")
    assert [key for key, _ in diffrax.unused()] == ["formulation", "multiplier_atol", "jacobian"]
    assert SolverSettings(formulation="index1", baumgarte_beta=5.0).unused() == []


def test_set_takes_lists_and_tables_and_one_way_of_a_value_replaces_another(tmp_path):
    """Scenario.set writes a Python list as a TOML array and a dict as an inline table; giving the wheel torque
    another way (per station, a profile) replaces the way the file gave it, while giving two ways at once is
    refused naming the key."""
    sc = mechsim.load("geneva-lc1")
    stations = sc.set({"load.wheel_torque_per_station": ["7 N*m", "2 N*m", "5 N*m", "0.5 N*m"]})
    assert stations["load.wheel_torque_per_station"] == [7.0, 2.0, 5.0, 0.5]
    assert "wheel_torque" not in stations.raw["load"]
    back = stations.set(["load.wheel_torque=3 N*m"])
    assert back.raw["load"] == {"wheel_torque": "3 N*m"}
    profile = sc.set({"load.wheel_torque_profile": {"t": ["0 s", "1 s"], "torque": ["1 N*m", "2 N*m"]}})
    (tmp_path / "profile.toml").write_text(profile.to_toml())
    assert mechsim.load(tmp_path / "profile.toml").si["load"] == profile.si["load"]
    with pytest.raises(mechsim.ScenarioError, match=r"^load\.wheel_torque_profile: give the wheel torque one way"):
        sc.set({"load.wheel_torque": "3 N*m", "load.wheel_torque_profile": {"t": ["0 s"], "torque": ["1 N*m"]}})
