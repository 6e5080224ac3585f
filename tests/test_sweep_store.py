"""The sweep store writes each case file as the earlier code did, byte for byte: the record (with the build that
computed it) as JSON reads it back, then its checksum (SHA-256 of the sorted-key JSON); the file verifies; a store
that wrote or verified a case tabulates it from memory with the same row."""
import json

import numpy as np
import pandas as pd

from mechsim.dynamics.user_cache import results_fingerprint
from mechsim.scenarios.output.atomic import json_default
from mechsim.scenarios.studies.sweep.store import SweepStore, _checksum


def _record():
    row = {"success": np.bool_(True), "failure": "", "peak_contact_force_N": np.float64(1234.5678901234567),
           "peak_temp_contact_C": np.float32(61.25), "events_entry": np.int64(3), "cycle_time_s": float("nan"),
           "work_damping_per_cycle_J": float("inf"), "solver_rows": 1271, "model_backend": None,
           "note": "µ = 0.3, θ ≥ 45°", "tiny": 5e-324, "big": 1.7976931348623157e308, "neg_zero": -0.0}
    return {"case_id": "0123456789abcdef", "run_id": "abc", "finished_at": 1764279000.123456,
            "overrides": ['contact.friction=0.1', 'duration="1.2 s"'], "params": {"contact.friction": 0.1,
            "load.wheel_torque_N_m": np.float64(5.0)}, "row": row}


def _as_before(record, extra=None):
    """The earlier write_case: round trip (the record with the build that computed it), extra entries, checksum,
    one more json.dumps."""
    rec = json.loads(json.dumps({**record, "computed_by": results_fingerprint()}, default=json_default))
    rec.update(extra or {})
    rec["checksum"] = _checksum(rec)
    return json.dumps(rec)


def test_case_file_bytes_equal_the_earlier_encoding_and_verify(tmp_path):
    store = SweepStore(tmp_path / "sw")
    rec = _record()
    store.write_case(rec)
    path = store.case_path(rec["case_id"])
    assert path.read_text() == _as_before(rec)
    fresh = SweepStore(tmp_path / "sw")
    assert fresh.verify(rec["case_id"], False) is None
    assert fresh.read_case(rec["case_id"])["row"]["events_entry"] == 3


def test_with_a_time_series_the_file_carries_its_checksum_too(tmp_path):
    store = SweepStore(tmp_path / "sw")
    rec = _record()
    series = pd.DataFrame({"t_s": [0.0, 0.005], "x": [1.0, 2.0]})
    store.write_case(rec, series)
    written = json.loads(store.case_path(rec["case_id"]).read_text())
    assert store.case_path(rec["case_id"]).read_text() == _as_before(
        rec, {"timeseries_sha256": written["timeseries_sha256"]})
    assert SweepStore(tmp_path / "sw").verify(rec["case_id"], True) is None


def test_the_table_from_memory_equals_the_table_from_the_files(tmp_path):
    store = SweepStore(tmp_path / "sw")
    recs = []
    for i in range(3):
        rec = _record()
        rec["case_id"] = f"{i:016x}"
        rec["row"]["peak_contact_force_N"] = np.float64(1000.0 + i / 3)
        store.write_case(rec)
        recs.append(rec)
    cases = [(i, r["case_id"], r["params"]) for i, r in enumerate(recs)]
    from_memory = store.table(cases)
    from_files = SweepStore(tmp_path / "sw").table(cases)
    pd.testing.assert_frame_equal(from_memory, from_files)
    assert store.finished([r["case_id"] for r in recs], False) == {r["case_id"] for r in recs}
