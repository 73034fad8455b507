"""Numba discrete-element soil: spheres, contact laws, rigid boundaries, energy ledger.

Public API (ARCHITECTURE section 1): Simulation, Particles, Material, Cohesion, Rolling,
BoundaryBody, Plane, Box, Cylinder, SphereBoundary, TriangleMesh.
"""

import os as _os

import numba as _numba

# Threading layer: OpenMP first, with passive waiting.  With Numba's TBB layer the resident
# memory of a process that steps the engine on 2+ threads grows by ~50 kB per step (a task
# arena per parallel call, numba/numba#10225 and #10556; measured here: +11 MB over 300 steps of
# a 1,728-grain scene, flat with "omp" and "workqueue").  GNU OpenMP's default active waiting
# spins on the cores it waits for: on a shared, oversubscribed machine that cut the 2-thread
# rate of the 40k bench from 8.0e5 to 3.0e5 particle-steps/s, hence OMP_WAIT_POLICY=PASSIVE.
# Only defaults change: NUMBA_THREADING_LAYER(_PRIORITY) and OMP_WAIT_POLICY set by the user
# win, and nothing changes once Numba's threads are running (docs/performance.md).
if ("NUMBA_THREADING_LAYER" not in _os.environ
        and "NUMBA_THREADING_LAYER_PRIORITY" not in _os.environ
        and _numba.config.THREADING_LAYER == "default"):
    _numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
    _os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from soil.boundaries import BoundaryBody, Box, Cylinder, Plane, SphereBoundary  # noqa: E402
from soil.params import Cohesion, Material, Rolling  # noqa: E402
from soil.particles import Particles  # noqa: E402
from soil.simulation import Simulation  # noqa: E402

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
