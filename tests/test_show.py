"""`mechsim show` (and `Scenario.to_toml(comments=True)`): the scenario as TOML with every key's meaning and unit as a
comment and every optional key it leaves out as a commented line with its default; the text loads back to the same
scenario (every built-in, and one with overrides), a commented default uncommented gives the default's value, and
the scenario file's own comments stay beside their keys."""
import tomllib

import pytest

import mechsim
from mechsim.scenarios.loader import sections_for
from mechsim.scenarios.schema import TOP

from cli_helpers import invoke, one_line_error


@pytest.mark.parametrize("name", mechsim.builtins())
def test_show_loads_back_to_the_same_scenario(name, tmp_path):
    res = invoke("show", name)
    assert res.exit_code == 0, res.output
    path = tmp_path / "shown.toml"
    path.write_text(res.stdout)
    sc, back = mechsim.load(name), mechsim.load(path)
    assert back.raw == sc.raw and back.si == sc.si


def test_every_key_is_there_set_or_commented_with_its_default():
    sc = mechsim.load("geneva-lc1")
    text = sc.to_toml(comments=True)
    lines = text.splitlines()
    for section, fields in [("", TOP)] + list(sections_for(sc.mechanism_type).items()):
        for key in fields:
            set_here = key in (sc.raw.get(section, {}) if section else sc.raw)
            prefix = f"{key} = " if set_here else f"# {key} = "
            assert any(line.startswith(prefix) for line in lines), (section, key)
    # a key's comment holds its meaning and SI unit
    assert any(line.startswith('crank_radius = "75 mm"') and "crank radius r [m]" in line for line in lines)
    assert "# [output]" in lines                  # a section the scenario leaves out, commented whole


def test_an_uncommented_default_is_the_default(tmp_path):
    """Removing the '# ' of an optional key sets it to the value the loader fills in anyway."""
    sc = mechsim.load("geneva-lc1")
    text = sc.to_toml(comments=True).replace("# crank_damping = ", "crank_damping = ")
    path = tmp_path / "damped.toml"
    path.write_text(text)
    back = mechsim.load(path)
    assert back.raw["mechanism"]["crank_damping"] == "0.0 N*m*s/rad" and back.si == sc.si


def test_overrides_and_the_files_own_comments(tmp_path):
    res = invoke("show", "geneva-lc1", "--set", "mechanism.crank_radius=80 mm", "--set", "initial.crank_angle=-90 deg")
    assert res.exit_code == 0
    parsed = tomllib.loads(res.stdout)
    assert parsed["mechanism"]["crank_radius"] == "80 mm"
    # the built-in's comment on the crank angle describes its value: dropped once the value is changed
    assert "mid-engagement" not in res.stdout
    assert "bulk pin/crank/wheel temperatures + the flash rise on top" in res.stdout     # [thermal] model, unchanged
    assert "mid-engagement" in invoke("show", "geneva-lc1").stdout


def test_a_file_with_its_comments_and_a_refusal(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(mechsim.load("geneva-torque").to_toml().replace('slots = 4', 'slots = 5   # five slots'))
    shown = invoke("show", path)
    assert shown.exit_code == 0 and "five slots" in shown.stdout
    assert tomllib.loads(shown.stdout) == tomllib.loads(path.read_text())
    res = invoke("show", "no-such-scenario")
    assert res.exit_code == 2 and "no-such-scenario" in one_line_error(res)
