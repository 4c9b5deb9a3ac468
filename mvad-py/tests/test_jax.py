"""mvad.jax: jax.grad, jax.vjp, jax.jit and jax.vmap through the custom VJP."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mvad
import mvad.jax
from conftest import BALL, TIGHT

jax.config.update("jax_enable_x64", True)

# 50 sample times on [0.02, 1.98]: both impacts (t ≈ 0.639 and 1.66) lie between samples.
TIMES = np.linspace(0.02, 1.98, 50)


def test_jax_grad_of_the_cost_equals_mvad_grad(ball, cli_grad):
    f = mvad.jax.cost(ball, wrt=["e", "g"], **TIGHT)
    theta = jnp.array([0.8, 9.81])
    grad = jax.grad(f)(theta)
    cli = cli_grad(BALL, "--wrt", "e,g", "--rtol", "1e-10", "--atol", "1e-12")
    want = np.array([cli["gradient"]["e"], cli["gradient"]["g"]])
    np.testing.assert_allclose(np.asarray(grad), want, rtol=1e-12, atol=1e-12)
    assert float(f(theta)) == pytest.approx(cli["cost"], rel=1e-12, abs=1e-12)
    value, g2 = jax.value_and_grad(f)(theta)
    assert float(value) == pytest.approx(cli["cost"], rel=1e-12)
    np.testing.assert_array_equal(np.asarray(g2), np.asarray(grad))


def _loss(y, target):
    return jnp.sum((y - target) ** 2)


def test_gradient_of_a_loss_over_observe_against_central_differences(ball):
    wrt = ["e", "g", "h0"]
    y = mvad.jax.observe(ball, TIMES, wrt=wrt, **TIGHT)
    target = jnp.asarray(0.3 * np.sin(TIMES)[:, None] * np.ones((1, 2)))
    theta = np.array([0.8, 9.81, 2.0])
    loss = lambda th: _loss(y(th), target)  # noqa: E731
    grad = np.asarray(jax.grad(loss)(jnp.asarray(theta)))
    assert y(jnp.asarray(theta)).shape == (50, 2)
    for j in range(len(wrt)):
        for h in (1e-4, 1e-5):
            up, down = theta.copy(), theta.copy()
            up[j] += h
            down[j] -= h
            fd = (float(loss(jnp.asarray(up))) - float(loss(jnp.asarray(down)))) / (2 * h)
            assert grad[j] == pytest.approx(fd, rel=1e-6, abs=1e-6), (wrt[j], h, grad[j], fd)


def test_jax_vjp_of_observe_equals_the_rust_vjp(ball):
    y = mvad.jax.observe(ball, TIMES, wrt=["e"], **TIGHT)
    ybar = np.cos(np.arange(100.0)).reshape(50, 2)
    out, pullback = jax.vjp(y, jnp.array([0.8]))
    (theta_bar,) = pullback(jnp.asarray(ybar))
    rust = ball.observe_vjp_batch(np.array([[0.8]]), TIMES, ybar[None], wrt=["e"], **TIGHT)
    np.testing.assert_array_equal(np.asarray(theta_bar), rust[0])
    np.testing.assert_array_equal(np.asarray(out), ball.observe_batch(np.array([[0.8]]), TIMES, wrt=["e"], **TIGHT)[0])


def test_jit_and_vmap_over_eight_parameter_sets(ball):
    f = mvad.jax.cost(ball, wrt=["e", "g"], **TIGHT)
    thetas = jnp.stack([jnp.linspace(0.5, 0.9, 8), jnp.linspace(9.5, 10.1, 8)], axis=1)
    batched = jax.jit(jax.vmap(jax.value_and_grad(f)))
    values, grads = batched(thetas)
    assert values.shape == (8,) and grads.shape == (8, 2)
    # The primal alone (a run without sensitivities, so its steps differ slightly).
    np.testing.assert_allclose(np.asarray(jax.vmap(f)(thetas)), np.asarray(values), rtol=1e-8)
    for k in range(8):
        r = ball.grad(params={"e": float(thetas[k, 0]), "g": float(thetas[k, 1])}, wrt=["e", "g"], **TIGHT)
        assert float(values[k]) == pytest.approx(r["cost"], rel=1e-12)
        np.testing.assert_allclose(np.asarray(grads[k]), [r["gradient"]["e"], r["gradient"]["g"]], rtol=1e-12)
    y = mvad.jax.observe(ball, TIMES, wrt=["e"], **TIGHT)
    es = jnp.linspace(0.5, 0.9, 8)[:, None]
    ys = jax.jit(jax.vmap(y))(es)
    assert ys.shape == (8, 50, 2)
    np.testing.assert_array_equal(np.asarray(ys[3]), np.asarray(y(es[3])))
    g = jax.jit(jax.vmap(jax.grad(lambda th: jnp.sum(y(th) ** 2))))(es)
    for k in (0, 7):
        single = jax.grad(lambda th: jnp.sum(y(th) ** 2))(es[k])
        np.testing.assert_allclose(np.asarray(g[k]), np.asarray(single), rtol=1e-12)


def test_jit_of_grad_and_bad_shapes(ball):
    f = mvad.jax.cost(ball, wrt=["e"], **TIGHT)
    g = jax.jit(jax.grad(f))(jnp.array([0.8]))
    assert float(g[0]) == pytest.approx(ball.grad(wrt=["e"], **TIGHT)["gradient"]["e"], rel=1e-12)
    with pytest.raises(ValueError, match="theta must have shape"):
        f(jnp.array([0.8, 9.81]))


def test_wrt_is_checked_when_the_function_is_made_and_a_repeat_counts_once(ball):
    """As in Model.grad and Model.cost_batch, a name given twice is one parameter: theta
    holds the distinct names. An unknown name fails at once, not at the first call."""
    f = mvad.jax.cost(ball, wrt=["e", "g", "e"], **TIGHT)
    g = jax.grad(f)(jnp.array([0.8, 9.81]))
    r = ball.grad(wrt=["e", "g"], **TIGHT)["gradient"]
    assert [float(v) for v in g] == [r["e"], r["g"]]
    with pytest.raises(ValueError, match="unknown parameter `q` in wrt"):
        mvad.jax.cost(ball, wrt=["q"])
    with pytest.raises(ValueError, match="unknown parameter `q` in wrt"):
        mvad.jax.observe(ball, TIMES, wrt=["e", "q"])


def test_a_failing_run_inside_jax_raises():
    blow = mvad.from_source("model Blow { param a = 1; state x = a; flow { der(x) = x^2; } cost = integral(x); horizon 2; }")
    f = mvad.jax.cost(blow, wrt=["a"])
    with pytest.raises(Exception, match="the run failed"):
        jax.grad(f)(jnp.array([1.0]))
