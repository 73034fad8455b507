"""Rigid-body specification: mass, centre of gravity, inertia, surface, sensor mounts.

The body frame has its origin at the centre of gravity (CG). Every vector and the inertia
tensor of a :class:`RigidBodySpec` are expressed in that frame, in SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping

import numpy as np

#: relative tolerance of the symmetry check of an inertia tensor [-]; a tensor assembled from
#: floats is symmetric to round-off (~1e-16); 1e-9 admits tensors typed in with ~9 digits.
INERTIA_SYMMETRY_RTOL = 1e-9
#: relative slack of the triangle inequality I_a + I_b >= I_c [-]: a thin plate or rod sits
#: exactly on the bound, which round-off may cross by a few ulp.
INERTIA_TRIANGLE_RTOL = 1e-9

SENSOR_KINDS = ("accelerometer", "gyro")


def _vec3(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}={value!r}: must be a finite 3-vector")
    return arr


def check_inertia(inertia, name: str = "RigidBodySpec.inertia") -> np.ndarray:
    """Validate a 3x3 inertia tensor about the CG and return it as a float64 array.

    Parameters
    ----------
    inertia : array_like, shape (3, 3)
        Inertia tensor [kg m^2].
    name : str
        Field name used in error messages.

    Returns
    -------
    numpy.ndarray
        The tensor, symmetrised to round-off.

    Raises
    ------
    ValueError
        If the tensor is not finite, not symmetric, not positive definite, or if its
        principal moments violate the triangle inequality ``I1 + I2 >= I3``.

    Notes
    -----
    Physical realisability of an inertia tensor (positive definiteness and the triangle
    inequality of the principal moments): Goldstein, *Classical Mechanics*, 3rd ed., §5.3.
    """
    j = np.asarray(inertia, dtype=np.float64)
    if j.shape != (3, 3) or not np.all(np.isfinite(j)):
        raise ValueError(f"{name}={inertia!r}: must be a finite 3x3 array [kg m^2]")
    scale = float(np.max(np.abs(j)))
    if scale <= 0.0:
        raise ValueError(f"{name}: is zero; must be positive definite [kg m^2]")
    asym = float(np.max(np.abs(j - j.T)))
    if asym > INERTIA_SYMMETRY_RTOL * scale:
        raise ValueError(f"{name}: asymmetric by {asym:.3g}; must be symmetric [kg m^2]")
    j = 0.5 * (j + j.T)
    principal = np.linalg.eigvalsh(j)
    if principal[0] <= 0.0:
        raise ValueError(
            f"{name}: principal moments {principal.tolist()} must all be > 0 [kg m^2]"
        )
    if principal[0] + principal[1] < principal[2] * (1.0 - INERTIA_TRIANGLE_RTOL):
        raise ValueError(
            f"{name}: principal moments {principal.tolist()} violate the triangle "
            "inequality I1 + I2 >= I3"
        )
    return j


@dataclass(frozen=True, eq=False)
class SensorMount:
    """A single-axis transducer fixed to the body.

    Parameters
    ----------
    name : str
        Channel name, e.g. ``"rear_accel_x"``.
    position : array_like, shape (3,)
        Mount point in the body frame (origin at the CG) [m].
    axis : array_like, shape (3,)
        Sensitive axis in the body frame (normalised on construction) [-].
    kind : str
        ``"accelerometer"`` (measures specific force along ``axis``, m/s^2) or ``"gyro"``
        (measures angular velocity about ``axis``, rad/s).
    full_scale : float
        Full-scale range: m/s^2 for accelerometers, rad/s for gyros; > 0.
    """

    name: str
    position: np.ndarray
    axis: np.ndarray
    kind: str = "accelerometer"
    full_scale: float = np.inf

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"SensorMount.name={self.name!r}: must be a non-empty string")
        object.__setattr__(self, "position",
                           _vec3(self.position, f"SensorMount({self.name}).position"))
        axis = _vec3(self.axis, f"SensorMount({self.name}).axis")
        norm = float(np.linalg.norm(axis))
        if norm == 0.0:
            raise ValueError(f"SensorMount({self.name}).axis={self.axis!r}: must be non-zero")
        object.__setattr__(self, "axis", axis / norm)
        if self.kind not in SENSOR_KINDS:
            raise ValueError(
                f"SensorMount({self.name}).kind={self.kind!r}: must be one of {SENSOR_KINDS}"
            )
        if not (self.full_scale > 0.0):
            raise ValueError(
                f"SensorMount({self.name}).full_scale={self.full_scale!r}: must be > 0 "
                "[m/s^2 or rad/s]"
            )


@dataclass(frozen=True, eq=False)
class MassComponent:
    """One item of a mass build-up, for documentation and checks.

    Parameters
    ----------
    name : str
        Component name.
    mass : float
        [kg], > 0.
    cg : array_like, shape (3,)
        Component CG in the construction frame of the build-up [m].
    inertia : array_like, shape (3, 3)
        Inertia of the component about its own CG [kg m^2] (zeros for a point mass).
    note : str
        The assumption behind the number.
    """

    name: str
    mass: float
    cg: np.ndarray
    inertia: np.ndarray
    note: str = ""

    def __post_init__(self):
        if not (self.mass > 0.0 and np.isfinite(self.mass)):
            raise ValueError(f"MassComponent({self.name}).mass={self.mass!r}: must be > 0 [kg]")
        object.__setattr__(self, "cg", _vec3(self.cg, f"MassComponent({self.name}).cg"))
        j = np.asarray(self.inertia, dtype=np.float64)
        if j.shape != (3, 3) or not np.all(np.isfinite(j)):
            raise ValueError(f"MassComponent({self.name}).inertia: must be a finite 3x3 array")
        object.__setattr__(self, "inertia", j)


def combine_components(components) -> tuple[float, np.ndarray, np.ndarray]:
    """Total mass, CG and inertia about the CG of a set of components.

    Parameters
    ----------
    components : iterable of MassComponent

    Returns
    -------
    mass : float
        [kg]
    cg : numpy.ndarray, shape (3,)
        [m], in the construction frame.
    inertia : numpy.ndarray, shape (3, 3)
        About the combined CG [kg m^2].

    Notes
    -----
    Parallel-axis (Huygens–Steiner) theorem in tensor form,
    ``J = J_c + m (|d|^2 I - d d^T)``: Goldstein, *Classical Mechanics*, 3rd ed., eq. 5.17.
    """
    comps = list(components)
    mass = sum(c.mass for c in comps)
    cg = sum(c.mass * c.cg for c in comps) / mass
    inertia = np.zeros((3, 3))
    for c in comps:
        d = c.cg - cg
        inertia += c.inertia + c.mass * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return float(mass), cg, inertia


@dataclass(frozen=True, eq=False)
class RigidBodySpec:
    """Everything the coupling needs to know about a rigid body.

    Parameters
    ----------
    name : str
        Body name.
    mass : float
        [kg], > 0.
    inertia : array_like, shape (3, 3)
        Full inertia tensor about the CG in body axes [kg m^2]; symmetric positive definite,
        principal moments obey the triangle inequality.
    vertices : array_like, shape (V, 3)
        Surface mesh vertices in the body frame (origin at the CG) [m].
    triangles : array_like, shape (T, 3) int
        Vertex indices of the triangles, counter-clockwise seen from outside.
    contact_radius : float or None
        If set, the contact shape is an exact sphere of this radius centred on the CG [m]
        (the mesh is then for visualisation and export only); if None the mesh is the
        contact surface.
    sensors : tuple of SensorMount
        Transducers fixed to the body.
    reference_dimensions : mapping str -> float
        Named reference lengths [m] (e.g. ``diameter``, ``length``).
    cg_in_construction_frame : array_like, shape (3,)
        Where the CG sits in the frame the body was designed in (e.g. from the nose) [m];
        informative only.
    components : tuple of MassComponent
        Mass build-up the defaults were derived from (may be empty).
    assumptions : tuple of str
        Human-readable list of the assumptions behind the numbers.

    Notes
    -----
    The body frame is the frame of the Exudyn node: origin at the CG, axes fixed to the body.
    """

    name: str
    mass: float
    inertia: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray
    contact_radius: float | None = None
    sensors: tuple = ()
    reference_dimensions: Mapping[str, float] = field(default_factory=dict)
    cg_in_construction_frame: np.ndarray = field(default_factory=lambda: np.zeros(3))
    components: tuple = ()
    assumptions: tuple = ()

    def __post_init__(self):
        if not (np.isfinite(self.mass) and self.mass > 0.0):
            raise ValueError(f"RigidBodySpec.mass={self.mass!r}: must be > 0 [kg]")
        object.__setattr__(self, "inertia", check_inertia(self.inertia))
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        t = np.ascontiguousarray(self.triangles, dtype=np.int32)
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3 or not np.all(np.isfinite(v)):
            raise ValueError(
                f"RigidBodySpec.vertices: shape {v.shape} must be (V>=3, 3), finite [m]"
            )
        if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] < 1:
            raise ValueError(f"RigidBodySpec.triangles: shape {t.shape} must be (T>=1, 3)")
        if t.min() < 0 or t.max() >= v.shape[0]:
            raise ValueError(
                f"RigidBodySpec.triangles: indices in [{t.min()}, {t.max()}] must be in "
                f"[0, {v.shape[0] - 1}]"
            )
        v.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "triangles", t)
        if self.contact_radius is not None and not (self.contact_radius > 0.0):
            raise ValueError(
                f"RigidBodySpec.contact_radius={self.contact_radius!r}: must be > 0 [m] or None"
            )
        sensors = tuple(self.sensors)
        names = [s.name for s in sensors]
        if len(set(names)) != len(names):
            raise ValueError(f"RigidBodySpec.sensors: duplicate names in {names}")
        for s in sensors:
            if not isinstance(s, SensorMount):
                raise ValueError(f"RigidBodySpec.sensors: {s!r} is not a SensorMount")
        object.__setattr__(self, "sensors", sensors)
        dims = {str(k): float(x) for k, x in dict(self.reference_dimensions).items()}
        for k, x in dims.items():
            if not (x > 0.0):
                raise ValueError(
                    f"RigidBodySpec.reference_dimensions[{k!r}]={x!r}: must be > 0 [m]")
        object.__setattr__(self, "reference_dimensions", MappingProxyType(dims))
        object.__setattr__(
            self,
            "cg_in_construction_frame",
            _vec3(self.cg_in_construction_frame, "RigidBodySpec.cg_in_construction_frame"),
        )
        object.__setattr__(self, "components", tuple(self.components))
        object.__setattr__(self, "assumptions", tuple(str(a) for a in self.assumptions))

    # ------------------------------------------------------------------ derived quantities
    @property
    def principal_moments(self) -> np.ndarray:
        """Principal moments of inertia about the CG, ascending [kg m^2]."""
        return np.linalg.eigvalsh(self.inertia)

    def sensor(self, name: str) -> SensorMount:
        """Return the sensor mount called ``name`` (KeyError listing the names otherwise)."""
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(f"no sensor {name!r}; available: {[s.name for s in self.sensors]}")

    def with_mass_properties(self, mass=None, cg_shift=None, inertia=None) -> "RigidBodySpec":
        """Copy with overridden mass properties.

        Parameters
        ----------
        mass : float, optional
            New mass [kg].
        cg_shift : array_like, shape (3,), optional
            Displacement of the CG in the current body frame [m]; the mesh and sensor
            positions are re-expressed about the new CG.
        inertia : array_like, shape (3, 3), optional
            New inertia about the (new) CG [kg m^2].

        Returns
        -------
        RigidBodySpec
        """
        shift = np.zeros(3) if cg_shift is None else _vec3(cg_shift, "cg_shift")
        if self.contact_radius is not None and np.any(shift != 0.0):
            raise ValueError(
                f"RigidBodySpec.with_mass_properties: cg_shift={shift.tolist()} must be zero for "
                "a body whose contact sphere is centred on the CG (contact_radius set)")
        sensors = tuple(
            SensorMount(s.name, s.position - shift, s.axis, s.kind, s.full_scale)
            for s in self.sensors
        )
        return RigidBodySpec(
            name=self.name,
            mass=self.mass if mass is None else mass,
            inertia=self.inertia if inertia is None else inertia,
            vertices=self.vertices - shift,
            triangles=self.triangles,
            contact_radius=self.contact_radius,
            sensors=sensors,
            reference_dimensions=dict(self.reference_dimensions),
            cg_in_construction_frame=self.cg_in_construction_frame + shift,
            components=self.components,
            assumptions=self.assumptions
            + (("mass properties overridden by the user",) if any(
                x is not None for x in (mass, cg_shift, inertia)) else ()),
        )
