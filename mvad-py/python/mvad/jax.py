"""mvad models as JAX functions with a custom VJP whose backward pass is mvad's derivative.

>>> import jax, jax.numpy as jnp, mvad, mvad.jax
>>> jax.config.update("jax_enable_x64", True)        # mvad computes in float64
>>> m = mvad.load("models/bouncing_ball.hyb")
>>> f = mvad.jax.cost(m, wrt=["e", "g"])              # f(theta) -> C, theta ordered as wrt
>>> jax.grad(f)(jnp.array([0.8, 9.81]))
>>> y = mvad.jax.observe(m, times, wrt=["e"])         # y(theta) -> (len(times), n_observables)

The functions run the model through ``jax.pure_callback``, so ``jax.jit`` accepts them, and
``jax.vmap`` hands the whole batch to one call that runs across cores. ``jax.grad`` and
``jax.vjp`` use ``jax.custom_vjp``: the cost's backward pass is c̄ · dC/dθ with dC/dθ from the
same run as C; the observables' is ``Model.observe_vjp_batch``. Both come from Rust's one VJP
entry point (``mvad::runtime::vjp``), in the mode the ``mode`` option names (``forward``,
``adjoint`` or ``auto``). Higher derivatives are not available.

Without ``jax_enable_x64`` JAX computes in float32 and the results are rounded to it; a
warning says so once.
"""

import warnings

import jax
import jax.numpy as jnp

from ._kernels import Cost, Observe

__all__ = ["cost", "observe"]

_warned = False


def _dtype():
    global _warned
    if not jax.config.jax_enable_x64 and not _warned:
        _warned = True
        warnings.warn(
            "mvad.jax: jax_enable_x64 is off, so results are rounded to float32; "
            'call jax.config.update("jax_enable_x64", True) for mvad\'s float64 accuracy',
            stacklevel=3,
        )
    return jnp.float64 if jax.config.jax_enable_x64 else jnp.float32


def _callback(fn, shapes, *args):
    """``fn`` on numpy arrays; batched by vmap into one call (all batch axes broadcast)."""
    return jax.pure_callback(fn, shapes, *args, vmap_method="broadcast_all")


def cost(model, wrt, params=None, **options):
    """f(theta) -> C(theta), theta a 1-D array ordered as ``wrt``; other parameters take
    ``params`` (overrides by name) or their declared values. ``options``: rtol, atol, method,
    t_end, grazing_tol, mode."""
    kernel = Cost(model, wrt, params, options)
    w = len(kernel.wrt)

    def value(theta):
        dt = _dtype()
        return kernel.value(theta).astype(dt)

    def value_and_grad(theta):
        dt = _dtype()
        c, g = kernel.value_and_grad(theta)
        return c.astype(dt), g.astype(dt)

    def shapes():
        dt = _dtype()
        return jax.ShapeDtypeStruct((), dt), jax.ShapeDtypeStruct((w,), dt)

    @jax.custom_vjp
    def f(theta):
        return _callback(value, shapes()[0], _checked(theta, w))

    def f_fwd(theta):
        c, g = _callback(value_and_grad, shapes(), _checked(theta, w))
        return c, g

    def f_bwd(g, cbar):
        return (cbar * g,)

    f.defvjp(f_fwd, f_bwd)
    return f


def observe(model, times, wrt, params=None, **options):
    """y(theta) -> the observables at ``times``, shape (len(times), n_observables), theta a
    1-D array ordered as ``wrt``. Samples are right-continuous at events."""
    kernel = Observe(model, times, wrt, params, options)
    w = len(kernel.wrt)

    def value(theta):
        return kernel.value(theta).astype(_dtype())

    def vjp(theta, ybar):
        return kernel.vjp(theta, ybar).astype(_dtype())

    @jax.custom_vjp
    def f(theta):
        return _callback(value, jax.ShapeDtypeStruct(kernel.shape, _dtype()), _checked(theta, w))

    def f_fwd(theta):
        return f(theta), theta

    def f_bwd(theta, ybar):
        return (_callback(vjp, jax.ShapeDtypeStruct((w,), _dtype()), theta, ybar),)

    f.defvjp(f_fwd, f_bwd)
    return f


def _checked(theta, w):
    theta = jnp.asarray(theta, dtype=_dtype())
    if theta.shape != (w,):
        raise ValueError(f"theta must have shape ({w},), one entry per wrt parameter; got {theta.shape}")
    return theta
