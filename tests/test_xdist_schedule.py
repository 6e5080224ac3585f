"""The suite's xdist schedule is derived from its own record (tests/xdist_schedule.py): files that share a compiled
program form one work unit while it stays under its share of the suite, and nothing is joined without a program
in common."""
from xdist_schedule import work_units


def test_files_sharing_a_program_join_while_the_unit_stays_small():
    files = {
        "a.py": {"seconds": 100.0, "programs": ["solve:1"]},
        "b.py": {"seconds": 60.0, "programs": ["solve:1", "run:2"]},
        "c.py": {"seconds": 30.0, "programs": ["run:2"]},
        "d.py": {"seconds": 40.0, "programs": []},
        "e.py": {"seconds": 150.0, "programs": ["solve:1"]},
    }
    unit_of, seconds = work_units(files, workers=2)
    # the suite: 380 s on 2 workers, a unit of joined files at most 0.5 x 190 s = 95 s, longest files first: e
    # (150 s) and a (100 s) alone, b (60 s) too large to join e; c joins b through the program they share (90 s);
    # d shares nothing
    assert unit_of["e.py"] == "e.py" and unit_of["a.py"] == "a.py"
    assert unit_of["b.py"] == "b.py" and unit_of["c.py"] == "b.py"
    assert unit_of["d.py"] == "d.py"
    assert seconds["b.py"] == 90.0 and sum(seconds.values()) == sum(f["seconds"] for f in files.values())
