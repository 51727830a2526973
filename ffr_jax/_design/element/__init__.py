from .base import AbstractElement as AbstractElement
from .q4 import Q4 as Q4
from .qm6 import QM6 as QM6
from .solid_base import AbstractSolidElement as AbstractSolidElement
from .h8 import H8 as H8
from .h11 import H11 as H11
from .tet10 import Tet10 as Tet10
