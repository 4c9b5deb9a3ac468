"""mvad: exact parameter derivatives of hybrid and non-smooth systems, as measures.

>>> import mvad
>>> m = mvad.load("models/bouncing_ball.hyb")
>>> r = m.grad(params={"e": 0.7}, wrt=["e", "g"], rtol=1e-10, atol=1e-12)
>>> r["cost"], r["gradient"]["e"], r["events"][0]["t"]   # the object of `mvad grad --json`

``Model.grad`` returns the JSON object of ``mvad grad --json`` as a dict; ``Model.simulate``
samples states and observables at given times; ``Model.measure`` gives the derivative of an
observable as a density on a grid plus atoms at the events (numpy arrays). ``Model.cost_batch``,
``Model.observe_batch`` and ``Model.observe_vjp_batch`` run many parameter sets across cores.

``mvad.jax`` and ``mvad.torch`` wrap a model as a differentiable function of a parameter
array whose backward pass is mvad's own derivative.

Every method takes ``params`` (overrides by name) and the run options ``rtol``, ``atol``,
``method`` (``auto``, ``tsit5``, ``verner9``, ``rosenbrock``), ``t_end``, ``grazing_tol`` and
``mode``: how derivatives are computed, ``forward`` (the default: sensitivities carried along
the run), ``adjoint`` (a primal run and one backward sweep, cost flat in the number of
parameters) or ``auto`` (adjoint from 50 parameters on). Both give the same numbers.
``tables`` replaces data tables the model declares: ``{"NAME": "FILE.csv"}`` or
``{"NAME": {"COL": array, ...}}`` (``mvad.load(path, tables=...)`` binds them once).

Errors: ``mvad.ModelError`` (a ``ValueError``) for a model that does not compile, its message
holding ``FILE:LINE:COL: error: ...``; ``ValueError`` for a bad request; ``mvad.SolveError``
(a ``RuntimeError``) for a run that failed. No input crashes the interpreter.
"""

from ._mvad import Model, ModelError, SolveError, __version__, from_source, load

__all__ = ["Model", "ModelError", "SolveError", "from_source", "load", "__version__"]
