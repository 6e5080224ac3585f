"""JAX's persistent compilation cache in mechsim's user cache folder (dynamics/user_cache.py `use_for_jax`): a
later process loads the compiled diffrax programs instead of compiling them again; a folder the user chose is
kept."""
import jax

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
