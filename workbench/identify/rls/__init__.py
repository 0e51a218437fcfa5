"""Recursive least squares with a forgetting factor for time-varying ARX models (paper 002).

The model is an ARX model whose parameters may change with time, with MATLAB's ``arx``
order convention ``(na, nb, nk)``::

    y(k) + a1(k) y(k-1) + ... + a_na(k) y(k-na)
         = b1(k) u(k-nk) + ... + b_nb(k) u(k-nk-nb+1) + e(k)

so ``theta = [a1 .. a_na, b1 .. b_nb]`` and the regressor is
``phi(k) = [-y(k-1) .. -y(k-na), u(k-nk) .. u(k-nk-nb+1)]``. At every sample the
estimate is corrected by the a priori prediction error (physics.md, "Identification")::

    eps(k)   = y(k) - phi(k)' theta(k-1)
    K(k)     = P(k-1) phi(k) / (lambda + phi(k)' P(k-1) phi(k))
    theta(k) = theta(k-1) + K(k) eps(k)
    P(k)     = (P(k-1) - K(k) phi(k)' P(k-1)) / lambda

with the forgetting factor ``0 < lambda <= 1``: data ``j`` samples old carry the weight
``lambda**j`` (memory of about ``1 / (1 - lambda)`` samples). Paper 002 tracked a
2nd-order model of a pneumatic cylinder from 1000 PRBS samples and found
``lambda = 0.99`` best; ``0.9`` follows changes faster but is much noisier.

Numerical form (what is computed, equivalent to the recursion above)
--------------------------------------------------------------------
* **Forget first, then a unit-weight update**: ``P~ = P(k-1) / lambda_k``,
  ``K = P~ phi / (1 + phi' P~ phi)``; this is algebraically the same gain and covariance
  as the textbook form.
* **Joseph form** of the covariance update,
  ``P(k) = (I - K phi') P~ (I - K phi')' + K K'``, which stays positive semi-definite
  under rounding (the short form ``P~ - K phi' P~`` can lose definiteness when ``P`` is
  badly conditioned), followed by **symmetrisation** ``(P + P') / 2``.
* **Bounded trace against wind-up.** When the input stops exciting the system, plain
  forgetting divides ``P`` by ``lambda`` at every sample in the unexcited directions and
  ``P`` grows without bound (estimator wind-up: a burst of huge gains when excitation
  returns, eventually overflow). Here the forgetting factor of a step is raised just
  enough to keep ``trace(P) <= p_max``: ``lambda_k = min(1, max(lambda, trace(P(k-1)) /
  p_max))`` (default ``p_max = trace(P(0)) / lambda``: ``P`` never grows beyond its
  forgotten prior). While the data excite the system ``trace(P)`` is far below the
  bound and ``lambda_k = lambda`` exactly; the
  fraction of samples where the bound acted is reported
  (:attr:`RlsResult.effective_forgetting`).

Standard deviations
-------------------
With white equation noise of variance ``sigma**2`` and constant parameters, the
estimate at ``k`` is a weighted least-squares estimate with weights ``w_i``
(products of the ``lambda_k``), ``P(k)**-1 = sum w_i phi_i phi_i'`` (plus the prior),
and its covariance is the sandwich ``sigma**2 P M P`` with ``M = sum w_i**2 phi_i
phi_i'`` (``M(k) = lambda_k**2 M(k-1) + phi phi'``). For ``lambda = 1`` this is
``sigma**2 P``; for ``lambda < 1`` in steady state it tends to ``sigma**2 P / (1 +
lambda)`` (about half of ``sigma**2 P``, as MATLAB's recursive estimators note), so
scaling ``P`` alone would overstate the spread by up to ``sqrt(2)``. ``sigma**2`` is
estimated on line from the weighted residual sum of squares
``V(k) = lambda_k V(k-1) + eps**2 / (1 + phi' P~ phi)`` divided by its degrees of
freedom ``sum w_i - trace(P M)`` (``N - n`` for ``lambda = 1``); it is NaN until more
than half a degree of freedom is left. The bands describe the noise-driven spread of
the estimate, not its lag behind a parameter that is moving.

Speed
-----
The recursion runs as a plain C loop (:mod:`.ckernel`): the number of parameters fixed
at build time, the regressors formed in the loop from ``y`` and ``u``, the covariance
update on the upper triangle, the tracks written straight into the result's arrays;
built by :func:`workbench.integrate.jit.shared_library` once per number of parameters
and cached on disk. Without a C compiler the per-sample step is one CasADi ``SX``
function that ``mapaccum`` turns into a loop over chunks of samples
(``method="casadi"``, on CasADi's virtual machine there). A plain numpy per-sample loop
of the same arithmetic (``method="numpy"``) is the independent check of both and the
accuracy reference of ``workbench bench rls`` (:mod:`workbench.bench.rls`), whose
baseline is the same recursion as a numba-compiled scalar loop.

Modules: :mod:`.estimator` (:func:`rls`, :class:`RlsResult`), :mod:`.kernels` (the
recursion, numpy and CasADi loops), :mod:`.ckernel` (the C loop), :mod:`.forgetting` (:func:`choose_forgetting`),
:mod:`.report` (the Markdown report), :mod:`.simulate` (the model's simulated output: open
loop, in the experiment's loop, or integrated from a velocity model). Command line: :mod:`workbench.cli.identify`.

Examples
--------
>>> import numpy as np
>>> from workbench.identify.rls import rls
>>> rng = np.random.default_rng(0)
>>> u = rng.choice([-1.0, 1.0], 500)
>>> y = np.zeros(500)
>>> for k in range(2, 500):        # y(k) - 1.5 y(k-1) + 0.7 y(k-2) = u(k-1) + 0.5 u(k-2)
...     y[k] = 1.5 * y[k-1] - 0.7 * y[k-2] + u[k-1] + 0.5 * u[k-2]
>>> res = rls(y, u, (2, 2, 1), forgetting=1.0)
>>> res.names
('a1', 'a2', 'b1', 'b2')
>>> np.round(res.theta[-1], 6).tolist()
[-1.5, 0.7, 1.0, 0.5]
"""

from __future__ import annotations

from .estimator import RlsResult, parameter_names, regressors, rls
from .forgetting import DEFAULT_CANDIDATES, ForgettingChoice, choose_forgetting
from .simulate import a_priori_track, simulate_tarx

__all__ = ["RlsResult", "ForgettingChoice", "rls", "choose_forgetting", "regressors",
           "parameter_names", "DEFAULT_CANDIDATES", "a_priori_track", "simulate_tarx"]
