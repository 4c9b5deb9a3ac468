"""The fit example, run as a user runs it."""

import pathlib
import re
import subprocess
import sys

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "examples" / "fit_restitution.py"


def test_the_fit_recovers_e_in_under_100_iterations():
    out = subprocess.run([sys.executable, str(EXAMPLE)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    found = re.search(r"estimate e = ([0-9.]+) after (\d+) iterations", out.stdout)
    assert found, out.stdout
    e, iterations = float(found.group(1)), int(found.group(2))
    assert abs(e - 0.75) < 0.01, out.stdout
    assert iterations < 100, out.stdout
