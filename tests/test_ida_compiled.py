"""The compiled IDA backend (`solver.backend = "ida-compiled"`, dynamics/backends/ida_compiled.py) runs the `ida`
backend's algorithm with native callbacks: its callbacks must equal the generated Python functions they are
printed from, called by SUNDIALS through real N_Vectors and a real dense matrix (so the data offsets the
callbacks read are exercised), and its runs must give the `ida` backend's events and results within the runs'
own accuracy on every mechanism type (Geneva with friction, chain with impacts, rolling pair through a branch
swap, Geneva with lumped thermal states).

Two runs whose step sequences differ by round-off differ by their global errors; the bound is the one of the
restart-perturbation test, GLOBAL_FACTOR (1000) x (rtol x scale + atol) (dynamics/invariants.py).
"""
import ctypes
import functools
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import mechsim
from mechsim.dynamics.backend import backend_for
from mechsim.dynamics.backends.compiled_model import compiled_mode
from mechsim.dynamics.hybrid import simulate
from mechsim.dynamics.invariants import GLOBAL_FACTOR
from mechsim.dynamics.result import FailureCode
from mechsim.dynamics.backends.sundials_c import sundials
from mechsim.dynamics.user_cache import cache_dir
from mechsim.scenarios.runner import execute, plan
from recording import Recording

pytestmark = pytest.mark.hybrid

CASES = {
    "geneva-motor-index1": ("geneva-motor", {"duration": "2 s", "solver.formulation": "index1"}),
    "geneva-motor-index2": ("geneva-motor", {"duration": "2 s"}),
    "chain-mech2-torque": ("chain-mech2-torque", {}),
    "rolling-b-components": ("rolling-b-components", {}),
    "geneva-lumped-thermal": ("geneva-seed-lc1-mu015", {"solver.method": "dae", "duration": "1.5 s"}),
}


def run(name, sets, backend_name, wrap=None):
    the_plan = plan(mechsim.load(name, set={**sets, "solver.backend": backend_name}))
    backend = backend_for(backend_name, the_plan.settings)
    if wrap:
        backend = wrap(backend)
    return execute(the_plan, integrate=functools.partial(simulate, backend=backend)), the_plan.settings, backend


@pytest.fixture(scope="module", params=list(CASES))
def both(request):
    name, sets = CASES[request.param]
    ida, settings, recorder = run(name, sets, "ida", Recording)
    compiled, _, _ = run(name, sets, "ida-compiled")
    return request.param, ida, compiled, settings, recorder.requests


def test_callbacks_equal_the_generated_python_functions(both):
    """Residual, exact Jacobian (column-major dense SUNMatrix) and guards of every mode met in the run, at the
    run's own restart states and at states moved off the constraint manifold (where no term cancels), through
    SUNDIALS' vectors: equal to the plain-Python functions to 1e-12 of each output's scale (the same
    straight-line expressions, compiled differently; round-off is ~1e-16 of the terms)."""
    _, _, _, _, requests = both
    lib = sundials()
    rng = np.random.default_rng(3)
    seen = {}
    for r in requests:
        seen.setdefault(r.mf.name, []).append(r)
    assert seen
    for mode, reqs in seen.items():
        mf = reqs[0].mf
        cm, _ = compiled_mode(mf, cache_dir() / "compiled")
        # (IDA's prototypes: the addresses IDA calls, whether numba or the kept object code gave them)
        res = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_double, *[ctypes.c_void_p] * 3,
                               ctypes.POINTER(ctypes.c_double))(cm.residual)
        jac = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_double, ctypes.c_double, *[ctypes.c_void_p] * 4,
                               ctypes.POINTER(ctypes.c_double), *[ctypes.c_void_p] * 3)(cm.jacobian)
        roots = ctypes.CFUNCTYPE(ctypes.c_int32, ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p,
                                 ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double))(cm.guards)
        for r in reqs[:3]:
            p = np.array(r.p, dtype=float)
            for shift in (0.0, 1e-2):
                y = np.array(r.y0) + shift * rng.normal(size=mf.ny) * (1 + np.abs(r.y0))
                yp = np.array(r.yp0) + shift * rng.normal(size=mf.ny) * (1 + np.abs(r.yp0))
                t, cj = r.t0 + 1e-3, 3.7e3
                ny, ng = mf.ny, max(len(mf.guard_names), 1)
                out_c, jac_c, g_c = np.zeros(ny), np.zeros(ny * ny), np.zeros(ng)
                vy, vyp, vr = lib.vector(y), lib.vector(yp), lib.vector(out_c)
                mat = lib.SUNDenseMatrix(ny, ny, lib.context)
                try:
                    pp = ctypes.cast(p.ctypes.data, ctypes.POINTER(ctypes.c_double))
                    ptr = ctypes.c_void_p
                    assert res(t, ptr(vy), ptr(vyp), ptr(vr), pp) == 0
                    assert jac(t, cj, ptr(vy), ptr(vyp), ptr(vr), ptr(mat), pp, None, None, None) == 0
                    jac_c[:] = np.ctypeslib.as_array(ctypes.cast(lib.SUNDenseMatrix_Data(mat),
                                                                  ctypes.POINTER(ctypes.c_double)), (ny * ny,))
                    gp = ctypes.cast(g_c.ctypes.data, ctypes.POINTER(ctypes.c_double))
                    assert roots(t, ptr(vy), ptr(vyp), gp, pp) == 0
                finally:
                    for v in (vy, vyp, vr):
                        lib.N_VDestroy(v)
                    lib.SUNMatDestroy(mat)
                out_py, jac_py = np.zeros(ny), np.zeros((ny, ny))
                mf.residual(t, y, yp, out_py, r.p)
                mf.jacobian(t, y, yp, out_py, cj, jac_py, r.p)
                g_py = np.zeros(len(mf.guard_names))
                if len(mf.guard_names):
                    mf.events(t, y, yp, g_py, r.p)
                for name, a, b in (("residual", out_c, out_py), ("jacobian", jac_c.reshape(ny, ny).T, jac_py),
                                   ("guards", g_c[:len(g_py)], g_py)):
                    scale = max(float(np.abs(b).max(initial=0.0)), 1e-300)
                    assert np.abs(a - b).max(initial=0.0) <= 1e-12 * scale, (mode, name, shift)


def test_runs_agree_with_the_scikit_sundae_backend(both):
    """Same events in the same order, at the same times and states, and the same motion at every output row,
    within GLOBAL_FACTOR x (rtol x scale + atol); both runs complete."""
    case, ida, compiled, settings, _ = both
    assert ida.failure is None and compiled.failure is None, (ida.failure, compiled.failure)
    rtol, atol = settings.rtol, settings.atol
    ea, eb = ida.events, compiled.events
    assert list(ea["kind"]) == list(eb["kind"]) and list(ea["to_mode"]) == list(eb["to_mode"]), case
    if len(ea):
        t_scale = max(1.0, float(ea["t_s"].abs().max()))
        assert np.abs(ea["t_s"].to_numpy() - eb["t_s"].to_numpy()).max() <= GLOBAL_FACTOR * (rtol * t_scale + atol)
    a, b = ida.timeseries, compiled.timeseries
    assert len(a) == len(b) and np.array_equal(a["t_s"], b["t_s"])
    angles = [c for c in a.columns if c.endswith("_angle_rad") or c.endswith("_speed_rad_s")
              or c.endswith("temperature_C") or c.endswith("_energy_J")]
    assert angles
    for c in angles:
        x, y = a[c].to_numpy(), b[c].to_numpy()
        scale = max(1.0, float(np.nanmax(np.abs(x))))
        assert np.nanmax(np.abs(x - y)) <= GLOBAL_FACTOR * (rtol * scale + atol), (case, c)
    sa, sb = ida.summary["solver"], compiled.summary["solver"]
    assert sb["backend"] == "ida-compiled" and sb["events"] == sa["events"]
    assert sb["accepted_steps"] > 0 and sb["rejected_steps"] >= 0
    assert sb["steps"] == sb["accepted_steps"] + sb["rejected_steps"]


def test_a_run_on_kept_ida_memories_is_the_computation_on_fresh_ones(both):
    """A thread's backends of one settings share each mode's IDA memory, re-initialised (IDAReInit) at every segment:
    a run on memories earlier runs used gives the rows and events of a run on fresh ones (a new thread's) to the last
    bit, so nothing of an earlier segment or run carries over into a run."""
    from concurrent.futures import ThreadPoolExecutor
    case, _, _, _, _ = both
    name, sets = CASES[case]
    with ThreadPoolExecutor(1) as pool:
        fresh = pool.submit(lambda: run(name, sets, "ida-compiled")[0]).result()
    again = run(name, sets, "ida-compiled")[0]
    pd.testing.assert_frame_equal(again.timeseries, fresh.timeseries, check_exact=True)
    pd.testing.assert_frame_equal(again.events, fresh.events, check_exact=True)


def test_rows_written_in_kept_or_per_segment_arrays_are_the_same_run(monkeypatch):
    """A segment's rows are written into arrays its IDA memory keeps between segments (up to
    `ida_compiled.SCRATCH_BYTES`), or into arrays made for the segment beyond that: the run is the same to the last
    bit either way (the rows are copied out at their count; nothing of an earlier, longer segment shows)."""
    from concurrent.futures import ThreadPoolExecutor

    from mechsim.dynamics.backends import ida_compiled
    name, sets = CASES["geneva-motor-index1"]
    kept = run(name, sets, "ida-compiled")[0]
    assert len(kept.events) > 2                   # several segments
    monkeypatch.setattr(ida_compiled, "SCRATCH_BYTES", 0)
    with ThreadPoolExecutor(1) as pool:           # a new thread's memories, which keep no rows now
        made = pool.submit(lambda: run(name, sets, "ida-compiled")[0]).result()
    pd.testing.assert_frame_equal(kept.timeseries, made.timeseries, check_exact=True)
    pd.testing.assert_frame_equal(kept.events, made.events, check_exact=True)


def test_step_budget_failure_keeps_what_ran_like_the_ida_backend():
    """Too small a step budget: both IDA backends stop with MAX_STEPS at the same instant, keep the rows
    before it, and name IDA's flag."""
    sets = {"duration": "1 s", "solver.max_steps": 15}
    ida, _, _ = run("geneva-motor", sets, "ida")
    compiled, _, _ = run("geneva-motor", sets, "ida-compiled")
    assert ida.failure is not None and compiled.failure is not None
    assert compiled.failure.code is FailureCode.MAX_STEPS is ida.failure.code
    assert compiled.failure.time == pytest.approx(ida.failure.time, rel=1e-9)
    assert "IDA_TOO_MUCH_WORK" in compiled.failure.reason
    assert len(compiled.timeseries) == len(ida.timeseries) > 0


def test_a_new_process_loads_the_callbacks_from_the_cache():
    """Compiled once per machine: after this process has built (or loaded) a model's callbacks, a new process
    finds numba's cache in the same cache folder and compiles none of them again; with the derived model on disk
    too (dynamics/derivation_cache.py) it never imports sympy."""
    code = ("import sys, mechsim; from mechsim.dynamics.backends.compiled_model import loaded_modes;"
            "mechsim.run('geneva-motor', set={'solver.backend': 'ida-compiled', 'duration': '0.3 s'});"
            "print(all(cm.loaded_from_cache for cm in loaded_modes()), len(loaded_modes()), 'sympy' in sys.modules)")
    mechsim.run("geneva-motor", set={"solver.backend": "ida-compiled", "duration": "0.3 s"})
    assert list((cache_dir() / "compiled").glob("mode_*.py"))
    second = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=dict(os.environ),
                            timeout=300)
    assert second.stdout.split() == ["True", "2", "False"], second.stderr[-2000:]


_RUN_AND_SAVE = ("import sys, mechsim, numpy as np\n"
                 "from mechsim.dynamics.backends.compiled_model import loaded_modes\n"
                 "r = mechsim.run('geneva-motor', set={'solver.backend': 'ida-compiled', 'duration': '1 s',"
                 " 'output.plots': False})\n"
                 "np.save(sys.argv[1], r.timeseries.select_dtypes('number').to_numpy())\n"
                 "print('numba' in sys.modules, [cm.module is None for cm in loaded_modes()])\n")


def test_a_new_process_runs_on_the_kept_object_code_without_numba_to_the_bit(tmp_path):
    """numba's object code is kept beside what it compiled (dynamics/backends/native_objects.py): a new process
    loads the modes' callbacks and the segment loop from it without importing numba, and its run equals the run of
    the process that compiled them, every column to the bit (the same machine code). Damaged files are passed
    over: the callbacks and the loop are compiled again (their object code kept anew), with the same run."""
    env = dict(os.environ, MECHSIM_CACHE_DIR=str(tmp_path / "cache"), MECHSIM_BACKGROUND_COMPILE="0")

    def run(name: str):
        out = subprocess.run([sys.executable, "-c", _RUN_AND_SAVE, str(tmp_path / name)], capture_output=True,
                             text=True, env=env, timeout=600)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout.split("\n")[0], np.load(tmp_path / name)

    first, a = run("a.npy")                          # a fresh cache folder: everything compiled here
    objects = sorted((tmp_path / "cache" / "compiled").glob("*.objects"))
    assert len(objects) == 3                         # the two modes' callbacks and the loop
    second, b = run("b.npy")
    assert first == "True [False, False]" and second == "False [True, True]"
    assert np.array_equal(a, b, equal_nan=True)
    for f in objects:
        f.write_bytes(f.read_bytes()[:100])
    third, c = run("c.npy")
    assert third == "True [False, False]" and np.array_equal(a, c, equal_nan=True)


def test_object_code_for_another_machine_or_naming_an_unknown_symbol_is_not_loaded(tmp_path):
    """A kept object file is loaded only where it was made for this numba, llvmlite and CPU, and where every
    symbol its code calls can be bound (an unbound one would stop the process when the code is linked)."""
    import pickle

    from mechsim.dynamics.backends import native_objects
    mechsim.run("geneva-motor", set={"solver.backend": "ida-compiled", "duration": "0.3 s"})
    kept = sorted((cache_dir() / "compiled").glob("loop_*.objects"), key=os.path.getmtime)[-1]
    data = pickle.loads(kept.read_bytes())
    assert set(data["functions"]) == {"segment", "read_rows"}
    (tmp_path / "same.objects").write_bytes(kept.read_bytes())
    assert set(native_objects.load(tmp_path / "same.objects")) == {"segment", "read_rows"}
    other = dict(data, key=data["key"].replace(data["key"].split("|")[3], "another-cpu"))
    (tmp_path / "other.objects").write_bytes(pickle.dumps(other))
    assert native_objects.load(tmp_path / "other.objects") is None
    name, (native, obj, externals) = next(iter(data["functions"].items()))
    unknown = dict(data, functions={name: (native, obj, externals + ["mechsim_no_such_symbol"])})
    (tmp_path / "unknown.objects").write_bytes(pickle.dumps(unknown))
    assert native_objects.load(tmp_path / "unknown.objects") is None
    assert native_objects.load(tmp_path / "missing.objects") is None


def test_without_the_sundials_libraries_the_backend_says_so_in_one_line(monkeypatch):
    """An installation whose scikit-sundae ships no usable SUNDIALS libraries: a ValueError naming the backend,
    the reason and the way out (the CLI prints it as one line, exit 2), not a crash inside a run."""
    from mechsim.dynamics.backends import ida_compiled
    from mechsim.dynamics.backends.sundials_c import SundialsUnavailable

    def missing():
        raise SundialsUnavailable("scikit-sundae's SUNDIALS library 'ida' was not found")
    monkeypatch.setattr(ida_compiled, "sundials", missing)
    with pytest.raises(ValueError, match=r"solver.backend = 'ida-compiled' is not available .*'ida' was not "
                                         r"found.*use solver.backend = 'ida'"):
        mechsim.run("geneva-motor", set={"solver.backend": "ida-compiled", "duration": "0.1 s"})


def test_the_sundials_version_is_checked_against_the_one_the_prototypes_were_written_for():
    """The loaded SUNDIALS is the release the C prototypes were written for (the headers they were checked
    against); any other major or minor release is refused in one line before a prototype is bound."""
    from mechsim.dynamics.backends.sundials_c import WRITTEN_FOR, SundialsVersionMismatch, check_version
    assert sundials().version[:2] == WRITTEN_FOR
    check_version(WRITTEN_FOR + (7,))
    for other in ((WRITTEN_FOR[0], WRITTEN_FOR[1] + 1, 0), (WRITTEN_FOR[0] + 1, 0, 0), (WRITTEN_FOR[0] - 1, 9, 0)):
        with pytest.raises(SundialsVersionMismatch) as err:
            check_version(other)
        assert "\n" not in str(err.value) and ".".join(map(str, other)) in str(err.value)


@pytest.fixture
def other_sundials_release(monkeypatch):
    """scikit-sundae's SUNDIALS reported as a release the prototypes were not written for (the version reader
    patched, the process's loaded interface dropped and restored afterwards)."""
    from mechsim.dynamics.backends import ida_compiled, sundials_c
    monkeypatch.setattr(sundials_c, "library_version", lambda core: (sundials_c.WRITTEN_FOR[0],
                                                                      sundials_c.WRITTEN_FOR[1] + 1, 0))
    monkeypatch.setattr(ida_compiled, "_NOTED", set())
    sundials_c.sundials.cache_clear()
    yield
    sundials_c.sundials.cache_clear()


@pytest.mark.parametrize("backend", ["ida-compiled", "auto"])
def test_another_sundials_release_runs_on_ida_after_a_one_line_note(backend, other_sundials_release, capfd):
    """Asked for the compiled path (or given it by default) on another SUNDIALS release: the run completes on the
    `ida` backend, exactly as an `ida` run, after one line on stderr naming both releases."""
    sets = {"duration": "0.3 s", "output.plots": False}
    result = mechsim.run("geneva-motor", set={**sets, "solver.backend": backend})
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SUNDIALS 7.10.0" in err[0] and "7.9.x" in err[0] and "'ida'" in err[0], err
    assert result.success and result.summary["solver"]["backend"] == "ida"
    reference = mechsim.run("geneva-motor", set={**sets, "solver.backend": "ida"})
    pd.testing.assert_frame_equal(result.timeseries, reference.timeseries)
    mechsim.run("geneva-motor", set={**sets, "solver.backend": backend})
    assert capfd.readouterr().err == ""                       # once per process


def _cache_without_ready_marks(tmp_path) -> dict:
    """The environment of a process on a copy of numba's cache of the modules this machine compiled already
    (geneva-motor's, built here if missing), without their ready marks: a process then loads instead of compiling
    (a fresh machine compiles; the tests are the same, only slower), while `auto` sees the model as not ready."""
    mechsim.run("geneva-motor", set={"solver.backend": "ida-compiled", "duration": "0.3 s"})
    shutil.copytree(cache_dir() / "compiled", tmp_path / "cache" / "compiled", copy_function=shutil.copy2,
                    ignore=shutil.ignore_patterns("*.ready", "*.failed", ".compile.lock"))
    return dict(os.environ, MECHSIM_CACHE_DIR=str(tmp_path / "cache"), MECHSIM_BACKGROUND_COMPILE="1")


@pytest.mark.parametrize("first", ["", "import jax\n"], ids=["forked", "jax-loaded"])
def test_the_default_runs_ida_then_compiled_once_the_background_compilation_is_done(tmp_path, first):
    """A fresh cache folder: the first process runs the model on `ida` and compiles its callbacks in a background
    process; a process started after that runs it compiled, loading everything from the cache (nothing compiled
    in it, and numba not imported: the object code is loaded as it is), with the first run's events and motion
    within the runs' accuracy. Within a process the first choice is
    kept. The first process never imports numba: its run costs what an `ida` run costs. Where JAX is loaded first
    (a notebook that ran diffrax: no fork is safe), the background process is a fresh interpreter that derives the
    model again from the pickled mechanism, with the same outcome."""
    env = _cache_without_ready_marks(tmp_path)
    code = (first + "import sys, mechsim, numpy as np\n"
            "from mechsim.dynamics.backends.compiled_model import loaded_modes\n"
            "runs = [mechsim.run('geneva-motor', set={'duration': '0.5 s', 'output.plots': False}) for _ in (0, 1)]\n"
            "native = sys.modules.get('mechsim.dynamics.backends.native')\n"
            "compiled_here = native is not None and sum(native.advance.stats.cache_misses.values())\n"
            "print(*[r.summary['solver']['backend'] for r in runs], 'numba' in sys.modules,"
            " all(cm.loaded_from_cache for cm in loaded_modes()) and not compiled_here,"
            " runs[0].timeseries.equals(runs[1].timeseries))\n"
            "np.save(sys.argv[1], runs[0].timeseries[['t_s', 'crank_angle_rad', 'wheel_angle_rad']].to_numpy())\n")
    first = subprocess.run([sys.executable, "-c", code, str(tmp_path / "a.npy")], capture_output=True, text=True,
                           env=env, timeout=600)
    assert first.stdout.split() == ["ida", "ida", "False", "True", "True"], first.stderr[-2000:]
    folder = tmp_path / "cache" / "compiled"
    for _ in range(600):                    # the background compilation: seconds to minutes on a loaded machine
        if len(list(folder.glob("*.ready"))) >= 3:
            break
        time.sleep(0.5)
    second = subprocess.run([sys.executable, "-c", code, str(tmp_path / "b.npy")], capture_output=True, text=True,
                            env=env, timeout=600)
    # (the callbacks and the segment loop loaded as the object code numba left: numba is not imported at all)
    assert second.stdout.split() == ["ida-compiled", "ida-compiled", "False", "True", "True"], second.stderr[-2000:]
    a, b = np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy")
    assert np.array_equal(a[:, 0], b[:, 0])
    rtol, atol = 1e-8, 1e-10                # the scenario's solver tolerances
    assert np.abs(a[:, 1:] - b[:, 1:]).max() <= GLOBAL_FACTOR * (rtol * np.abs(a[:, 1:]).max() + atol)


def test_a_spawned_worker_compiles_only_the_modules_it_was_asked_for(tmp_path):
    """The background compilation where JAX is loaded runs in a fresh interpreter that derives the model again from
    its pickled recipe (`compiled_model.compile_pickled`); it compiles only where the modules' names it derives are
    the ones the asking process computed (the same code and structure), so that another install on the import path
    can never mark ready what the asking process would load. Asked with other names it marks nothing; asked with
    the model's own it marks its modes and the segment loop ready."""
    env = _cache_without_ready_marks(tmp_path)
    folder = tmp_path / "cache" / "compiled"
    code = ("import pickle, sys\n"
            "from mechsim.dynamics.backends.compiled_model import module_name\n"
            "from mechsim.dynamics.model import derive\n"
            "from mechsim.scenarios.loader import build_mechanism, load\n"
            "model = derive(build_mechanism(load('geneva-motor').si), 'index2', False)\n"
            "names = list(model.modes)\n"
            "own = [module_name(model.modes[n]) for n in names]\n"
            "modules = own if sys.argv[1] == 'own' else ['x' + m for m in own]\n"
            "sys.stdout.buffer.write(pickle.dumps((model.recipe, names, modules, sys.argv[2])))\n")
    worker = ("import sys\nfrom mechsim.dynamics.backends.compiled_model import compile_pickled\n"
              "compile_pickled(sys.stdin.buffer.read())\n")
    for asked, marks in (("other", 0), ("own", 3)):
        data = subprocess.run([sys.executable, "-c", code, asked, str(folder)], capture_output=True, env=env,
                              timeout=600, check=True).stdout
        subprocess.run([sys.executable, "-c", worker], input=data, env=env, timeout=600, check=True)
        assert len(list(folder.glob("*.ready"))) == marks, asked


def _holders(path) -> list[int]:
    """The processes (not this one) with `path` open (Linux: /proc)."""
    out = []
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        try:
            if int(fd_dir.parent.name) != os.getpid() and any(
                    os.readlink(fd) == str(path) for fd in fd_dir.iterdir()):
                out.append(int(fd_dir.parent.name))
        except OSError:                      # a process gone meanwhile, or not ours to read
            continue
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_background_compilation_holds_none_of_the_commands_descriptors(tmp_path):
    """The default's background compilation outlives the command that started it: it must hold none of its open
    files, or a caller reading the command's output through a pipe (`mechsim run ... | tee log`, subprocess with
    captured output) waits for the end of the compilation, not of the command. Here the compilation is held back
    (this test holds its lock), so the worker is still waiting when the command ends: the command's output is
    read to its end all the same, and the worker holds no pipe."""
    import fcntl
    import signal
    env = _cache_without_ready_marks(tmp_path)
    lock_path = tmp_path / "cache" / "compiled" / ".compile.lock"
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        workers = []
        try:
            out = subprocess.run([sys.executable, "-m", "mechsim.scenarios.cli", "run", "geneva-motor", "--set",
                                  "duration=0.3 s", "--set", "output.plots=false", "--out", str(tmp_path / "o")],
                                 env=env, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stderr[-2000:]
            assert out.stdout.rstrip().splitlines()[-1].startswith("time: ")
            for _ in range(100):             # the worker, waiting for the lock (it opens it at once)
                workers = _holders(lock_path)
                if workers:
                    break
                time.sleep(0.1)
            assert len(workers) == 1
            held = [os.readlink(fd) for fd in Path(f"/proc/{workers[0]}/fd").iterdir()]
            assert not [target for target in held if target.startswith("pipe:")], held
        finally:
            for pid in workers or _holders(lock_path):
                os.kill(pid, signal.SIGKILL)


def test_a_model_run_on_ida_compiled_is_the_defaults_compiled_model_in_later_processes(tmp_path):
    """Where no background compilation can start (here: JAX loaded, so no fork), a process that ran the model on
    `ida-compiled` leaves it marked ready: the default runs it compiled in a later process, loading everything from
    the cache, and where it did not (before: the first process's first run), the default ran it on `ida`. The
    first process runs the default, then `ida-compiled` by name (its default's choice, `ida`, made at its first
    run, is its own: the name still runs compiled); the second process runs the default."""
    env = _cache_without_ready_marks(tmp_path)
    code = ("import sys, jax, mechsim\n"
            "from mechsim.dynamics.backends.compiled_model import loaded_modes\n"
            "for backend in sys.argv[1:]:\n"
            "    r = mechsim.run('geneva-motor', set={'duration': '0.3 s', 'output.plots': False, "
            "'solver.backend': backend})\n"
            "    print(r.summary['solver']['backend'], all(cm.loaded_from_cache for cm in loaded_modes()))\n")
    outputs = []
    for backends in (("auto", "ida-compiled"), ("auto",)):
        done = subprocess.run([sys.executable, "-c", code, *backends], capture_output=True, text=True, env=env,
                              timeout=600)
        outputs.append(done.stdout.split())
    assert outputs == [["ida", "True", "ida-compiled", "True"], ["ida-compiled", "True"]], done.stderr[-2000:]


def test_a_compiled_runs_peaks_are_re_integrated_on_its_compiled_callbacks(monkeypatch):
    """The located peaks of an `ida-compiled` run re-integrate on the compiled callbacks (dynamics/extrema.py
    TrajectoryReader): the same IDA algorithm as scikit-sundae's binding, so every located value and instant
    agrees with the readings through that binding, and lies at the same kind of place, within the readings' own
    accuracy, GLOBAL_FACTOR x (their rtol x scale + atol) (the two step sequences differ by round-off only)."""
    from mechsim.dynamics.backends import ida_compiled
    sets = {"duration": "1 s", "solver.formulation": "index1", "solver.backend": "ida-compiled"}
    used = []
    real = ida_compiled.runs_compiled
    monkeypatch.setattr(ida_compiled, "runs_compiled", lambda s, m: used.append(real(s, m)) or used[-1])
    sc = mechsim.load("geneva-motor", set=sets)
    fast = mechsim.run(sc)
    monkeypatch.setattr(ida_compiled, "runs_compiled", lambda s, m: False)
    binding = mechsim.run(sc)
    assert used and all(used)
    settings = plan(sc).settings
    rtol, atol = 0.1 * settings.rtol, 0.1 * settings.atol          # the readings' (TrajectoryReader's tighten)
    pa, pb = fast.summary["peaks"], binding.summary["peaks"]
    assert pa.keys() == pb.keys() and len(pa) > 3
    for col in pa:
        for side in ("max", "min"):
            a, b = pa[col][side], pb[col][side]
            assert a["at"] == b["at"], (col, side)
            if a["value"] is None:
                assert b["value"] is None
                continue
            scale = max(1.0, abs(b["value"]))
            assert abs(a["value"] - b["value"]) <= GLOBAL_FACTOR * (rtol * scale + atol), (col, side)


def test_readings_run_ahead_together_are_each_reading_run_alone(monkeypatch):
    """The located peaks' readings of a `read_many` call run on the compiled callbacks in one call per mode
    (`TrajectoryReader._read_ahead`, `IdaCompiledBackend.read_many`): IDA is re-initialised at every reading's own
    start, so each reading's rows are, to the last bit, those of that reading run alone (`_reading`, one
    `IdaCompiledBackend.read`), whatever ran on the IDA memory before it."""
    from mechsim.dynamics.trajectory_reader import TrajectoryReader
    calls = []
    real = TrajectoryReader.read_many
    monkeypatch.setattr(TrajectoryReader, "read_many",
                        lambda self, requests: calls.append((self, list(requests))) or real(self, requests))
    sc = mechsim.load("geneva-motor", set={"duration": "1 s", "solver.formulation": "index1",
                                           "solver.backend": "ida-compiled"})
    mechsim.run(sc)
    settings = plan(sc).settings
    reader, requests = max(calls, key=lambda c: len(c[1]))
    assert len(requests) > 5
    _, ready = TrajectoryReader(reader.traj, reader.angle_coordinates, settings)._read_ahead(requests)
    assert sum(r is not None for r in ready) > 5
    for request, hit in zip(requests, ready):
        if hit is not None:
            piece = TrajectoryReader(reader.traj, reader.angle_coordinates, settings)._reading(*request)
            for a, b in zip(hit[3:], (piece.t, piece.y, piece.yp)):
                assert np.array_equal(a, b)


@pytest.mark.parametrize("backend", ["ida-compiled", "ida"])
def test_limits_read_out_with_the_first_readings_are_those_read_out_alone(monkeypatch, backend):
    """The one-sided limits at the events (the states the run holds there, `TrajectoryReader.stored_columns`) are
    read out in the first readings' read-out of each mode (`stage_limits`), not in one of their own. Each row's
    read-outs are the same operations on the same state wherever it sits in the stack, but the KKT solve of a stack
    of more than 64 + 40 n^2 systems (n = 3 here) is the elimination of `kkt._stacked`, which rounds otherwise than
    LAPACK's solve of the limits' short stack alone: the accelerations and forces then differ by round-off of a
    3 x 3 solve (measured up to 2e-15 of the column's largest value on geneva-torque; 1e-12 bounds it for a
    condition number up to ~1e3), every other column to the last bit."""
    from mechsim.dynamics.trajectory_reader import TrajectoryReader
    calls = []
    real = TrajectoryReader.stored_columns
    monkeypatch.setattr(TrajectoryReader, "stored_columns", lambda self, ends, read_many=None: calls.append(
        (self, list(ends), real(self, ends, read_many))) or calls[-1][2])
    sc = mechsim.load("geneva-torque", set={"duration": "2.5 s", "solver.backend": backend})
    mechsim.run(sc)
    reader, ends, (staged, where) = calls[0]
    assert reader._limit_parts and len(where) > 40                # read out with the readings, most ends held
    alone, where_alone = real(TrajectoryReader(reader.traj, reader.angle_coordinates, plan(sc).settings), ends)
    assert np.array_equal(where, where_alone) and list(staged) == list(alone)
    solved = {"crank_accel_rad_s2", "wheel_accel_rad_s2", "contact_force_N"}
    for c in alone:
        got, want = np.asarray(staged[c]), np.asarray(alone[c])
        if c in solved:
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max(), err_msg=c)
        else:
            assert np.array_equal(got, want, equal_nan=got.dtype.kind == "f"), c


def test_a_stored_limit_asked_for_again_is_the_one_read_out_with_the_first_readings(monkeypatch):
    """A request for just a one-sided limit the run holds (an interval's end, from that end's row: what
    `end_limits` asks for) is the read-out staged with the first readings (`TrajectoryReader._stored_limit`), not a
    reading and read-out of its own, and equals the reading of that instant by a reader that staged nothing (the
    same state; the accelerations and forces to the round-off of the stacked KKT solve, as above)."""
    from mechsim.dynamics.trajectory_reader import TrajectoryReader
    staged = []
    real = TrajectoryReader.stage_limits
    monkeypatch.setattr(TrajectoryReader, "stage_limits",
                        lambda self, ends: staged.append((self, list(ends))) or real(self, ends))
    sc = mechsim.load("geneva-torque", set={"duration": "2.5 s", "solver.backend": "ida-compiled"})
    mechsim.run(sc)
    reader, ends = staged[0]
    held = [(iv, side) for iv, side in ends if reader._limit_parts.get((id(iv), side), (None, None))[1] is not None]
    assert len(held) > 40
    requests = [(iv, 0 if side == "after" else len(iv.rows) - 1, np.array([iv.lo if side == "after" else iv.hi]))
                for iv, side in held]
    got = reader.read_many(requests)
    assert all(g is reader._limit_parts[id(iv), side][1] for g, (iv, side) in zip(got, held))
    alone = TrajectoryReader(reader.traj, reader.angle_coordinates, plan(sc).settings).read_many(requests)
    for c in ("crank_angle_rad", "wheel_speed_rad_s", "crank_accel_rad_s2", "contact_force_N"):
        have = np.array([np.asarray(g[c])[0] for g in got])
        want = np.array([np.asarray(a[c])[0] for a in alone])
        np.testing.assert_allclose(have, want, rtol=0, atol=1e-12 * np.abs(want).max(), err_msg=c)
