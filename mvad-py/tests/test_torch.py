"""mvad.torch: autograd.Functions for the cost and the observables, float64."""

import numpy as np
import pytest
import torch

import mvad.torch
from conftest import BALL, TIGHT

TIMES = np.linspace(0.02, 1.98, 50)


def test_torch_autograd_grad_of_the_cost_equals_mvad_grad(ball, cli_grad):
    f = mvad.torch.cost(ball, wrt=["e", "g"], **TIGHT)
    theta = torch.tensor([0.8, 9.81], dtype=torch.float64, requires_grad=True)
    c = f(theta)
    (grad,) = torch.autograd.grad(c, theta)
    cli = cli_grad(BALL, "--wrt", "e,g", "--rtol", "1e-10", "--atol", "1e-12")
    want = np.array([cli["gradient"]["e"], cli["gradient"]["g"]])
    np.testing.assert_allclose(grad.numpy(), want, rtol=1e-12, atol=1e-12)
    assert c.item() == pytest.approx(cli["cost"], rel=1e-12)
    assert c.dtype == torch.float64
    with torch.no_grad():
        assert f(theta).item() == pytest.approx(cli["cost"], rel=1e-9)


def test_gradient_of_a_loss_over_observe_against_central_differences(ball):
    wrt = ["e", "g", "h0"]
    y = mvad.torch.observe(ball, TIMES, wrt=wrt, **TIGHT)
    target = torch.from_numpy(0.3 * np.sin(TIMES)[:, None] * np.ones((1, 2)))
    theta = torch.tensor([0.8, 9.81, 2.0], dtype=torch.float64, requires_grad=True)
    loss = lambda th: ((y(th) - target) ** 2).sum()  # noqa: E731
    (grad,) = torch.autograd.grad(loss(theta), theta)
    base = theta.detach().numpy()
    for j in range(len(wrt)):
        for h in (1e-4, 1e-5):
            up, down = base.copy(), base.copy()
            up[j] += h
            down[j] -= h
            fd = (loss(torch.from_numpy(up)).item() - loss(torch.from_numpy(down)).item()) / (2 * h)
            assert grad[j].item() == pytest.approx(fd, rel=1e-6, abs=1e-6), (wrt[j], h)


def test_batched_theta_and_gradcheck(ball):
    f = mvad.torch.cost(ball, wrt=["e", "g"], **TIGHT)
    thetas = torch.stack([torch.linspace(0.5, 0.9, 8), torch.linspace(9.5, 10.1, 8)], dim=1).double()
    thetas.requires_grad_(True)
    c = f(thetas)
    assert c.shape == (8,)
    (g,) = torch.autograd.grad(c.sum(), thetas)
    for k in (0, 5):
        r = ball.grad(params={"e": thetas[k, 0].item(), "g": thetas[k, 1].item()}, wrt=["e", "g"], **TIGHT)
        np.testing.assert_allclose(g[k].numpy(), [r["gradient"]["e"], r["gradient"]["g"]], rtol=1e-12)
    y = mvad.torch.observe(ball, TIMES[:10], wrt=["e", "g"], **TIGHT)
    theta = torch.tensor([0.8, 9.81], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(y, (theta,), eps=1e-6, atol=1e-5, rtol=1e-5)
