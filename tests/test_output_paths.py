"""Output paths: a scenario's name is a label, never a path; --force replaces only mechsim's own folders; stale
temporary folders of killed runs are cleaned; the operating system's refusals are one line (exit 4)."""
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import tomli_w
from cli_helpers import invoke, one_line_error

from mechsim.scenarios.output.atomic import MARKER, OWNER
from mechsim.scenarios.output.paths import slug

SHORT = ("--quiet", "--set", "duration=0.05 s", "--set", "output.plots=false", "--set", "thermal.model='none'")


def tree(root):
    return {p for p in root.rglob("*")}


def scenario_named(tmp_path, lc1_raw, name):
    lc1_raw["name"] = name
    path = tmp_path / "work" / "that.toml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(tomli_w.dumps(lc1_raw))
    return path


def test_issue_reproduction_keeps_the_victims_files(tmp_path, lc1_raw, monkeypatch):
    """name = an absolute folder of the user's, run with --force from elsewhere: keep.txt stays, and the output
    goes to results/<slug> under the working directory."""
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("mine")
    path = scenario_named(tmp_path, lc1_raw, str(victim))
    monkeypatch.chdir(tmp_path / "work")
    r = invoke("run", path, "--force", *SHORT)
    assert r.exit_code == 0, r.output
    assert (victim / "keep.txt").read_text() == "mine" and sorted(p.name for p in victim.iterdir()) == ["keep.txt"]
    out = tmp_path / "work" / "results" / slug(str(victim))
    assert (out / "timeseries.csv").is_file() and (out / MARKER).is_file()


def test_force_refuses_a_folder_mechsim_did_not_write(tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "keep.txt").write_text("mine")
    r = invoke("run", "geneva-lc1", "--out", victim, "--force", *SHORT)
    assert r.exit_code == 2
    line = one_line_error(r)
    assert "--out" in line and "not written by mechsim" in line
    assert sorted(p.name for p in victim.iterdir()) == ["keep.txt"]
    a_file = tmp_path / "notes.txt"
    a_file.write_text("x")
    r = invoke("run", "geneva-lc1", "--out", a_file, "--force", *SHORT)
    assert r.exit_code == 2 and "--out" in one_line_error(r) and a_file.read_text() == "x"
    link = tmp_path / "link"
    link.symlink_to(victim)
    r = invoke("run", "geneva-lc1", "--out", link, "--force", *SHORT)
    assert r.exit_code == 2 and "link" in one_line_error(r) and (victim / "keep.txt").is_file()


def test_force_replaces_mechsims_own_folder(tmp_path):
    out = tmp_path / "o"
    assert invoke("run", "geneva-lc1", "--out", out, *SHORT).exit_code == 0
    (out / "stale.txt").write_text("from before")
    assert invoke("run", "geneva-lc1", "--out", out, "--force", *SHORT).exit_code == 0
    assert not (out / "stale.txt").exists() and (out / MARKER).is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["o"]         # no temporary or old folders left


@pytest.mark.parametrize("name", ["../../escape", "/tmp/../etc/x", "a/../../b", "..", ".", "", "~/x", "C:\\x",
                                  "nul\u0000byte", "sp ace/é/../ü", "-" * 300])
def test_a_name_never_writes_outside_results(tmp_path, lc1_raw, monkeypatch, name):
    path = scenario_named(tmp_path, lc1_raw, name)
    monkeypatch.chdir(tmp_path / "work")
    before = tree(tmp_path)
    r = invoke("run", path, *SHORT)
    assert r.exit_code == 0, r.output
    results = tmp_path / "work" / "results"
    new = tree(tmp_path) - before
    assert new and all(p == results or results in p.parents for p in new)
    (folder,) = results.iterdir()
    assert folder.name == slug(name) and not folder.name.startswith(".") and "/" not in folder.name


def test_slug_is_one_safe_component():
    for name in ["geneva-lc1", "../x", "/abs/p", "a\\b", "..", "x" * 500, "\n\t"]:
        s = slug(name)
        assert s and s not in (".", "..") and "/" not in s and "\\" not in s and len(s) <= 64
        assert not s.startswith(".")
    assert slug("geneva-lc1") == "geneva-lc1"


def _dead_pid():
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _leftover(parent, kind, pid, owner=True, host=None, tag="abc123"):
    d = parent / f".o.{kind}-{pid}-{tag}"
    d.mkdir()
    if owner:
        (d / OWNER).write_text(json.dumps({"pid": pid, "host": host or socket.gethostname()}))
    (d / "timeseries.csv").write_text("t_s\n0\n")
    return d


def test_next_run_removes_only_provably_stale_temporaries(tmp_path):
    dead = _dead_pid()
    stale = [_leftover(tmp_path, "tmp", dead), _leftover(tmp_path, "old", dead)]
    live = _leftover(tmp_path, "tmp", os.getppid())                       # owner still running
    elsewhere = _leftover(tmp_path, "tmp", dead, host="another-host", tag="h")     # maybe alive on another machine
    unowned = _leftover(tmp_path, "tmp", dead, owner=False, tag="u")               # not provably ours
    users = tmp_path / ".o.tmp-notapid"
    users.mkdir()
    r = invoke("run", "geneva-lc1", "--out", tmp_path / "o", *SHORT)
    assert r.exit_code == 0, r.output
    assert not any(d.exists() for d in stale)
    assert live.exists() and elsewhere.exists() and unowned.exists() and users.exists()


def _interrupted_after_making(monkeypatch, kind):
    """os.mkdir raising KeyboardInterrupt once it has made a temporary folder of `kind` (tmp, old): where a Ctrl-C
    lands on a loaded machine when the caller watching the parent sends it the moment the folder appears (the
    signal is handled on the interpreter's first check after the system call returns)."""
    real = os.mkdir

    def mkdir(path, *args, **kwargs):
        real(path, *args, **kwargs)
        if f".{kind}-" in os.fspath(path):
            raise KeyboardInterrupt
    monkeypatch.setattr(os, "mkdir", mkdir)


def test_ctrl_c_just_after_the_temporary_folder_is_made_leaves_nothing(tmp_path, monkeypatch):
    from mechsim.scenarios.output.atomic import atomic_folder
    _interrupted_after_making(monkeypatch, "tmp")
    with pytest.raises(KeyboardInterrupt):
        with atomic_folder(tmp_path / "o"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_ctrl_c_while_replacing_keeps_the_old_folder(tmp_path, monkeypatch):
    """Interrupted once the old folder's holding place is made, and between the two renames: the old folder is
    where it was, whole, and no temporary is left."""
    from mechsim.scenarios.output.atomic import atomic_folder
    old = tmp_path / "o"
    with atomic_folder(old) as tmp:
        (tmp / "summary.json").write_text("old")
    _interrupted_after_making(monkeypatch, "old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_folder(old, force=True) as tmp:
            (tmp / "summary.json").write_text("new")
    monkeypatch.undo()
    real_rename = Path.rename

    def rename(self, target):
        raise KeyboardInterrupt                  # after the old folder moved aside, before the new one moves in
    monkeypatch.setattr(Path, "rename", rename)
    with pytest.raises(KeyboardInterrupt):
        with atomic_folder(old, force=True) as tmp:
            (tmp / "summary.json").write_text("new")
    monkeypatch.setattr(Path, "rename", real_rename)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]
    assert (old / "summary.json").read_text() == "old" and (old / MARKER).is_file()


@pytest.mark.parametrize("writer", ["sweep store", "user cache"])
def test_ctrl_c_just_after_a_temporary_file_is_made_leaves_nothing(tmp_path, monkeypatch, writer):
    """The file writers (a sweep's case files and tables; the user cache's files, the JSON caches' too) the same
    way: os.open raising KeyboardInterrupt once it has made the temporary file."""
    from mechsim.dynamics.user_cache import write_atomically
    from mechsim.scenarios.studies.sweep.store import atomic_write_text
    real = os.open

    def open_(path, flags, *args):
        fd = real(path, flags, *args)
        os.close(fd)
        raise KeyboardInterrupt
    monkeypatch.setattr(os, "open", open_)
    with pytest.raises(KeyboardInterrupt):
        if writer == "sweep store":
            atomic_write_text(tmp_path / "case.json", "{}")
        else:
            write_atomically(tmp_path / "entry.bin", b"x")
    assert list(tmp_path.iterdir()) == []


def test_kill_9_while_writing_then_the_next_run_cleans_up(tmp_path):
    """A real SIGKILL in the middle of filling the temporary folder."""
    code = textwrap.dedent(f"""
        import os, signal
        from pathlib import Path
        from mechsim.scenarios.output.atomic import atomic_folder
        with atomic_folder(Path({str(tmp_path / 'o')!r})) as tmp:
            (tmp / "timeseries.csv").write_text("t_s\\n0\\n")
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.run([sys.executable, "-c", code], env=os.environ.copy())
    assert proc.returncode == -signal.SIGKILL
    left = [p for p in tmp_path.iterdir() if p.name.startswith(".o.tmp-")]
    assert len(left) == 1 and not (tmp_path / "o").exists()
    assert invoke("run", "geneva-lc1", "--out", tmp_path / "o", *SHORT).exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def test_read_only_parent_is_one_line_exit_4(tmp_path, monkeypatch):
    """The operating system refuses to create the folder (patched at the OS boundary: os.mkdir)."""
    real_mkdir = os.mkdir

    def refuse(path, *args, **kwargs):
        if str(path).startswith(str(tmp_path / "ro")):
            raise PermissionError(13, "Permission denied", str(path))
        return real_mkdir(path, *args, **kwargs)

    (tmp_path / "ro").mkdir()
    monkeypatch.setattr(os, "mkdir", refuse)
    r = invoke("run", "geneva-lc1", "--out", tmp_path / "ro" / "o", *SHORT)
    assert r.exit_code == 4
    line = one_line_error(r)
    assert "Permission denied" in line and str(tmp_path / "ro") in line
    assert list((tmp_path / "ro").iterdir()) == []


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions")
def test_read_only_working_directory_is_one_line_exit_4(tmp_path, monkeypatch):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    monkeypatch.chdir(ro)
    try:
        r = invoke("run", "geneva-lc1", *SHORT)
    finally:
        ro.chmod(0o755)
    assert r.exit_code == 4 and "Permission denied" in one_line_error(r)
    assert list(ro.iterdir()) == []


def test_full_disk_is_one_line_exit_4_and_leaves_nothing(tmp_path):
    """A file-size limit (RLIMIT_FSIZE) makes the kernel refuse writes past 64 kB, as a full disk would."""
    code = textwrap.dedent("""
        import resource, signal, sys
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))
        sys.argv = ["mechsim"] + sys.argv[1:]
        from mechsim.scenarios.cli import main
        main()
    """)
    proc = subprocess.run([sys.executable, "-c", code, "run", "geneva-lc1", "--out", str(tmp_path / "o"), *SHORT[:-4],
                           "--set", "duration=2 s"], capture_output=True, text=True)
    assert proc.returncode == 4, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in proc.stderr
    assert "File too large" in lines[0]
    assert list(tmp_path.iterdir()) == []
