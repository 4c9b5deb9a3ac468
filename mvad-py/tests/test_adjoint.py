"""mode="adjoint" from Python: the same derivatives as forward mode through every door
(Model.grad, the batches, mvad.jax, mvad.torch), and "auto" choosing by the parameter count."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import torch

import mvad
import mvad.jax
import mvad.torch
from conftest import BALL_COST, BALL_DC_DE, TIGHT

jax.config.update("jax_enable_x64", True)

# Sample times before, between and after the two impacts (t ≈ 0.639 and 1.66), and T.
TIMES = np.array([0.1, 0.5, 0.7, 1.2, 1.7, 1.9, 2.0])
WRT = ["e", "g", "h0", "v0"]
THETAS = np.array([[0.8, 9.81, 2.0, 0.0], [0.7, 9.5, 1.8, 0.3]])


def _close(a, b, rel=1e-8):
    a, b = np.asarray(a), np.asarray(b)
    np.testing.assert_allclose(a, b, rtol=0, atol=rel * max(1.0, float(np.max(np.abs(b)))))


def test_grad_in_adjoint_mode_equals_forward_and_e1(ball):
    f = ball.grad(mode="forward", **TIGHT)
    a = ball.grad(mode="adjoint", **TIGHT)
    assert a["stats"]["mode"] == "adjoint" and a["mode"] == "adjoint"
    assert a["stats"]["record_bytes"] > 0 and f["stats"]["record_bytes"] == 0
    assert a["cost"] == pytest.approx(BALL_COST, rel=1e-9)
    assert a["gradient"]["e"] == pytest.approx(BALL_DC_DE, rel=1e-8)
    for name in WRT:
        assert a["gradient"][name] == pytest.approx(f["gradient"][name], rel=1e-8, abs=1e-10)
    # The adjoint's events carry no t' and no atoms (forward quantities).
    assert len(a["events"]) == 2 and "dt" not in a["events"][0]
    # The ball has 4 parameters: auto stays forward.
    assert ball.grad(mode="auto", **TIGHT)["stats"]["mode"] == "forward"


def test_observe_vjp_and_cost_batch_adjoint_equal_forward(ball):
    cot = np.cos(np.arange(2 * len(TIMES) * 2.0)).reshape(2, len(TIMES), 2)
    vf = ball.observe_vjp_batch(THETAS, TIMES, cot, wrt=WRT, mode="forward", **TIGHT)
    va = ball.observe_vjp_batch(THETAS, TIMES, cot, wrt=WRT, mode="adjoint", **TIGHT)
    assert va.shape == (2, 4)
    _close(va, vf)
    cf, gf = ball.cost_batch(THETAS, wrt=WRT, mode="forward", **TIGHT)
    ca, ga = ball.cost_batch(THETAS, wrt=WRT, mode="adjoint", **TIGHT)
    _close(ca, cf, rel=1e-10)
    _close(ga, gf)


def test_jax_and_torch_layers_in_adjoint_mode(ball):
    theta = jnp.asarray(THETAS[0])
    ybar = np.sin(np.arange(len(TIMES) * 2.0)).reshape(len(TIMES), 2)
    pulled = {}
    for mode in ("forward", "adjoint"):
        y = mvad.jax.observe(ball, TIMES, wrt=WRT, mode=mode, **TIGHT)
        _, pullback = jax.vjp(y, theta)
        c = mvad.jax.cost(ball, wrt=WRT, mode=mode, **TIGHT)
        th = torch.tensor(THETAS[0], dtype=torch.float64, requires_grad=True)
        mvad.torch.cost(ball, wrt=WRT, mode=mode, **TIGHT)(th).backward()
        pulled[mode] = (np.asarray(pullback(jnp.asarray(ybar))[0]), np.asarray(jax.grad(c)(theta)), th.grad.numpy())
    for a, f in zip(pulled["adjoint"], pulled["forward"]):
        _close(a, f)


def test_auto_picks_the_adjoint_for_many_parameters():
    # 60 parameters: a decay rate per term of the cost, with an event.
    p = 60
    params = " ".join(f"param k{i} = {0.01 * (i + 1)};" for i in range(p))
    rate = " + ".join(f"k{i}" for i in range(p))
    src = (
        f"model Many {{ {params} state x = 1; flow {{ der(x) = -({rate}) * x / {p}; }}"
        " event half when x <= 0.5 { x = 0.9 * x; } cost = integral(x^2); horizon 3; }"
    )
    m = mvad.from_source(src)
    f = m.grad(mode="forward", **TIGHT)
    a = m.grad(mode="auto", **TIGHT)
    assert a["stats"]["mode"] == "adjoint" and len(a["events"]) == 1
    for name in m.params:
        assert a["gradient"][name] == pytest.approx(f["gradient"][name], rel=1e-8, abs=1e-12)
