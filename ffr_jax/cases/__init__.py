"""Ready-made scenes with their designs: the paper's slider–crank first."""

from ._slider_crank import slider_crank as slider_crank
