"""A design's own run, read as the sizing reads its quantities (docs/sensitivity.md, "Sizing"): what
`mechsim run design.toml` reports, so that `mechsim size` can check its design against the limits."""
from __future__ import annotations

import time



def design_run(design) -> dict:
    """The design's own run (as `mechsim run design.toml`): its quantities (`run_quantities`) and its wall time."""
    from mechsim.scenarios import runner
    wall = time.perf_counter()
    plan = runner.plan(design)
    result = runner.execute(plan)
    pmap = plan.mechanism.parameter_map()
    out = run_quantities(result, pmap.engage, pmap.release)
    out["_wall_time_s"] = time.perf_counter() - wall
    return out


def run_quantities(result, engage: str, release: str) -> dict:
    """The headline quantities a run reports itself: each peak's magnitude from summary.json `peaks` (the `abs_max`
    of the column docs/sensitivity.md names; the named extrema `max_<column>`, ... their signed values, None where
    the run has none), the index time (the last release and the engage before it) and the cycle time (the last two
    engages) from its events table, as the sensitivities define them. Others (the energy per cycle, the heat per
    index: work states at events, which the run's tables do not hold) are None. "_failure": the run's failure, or
    None."""
    from mechsim.scenarios.studies.sensitivity import run_event_quantities
    from mechsim.scenarios.studies.sensitivity_map import PEAKS, SIDES, THERMAL_PEAKS, extremum
    peaks = result.summary.get("peaks", {})
    out = {q: (peaks[c]["abs_max"]["value"] if c in peaks else None) for q, c in {**PEAKS, **THERMAL_PEAKS}.items()}
    for prefix, side in SIDES.items():          # the named extrema (signed): max_, min_, startup_max_, startup_min_
        for c in PEAKS.values():
            found = extremum(peaks[c], side) if c in peaks else None
            out[prefix + c] = found["value"] if found is not None else None
    out.update(run_event_quantities(result.events, engage, release))
    out["_failure"] = result.failure.message() if result.failure is not None else None
    return out
