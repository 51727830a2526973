from .auto import AutoModes as AutoModes
from .base import AbstractModalSolver as AbstractModalSolver
from .basis import ModalBasis as ModalBasis
from .dense import DenseModes as DenseModes, retained_eigenpairs as retained_eigenpairs
from .interface import Interface as Interface, ReductionLayout as ReductionLayout
from .lanczos import LanczosModes as LanczosModes
from .reduction import ModalReduction as ModalReduction
from .reference import AbstractReference as AbstractReference, Clamped as Clamped, FixedDofs as FixedDofs, HingedHinged as HingedHinged
