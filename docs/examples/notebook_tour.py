"""A tour of mechsim's Python API, written as notebook cells (`# %%`): open it in Jupyter (jupytext), VS Code
or Spyder and run cell by cell, or run it whole: `python docs/examples/notebook_tour.py [output folder]`.
tests/test_api.py runs it."""
# %% [markdown]
# # mechsim from Python
# A scenario is a TOML file or a built-in name; `mechsim.load` validates it (units at the edge, SI inside) and
# `mechsim.run` integrates it. Overrides work as `--set` on the command line.

# %%
import sys
import tempfile
from pathlib import Path

import numpy as np

import mechsim

print(mechsim.__version__, "| built-in scenarios:", ", ".join(mechsim.builtins()[:4]), "...")
sc = mechsim.load("geneva-lc1", set={"duration": "1.2 s", "thermal.model": "lumped"})
print(sc.name, "-", sc.mechanism_type, "- crank speed", sc["drive.speed"], "rad/s")  # resolved values are SI

# %% [markdown]
# A scenario is edited by `set` (a new, validated scenario; the original is unchanged) and written by `to_toml`,
# which `mechsim.load` reads back to the same values.

# %%
wide = sc.set({"mechanism.crank_radius": "80 mm"})
print("crank radius", sc["mechanism.crank_radius"], "->", wide["mechanism.crank_radius"], "m")
scratch = Path(tempfile.mkdtemp())
(scratch / "wide.toml").write_text(wide.to_toml())
print("to_toml round-trips:", mechsim.load(scratch / "wide.toml").si == wide.si)
print(sc)

# %% [markdown]
# ## Run and look at the tables
# `timeseries` has one row per output step, columns `<quantity>_<unit>` in SI; `events` one row per mode change.

# %%
r = mechsim.run(sc)
print(r)
ts = r.timeseries
print(ts[["t_s", "crank_angle_rad", "wheel_angle_rad", "contact_force_N", "temp_contact_C"]].describe().T)
print(r.events[["t_s", "kind", "from_mode", "to_mode"]])

# %% [markdown]
# Numbers you can check: at a constant crank speed the wheel of an n-slot Geneva indexes 2 pi/n per crank turn.

# %%
n = sc.si["mechanism"]["slots"]
turns = (ts["crank_angle_rad"].iloc[-1] - ts["crank_angle_rad"].iloc[0]) / (2 * np.pi)
indexed = (ts["wheel_angle_rad"].iloc[-1] - ts["wheel_angle_rad"].iloc[0]) / (2 * np.pi / n)
print(f"{turns:.3f} crank turns, {indexed:.3f} wheel indexes")
peak = r.summary["peaks"]["contact_force_N"]["max"]   # located in continuous time
print(f"peak contact force {peak['value']:.1f} N at t = {peak['t_s']:.3f} s")
print("heat balance closes to", r.summary["thermal"]["heat_balance"]["closure_error_relative"])

# %% [markdown]
# ## Figures and files
# `plot()` returns the figures the CLI writes, as matplotlib Figures (a notebook shows one left as a cell's value);
# `save()` writes the CLI's output folder, all or nothing.

# %%
figures = r.plot()
print("figures:", ", ".join(figures))
folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp()) / "tour"
r.save(folder / "geneva-lc1", force=True)
print("written:", ", ".join(sorted(p.name for p in (folder / "geneva-lc1").iterdir())))

# %% [markdown]
# Any column, or several, against time or folded over the crank's turn (a line per cycle); `r[column]` is the
# column itself. A saved folder reads back into a Result with `mechsim.open`.

# %%
force = r.plot("contact_force_N")
speeds = r.plot(["crank_speed_rad_s", "wheel_speed_rad_s"], x="angle")
force.savefig(folder / "contact_force.png")
print("peak of the sampled contact force", round(r["contact_force_N"].max(), 1), "N")
again = mechsim.open(folder / "geneva-lc1")
print(again, "| same timeseries:", again.timeseries.equals(r.timeseries))

# %% [markdown]
# ## A small sweep
# One row per case; `vary` takes the command line's value lists (`5,7,14 N*m`, `a:b:count`, `log:a:b:count`).

# %%
table = mechsim.sweep("geneva-lc1", vary={"drive.speed": "2,3,4 rad/s"}, set={"duration": "2 s"})
print(table[["drive.speed_rad_s", "success", "peak_max_contact_force_N"]])

# %% [markdown]
# ## Two designs side by side
# `mechsim.compare(a, b)` takes a scenario or a finished run on each side (here the run above, a Result, against
# the same scenario with a heavier wheel load) and gives the headline numbers of both with their differences, and
# figures of both runs overlaid (A solid, B dashed). `mechsim compare A B` on the command line is the same.

# %%
heavy = sc.set({"load.wheel_torque": "10 N*m"})
c = mechsim.compare(r, heavy)
print(c)
rows = ["peak_max_contact_force_N", "cycle_mean_drive_torque_N_m", "work_load_per_cycle_J", "peak_max_temp_contact_C"]
print(c.table.set_index("quantity").loc[rows])
# the crank turns at a prescribed speed, so the wheel moves alike and the load's work per index scales with torque
print("wheel speed peak differs by", c.table.set_index("quantity").loc["peak_max_wheel_speed_rad_s", "difference"])
c.plot()["forces_vs_angle"].savefig(folder / "compare_forces_vs_angle.png")
print("compared:", ", ".join(sorted(p.name for p in c.save(folder / "compare", force=True).iterdir())))

# %% [markdown]
# `mechsim show NAME` prints a scenario with every key's meaning and unit, and the keys it leaves out commented
# with their defaults: a template to start your own (`Scenario.to_toml(comments=True)` is the same text).

# %%
print("\n".join(heavy.to_toml(comments=True).splitlines()[:12]))

# %% [markdown]
# ## Loads that change
# The wheel torque may differ per station (one value per slot, in the order the slots engage) or follow a
# piecewise-linear profile in time; the motor may run a duty cycle (`drive.duty_on`, `drive.duty_off`). Each
# breakpoint is an event: the integrator stops there and restarts, so no step straddles a kink.

# %%
stations = sc.set({"load.wheel_torque_per_station": ["7 N*m", "2 N*m", "5 N*m", "0.5 N*m"], "duration": "4.8 s"})
rs = mechsim.run(stations)
ts = rs.timeseries
index = np.searchsorted(rs.events.loc[rs.events["kind"] == "entry", "t_s"].to_numpy(), ts["t_s"], side="right")
engaged = ts[ts["mode"] == "engaged"].assign(index=index[ts["mode"] == "engaged"])
print("peak contact force per index:", ", ".join(f"{f:.0f} N" for f in engaged.groupby("index")["contact_force_N"].max()))

# %% [markdown]
# How large a run's tables will be is known before it runs; a large output is said by `mechsim run`, and
# `[output] csv = "auto"` then writes Parquet only.

# %%
size = mechsim.output_size(sc.set({"duration": "120 s", "output_step": "0.1 ms"}))
print(f"120 s at 0.1 ms: {size.rows} rows, about {size.total_bytes / 2**20:.0f} MiB, large: {size.large}")
