"""Build the DEM boundary body of a rigid-body specification (soil public API only)."""

from __future__ import annotations

import numpy as np


def boundary_for(spec, material: int, position=(0.0, 0.0, 0.0), rotation=None,
                 velocity=(0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 0.0)):
    """A ``soil.BoundaryBody(motion="coupled")`` carrying the contact shape of ``spec``.

    Parameters
    ----------
    spec : bodies.RigidBodySpec
        ``contact_radius`` set: exact ``soil.SphereBoundary``; otherwise the surface mesh as a
        ``soil.TriangleMesh`` in the body frame (origin at the CG).
    material : int
        Material index in the DEM.
    position, rotation, velocity, angular_velocity
        Initial pose and velocities (world frame, SI); the torque reference is the body
        origin, i.e. the CG.

    Returns
    -------
    soil.BoundaryBody
    """
    import soil

    if spec.contact_radius is not None:
        shape = soil.SphereBoundary(float(spec.contact_radius))
    else:
        shape = soil.TriangleMesh(np.array(spec.vertices), np.array(spec.triangles))
    return soil.BoundaryBody(
        shapes=[shape], material=int(material), motion="coupled",
        position=np.asarray(position, dtype=np.float64),
        rotation=np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64),
        velocity=np.asarray(velocity, dtype=np.float64),
        angular_velocity=np.asarray(angular_velocity, dtype=np.float64),
        reference_point=None)
