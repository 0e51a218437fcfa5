"""ARX models by least squares: estimation, order selection and validation.

The model structure follows MATLAB's ``arx`` with orders ``[na nb nk]``::

    y(k) + a1 y(k-1) + ... + a_na y(k-na) = b1 u(k-nk) + ... + b_nb u(k-nk-nb+1) + e(k)

``a`` excludes the leading 1; ``nk`` is the delay in samples from the input to the first
``b`` term. Paper 000's closed-loop model ``[na nb d] = [4 1 1]`` (dead time d = 1 on top of
the one-sample delay of any sampled system) is ``orders=(4, 1, 2)`` here.

* :func:`fit_arx` estimates ``a``, ``b`` with their standard deviations (numerically
  sound least squares: SVD of the column-scaled regressor matrix, never the normal
  equations) and returns a frozen :class:`ArxModel`.
* :func:`select_order` compares candidate orders by loss, AIC, BIC, FPE (all on the same
  estimation samples) or on validation data, and returns a :class:`OrderSelection`.
* :func:`validate` simulates the model on (held-out) data - fit in percent - and tests
  the one-step residuals: autocorrelation (whiteness) and input-residual
  cross-correlation (independence) against 99 % confidence bands, returning a
  :class:`ArxValidation`.

Modules: :mod:`.model` (the model, :func:`fit_arx`), :mod:`.order` (:func:`select_order`),
:mod:`.validation` (:func:`validate`); the residual tests themselves are in
:mod:`workbench.signals`. Command line: :mod:`workbench.cli.identify`.

Closed-loop data: identifying the closed loop from the reference ``r`` to the position
``x`` (as paper 000 does) is an ordinary open-loop problem, because ``r`` is chosen by the
experimenter and does not depend on the noise. Identifying the plant from ``u`` to ``x``
inside a loop is not: the noise then feeds back into ``u`` and least squares is biased
unless the noise really has the ARX structure.

Examples
--------
>>> import numpy as np
>>> from workbench.identify.arx import fit_arx, validate
>>> from workbench.identify.excitation import aprbs
>>> rng = np.random.default_rng(0)
>>> u = aprbs(800, hold_min=5, low=0.0, high=10.0, seed=0)
>>> y = np.zeros(800)
>>> for k in range(2, 800):       # y(k) - 0.9 y(k-1) = 0.1 u(k-2) + e(k)
...     y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 2] + 0.01 * rng.standard_normal()
>>> model = fit_arx(y[:400], u[:400], orders=(1, 1, 2), sample_time=0.01)
>>> np.round(model.a, 2), np.round(model.b, 2)
(array([-0.9]), array([0.1]))
>>> check = validate(model, y[400:], u[400:])
>>> bool(check.fit > 95.0), check.whiteness_ok
(True, True)
"""

from __future__ import annotations

from ...signals import CONFIDENCE_Z99
from ...signals import WHITENESS_LEVEL as TEST_LEVEL
from .model import ArxModel, fit_arx
from .order import CRITERIA, OrderCandidate, OrderSelection, select_order
from .validation import ArxValidation, validate

__all__ = [
    "ArxModel", "fit_arx", "OrderCandidate", "OrderSelection", "select_order",
    "ArxValidation", "validate", "CONFIDENCE_Z99", "CRITERIA", "TEST_LEVEL",
]
