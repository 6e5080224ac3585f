"""JAX's persistent compilation cache in mechsim's user cache folder (dynamics/user_cache.py `use_for_jax`): a
later process loads the compiled diffrax programs instead of compiling them again; a folder the user chose is
kept."""
import os

import jax
import numpy as np
import pytest

from mechsim.dynamics import user_cache


def test_compiled_programs_go_to_the_user_cache_unless_a_folder_is_chosen(monkeypatch, tmp_path):
    before = jax.config.jax_compilation_cache_dir     # the test session's own folder (tests/jax_cache.py)
    monkeypatch.setenv("MECHSIM_CACHE_DIR", str(tmp_path))
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        assert user_cache.use_for_jax(jax) == str(tmp_path / "jax")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "jax")
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "chosen"))
        assert user_cache.use_for_jax(jax) == str(tmp_path / "chosen")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "chosen")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_importing_the_jax_model_keeps_the_sessions_folder():
    """The test session exports JAX_COMPILATION_CACHE_DIR (tests/jax_cache.py): importing the diffrax side of
    mechsim must not move JAX to another folder."""
    import os

    import mechsim.dynamics.jax_model  # noqa: F401
    assert jax.config.jax_compilation_cache_dir == os.environ["JAX_COMPILATION_CACHE_DIR"]


def _lowered_texts(monkeypatch) -> list:
    """Every program lowered from here on: its StableHLO text, in place of compiling it (the check needs no
    compilation)."""
    texts = []
    monkeypatch.setattr(jax.stages.Lowered, "compile", lambda self, *a, **k: texts.append(self.as_text()))
    return texts


def test_the_segment_solves_hold_no_host_callbacks(seed_geometry, monkeypatch):
    """JAX's persistent cache refuses a program with host callbacks, which equinox's runtime checks are by default;
    mechsim's processes (the CLI, this session: tests/jax_cache.py) make them NaN-returning checks instead
    (xla_options.checks_without_callbacks), so the diffrax segment solve and the sensitivity pass's segment solve,
    each compiled in seconds, are kept and loaded by a later process."""
    import equinox

    from mechsim.dynamics import sensitivity
    from mechsim.dynamics.backends import diffrax_backend as dbk
    from mechsim.dynamics.backends.diffrax_common import default_options
    from mechsim.dynamics.model import derive
    from mechsim.dynamics.jax_model import jax_model
    from mechsim.dynamics.settings import SolverSettings
    from mechsim.mechanisms.geneva.model import Geneva

    assert equinox._config.EQX_ON_ERROR == os.environ["EQX_ON_ERROR"] == "nan"
    model = derive(Geneva(seed_geometry, 0.02, 1.5626e-3, wheel_torque=7.0, friction=0.15), "index1", False, None)
    jmod = jax_model(model)
    texts = _lowered_texts(monkeypatch)
    o = default_options(SolverSettings(backend="diffrax"))
    jax.jit(dbk.make_solve(jmod, o)).lower(*dbk.segment_arguments(
        0, 0.0, 1.0, np.zeros(jmod.nz), np.zeros(len(model.parameter_names)), np.ones(jmod.ng_max, bool),
        np.ones(o.rows(jmod.nz)), 1e-3, (o.rtol, o.atol))).compile()
    sensitivity._compile_segment_solve(jmod, model, sensitivity.COLUMNS, "Tsit5", 1000)
    assert len(texts) == 2 and all("diffeqsolve" in t for t in texts)
    assert not [t for t in texts if "callback" in t]


def test_save_times_are_checked_before_the_solve():
    """With the checks inside the program NaN-returning, diffrax's checks of the save times are made before the
    call (diffrax_common.save_times): padded with t1; unordered or outside [t0, t1] raises, in either direction."""
    from mechsim.dynamics.backends.diffrax_common import save_times

    assert save_times([0.1, 0.2], 0.0, 0.5, 4).tolist() == [0.1, 0.2, 0.5, 0.5]
    assert save_times([0.4], 0.5, 0.0, 2).tolist() == [0.4, 0.0]          # backwards in time, as diffrax allows
    for times, t0, t1 in (([0.2, 0.1], 0.0, 0.5), ([0.6], 0.0, 0.5), ([-0.1], 0.0, 0.5), ([0.1, 0.4], 0.5, 0.0)):
        with pytest.raises(RuntimeError, match="saveat.ts must"):
            save_times(times, t0, t1, 3)
