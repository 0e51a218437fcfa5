"""Coefficients of the one-step methods: immutable tableaux (as in diffrax).

A tableau holds numbers only; :mod:`.steppers` turns a tableau, a right-hand side
and a step size into CasADi expressions and Functions.

* :class:`ButcherTableau`: Runge-Kutta methods (explicit :data:`RK4`, implicit
  Radau IIA with 1, 2 or 3 stages, :data:`RADAU_IIA`).
* :class:`RosenbrockTableau`: linearly implicit methods in the form of Hairer &
  Wanner (Solving ODEs II, sec. IV.7), :data:`ROS2`, :data:`ROS4`, :data:`RODAS4`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ButcherTableau", "RosenbrockTableau", "RK4", "RADAU_IIA_1", "RADAU_IIA_2",
           "RADAU_IIA_3", "RADAU_IIA", "ROS2", "ROS4", "RODAS4"]


@dataclass(frozen=True)
class ButcherTableau:
    """A Runge-Kutta method: stages k_i = f(x + h sum_j a_ij k_j), x+ = x + h sum_i b_i k_i.

    Attributes
    ----------
    name : str
    a : rows of the Butcher matrix (lower triangular with zero diagonal: explicit).
    b : weights. c : nodes (row sums of a), fractions of the step.
    order : classical order of the method.
    stability : the linear stability property, in words.
    """

    name: str
    a: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]
    order: int
    stability: str

    @property
    def stages(self) -> int:
        return len(self.b)

    @property
    def A(self) -> np.ndarray:
        """The Butcher matrix as an (s, s) array."""
        return np.array(self.a, dtype=float)

    @property
    def explicit(self) -> bool:
        return all(self.a[i][j] == 0.0 for i in range(self.stages)
                   for j in range(i, self.stages))


#: Classical Runge-Kutta, 4 stages, order 4; explicit: stable only for h |lambda| below
#: ~2.8 on the real axis (not for stiff problems). Exact for polynomials of degree 4 in t.
RK4 = ButcherTableau(
    name="rk4",
    a=((0.0, 0.0, 0.0, 0.0), (0.5, 0.0, 0.0, 0.0), (0.0, 0.5, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)),
    b=(1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0),
    c=(0.0, 0.5, 0.5, 1.0),
    order=4,
    stability="explicit: bounded stability region (about h lambda > -2.79 on the real axis)",
)

#: Radau IIA, 1 stage (implicit Euler), order 1, L-stable and stiffly accurate.
RADAU_IIA_1 = ButcherTableau(name="radau_iia_1", a=((1.0,),), b=(1.0,), c=(1.0,), order=1,
                             stability="L-stable, stiffly accurate")

#: Radau IIA, 2 stages, order 3, L-stable and stiffly accurate (Hairer & Wanner, IV.5).
RADAU_IIA_2 = ButcherTableau(
    name="radau_iia_2",
    a=((5.0 / 12.0, -1.0 / 12.0), (3.0 / 4.0, 1.0 / 4.0)),
    b=(3.0 / 4.0, 1.0 / 4.0),
    c=(1.0 / 3.0, 1.0),
    order=3,
    stability="L-stable, stiffly accurate")

_S6 = math.sqrt(6.0)
_R3 = (((88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225),
       ((296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225),
       ((16 - _S6) / 36, (16 + _S6) / 36, 1.0 / 9.0))
#: Radau IIA, 3 stages, order 5, L-stable and stiffly accurate (Hairer & Wanner, IV.5;
#: the last row of a is b).
RADAU_IIA_3 = ButcherTableau(name="radau_iia_3", a=_R3, b=_R3[2],
                             c=((4 - _S6) / 10, (4 + _S6) / 10, 1.0), order=5,
                             stability="L-stable, stiffly accurate")

#: Radau IIA tableaux by number of stages.
RADAU_IIA: dict[int, ButcherTableau] = {1: RADAU_IIA_1, 2: RADAU_IIA_2, 3: RADAU_IIA_3}


@dataclass(frozen=True)
class RosenbrockTableau:
    """A Rosenbrock method, with J = f'(x) (or an approximation of it).

    Two normalisations of the coefficients are in use in the literature:

    * ``form="hw"``, Hairer & Wanner (Solving ODEs II, sec. IV.7):
      (1/(h gamma) I - J) k_i = f(x + sum_j a_ij k_j) + sum_j c_ij / h k_j,
      x+ = x + sum_i m_i k_i;
    * ``form="w"``, Verwer et al. (1999):
      (I - gamma h J) k_i = f(x + h sum_j a_ij k_j) + sum_j c_ij k_j,
      x+ = x + h sum_i m_i k_i.

    Attributes
    ----------
    name : str
    gamma : diagonal coefficient. a, c : strictly lower rows (row i has i entries).
    m : weights of the stages. order : classical order. stability : in words.
    form : ``"hw"`` or ``"w"``, the normalisation above.
    e : weights of the embedded error estimate, err = sum_i e_i k_i (the difference
        between the method and an embedded one of order ``order - 1``); empty when
        the method has none.
    """

    name: str
    gamma: float
    a: tuple[tuple[float, ...], ...]
    c: tuple[tuple[float, ...], ...]
    m: tuple[float, ...]
    order: int
    stability: str
    form: str = "hw"
    e: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.form not in ("hw", "w"):
            raise ValueError(f"form must be 'hw' or 'w', got {self.form!r}")
        if self.e and len(self.e) != len(self.m):
            raise ValueError(f"{self.name}: {len(self.e)} error weights for {len(self.m)} stages")

    @property
    def stages(self) -> int:
        return len(self.m)


#: ROS2 (Verwer et al. 1999), 2 stages, order 2, L-stable, gamma = 1 + 1/sqrt(2); keeps
#: order 2 for any approximation W of the Jacobian. Verwer's form: with W = I - gamma h J,
#: W k1 = f(x), W k2 = f(x + h k1) - 2 k1, x+ = x + h (1.5 k1 + 0.5 k2).
ROS2 = RosenbrockTableau(name="ros2", gamma=1.0 + 1.0 / math.sqrt(2.0), a=((), (1.0,)),
                         c=((), (-2.0,)), m=(1.5, 0.5), order=2,
                         stability="L-stable, order 2 for any Jacobian approximation", form="w")

#: ROS4: the 4-stage method of order 4 of Hairer & Wanner (Solving ODEs II, sec. IV.7;
#: the L-stable choice of ros4.f); stages 3 and 4 share one f. ``e``: ros4.f's embedded
#: error estimate (x+ minus a solution of order 3; local error O(h^4)).
ROS4 = RosenbrockTableau(
    name="ros4",
    gamma=0.57282,
    a=((), (2.0,), (1.867943637803922, 0.2344449711399156),
       (1.867943637803922, 0.2344449711399156, 0.0)),
    c=((), (-7.137615036412310,), (2.580708087951457, 0.6515950076447975),
       (-2.137148994382534, -0.3214669691237626, -0.6949742501781779)),
    m=(2.255570073418735, 0.2870493262186792, 0.4353179431840180, 1.093502252409163),
    order=4,
    stability="L-stable",
    e=(-0.2815431932141155, -0.07276199124938920, -0.1082196201495311, -1.093502252409163))

_RODAS_A5 = (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950)
#: RODAS, 6 stages, order 4, L-stable and stiffly accurate (Hairer & Wanner, rodas.f).
RODAS4 = RosenbrockTableau(
    name="rodas4",
    gamma=0.25,
    a=((), (1.544,), (0.9466785280815826, 0.2557011698983284),
       (3.314825187068521, 2.896124015972201, 0.9986419139977817),
       _RODAS_A5, _RODAS_A5 + (1.0,)),
    c=((), (-5.6688,), (-2.430093356833875, -0.2063599157091915),
       (-0.1073529058151375, -9.594562251023355, -20.47028614809616),
       (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160),
       (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136,
        -6.058818238834054)),
    m=_RODAS_A5 + (1.0, 1.0),
    order=4,
    stability="L-stable, stiffly accurate")
