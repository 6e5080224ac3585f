"""The run summary's events by kind (scenarios/runner.py `event_counts`) equal pandas' value_counts: the same
kinds, counts and order (the order becomes the sweep table's events_<kind> column order)."""
import random

import numpy as np
import pandas as pd

from mechsim.scenarios.runner import event_counts


def test_event_counts_equal_pandas_value_counts():
    """Most frequent first, ties in order of first appearance, missing kinds left out: as value_counts."""
    rng = random.Random(7)
    kinds = ["entry", "exit", "slip_reversal", "flank switch", "impact", None]
    for _ in range(300):
        values = [rng.choice(kinds[:rng.randint(1, 6)]) for _ in range(rng.randint(1, 25))]
        events = pd.DataFrame({"t_s": np.arange(len(values), dtype=float), "kind": values})
        expected = {str(k): int(v) for k, v in events["kind"].value_counts().items()}
        assert list(event_counts(events).items()) == list(expected.items())
    assert event_counts(pd.DataFrame(columns=["t_s", "kind"])) == {}
