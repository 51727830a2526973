"""ffr_jax: flexible multibody dynamics (floating frame of reference) with exact design gradients."""

import importlib as _importlib
import warnings as _warnings

import jax as _jax

# float64 throughout: the one place the package sets it.
_jax.config.update("jax_enable_x64", True)

from . import cases as cases
from ._errors import DesignError as DesignError, FFRJaxError as FFRJaxError, SimulationError as SimulationError, clean_errors as clean_errors
from ._api import objective as objective, simulate as simulate, value_and_grad as value_and_grad, value_and_grad_scene as value_and_grad_scene
from ._dynamics._case import Case as Case
from ._design import (
    AbstractDesignMap as AbstractDesignMap,
    AbstractElement as AbstractElement, AbstractModalSolver as AbstractModalSolver,
    AbstractReference as AbstractReference, AutoModes as AutoModes, Clamped as Clamped, DenseModes as DenseModes,
    DensityFilter as DensityFilter, DesignDomain as DesignDomain, DesignedBody as DesignedBody, DesignMap as DesignMap, FEModel as FEModel, FixedDofs as FixedDofs, HingedHinged as HingedHinged,
    Interface as Interface, LanczosModes as LanczosModes, ModalBasis as ModalBasis,
    ModalReduction as ModalReduction, Q4 as Q4, QM6 as QM6, QuadMesh as QuadMesh,
    SIMP as SIMP, StackedDesigns as StackedDesigns, StackedFilter as StackedFilter, from_meshio as from_meshio, link_with_holes as link_with_holes,
    plate_with_hole as plate_with_hole, read_mesh as read_mesh,
    structured_grid as structured_grid, write_mesh as write_mesh,
)
from ._design import (H8 as H8, H11 as H11, Tet10 as Tet10, SolidMesh as SolidMesh, SolidFEModel as SolidFEModel, box_grid as box_grid,
                      hex_to_tet10 as hex_to_tet10, read_solid_mesh as read_solid_mesh, free_modes_dense as free_modes_dense,
                      free_modes_sparse as free_modes_sparse)
from ._design.solid_groups import (PhysicalGroups as PhysicalGroups, read_solid_groups as read_solid_groups,
                                   solid_groups_from_meshio as solid_groups_from_meshio)
from ._design.solid_domain import SolidDesignDomain as SolidDesignDomain
from ._design.planar_groups import (PlanarGroups as PlanarGroups, planar_groups_from_meshio as planar_groups_from_meshio,
                                    read_planar_groups as read_planar_groups)
from ._design.link_profile import Hole as Hole, QuadMeshing as QuadMeshing, Slot as Slot, link_profile as link_profile
from ._design.solid_designed_body import SolidDesignedBody as SolidDesignedBody, solid_designed_body as solid_designed_body
from ._design.solid_design_map import SolidDesignMap as SolidDesignMap
from ._api import check_gradient as check_gradient
from ._app._gradient_plot import plot_field as plot_field, plot_gradient as plot_gradient
from ._app._animation import animate as animate
from ._app._outline import density_outline as density_outline, write_dxf as write_dxf, write_svg as write_svg
from ._app._vtu import write_vtu as write_vtu
from ._app._vtu_series import write_vtu_series as write_vtu_series
from ._app._solid_render import plot_solid_design as plot_solid_design
from ._objective._base import AbstractIntegrand as AbstractIntegrand
from ._objective._base import Scaled as Scaled, Sum as Sum
from ._objective._compliance import Compliance as Compliance
from ._objective._time_window import TimeWindow as TimeWindow
from ._objective._function import FunctionIntegrand as FunctionIntegrand
from ._objective._kinetic_energy import KineticEnergy as KineticEnergy
from ._objective._joint_load import JointLoad as JointLoad
from ._objective._stress_measure import StressMeasure as StressMeasure
from ._objective._aggregated_stress import aggregated_stress as aggregated_stress
from ._objective._objective import Objective as Objective
from ._objective._tracking import AbstractPath as AbstractPath, FixedPoint as FixedPoint, FunctionPath as FunctionPath, LinearPath as LinearPath, MarkerTracking as MarkerTracking
from ._outputs._accelerations import redundant_accelerations as redundant_accelerations
from ._outputs._along_motion import accelerations as accelerations, joint_forces as joint_forces
from ._outputs._joint_forces import JointForce as JointForce, joint_forces_at as joint_forces_at, joint_names as joint_names
from ._outputs._multipliers import constraint_multipliers as constraint_multipliers
from ._outputs._stresses import modal_stresses as modal_stresses, stress_modes as stress_modes, stresses as stresses, von_mises as von_mises
from ._outputs._relaxed_stresses import relaxed_stress_modes as relaxed_stress_modes
from ._outputs._peak_stress import peak_von_mises as peak_von_mises
from ._app._stress_plot import plot_peak_stress as plot_peak_stress
from ._dynamics._problem import Problem as Problem
from ._scene._angle_driver import AngleDriver as AngleDriver
from ._scene._applied_force import AppliedForce as AppliedForce
from ._scene._base import AbstractConstraint as AbstractConstraint, AbstractForce as AbstractForce
from ._scene._body import Body as Body
from ._scene._body_data import BodyData as BodyData, rigid_body_data as rigid_body_data
from ._scene._damping import ModalDamping as ModalDamping, RayleighDamping as RayleighDamping
from ._scene._ground_revolute import GroundRevolute as GroundRevolute
from ._scene._gravity import Gravity as Gravity
from ._scene._laws import AbstractLaw as AbstractLaw, ConstantLaw as ConstantLaw, ConstantSpeedLaw as ConstantSpeedLaw, HarmonicLaw as HarmonicLaw, RampLaw as RampLaw
from ._scene._point_on_line import PointOnLine as PointOnLine
from ._scene._prescribed_point import CrankPin as CrankPin
from ._scene._revolute import Revolute as Revolute
from ._scene._scene import Scene as Scene
from ._scene._spring_damper import SpringDamper as SpringDamper
from ._scene._stiffening import GeometricStiffening as GeometricStiffening
from ._scene._spin_up_law import SpinUpLaw as SpinUpLaw
from ._spatial._stiffening import SpatialGeometricStiffening as SpatialGeometricStiffening
from ._design.solid_geometric_stiffness import solid_centrifugal_geometric_stiffness as solid_centrifugal_geometric_stiffness
from ._spatial._angle_driver import EulerNormalisation as EulerNormalisation, SpatialAngleDriver as SpatialAngleDriver
from ._spatial._body_data import SpatialBodyData as SpatialBodyData, spatial_rigid_body_data as spatial_rigid_body_data
from ._spatial._euler_parameters import euler_parameter_rates as euler_parameter_rates, euler_parameters as euler_parameters
from ._spatial._flexible_body_data import SpatialFlexibleBodyData as SpatialFlexibleBodyData, spatial_flexible_body_data as spatial_flexible_body_data
from ._spatial._lift import lifted_body_data as lifted_body_data
from ._spatial._solid_body_data import solid_body_data as solid_body_data
from ._spatial._body_data_file import BodyDataFileError as BodyDataFileError, read_body_data as read_body_data, write_body_data as write_body_data
from ._spatial._body_from_matrices import body_data_from_matrices as body_data_from_matrices
from ._spatial._point_on_line import SpatialPointOnLine as SpatialPointOnLine
from ._spatial._point_on_plane import SpatialPointOnPlane as SpatialPointOnPlane
from ._spatial._revolute import SpatialRevolute as SpatialRevolute
from ._spatial._spherical import SphericalJoint as SphericalJoint
from ._spatial._universal import SpatialUniversal as SpatialUniversal
from ._spatial._cylindrical import SpatialCylindrical as SpatialCylindrical
from ._spatial._prismatic import SpatialPrismatic as SpatialPrismatic
from ._spatial._rigid_attachment import SpatialRigidAttachment as SpatialRigidAttachment
from ._spatial._translation_driver import SpatialTranslationDriver as SpatialTranslationDriver
from ._spatial._spring_damper import SpatialSpringDamper as SpatialSpringDamper
from ._spatial._applied_force import SpatialAppliedForce as SpatialAppliedForce
from ._sensitivity._adjoint import Adjoint as Adjoint
from ._sensitivity._autodiff import Autodiff as Autodiff
from ._sensitivity._backsolve import Backsolve as Backsolve
from ._sensitivity._base import AbstractSensitivity as AbstractSensitivity
from ._sensitivity._direct import Direct as Direct
from ._sensitivity._discrete_adjoint import DiscreteAdjoint as DiscreteAdjoint
from ._sensitivity._finite_differences import FiniteDifferences as FiniteDifferences
from ._sensitivity._route import Route as Route, choose_route as choose_route
from ._dynamics._sharding import sharded_map as sharded_map
from ._solver import Rodas4 as Rodas4, Rodas5P as Rodas5P
from ._dynamics._simulate import Trajectory as Trajectory
from ._app._checkpoint import CheckpointError as CheckpointError, load_checkpoint as load_checkpoint
from ._optimize._conditions import OperatingConditions as OperatingConditions
from ._optimize._constraint import AbstractDesignConstraint as AbstractDesignConstraint
from ._app._driver import ConstraintViolationWarning as ConstraintViolationWarning, OptimizeResult as OptimizeResult, optimize as optimize
from ._app._step_error import StepBackOffWarning as StepBackOffWarning
from ._optimize._frequency import FrequencyConstraint as FrequencyConstraint
from ._optimize._function_constraint import FunctionConstraint as FunctionConstraint
from ._optimize._grey import grey_share as grey_share
from ._app._history import History as History
from ._optimize._mass import MassConstraint as MassConstraint
from ._optimize._mma import MMA as MMA
from ._optimize._oc import optimality_criteria as optimality_criteria
from ._optimize._optimizer import AbstractOptimizer as AbstractOptimizer, ProjectedOptax as ProjectedOptax
from ._optimize._objective import filtered_objective as filtered_objective, make_objective as make_objective, physical_densities as physical_densities
from ._optimize._pytree import OnBody as OnBody
from ._optimize._projection import HeavisideProjection as HeavisideProjection, beta_continuation as beta_continuation
from ._app._plot_optimize import plot_constraints as plot_constraints, plot_design as plot_design, plot_designs as plot_designs, plot_history as plot_history
from ._optimize._step import StepInfo as StepInfo, make_step as make_step
from ._optimize._stress_constraint import stress_constraint as stress_constraint
from ._optimize._volume import VolumeConstraint as VolumeConstraint


# Public names of earlier releases, kept for one release with a DeprecationWarning (CHANGELOG.md):
# old name -> (module, attribute, what to use instead).
_DEPRECATED = {
    "DESIGN": ("._design.domain", "DESIGN", "the DesignDomain's own API (an internal code)"),
    "SOLID": ("._design.domain", "SOLID", "the DesignDomain's own API (an internal code)"),
    "VOID": ("._design.domain", "VOID", "the DesignDomain's own API (an internal code)"),
    "StructuredGrid": ("._design.mesh", "StructuredGrid", "ffr_jax.structured_grid(...) (its return value)"),
    "LinkMesh": ("._design.geometry", "LinkMesh", "ffr_jax.link_with_holes(...) (its return value)"),
    "PlateWithHole": ("._design.geometry", "PlateWithHole", "ffr_jax.plate_with_hole(...) (its return value)"),
    "Animation": ("._app._animation", "Animation", "ffr_jax.animate(...) (its return value)"),
    "GradientCheck": ("._sensitivity._check", "GradientCheck", "ffr_jax.check_gradient(...) (its return value)"),
    "simulate_case": ("._api", "simulate_case", "ffr_jax.simulate(case, x)"),
    "MinimalModel": ("._dynamics._model", "MinimalModel", "ffr_jax.Problem (its .model)"),
    "Partition": ("._dynamics._model", "Partition", "ffr_jax.Problem (its .partition)"),
    "choose_partition": ("._dynamics._model", "choose_partition", "ffr_jax.Problem (it chooses the partition)"),
    "consistent_minimal_state": ("._dynamics._simulate", "consistent_minimal_state", "ffr_jax.simulate (it assembles the initial state)"),
    "retained_eigenpairs": ("._design.modal.dense", "retained_eigenpairs", "a modal solver (ffr_jax.DenseModes, LanczosModes, AutoModes)"),
    "quad_cell_data": ("._design.mesh", "quad_cell_data", "ffr_jax.from_meshio / read_mesh"),
    "rod_domain": ("._design.geometry", "rod_domain", "ffr_jax.cases.slider_crank (the reference rod) or ffr_jax.DesignDomain"),
    "rod_joint_nodes": ("._design.geometry", "rod_joint_nodes", "ffr_jax.Interface"),
    "ElementOperator": ("._design.assembly", "ElementOperator", "ffr_jax.FEModel"),
    "row_signs": ("._app._gradient_plot", "row_signs", "ffr_jax.plot_gradient"),
    "body_motion": ("._app._animation", "body_motion", "ffr_jax.animate or ffr_jax.write_vtu_series"),
    "MMAState": ("._optimize._mma", "MMAState", "ffr_jax.MMA (its state is internal)"),
    "Checkpoint": ("._app._checkpoint", "Checkpoint", "ffr_jax.load_checkpoint"),
    "save_checkpoint": ("._app._checkpoint", "save_checkpoint", "ffr_jax.optimize(..., directory=...) (it writes the checkpoints)"),
    "restore_opt_state": ("._app._checkpoint", "restore_opt_state", "ffr_jax.optimize(..., resume=True)"),
    "FlexibleRodCase": ("._dynamics._case", "FlexibleRodCase", "ffr_jax.Case"),
}


def __getattr__(name: str):
    if name in _DEPRECATED:
        module, attribute, instead = _DEPRECATED[name]
        _warnings.warn(f"ffr_jax.{name} is deprecated and will be removed in the next release; use {instead}.",
                       DeprecationWarning, stacklevel=2)
        return getattr(_importlib.import_module(module, __name__), attribute)
    raise AttributeError(f"module 'ffr_jax' has no attribute {name!r}")


# The public names: everything above except the modules that import hooks may add (e.g. jaxtyping's).
__all__ = sorted(name for name, value in globals().items()
                 if not name.startswith("_") and (name == "cases" or not isinstance(value, type(_warnings))))
