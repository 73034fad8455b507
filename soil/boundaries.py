"""Boundary shapes and the rigid boundary bodies that carry them.

Shapes are given in the BODY frame; the engine maps them to the world frame with the body pose
(position X, rotation matrix R): p_world = X + R p_body.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Plane",
    "Box",
    "Cylinder",
    "SphereBoundary",
    "BoundaryBody",
    "rotation_increment",
    "ELEM_PLANE",
    "ELEM_CYLINDER",
    "ELEM_SPHERE",
]

ELEM_PLANE = 0
ELEM_CYLINDER = 1
ELEM_SPHERE = 2


def _vec3(cls, name, v):
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{cls}.{name}={v!r}: must be a finite 3-vector [m]")
    return a


@dataclass(frozen=True)
class Plane:
    """Infinite plane; particles live on the +normal side.

    Parameters
    ----------
    point : (3,) [m]
    normal : (3,) [-] (normalised on construction)

    Notes
    -----
    Contact stiffness uses the sphere's own radius on the wall side (Yade ``utils.wall``).
    """

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 0.0, 1.0)

    def __post_init__(self):
        p = _vec3("Plane", "point", self.point)
        n = _vec3("Plane", "normal", self.normal)
        ln = float(np.linalg.norm(n))
        if ln <= 0.0:
            raise ValueError(f"Plane.normal={self.normal!r}: must be non-zero")
        object.__setattr__(self, "point", tuple(p))
        object.__setattr__(self, "normal", tuple(n / ln))

    def elements(self):
        return [(ELEM_PLANE, self.point, self.normal, 0.0, 0.0, 0.0)]


@dataclass(frozen=True)
class Box:
    """Inside of an axis-aligned (body frame) box: 5 planes with ``open_top`` else 6.

    Parameters
    ----------
    lo, hi : (3,) [m], hi > lo componentwise
    open_top : bool
        Omit the +z lid.
    """

    lo: tuple
    hi: tuple
    open_top: bool = True

    def __post_init__(self):
        lo = _vec3("Box", "lo", self.lo)
        hi = _vec3("Box", "hi", self.hi)
        if np.any(hi <= lo):
            raise ValueError(f"Box.hi={tuple(hi)!r}: must be > lo={tuple(lo)!r} componentwise [m]")
        object.__setattr__(self, "lo", tuple(lo))
        object.__setattr__(self, "hi", tuple(hi))

    def elements(self):
        out = []
        for k in range(3):
            e = [0.0, 0.0, 0.0]
            e[k] = 1.0
            out.append((ELEM_PLANE, tuple(self.lo), tuple(e), 0.0, 0.0, 0.0))
            if not (k == 2 and self.open_top):
                e2 = [0.0, 0.0, 0.0]
                e2[k] = -1.0
                out.append((ELEM_PLANE, tuple(self.hi), tuple(e2), 0.0, 0.0, 0.0))
        return out


@dataclass(frozen=True)
class Cylinder:
    """Inside of a vertical (body z) cylinder: the test tank wall (no floor, add a Plane).

    Parameters
    ----------
    center : (2,) [m]
        Axis position (x, y) in the body frame.
    radius : float [m], > 0
    z_min, z_max : float [m], z_max > z_min
        Axial extent of the wall (particle centres outside it do not touch the wall).
    """

    center: tuple = (0.0, 0.0)
    radius: float = 1.0
    z_min: float = 0.0
    z_max: float = 1.0

    def __post_init__(self):
        c = np.asarray(self.center, np.float64)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"Cylinder.center={self.center!r}: must be a finite (x, y) [m]")
        if not (math.isfinite(self.radius) and self.radius > 0.0):
            raise ValueError(f"Cylinder.radius={self.radius!r}: must be > 0 [m]")
        if not (math.isfinite(self.z_min) and math.isfinite(self.z_max)
                and self.z_max > self.z_min):
            raise ValueError(f"Cylinder.z_max={self.z_max!r}: must be > z_min={self.z_min!r} [m]")
        object.__setattr__(self, "center", tuple(c))

    def elements(self):
        p = (self.center[0], self.center[1], 0.0)
        return [(ELEM_CYLINDER, p, (0.0, 0.0, 1.0), float(self.radius), float(self.z_min),
                 float(self.z_max))]


@dataclass(frozen=True)
class SphereBoundary:
    """Outside of a rigid sphere centred on the body origin (the drop mass).

    Parameters
    ----------
    radius : float [m], > 0

    Notes
    -----
    Stiffness uses this radius exactly as for a sphere particle (Yade sphere-sphere).
    """

    radius: float

    def __post_init__(self):
        if not (math.isfinite(self.radius) and self.radius > 0.0):
            raise ValueError(f"SphereBoundary.radius={self.radius!r}: must be > 0 [m]")

    def elements(self):
        return [(ELEM_SPHERE, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), float(self.radius), 0.0, 0.0)]


def _skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def rotation_increment(w, dt: float) -> np.ndarray:
    """expm(skew(w) dt) by Rodrigues' formula.

    Notes
    -----
    Rodrigues' rotation formula: exp(K) = I + sin(a)/a K + (1 - cos a)/a^2 K^2, a = |w| dt.
    """
    w = np.asarray(w, np.float64)
    a = float(np.linalg.norm(w)) * dt
    if a == 0.0:
        return np.eye(3)
    k = _skew(w * dt)
    return np.eye(3) + (math.sin(a) / a) * k + ((1.0 - math.cos(a)) / (a * a)) * (k @ k)


_MOTIONS = ("fixed", "prescribed", "coupled")


@dataclass(eq=False)
class BoundaryBody:
    """A rigid boundary carrying one or more shapes.

    Parameters
    ----------
    shapes : list
        Plane, Box, Cylinder, SphereBoundary or soil.TriangleMesh objects (body frame).
    material : int
        Material index into ``Simulation(materials=...)``.
    motion : {"fixed", "prescribed", "coupled"}
    position : (3,) [m]; rotation : (3, 3) [-]; velocity : (3,) [m/s];
    angular_velocity : (3,) [rad/s] (world frame)
    reference_point : (3,) [m] or None
        Torque reference as an offset in the BODY frame from the body origin (it moves with the
        body); None = the body origin (the CG for coupled bodies).
    prescribed : callable or None
        ``t -> (position, rotation, velocity, angular_velocity)`` for motion="prescribed".

    Attributes
    ----------
    force, torque : ndarray (3,)
        Wrench exerted BY the particles ON the body at the last force evaluation [N], [N m]
        (torque about the reference point).
    impulse, angular_impulse : ndarray (3,)
        Sum over DEM steps of force*dt [N s] and torque*dt [N m s] since the last reset, each
        step using the wrench that drove that step's particle update (exact momentum exchange).
    work : float
        Work done by the body on the particles since the start [J].

    Notes
    -----
    Between calls the engine advances a prescribed/coupled body at constant velocity:
    x += v dt, R = expm(skew(w) dt) R (ARCHITECTURE section 1).
    """

    shapes: list = field(default_factory=list)
    material: int = 0
    motion: str = "fixed"
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    reference_point: np.ndarray | None = None
    prescribed: object = None

    def __post_init__(self):
        if self.motion not in _MOTIONS:
            raise ValueError(f"BoundaryBody.motion={self.motion!r}: must be one of {_MOTIONS}")
        if self.motion == "prescribed" and not callable(self.prescribed):
            raise ValueError(
                f"BoundaryBody.prescribed={self.prescribed!r}: must be callable t -> (position, "
                "rotation, velocity, angular_velocity) when motion='prescribed'"
            )
        if not isinstance(self.material, (int, np.integer)) or self.material < 0:
            raise ValueError(f"BoundaryBody.material={self.material!r}: must be an int >= 0")
        self.shapes = list(self.shapes)
        self.position = _vec3("BoundaryBody", "position", self.position).copy()
        self.velocity = _vec3("BoundaryBody", "velocity", self.velocity).copy()
        self.angular_velocity = _vec3(
            "BoundaryBody", "angular_velocity", self.angular_velocity
        ).copy()
        r = np.asarray(self.rotation, np.float64)
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9):
            raise ValueError(f"BoundaryBody.rotation={self.rotation!r}: must be a 3x3 rotation")
        self.rotation = r.copy()
        if self.reference_point is not None:
            self.reference_point = _vec3("BoundaryBody", "reference_point", self.reference_point)
        self.force = np.zeros(3)
        self.torque = np.zeros(3)
        self.impulse = np.zeros(3)
        self.angular_impulse = np.zeros(3)
        self.work = 0.0
        if self.motion == "prescribed":
            self._apply_prescribed(0.0)

    # -- kinematics ---------------------------------------------------------------------------
    def set_kinematics(self, position, rotation, velocity, angular_velocity) -> None:
        """Set the pose and velocities (motion="coupled"; world frame, SI)."""
        self.position[:] = _vec3("BoundaryBody", "position", position)
        self.rotation[:] = np.asarray(rotation, np.float64)
        self.velocity[:] = _vec3("BoundaryBody", "velocity", velocity)
        self.angular_velocity[:] = _vec3("BoundaryBody", "angular_velocity", angular_velocity)

    def _apply_prescribed(self, t: float) -> None:
        pos, rot, vel, omg = self.prescribed(t)
        self.set_kinematics(pos, rot, vel, omg)

    def advance(self, dt: float, t_new: float) -> None:
        """Advance the pose over one DEM step (constant velocity, or the prescribed motion)."""
        if self.motion == "fixed":
            return
        if self.motion == "prescribed":
            self._apply_prescribed(t_new)
            return
        from soil._kernels_loop import advance_rotation  # noqa: PLC0415  (numba kernels)

        self.position += self.velocity * dt
        advance_rotation(self.rotation, self.angular_velocity, dt)

    def reference_world(self) -> np.ndarray:
        """Torque reference point in the world frame [m]."""
        if self.reference_point is None:
            return self.position.copy()
        return self.position + self.rotation @ self.reference_point

    def reset_impulse(self) -> None:
        """Zero the impulse and angular impulse accumulators."""
        self.impulse[:] = 0.0
        self.angular_impulse[:] = 0.0

    # -- state ---------------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "position": self.position.copy(),
            "rotation": self.rotation.copy(),
            "velocity": self.velocity.copy(),
            "angular_velocity": self.angular_velocity.copy(),
            "force": self.force.copy(),
            "torque": self.torque.copy(),
            "impulse": self.impulse.copy(),
            "angular_impulse": self.angular_impulse.copy(),
            "work": self.work,
        }

    def load_state_dict(self, d: dict) -> None:
        for k in ("position", "rotation", "velocity", "angular_velocity", "force", "torque",
                  "impulse", "angular_impulse"):
            getattr(self, k)[...] = d[k]
        self.work = float(d["work"])
