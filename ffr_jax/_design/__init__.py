"""The design side of a flexible body, in the order the data flows.

`mesh -> domain (roles) -> element -> FE model (assembly) -> material (SIMP) -> modal reduction
-> body data`, composed by [`DesignedBody`][] (design -> body data of one body, with the
geometric stiffness of a spinning body beside it) and [`DesignMap`][] (designs of several bodies
-> scene); the density filter and the geometry generators sit beside it.
"""

from .mesh import QuadMesh as QuadMesh, StructuredGrid as StructuredGrid, from_meshio as from_meshio, quad_cell_data as quad_cell_data, read_mesh as read_mesh, structured_grid as structured_grid, write_mesh as write_mesh
from .domain import DESIGN as DESIGN, SOLID as SOLID, VOID as VOID, DesignDomain as DesignDomain
from .element import AbstractElement as AbstractElement, Q4 as Q4, QM6 as QM6
from .assembly import ElementOperator as ElementOperator, FEModel as FEModel, csc_matrices as csc_matrices, dense_matrix as dense_matrix
from .material import SIMP as SIMP
from .modal import AbstractModalSolver as AbstractModalSolver, AbstractReference as AbstractReference, AutoModes as AutoModes, Clamped as Clamped, DenseModes as DenseModes, FixedDofs as FixedDofs, HingedHinged as HingedHinged, Interface as Interface, LanczosModes as LanczosModes, ModalBasis as ModalBasis, ModalReduction as ModalReduction, retained_eigenpairs as retained_eigenpairs
from .body_data import body_data as body_data
from .designed_body import DesignedBody as DesignedBody
from .design_map import AbstractDesignMap as AbstractDesignMap, DesignMap as DesignMap
from .filter import DensityFilter as DensityFilter
from .stacked import StackedDesigns as StackedDesigns, StackedFilter as StackedFilter
from .geometry import LinkMesh as LinkMesh, PlateWithHole as PlateWithHole, link_with_holes as link_with_holes, plate_with_hole as plate_with_hole, rod_domain as rod_domain, rod_joint_nodes as rod_joint_nodes
from .element import AbstractSolidElement as AbstractSolidElement, H8 as H8, H11 as H11, Tet10 as Tet10
from .solid_mesh import SolidGrid as SolidGrid, SolidMesh as SolidMesh, box_grid as box_grid, hex_to_tet10 as hex_to_tet10, read_solid_mesh as read_solid_mesh, solid_cell_data as solid_cell_data, solid_from_meshio as solid_from_meshio
from .solid_assembly import SolidFEModel as SolidFEModel, SolidOperator as SolidOperator, solid_bcoo as solid_bcoo, solid_csc_matrices as solid_csc_matrices, solid_dense_matrix as solid_dense_matrix
from .solid_modes import free_modes_dense as free_modes_dense, free_modes_sparse as free_modes_sparse, rigid_motions as rigid_motions
