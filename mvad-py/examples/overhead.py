"""The overhead of mvad's Python layers over the Rust gradient, for the bouncing ball.

    python mvad-py/examples/overhead.py [REPEATS]

Prints the median wall time of one gradient computed five ways: the solve alone as Rust
measures it (`stats.wall_seconds` of `Model.grad`), `Model.cost_batch` on one row (the call
the layers make), `Model.grad` (which also builds the JSON dict), `jax.grad` of
`mvad.jax.cost` (eager and under `jax.jit`) and `torch.autograd.grad` of `mvad.torch.cost`.
"""

import pathlib
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import torch

import mvad
import mvad.jax
import mvad.torch

jax.config.update("jax_enable_x64", True)
MODEL = pathlib.Path(__file__).resolve().parents[2] / "models" / "bouncing_ball.hyb"


def median_seconds(fn, repeats):
    fn()  # warm up (JIT compilation, first calls)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(repeats=200):
    ball = mvad.load(str(MODEL))
    wrt = ["e", "g"]
    theta = np.array([0.8, 9.81])
    rust = statistics.median(ball.grad(wrt=wrt)["stats"]["wall_seconds"] for _ in range(repeats))
    f = mvad.jax.cost(ball, wrt=wrt)
    grad = jax.grad(f)
    jit_grad = jax.jit(grad)
    jtheta = jnp.asarray(theta)
    tf = mvad.torch.cost(ball, wrt=wrt)
    ttheta = torch.tensor(theta, requires_grad=True)
    rows = [
        ("Rust solve (stats.wall_seconds)", rust),
        ("Model.cost_batch, one row", median_seconds(lambda: ball.cost_batch(theta[None], wrt=wrt), repeats)),
        ("Model.grad (JSON dict)", median_seconds(lambda: ball.grad(wrt=wrt), repeats)),
        ("jax.grad(mvad.jax.cost)", median_seconds(lambda: grad(jtheta).block_until_ready(), repeats)),
        ("jax.jit(jax.grad(...))", median_seconds(lambda: jit_grad(jtheta).block_until_ready(), repeats)),
        ("torch.autograd.grad", median_seconds(lambda: torch.autograd.grad(tf(ttheta), ttheta), repeats)),
    ]
    print(f"bouncing ball, dC/d(e, g), default tolerances, median of {repeats} calls")
    print(f"{'':34} {'µs':>10} {'overhead µs':>12}")
    for name, t in rows:
        print(f"{name:34} {t * 1e6:>10.1f} {(t - rust) * 1e6:>12.1f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
