"""Numba discrete-element soil: spheres, contact laws, rigid boundaries, energy ledger.

Public API (ARCHITECTURE section 1): Simulation, Particles, Material, Cohesion, Rolling,
BoundaryBody, Plane, Box, Cylinder, SphereBoundary, TriangleMesh.
"""

from soil.boundaries import BoundaryBody, Box, Cylinder, Plane, SphereBoundary
from soil.params import Cohesion, Material, Rolling
from soil.particles import Particles
from soil.simulation import Simulation

try:  # written by another engineer; optional until it lands
    from soil.mesh import TriangleMesh
except ImportError:  # pragma: no cover
    TriangleMesh = None

__all__ = [
    "Simulation",
    "Particles",
    "Material",
    "Cohesion",
    "Rolling",
    "BoundaryBody",
    "Plane",
    "Box",
    "Cylinder",
    "SphereBoundary",
    "TriangleMesh",
]
