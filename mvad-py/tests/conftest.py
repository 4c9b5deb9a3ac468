"""Shared fixtures: the repository's models, the `mvad` binary, JAX in float64."""

import json
import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
BALL = REPO / "models" / "bouncing_ball.hyb"

# The E1 ball's closed forms (docs: DESIGN.md): C = ∫₀² h dt and dC/de at e = 0.8.
BALL_COST = 1.8905137123173506
BALL_DC_DE = 2.8314408141470055
TIGHT = {"rtol": 1e-10, "atol": 1e-12}

try:
    import jax

    jax.config.update("jax_enable_x64", True)
except ImportError:  # the JAX tests import it themselves and fail loudly
    pass


@pytest.fixture(scope="session")
def ball():
    import mvad

    return mvad.load(str(BALL))


@pytest.fixture(scope="session")
def mvad_bin():
    """The `mvad` command line (MVAD_BIN, else target/release/mvad, built if missing)."""
    path = os.environ.get("MVAD_BIN") or str(REPO / "target" / "release" / "mvad")
    if not os.path.exists(path):
        subprocess.run(
            ["cargo", "build", "--release", "--quiet", "-p", "mvad"], cwd=REPO, check=True
        )
    return path


@pytest.fixture(scope="session")
def cli_grad(mvad_bin):
    """`mvad grad MODEL --json ARGS...` as a dict."""

    def run(model, *args):
        out = subprocess.run(
            [mvad_bin, "grad", str(model), "--json", *args],
            cwd=REPO,
            check=True,
            capture_output=True,
            text=True,
        )
        return json.loads(out.stdout)

    return run
