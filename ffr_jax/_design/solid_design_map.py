"""The design map of one designed solid part in a spatial scene: its densities -> its spatial body data."""

import equinox as eqx

from .._scene._scene import Scene
from .._spatial._flexible_body_data import SpatialFlexibleBodyData
from .design_map import AbstractDesignMap
from .solid_designed_body import SolidDesignedBody


class SolidDesignMap(AbstractDesignMap):
    """Writes a [`SolidDesignedBody`][]'s spatial body data for a design into the scene body `name`.

    The design is the part's `(n_design,)` density vector (or `{name: x}`); `psi(x)` and its gradient follow from a
    [`Case`][] with this map as for a planar design map: the gradient is one VJP of `x -> body data` after the
    sensitivity method, its cost independent of the number of densities.

    **Arguments:** `body`, the [`SolidDesignedBody`][]; `name`, the scene body it writes (default `"rod"`).
    """

    body: SolidDesignedBody
    name: str = eqx.field(static=True, default="rod")

    @property
    def n_design(self) -> int:
        return self.body.n_design

    @property
    def design(self) -> SolidDesignedBody:
        """The designed body (e.g. for `fj.DensityFilter(design_map.design, radius, scale=(1, 1, 1))`)."""
        return self.body

    @property
    def only(self) -> SolidDesignedBody:
        """The designed body (the one a solid design map has)."""
        return self.body

    def frequencies(self, designs):
        """Retained natural frequencies in Hz, `(n_modes,)`."""
        return self.body.frequencies(self.check(designs))

    def initial_design(self, value=0.5):
        return self.body.initial_design(value)

    def check(self, designs):
        if isinstance(designs, dict):
            if set(designs) != {self.name}:
                raise ValueError(f"The design has entries {sorted(designs)}; the designed body is {self.name!r}.")
            designs = designs[self.name]
        return self.body.check(designs, self.name)

    def check_scene(self, scene: Scene) -> None:
        data = scene.bodies[scene.body_index(self.name)].data
        n_markers = len(self.body.markers)
        if (not isinstance(data, SpatialFlexibleBodyData) or data.n_modes != self.body.n_modes
                or data.marker_positions.shape[0] != n_markers):
            raise ValueError(f"The scene's body {self.name!r} must be a spatial flexible body with {self.body.n_modes} "
                             f"modes and {n_markers} markers: build it from SolidDesignedBody.body_data.")

    def __call__(self, designs, scene: Scene) -> Scene:
        index = scene.body_index(self.name)
        return eqx.tree_at(lambda s: s.bodies[index].data, scene, self.body_data(designs))

    def body_data(self, designs) -> SpatialFlexibleBodyData:
        """The spatial body data of the designed part."""
        return self.body.body_data(self.check(designs))
