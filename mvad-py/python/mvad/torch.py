"""mvad models as PyTorch functions (``torch.autograd.Function``, float64) whose backward pass
is mvad's derivative.

>>> import torch, mvad, mvad.torch
>>> m = mvad.load("models/bouncing_ball.hyb")
>>> f = mvad.torch.cost(m, wrt=["e", "g"])
>>> theta = torch.tensor([0.8, 9.81], dtype=torch.float64, requires_grad=True)
>>> f(theta).backward(); theta.grad
>>> y = mvad.torch.observe(m, times, wrt=["e"])(theta_e)   # (len(times), n_observables)

theta may carry leading batch axes, ``(..., len(wrt))``: the batch runs across cores. The
cost's backward pass is c̄ · dC/dθ with dC/dθ from the same run as C (computed only when theta
requires grad); the observables' is ``Model.observe_vjp_batch``. Both are computed in the mode
the ``mode`` option names (``forward``, ``adjoint`` or ``auto``). Higher derivatives are not
available (``once_differentiable``).
"""

import torch
from torch.autograd.function import once_differentiable

from ._kernels import Cost, Observe

__all__ = ["cost", "observe"]


def _numpy(t):
    return t.detach().to(device="cpu", dtype=torch.float64).numpy()


def _tensor(a, like):
    return torch.from_numpy(a).to(device=like.device, dtype=torch.float64)


class _CostFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, theta, kernel):
        if theta.requires_grad:
            c, g = kernel.value_and_grad(_numpy(theta))
            ctx.save_for_backward(_tensor(g, theta))
        else:
            c = kernel.value(_numpy(theta))
        return _tensor(c, theta)

    @staticmethod
    @once_differentiable
    def backward(ctx, cbar):
        (g,) = ctx.saved_tensors
        return cbar.unsqueeze(-1) * g, None


class _ObserveFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, theta, kernel):
        ctx.kernel = kernel
        ctx.save_for_backward(theta.detach())
        return _tensor(kernel.value(_numpy(theta)), theta)

    @staticmethod
    @once_differentiable
    def backward(ctx, ybar):
        (theta,) = ctx.saved_tensors
        return _tensor(ctx.kernel.vjp(_numpy(theta), _numpy(ybar)), theta), None


def cost(model, wrt, params=None, **options):
    """f(theta) -> C(theta), theta a float64 tensor ordered as ``wrt`` (leading batch axes
    allowed); other parameters take ``params`` or their declared values. ``options``: rtol,
    atol, method, t_end, grazing_tol."""
    kernel = Cost(model, wrt, params, options)
    return lambda theta: _CostFunction.apply(theta, kernel)


def observe(model, times, wrt, params=None, **options):
    """y(theta) -> the observables at ``times``, shape (..., len(times), n_observables)."""
    kernel = Observe(model, times, wrt, params, options)
    return lambda theta: _ObserveFunction.apply(theta, kernel)
