from .base import AbstractElement as AbstractElement
from .q4 import Q4 as Q4
from .qm6 import QM6 as QM6
