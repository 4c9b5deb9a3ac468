"""mvad.load, Model.grad/simulate/measure, the batch path and the errors."""

import math
import threading
import time

import numpy as np
import pytest

import mvad
from conftest import BALL, BALL_COST, BALL_DC_DE, TIGHT

REPO_TESTS = BALL.parents[1] / "tests" / "tests"
G = 9.81
T1 = math.sqrt(2 * 2.0 / G)  # first impact of the E1 ball (h0 = 2, v0 = 0)


def test_grad_is_the_object_of_mvad_grad_json(ball, cli_grad):
    r = ball.grad(params={"e": 0.7}, wrt=["e", "g"], **TIGHT)
    c = cli_grad(BALL, "--set", "e=0.7", "--wrt", "e,g", "--rtol", "1e-10", "--atol", "1e-12")
    r["stats"].pop("wall_seconds")
    c["stats"].pop("wall_seconds")
    assert r == c
    assert list(r["gradient"]) == ["e", "g"]
    assert r["params"]["e"] == 0.7
    assert r["events"][0]["name"] == "impact"


def test_grad_against_the_closed_form(ball):
    r = ball.grad(**TIGHT)
    assert r["cost"] == pytest.approx(BALL_COST, rel=1e-9)
    assert r["gradient"]["e"] == pytest.approx(BALL_DC_DE, rel=1e-8)
    assert r["events"][0]["t"] == pytest.approx(T1, rel=1e-10)
    assert r["mode"] == "forward"


def test_model_description(ball):
    assert ball.name == "BouncingBall"
    assert ball.params == ["e", "g", "h0", "v0"]
    assert ball.param_defaults == {"e": 0.8, "g": 9.81, "h0": 2.0, "v0": 0.0}
    assert ball.states == ["h", "v"]
    assert ball.observables == ["height", "velocity"]
    assert ball.events == ["impact"]
    assert "BouncingBall" in repr(ball)


def test_simulate_follows_the_closed_form(ball):
    events = ball.simulate(np.array([0.0]), **TIGHT)["events"]
    assert [e["name"] for e in events] == ["impact", "impact"]
    t_impact = events[0]["t"]
    assert t_impact == pytest.approx(T1, rel=1e-10)
    assert events[0]["x_after"][1] == pytest.approx(-0.8 * events[0]["x_before"][1], rel=1e-14)
    t = np.array([0.0, 0.3, 0.6, t_impact, 0.9, 2.0])
    s = ball.simulate(t, **TIGHT)
    h, v = s["states"]["h"], s["states"]["v"]
    assert np.array_equal(s["t"], t)
    np.testing.assert_allclose(h[:3], 2.0 - 0.5 * G * t[:3] ** 2, atol=1e-9)
    np.testing.assert_allclose(v[:3], -G * t[:3], atol=1e-9)
    # Right-continuous at the impact time the run found: v(t1+) = e g t1.
    assert v[3] == pytest.approx(0.8 * G * T1, rel=1e-8)
    assert np.array_equal(s["observables"]["height"], h)
    assert s["diagnostics"] == []


def test_measure_density_and_atoms(ball):
    mu = ball.measure("velocity", wrt=["e", "g"], grid=np.array([0.2, 0.5]), **TIGHT)
    assert mu["wrt"] == ["e", "g"]
    assert mu["density"].shape == (2, 2)
    # Before the impact v = -g t: dv/de = 0, dv/dg = -t.
    np.testing.assert_allclose(mu["density"], [[0.0, -0.2], [0.0, -0.5]], atol=1e-9)
    r = ball.grad(wrt=["e", "g"], **TIGHT)
    np.testing.assert_allclose(mu["atoms"]["t"], [ev["t"] for ev in r["events"]], rtol=0, atol=0)
    want = [[ev["atoms"]["velocity"]["e"], ev["atoms"]["velocity"]["g"]] for ev in r["events"]]
    np.testing.assert_allclose(mu["atoms"]["values"], want, rtol=0, atol=0)
    # d/dg ∫ v dt = d/dg (h(T) - h0): the pairing includes the atoms.
    assert mu["integral_derivative"].shape == (2,)
    default = ball.measure("height", **TIGHT)
    assert default["grid"].shape == (201,) and default["density"].shape == (201, 4)


def test_measure_with_a_moving_horizon_has_the_atom_at_t_end():
    # tests/tests/moving_horizon.hyb: T = Tf, d/dTf ∫0^T x dt = x(T) (the atom at T).
    m = mvad.load(str(REPO_TESTS / "moving_horizon.hyb"))
    k, tau, d, tf = 0.8, 0.6, 0.5, 2.5
    x_end = (math.exp(-k * tau) + d) * math.exp(-k * (tf - tau))
    mu = m.measure("y", **TIGHT)
    r = m.grad(**TIGHT)
    want = [r["gradient"][name] for name in mu["wrt"]]
    np.testing.assert_allclose(mu["integral_derivative"], want, rtol=1e-9, atol=1e-12)
    assert mu["atoms"]["t"][-1] == tf
    i = mu["wrt"].index("Tf")
    assert mu["atoms"]["values"][-1][i] == pytest.approx(x_end, rel=1e-9)


def test_cost_batch_equals_single_runs_in_order(ball):
    thetas = np.column_stack([np.linspace(0.5, 0.9, 7), np.linspace(9.0, 10.0, 7)])
    c, g = ball.cost_batch(thetas, wrt=["e", "g"], **TIGHT)
    assert c.shape == (7,) and g.shape == (7, 2)
    for k, (e, gg) in enumerate(thetas):
        r = ball.grad(params={"e": e, "g": gg}, wrt=["e", "g"], **TIGHT)
        assert c[k] == r["cost"]
        assert list(g[k]) == [r["gradient"]["e"], r["gradient"]["g"]]
    c2, g2 = ball.cost_batch(thetas, wrt=["e", "g"], gradient=False, **TIGHT)
    assert g2.shape == (7, 0)
    np.testing.assert_allclose(c2, c, rtol=1e-9)


def test_observe_batch_rows_are_single_runs(ball):
    times = np.linspace(0.1, 1.9, 7)
    thetas = np.array([[0.6], [0.7], [0.8]])
    ys = ball.observe_batch(thetas, times, wrt=["e"], **TIGHT)
    assert ys.shape == (3, 7, 2)
    for k, (e,) in enumerate(thetas):
        s = ball.simulate(times, params={"e": e}, **TIGHT)
        np.testing.assert_array_equal(ys[k, :, 0], s["observables"]["height"])
    cot = np.ones((3, 7, 2))
    v = ball.observe_vjp_batch(thetas, times, cot, wrt=["e"], **TIGHT)
    single = ball.observe_vjp_batch(thetas[1:2], times, cot[1:2], wrt=["e"], **TIGHT)
    assert v.shape == (3, 1) and v[1, 0] == single[0, 0]


def test_a_bad_model_raises_model_error_with_the_location(tmp_path):
    bad = tmp_path / "bad.hyb"
    bad.write_text(BALL.read_text().replace("der(v) = -g;", "der(v) = -gg;"))
    with pytest.raises(mvad.ModelError) as info:
        mvad.load(str(bad))
    assert f"{bad}:12:19: error: undefined name `gg`" in str(info.value)
    assert isinstance(info.value, ValueError)
    with pytest.raises(mvad.ModelError, match=r"<string>:1:\d+: error"):
        mvad.from_source("model M { state x = ; }")
    with pytest.raises(FileNotFoundError):
        mvad.load(str(tmp_path / "missing.hyb"))
    with pytest.raises(mvad.ModelError):
        mvad.from_source("\x00\x01 binary")


def test_bad_requests_are_value_errors(ball):
    with pytest.raises(ValueError, match="unknown parameter `q` in params; known parameters: e, g, h0, v0"):
        ball.grad(params={"q": 1.0})
    with pytest.raises(ValueError, match="unknown parameter `x` in wrt"):
        ball.grad(wrt=["x"])
    with pytest.raises(ValueError, match="rtol must be in"):
        ball.grad(rtol=0.0)
    with pytest.raises(ValueError, match="unknown mode `backward`; use forward, adjoint or auto"):
        ball.grad(mode="backward")
    with pytest.raises(ValueError, match="unknown mode `reverse`"):
        ball.cost_batch(np.array([[0.8]]), wrt=["e"], mode="reverse")
    with pytest.raises(ValueError, match="unknown method"):
        ball.grad(method="euler")
    with pytest.raises(TypeError, match="unexpected keyword argument `rtl`"):
        ball.grad(rtl=1e-6)
    with pytest.raises(ValueError, match="not a finite number"):
        ball.grad(params={"e": float("nan")})
    with pytest.raises(ValueError, match="outside the horizon"):
        ball.simulate(np.array([3.0]))
    with pytest.raises(ValueError, match="unknown observable"):
        ball.measure("speed")
    with pytest.raises(ValueError, match="thetas has 3 columns; it needs 2"):
        ball.cost_batch(np.ones((2, 3)), wrt=["e", "g"])
    # A name given twice is one parameter, as in Model.grad.
    c, g = ball.cost_batch(np.array([[0.8]]), wrt=["e", "e"])
    assert g.shape == (1, 1)
    with pytest.raises(ValueError, match="cotangents must have shape"):
        ball.observe_vjp_batch(np.ones((2, 1)), np.array([0.5]), np.ones((1, 1, 2)), wrt=["e"])
    with pytest.raises(ValueError, match="points must be between 2 and 1000000, got -1"):
        ball.measure("height", points=-1)
    with pytest.raises(ValueError, match=r"thetas must be a 2-D array, got shape \[2\]"):
        ball.cost_batch([0.8, 0.7], wrt=["e"])
    with pytest.raises(ValueError, match="times must be an array of numbers"):
        ball.simulate(["soon"])
    # Numbers far from 1 are printed in exponent form, not as hundreds of digits.
    with pytest.raises(ValueError, match=r"sample time 1e-300 \(index 0\) is outside the horizon \[0, 1e-305\]"):
        ball.simulate([1e-300], t_end=1e-305)


def test_array_arguments_take_any_array_like_of_numbers(ball):
    """Lists, tuples and integer arrays are read as float64, with the same numbers."""
    ref = ball.simulate(np.array([0.0, 1.0, 2.0]), **TIGHT)
    for times in ([0, 1, 2], (0.0, 1.0, 2.0), np.array([0, 1, 2])):
        s = ball.simulate(times, **TIGHT)
        np.testing.assert_array_equal(s["observables"]["height"], ref["observables"]["height"])
    c, g = ball.cost_batch([[0.8, 9.81]], wrt=["e", "g"], **TIGHT)
    c2, g2 = ball.cost_batch(np.array([[0.8, 9.81]]), wrt=["e", "g"], **TIGHT)
    assert c[0] == c2[0] and list(g[0]) == list(g2[0])
    mu = ball.measure("height", grid=[0, 1, 2], **TIGHT)
    assert mu["grid"].dtype == np.float64 and list(mu["grid"]) == [0.0, 1.0, 2.0]


def test_a_failing_run_raises_solve_error():
    blow = mvad.from_source("model Blow { state x = 1; flow { der(x) = x^2; } horizon 2; }")
    with pytest.raises(mvad.SolveError, match="the run failed"):
        blow.grad()
    assert issubclass(mvad.SolveError, RuntimeError)


def test_the_gil_is_released_while_solving(ball):
    thetas = np.column_stack([np.linspace(0.5, 0.9, 4000)])
    done = threading.Event()

    def work():
        ball.cost_batch(thetas, wrt=["e"], rtol=1e-12, atol=1e-14)
        done.set()

    worker = threading.Thread(target=work)
    start = time.perf_counter()
    worker.start()
    spins = 0
    while not done.is_set():
        spins += 1
    worker.join()
    elapsed = time.perf_counter() - start
    # Python kept running while Rust solved: far more than one loop turn per switch interval.
    assert elapsed > 0.05, "the batch was too short to tell"
    assert spins > 10_000, (spins, elapsed)
