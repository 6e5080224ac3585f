"""In-process CLI helpers shared by the command-line tests."""
from typer.testing import CliRunner

from mechsim.scenarios.cli import app

runner = CliRunner()


def invoke(*args):
    """Run `mechsim ARGS...` in-process; paths and numbers are passed as strings."""
    return runner.invoke(app, list(map(str, args)))


def one_line_error(result):
    """The single `error: ...` line of a failed command (and no traceback anywhere)."""
    text = result.stderr.strip()
    assert "Traceback" not in result.output + text
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == 1, text
    assert lines[0].startswith("error: ")
    return lines[0]
