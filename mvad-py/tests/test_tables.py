"""Data tables from Python: `tables=` on `mvad.load` and on every run method (a CSV file or
columns in memory), against the exact Lindley recursion and `mvad grad --table`."""

import json

import numpy as np
import pytest

import mvad
from conftest import REPO

QUEUE = REPO / "models" / "queue.hyb"
CSV = REPO / "models" / "queue.csv"
# C and dC/dμ of models/queue.csv by the recursion in integer arithmetic.
EXACT = json.loads((REPO / "models" / "queue_exact.json").read_text())


def lindley(t, s, mu):
    """C and dC/dμ by the Lindley recursion (float), for tables built here."""
    u = du = c = dc = 0.0
    prev = 0.0
    for ti, si in zip(t, s):
        if u > ti - prev:
            u -= ti - prev
        else:
            u, du = 0.0, 0.0
        u += si / mu
        du -= si / mu**2
        c += u
        dc += du
        prev = ti
    return c, dc


@pytest.fixture(scope="module")
def queue():
    return mvad.load(str(QUEUE))


def test_the_declared_table_matches_the_exact_recursion(queue):
    r = queue.grad()
    assert r["cost"] == pytest.approx(EXACT["cost"], rel=1e-12)
    assert r["gradient"]["mu"] == pytest.approx(EXACT["gradient"]["mu"], rel=1e-12)
    # The JSON lists the first 1000 events, as `mvad grad --json`; all on request.
    assert r["stats"]["events"] > 1000
    assert len(r["events"]) == 1000
    assert len(queue.grad(all_events=True)["events"]) == r["stats"]["events"]


def test_tables_given_as_columns_or_files(queue, tmp_path, cli_grad):
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.exponential(size=300))
    s = rng.exponential(size=300)
    want = lindley(t, s, 1.25)
    by_columns = queue.grad(tables={"arrivals": {"t": t, "s": s}})
    path = tmp_path / "arrivals.csv"
    path.write_text("t,s\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, s)))
    by_file = queue.grad(tables={"arrivals": str(path)})
    loaded = mvad.load(str(QUEUE), tables={"arrivals": path}).grad()
    cli = cli_grad(QUEUE, "--table", f"arrivals={path}")
    for r in (by_columns, by_file, loaded, cli):
        assert r["cost"] == pytest.approx(want[0], rel=1e-12)
        assert r["gradient"]["mu"] == pytest.approx(want[1], rel=1e-12)
    for r in (by_columns, by_file, loaded):
        r["stats"].pop("wall_seconds")
    cli["stats"].pop("wall_seconds")
    assert by_file == cli
    # The model's own table is untouched by a call that replaces it.
    assert queue.grad()["cost"] == pytest.approx(EXACT["cost"], rel=1e-12)
    # The batch path takes them too.
    costs, grads = queue.cost_batch(
        np.array([[1.25], [1.5]]), tables={"arrivals": {"t": t, "s": s}}
    )
    assert costs[0] == pytest.approx(want[0], rel=1e-12)
    assert grads[1, 0] == pytest.approx(lindley(t, s, 1.5)[1], rel=1e-12)


def test_bad_tables_are_errors(queue, tmp_path):
    with pytest.raises(ValueError, match="has no table `nope`"):
        queue.grad(tables={"nope": {"t": [1.0]}})
    with pytest.raises(mvad.ModelError, match="table `arrivals` has no column `s`"):
        queue.grad(tables={"arrivals": {"t": np.array([1.0, 2.0])}})
    bad = tmp_path / "bad.csv"
    bad.write_text("t,s\n1,2\n0.5,x\n")
    with pytest.raises(mvad.ModelError, match=r"bad\.csv:3:5: error: "):
        queue.grad(tables={"arrivals": str(bad)})
    with pytest.raises(mvad.ModelError, match="decreases"):
        queue.grad(tables={"arrivals": {"t": [2.0, 1.0], "s": [1.0, 1.0]}})
    with pytest.raises(ValueError, match="rows"):
        queue.grad(tables={"arrivals": {"t": [1.0, 2.0], "s": [1.0]}})
    with pytest.raises(TypeError, match="tables must be a dict"):
        queue.grad(tables=["arrivals"])
    # Columns in memory are held to what a CSV file's fields are held to: finite numbers.
    for bad in (np.nan, np.inf, -np.inf):
        with pytest.raises(ValueError, match=r"in column `t` \(row 2\) is not a finite number"):
            queue.grad(tables={"arrivals": {"t": [0.5, bad], "s": [1.0, 1.0]}})
    with pytest.raises(ValueError, match=r'tables\["arrivals"\]\["s"\] must be an array of numbers'):
        queue.grad(tables={"arrivals": {"t": [0.5], "s": ["x"]}})
