"""Ready-made scenes with their designs: the paper's slider–crank first."""

from ._slider_crank import slider_crank as slider_crank
from ._flexible_pendulum import flexible_pendulum as flexible_pendulum
from ._four_bar import four_bar as four_bar
from ._rigid_slider_crank import rigid_slider_crank as rigid_slider_crank
from ._spinning_beam import spinning_beam as spinning_beam
from ._rod import rod_body as rod_body
