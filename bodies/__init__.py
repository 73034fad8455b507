"""Rigid bodies of crashdem: specifications (mass, CG, inertia, mesh, sensors) and their
Exudyn model.

Public API
----------
RigidBodySpec, SensorMount, MassComponent : specification dataclasses
drop_sphere() : the 850 kg, 0.90 m reinforced-concrete drop mass
glider_fuselage(...), GliderBuildUp : the 343 kg V1/2 Rondine crash mock-up
ExudynRigidBody, BodyState : the Exudyn body stepped from a DEM loop
ExudynCrushableBody, split_nose : a body and its crushable nose (force-limited prismatic
    element in Exudyn)
mesh : icosphere, loft_fuselage, read_mesh, write_mesh, shell mass properties
"""

from . import mesh
from .crush import ExudynCrushableBody
from .exudyn_model import BodyState, ExudynRigidBody
from .library import (
    GliderBuildUp,
    drop_sphere,
    glider_fuselage,
    sphere_with_cavity_inertia,
    split_nose,
)
from .spec import MassComponent, RigidBodySpec, SensorMount, check_inertia, combine_components

__all__ = [
    "BodyState",
    "ExudynCrushableBody",
    "ExudynRigidBody",
    "GliderBuildUp",
    "MassComponent",
    "RigidBodySpec",
    "SensorMount",
    "check_inertia",
    "combine_components",
    "drop_sphere",
    "glider_fuselage",
    "mesh",
    "sphere_with_cavity_inertia",
    "split_nose",
]
