"""Cross-check of the seed's load case 1 sizing's shadow prices (docs/sensitivity.md, "A thermal sizing: the seed's
load case 1"): the sizing re-solved with each limit moved by +-delta, the central difference of the optimal crank
radius against the shadow price `mechsim size` reports at the nominal limits (dr*/d limit, Nocedal & Wright eq.
12.34). Each solve starts from the design given (the nominal optimum), so it takes a few iterations.

    python -m mechsim.benchmarks.lc1_shadow_prices RADIUS_MM STALL_TORQUE_NM [--index-step 0.0025] [--temp-step 0.5]
        [--design docs/lc1_sizing_design.toml]
"""
from __future__ import annotations

import argparse
import time

import mechsim
from mechsim.scenarios.studies.sizing import size

NAME = "geneva-seed-lc1-mu015"
SETS = ["duration=1 h", "drive.type=motor", "drive.no_load_speed=8 rad/s", "thermal.averaging=cycle"]
VARY = ["mechanism.crank_radius=40:120 mm", "drive.stall_torque=25:80 N*m"]
LIMIT_C, LIMIT_S = 60.0, 0.3


def solve(radius_mm: float, torque_nm: float, limit_c: float, limit_s: float):
    """(optimal crank radius in m, the result) of the sizing with the given limits, from the given design."""
    scenario = mechsim.load(NAME, set=SETS + [f"mechanism.crank_radius={radius_mm!r} mm",
                                              f"drive.stall_torque={torque_nm!r} N*m"])
    wall = time.perf_counter()
    result = size(scenario, VARY, "mechanism.crank_radius",
                  [f"peak_temp_contact_C <= {limit_c!r}", f"index_time_s <= {limit_s!r}"])
    r = float(result.values["mechanism.crank_radius"])
    prices = {c["quantity"]: c["shadow_price"] for c in result.constraints}
    print(f"limits {limit_c!r} C, {limit_s!r} s: r* = {r * 1e3:.9f} mm, stall torque "
          f"{result.values['drive.stall_torque']:.9f} N*m, shadow prices {prices}, "
          f"{len(result.history)} iterations, {time.perf_counter() - wall:.0f} s", flush=True)
    return r, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("radius_mm", type=float)
    parser.add_argument("torque_nm", type=float)
    parser.add_argument("--index-step", type=float, default=0.0025, help="index-time limit moved by +-this (s)")
    parser.add_argument("--temp-step", type=float, default=0.5, help="temperature limit moved by +-this (K)")
    parser.add_argument("--design", help="write the nominal design (the design.toml `mechsim size` writes) here")
    args = parser.parse_args()
    r0, nominal = solve(args.radius_mm, args.torque_nm, LIMIT_C, LIMIT_S)
    if args.design:
        with open(args.design, "w", encoding="utf-8") as fh:
            fh.write(nominal.design_toml())
    print(nominal.summary, flush=True)
    prices = {c["quantity"]: c["shadow_price"] for c in nominal.constraints}
    start = (r0 * 1e3, float(nominal.values["drive.stall_torque"]))
    for quantity, step, moved in (("index_time_s", args.index_step, lambda d: (LIMIT_C, LIMIT_S + d)),
                                  ("peak_temp_contact_C", args.temp_step, lambda d: (LIMIT_C + d, LIMIT_S))):
        plus, _ = solve(*start, *moved(step))
        minus, _ = solve(*start, *moved(-step))
        resolved = (plus - minus) / (2 * step)
        print(f"{quantity}: shadow price {prices[quantity]:.6g}, re-solved with the limit moved by +-{step:g}: "
              f"{resolved:.6g} (relative difference {(prices[quantity] - resolved) / resolved:+.2%})", flush=True)


if __name__ == "__main__":
    main()
