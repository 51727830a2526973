"""Ready-made scenes with their designs: the paper's slider–crank first."""

from ._slider_crank import slider_crank as slider_crank
from ._flexible_pendulum import flexible_pendulum as flexible_pendulum
from ._four_bar import four_bar as four_bar
from ._four_bar_two_links import four_bar_two_links as four_bar_two_links
from ._rigid_slider_crank import rigid_slider_crank as rigid_slider_crank
from ._spinning_beam import spinning_beam as spinning_beam
from ._spin_up_beam import spin_up_beam as spin_up_beam
from ._link_four_bar import link_body as link_body, link_four_bar as link_four_bar
from ._rod import rod_body as rod_body
from ._spatial_four_bar import spatial_four_bar as spatial_four_bar
from ._solid_rod import SolidRod as SolidRod, solid_rod as solid_rod
from ._solid_slider_crank import solid_slider_crank as solid_slider_crank
from ._connecting_rod import connecting_rod as connecting_rod, connecting_rod_slider_crank as connecting_rod_slider_crank
from ._connecting_rod_mesh import connecting_rod_groups as connecting_rod_groups
