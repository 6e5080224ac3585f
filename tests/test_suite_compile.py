"""benchmarks/suite_compile.py adds up the compilation the workers recorded: every kind over all workers, the
seconds JAX's cache saved kept out of the files' and functions' compilation time."""
from __future__ import annotations

import json

from mechsim.benchmarks import suite_compile


def _numbers(text: str, label: str) -> list[str]:
    return [line.split() for line in text.splitlines() if label in line][0]


def test_records_of_every_worker_are_summed_by_kind_file_and_function(tmp_path):
    (tmp_path / "gw0.json").write_text(json.dumps([
        ["tests/test_a.py::one", "xla compile", "jit(call)", 2.0],
        ["tests/test_a.py::two", "jax trace", "call", 0.5],
        ["tests/test_a.py::two", "xla saved by the cache", "jit(call)", 9.0]]))
    (tmp_path / "gw1.json").write_text(json.dumps([
        ["tests/test_b.py::one", "xla compile", "jit(call)", 1.3],
        ["tests/test_b.py::one", "numba compile", "jacobian_kernel", 4.0]]))
    text = suite_compile.summarise(tmp_path)
    assert _numbers(text, "  xla compile")[2:4] == ["3.3", "s"] and "(2 events)" in text      # 2.0 + 1.3
    assert _numbers(text, "xla saved by the cache")[5] == "9.0"
    # by file: test_b 5.3 s (numba 4 + xla 1.3), test_a 2.5 s (the 9 s saved are not compilation)
    files = [line.split() for line in text.splitlines() if "tests/test_" in line]
    assert files == [["5.3", "s", "tests/test_b.py"], ["2.5", "s", "tests/test_a.py"]]
    assert _numbers(text, "xla compile: jit(call)")[:3] == ["3.3", "s", "2x"]


def test_a_record_goes_to_the_test_running(monkeypatch):
    monkeypatch.setattr(suite_compile, "_records", [])
    monkeypatch.setattr(suite_compile, "_current", ["tests/test_c.py::x"])
    suite_compile._jax_listener("/jax/core/compile/backend_compile_duration", 1.5, fun_name="jit(call)")
    suite_compile._jax_listener("/jax/some/other_event", 7.0)
    assert suite_compile._records == [("tests/test_c.py::x", "xla compile", "jit(call)", 1.5)]
