"""A sweep parses its base scenario once and validates each case from it (`from_raw`), and reads repeated
override values from a cache: both must give what `load` gives, and a cached value must not be shared."""
from mechsim.scenarios.loader import from_raw, load, parse_override, read_raw


def test_from_raw_equals_load_and_leaves_the_base_untouched():
    overrides = ['output_step="5 ms"', "contact.friction=0.3", 'load.wheel_torque="12 N*m"']
    raw, source = read_raw("geneva-lc1")
    before = repr(raw)
    a, b = from_raw(raw, source, overrides), load("geneva-lc1", overrides)
    assert (a.name, a.raw, a.si, a.source) == (b.name, b.raw, b.si, b.source)
    assert repr(raw) == before                      # the parsed base serves the next case unchanged


def test_cached_override_values_are_copies():
    _, first = parse_override('mechanism.points=[["1 mm", "2 mm"]]')
    first[0].append("mutated")
    _, again = parse_override('mechanism.points=[["1 mm", "2 mm"]]')
    assert again == [["1 mm", "2 mm"]]
    assert parse_override("contact.friction=0.25") == (["contact", "friction"], 0.25)
    assert parse_override("name=plain words") == (["name"], "plain words")
