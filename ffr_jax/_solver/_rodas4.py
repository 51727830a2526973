"""Rodas4: a 6-stage, order-4 stiffly accurate L-stable Rosenbrock method with order-3 dense output."""

from typing import ClassVar

import numpy as np

from ._rosenbrock import AbstractRosenbrock, RosenbrockTableau, lower, stiffly_accurate_rows


_S = 6
_A, _B, _B_ERROR = stiffly_accurate_rows(
    (
        (1.544,),
        (0.9466785280815826, 0.2557011698983284),
        (3.314825187068521, 2.896124015972201, 0.9986419139977817),
        (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950),
    ),
    _S,
)

_TABLEAU = RosenbrockTableau(
    gamma=0.25,
    a=_A,
    c_coupling=lower(
        (
            (-5.6688,),
            (-2.430093356833875, -0.2063599157091915),
            (-0.1073529058151375, -9.594562251023355, -20.47028614809616),
            (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160),
            (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054),
        ),
        _S,
    ),
    c=np.array([0.0, 0.386, 0.21, 0.63, 1.0, 1.0]),
    d=np.array([0.25, -0.1043, 0.1035, -0.03620000000000023, 0.0, 0.0]),
    b=_B,
    b_error=_B_ERROR,
    dense=np.array([
        [10.12623508344586, -7.487995877610167, -34.80091861555747, -7.992771707568823, 1.025137723295662, 0.0],
        [-0.6762803392801253, 6.087714651680015, 16.43084320892478, 24.76722511418386, -6.594389125716872, 0.0],
    ]),
    order=4,
    dense_order=3,
    embedded_order=3,
)


class Rodas4(AbstractRosenbrock):
    """Rodas4 (Hairer and Wanner): 6 stages, order 4 with an embedded order-3 error estimate,
    stiffly accurate and L-stable, order-3 dense output (Shampine's form); one Jacobian and one LU
    per step.

    !!! cite "Reference"
        Hairer, Wanner (1996). Solving Ordinary Differential Equations II: Stiff and
        Differential-Algebraic Problems, 2nd ed., Sect. VI.4 (code RODAS). Coefficients as in
        OrdinaryDiffEq.jl (`Rodas4Tableau`).
    """

    tableau: ClassVar[RosenbrockTableau] = _TABLEAU
