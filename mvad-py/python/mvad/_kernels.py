"""The numpy kernels behind ``mvad.jax`` and ``mvad.torch``: a model, the parameters to
differentiate by (``wrt``, the order of theta) and the run options, applied to parameter
arrays of any leading batch shape ``(..., len(wrt))``. Batches run across cores in Rust
(``Model.cost_batch``, ``Model.observe_batch``, ``Model.observe_vjp_batch``).

The backward passes are Rust's: ``c̄ · dC/dθ`` with dC/dθ from the same run as C
(``mvad::runtime::vjp::cost_gradient``), and ``Model.observe_vjp_batch``
(``mvad::runtime::vjp::observe_vjp``): both go through ``mvad::runtime::vjp::vjp``, the one
entry point, which computes them in the mode of the ``mode`` option (forward sensitivities,
or the adjoint's backward sweep).
"""

import numpy as np


def _rows(theta, width):
    theta = np.asarray(theta, dtype=np.float64)
    if theta.ndim == 0 or theta.shape[-1] != width:
        raise ValueError(
            f"theta must end in an axis of length {width} (one entry per wrt parameter), "
            f"got shape {theta.shape}"
        )
    return np.ascontiguousarray(theta.reshape(-1, width)), theta.shape[:-1]


def _distinct(wrt):
    """``wrt`` with a repeated name kept once, in first-seen order: the parameters theta holds
    (``Model.cost_batch`` and ``Model.grad`` count a repeated name once too)."""
    return list(dict.fromkeys(wrt))


def _check_request(model, wrt, params, options):
    """Raises the ValueError a batch with this ``wrt`` (names known), ``params`` and
    ``options`` would raise, now rather than at the first call: Rust checks a batch of no rows
    exactly as it checks every batch."""
    if not wrt:
        raise ValueError("wrt names no parameter")
    model.cost_batch(
        np.empty((0, len(wrt))), wrt=wrt, params=params, gradient=False, **options
    )


class Cost:
    """C(theta) and dC/dtheta for the parameters ``wrt``."""

    def __init__(self, model, wrt, params=None, options=None):
        self.model = model
        self.wrt = _distinct(wrt)
        self.params = params
        self.options = dict(options or {})
        _check_request(model, self.wrt, params, self.options)

    def value(self, theta):
        rows, batch = _rows(theta, len(self.wrt))
        c, _ = self.model.cost_batch(
            rows, wrt=self.wrt, params=self.params, gradient=False, **self.options
        )
        return c.reshape(batch)

    def value_and_grad(self, theta):
        rows, batch = _rows(theta, len(self.wrt))
        c, g = self.model.cost_batch(
            rows, wrt=self.wrt, params=self.params, gradient=True, **self.options
        )
        return c.reshape(batch), g.reshape(batch + (len(self.wrt),))


class Observe:
    """The observables at ``times`` (shape ``(len(times), n_observables)``) and their VJP."""

    def __init__(self, model, times, wrt, params=None, options=None):
        self.model = model
        self.times = np.ascontiguousarray(np.asarray(times, dtype=np.float64).ravel())
        self.wrt = _distinct(wrt)
        self.params = params
        self.options = dict(options or {})
        self.shape = (len(self.times), len(model.observables))
        _check_request(model, self.wrt, params, self.options)

    def value(self, theta):
        rows, batch = _rows(theta, len(self.wrt))
        y = self.model.observe_batch(
            rows, self.times, wrt=self.wrt, params=self.params, **self.options
        )
        return y.reshape(batch + self.shape)

    def vjp(self, theta, cotangent):
        rows, batch = _rows(theta, len(self.wrt))
        cot = np.asarray(cotangent, dtype=np.float64)
        cot = np.ascontiguousarray(np.broadcast_to(cot, batch + self.shape).reshape((-1,) + self.shape))
        v = self.model.observe_vjp_batch(
            rows, self.times, cot, wrt=self.wrt, params=self.params, **self.options
        )
        return v.reshape(batch + (len(self.wrt),))
