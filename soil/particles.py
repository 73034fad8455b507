"""Polydisperse spheres stored as struct-of-arrays."""

from __future__ import annotations

import numpy as np

from .portable import sphere_volume

__all__ = ["Particles"]


class Particles:
    """Struct-of-arrays sphere set.

    Parameters
    ----------
    x : array_like, shape (N, 3)
        Centre positions [m].
    radius : array_like, shape (N,)
        Radii [m], > 0.
    material : array_like of int, shape (N,)
        Material index into ``Simulation(materials=...)``.
    rotation_blocked : bool or array_like of bool, shape (N,)
        True blocks the rotations of a particle (the thesis blocks all soil rotations).
    v, w : array_like, shape (N, 3), optional
        Initial velocity [m/s] and angular velocity [rad/s]; zero when omitted.

    Notes
    -----
    Mass m = 4/3 pi r^3 rho and inertia I = 2/5 m r^2 (solid sphere) are filled in by
    :class:`soil.Simulation` from the material densities. Arrays are float64 / int32 / bool and
    C-contiguous; ``f`` and ``t`` hold the force [N] and torque [N m] of the last evaluation.
    """

    def __init__(self, x, radius, material=None, rotation_blocked=True, v=None, w=None):
        x = np.ascontiguousarray(x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"Particles.x shape={x.shape}: must be (N, 3) [m]")
        n = x.shape[0]
        radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, np.float64), (n,)))
        if not np.all(np.isfinite(x)):
            raise ValueError("Particles.x: must be finite [m]")
        if n and not (np.all(np.isfinite(radius)) and radius.min() > 0.0):
            raise ValueError(f"Particles.radius min={radius.min()!r}: must be finite and > 0 [m]")
        if material is None:
            material = np.zeros(n, np.int32)
        material = np.ascontiguousarray(
            np.broadcast_to(np.asarray(material), (n,))).astype(np.int32)
        if n and material.min() < 0:
            raise ValueError(f"Particles.material min={material.min()}: must be >= 0")
        blocked = np.ascontiguousarray(
            np.broadcast_to(np.asarray(rotation_blocked, dtype=bool), (n,))
        ).copy()
        self.x = x.copy()
        self.radius = radius.copy()
        self.material = material.copy()
        self.rotation_blocked = blocked
        self.v = self._vec(v, n, "v")
        self.w = self._vec(w, n, "w")
        self.w[blocked] = 0.0
        self.f = np.zeros((n, 3))
        self.t = np.zeros((n, 3))
        self.mass = np.zeros(n)
        self.inv_mass = np.zeros(n)
        self.inertia = np.zeros(n)
        self.inv_inertia = np.zeros(n)

    @staticmethod
    def _vec(a, n, name):
        if a is None:
            return np.zeros((n, 3))
        a = np.array(np.broadcast_to(np.asarray(a, np.float64), (n, 3)), dtype=np.float64)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"Particles.{name}: must be finite")
        return a

    @property
    def n(self) -> int:
        """Number of particles."""
        return self.x.shape[0]

    def __len__(self) -> int:
        return self.n

    def set_masses(self, densities: np.ndarray) -> None:
        """Fill mass, inertia and their inverses from per-material densities [kg/m^3].

        Notes
        -----
        Solid sphere: m = 4/3 pi r^3 rho, I = 2/5 m r^2; blocked particles get 1/I = 0.
        """
        if self.n and self.material.max() >= len(densities):
            raise ValueError(
                f"Particles.material max={self.material.max()}: must be < number of materials "
                f"({len(densities)})"
            )
        rho = np.asarray(densities, np.float64)[self.material]
        self.mass[:] = sphere_volume(self.radius) * rho
        self.inv_mass[:] = 1.0 / self.mass
        self.inertia[:] = 0.4 * self.mass * self.radius**2
        self.inv_inertia[:] = np.where(self.rotation_blocked, 0.0, 1.0 / self.inertia)

    def nbytes(self) -> int:
        """Memory held by the per-particle arrays [bytes]."""
        return sum(
            a.nbytes
            for a in (
                self.x, self.v, self.w, self.f, self.t, self.radius, self.material,
                self.rotation_blocked, self.mass, self.inv_mass, self.inertia, self.inv_inertia,
            )
        )

    _ARRAYS = ("x", "v", "w", "f", "t", "radius", "material", "rotation_blocked", "mass",
               "inv_mass", "inertia", "inv_inertia")

    def state_dict(self) -> dict:
        return {k: getattr(self, k).copy() for k in self._ARRAYS}

    @classmethod
    def from_state_dict(cls, d: dict) -> "Particles":
        p = cls(d["x"], d["radius"], d["material"], d["rotation_blocked"], d["v"], d["w"])
        for k in cls._ARRAYS:
            getattr(p, k)[...] = d[k]
        return p
