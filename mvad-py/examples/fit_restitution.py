"""Recover the bouncing ball's restitution e from noisy heights, as a user would: a JAX loss
over mvad.jax.observe, minimised with optax's L-BFGS.

    python mvad-py/examples/fit_restitution.py        # prints the iterations and the estimate

The data are heights at 40 times over [0, 2] s (two impacts) of the ball with e = 0.75, plus
Gaussian noise of 1 cm (seeded). The fit starts at e = 0.5.
"""

import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import optax

import mvad
import mvad.jax

jax.config.update("jax_enable_x64", True)

MODEL = pathlib.Path(__file__).resolve().parents[2] / "models" / "bouncing_ball.hyb"
E_TRUE, E_START, NOISE = 0.75, 0.5, 0.01


def fit(max_iterations=100, tol=1e-9):
    """Returns (estimate, iterations, final loss); stops when |dL/de| < tol."""
    ball = mvad.load(str(MODEL))
    times = np.linspace(0.05, 1.95, 40)
    heights = ball.simulate(times, params={"e": E_TRUE})["observables"]["height"]
    data = heights + NOISE * np.random.default_rng(0).standard_normal(times.size)

    y = mvad.jax.observe(ball, times, wrt=["e"], rtol=1e-10, atol=1e-12)

    def loss(theta):
        return jnp.mean((y(theta)[:, 0] - data) ** 2)

    # L-BFGS with optax's zoom line search; the gradient is mvad's, through the custom VJP.
    opt = optax.lbfgs()
    value_and_grad = optax.value_and_grad_from_state(loss)

    @jax.jit
    def step(theta, state):
        value, grad = value_and_grad(theta, state=state)
        updates, state = opt.update(grad, state, theta, value=value, grad=grad, value_fn=loss)
        return optax.apply_updates(theta, updates), state, value, grad

    theta = jnp.array([E_START])
    state = opt.init(theta)
    for it in range(1, max_iterations + 1):
        new_theta, new_state, value, grad = step(theta, state)
        if abs(float(grad[0])) < tol:
            break
        theta, state = new_theta, new_state
    return float(theta[0]), it, float(value)


def main():
    e, iterations, value = fit()
    print(f"true e = {E_TRUE}, start e = {E_START}, noise = {NOISE} m")
    print(f"estimate e = {e:.6f} after {iterations} iterations (mean squared residual {value:.3e})")
    return 0 if abs(e - E_TRUE) < 0.01 and iterations < 100 else 1


if __name__ == "__main__":
    sys.exit(main())
