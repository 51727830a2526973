"""Stiff ODE solvers for diffrax: linearly implicit Rosenbrock methods (one class per file)."""

from ._rodas4 import Rodas4 as Rodas4
from ._rodas5p import Rodas5P as Rodas5P
from ._rosenbrock import AbstractRosenbrock as AbstractRosenbrock, RosenbrockInterpolation as RosenbrockInterpolation, RosenbrockTableau as RosenbrockTableau
