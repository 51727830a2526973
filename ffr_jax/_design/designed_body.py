"""A designed flexible body: the pure map from its design vector to its body data.

`x -> x_e (roles) -> (E_e, rho_e) (SIMP) -> (K, M) -> Phi (modal reduction) -> body data`
"""

import equinox as eqx

from .._errors import clean_errors
from .._scene._body_data import BodyData, _check_body_data
from .assembly import ElementOperator, FEModel
from .body_data import body_data, marker_node_sets
from .domain import DesignDomain
from .geometric_stiffness import centrifugal_geometric_stiffness
from .material import SIMP
from .mesh import QuadMesh
from .modal.basis import ModalBasis
from .modal.reduction import ModalReduction


class DesignedBody(eqx.Module):
    """One density-designed flexible body: FE model, design domain, material, modal basis, markers.

    **Arguments:**
    - `model`: the [`FEModel`][] (mesh, element, thickness, Poisson ratio).
    - `domain`: the [`DesignDomain`][] on the same mesh (which elements are design variables).
    - `material`: the [`SIMP`][] law.
    - `reduction`: the [`ModalReduction`][] (modes, reference conditions, interfaces, solver).
    - `markers`: static tuple of joint points, each a node index or a tuple of nodes (centroid).

    Every method is a pure function of `x` `(n_design,)`; pass the body itself as an argument of
    compiled functions (`eqx.filter_jit(lambda body, x: body.body_data(x))(body, x)`), so that its
    arrays are program inputs, not constants.
    """

    model: FEModel
    domain: DesignDomain
    material: SIMP
    reduction: ModalReduction
    markers: tuple = eqx.field(static=True)

    def __check_init__(self):
        if self.model.mesh != self.domain.mesh:
            raise ValueError("The FE model and the design domain must be built on the same mesh.")
        self.reduction.layout(self.model.mesh)  # raises on interface or reference nodes not in the mesh
        marker_node_sets(self.model.mesh, self.markers)

    @property
    def mesh(self) -> QuadMesh:
        return self.model.mesh

    @property
    def n_design(self) -> int:
        return self.domain.n_design

    @property
    def n_modes(self) -> int:
        """Number of retained eigenmodes (the basis adds the interfaces' static modes)."""
        return self.reduction.n_modes

    @property
    def fixed_dofs(self) -> tuple[int, ...]:
        """The degrees of freedom the reference conditions hold (sorted)."""
        return self.reduction.reference.fixed_dofs(self.model.mesh)

    def initial_design(self, value: float = 0.5):
        """A uniform design `x_e = value`, `(n_design,)`."""
        if not self.material.x_min <= float(value) <= 1.0:
            raise ValueError(f"Design value {value} lies outside [x_min, 1] = [{self.material.x_min}, 1].")
        return self.domain.initial_design(value)

    def check(self, x):
        """Validate a design: shape at trace time; NaN and the bounds `[x_min, 1]` at run time."""
        return self.domain.check(x, self.material.x_min)

    def element_densities(self, x):
        """All element densities `(n_elements,)` for design `x` (validated): `x` on the design
        elements, 1 on passive solid, `x_min` on passive void."""
        return self.domain.element_densities(self.check(x), self.material.x_min)

    def element_values(self, x):
        """`(E_e, rho_e)`, `(n_elements,)` each, for design `x` (validated)."""
        xe = self.element_densities(x)
        return self.material.youngs(xe), self.material.densities(xe)

    def matrices(self, x) -> tuple[ElementOperator, ElementOperator]:
        """Matrix-free `(K(x), M(x))` (`.todense()` on small meshes)."""
        youngs, densities = self.element_values(x)
        return self.model.stiffness(youngs), self.model.mass(densities)

    def modes(self, x) -> ModalBasis:
        youngs, densities = self.element_values(x)
        return self.reduction(self.model, youngs, densities)

    def frequencies(self, x):
        """Eigenfrequencies of the retained eigenmodes in Hz, `(n_modes,)`."""
        return self.modes(x).frequencies

    def body_data(self, x) -> BodyData:
        """Standard input data of the body for design `x`."""
        return self.body_data_and_geometric_stiffness(x, stiffening=False)[0]

    def geometric_stiffness(self, x):
        """`K_geo(x)` `(n_q, n_q)`: the modal geometric stiffness per unit `omega^2` of a rotation about
        the frame origin (see `ffr_jax._design.geometric_stiffness`), supports = reference conditions."""
        return self.body_data_and_geometric_stiffness(x, stiffening=True)[1]

    def body_data_and_geometric_stiffness(self, x, stiffening: bool = True):
        """`(body data, K_geo or None)` from one modal reduction (`stiffening` static)."""
        youngs, densities = self.element_values(x)
        basis = self.reduction(self.model, youngs, densities)
        k, m = self.model.stiffness(youngs), self.model.mass(densities)
        data = body_data(self.model, k, m, basis.modes, self.markers)
        if not stiffening:
            return data, None
        return data, centrifugal_geometric_stiffness(self.model, youngs, densities, basis.modes, self.fixed_dofs)

    def uniform_body_data(self, value: float = 0.5) -> BodyData:
        """Body data of the uniform design `x_e = value`, compiled once per body structure (templates
        of scenes are built from it)."""
        data = clean_errors(_compiled_body_data)(self, self.initial_design(value))
        _check_body_data(data)  # computed under jit, where BodyData's own value checks cannot run
        return data


@eqx.filter_jit
def _compiled_body_data(body: DesignedBody, x) -> BodyData:
    return body.body_data(x)
