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


def durations(line: str) -> list[float]:
    """The durations a `time:` line states, in seconds, in order ("4.2 ms" and "0.13 s" alike)."""
    import re
    return [float(x) * (1e-3 if unit == "ms" else 1.0) for x, unit in re.findall(r"(\d+\.\d+) (ms|s)\b", line)]

