"""Packings: loose clouds, gravity deposition, porosity, layers, 45 degree slopes, HDF5 and a cache.

A packing is a set of sphere centres, radii and material ids in static equilibrium inside a
container, plus the parameters that produced it.  The pipeline is::

    cloud (lattice or RSA)  ->  deposit (Cundall damping until unbalanced < threshold)
        ->  carve (flat layer tops, inclined free surface)  ->  Packing (HDF5, hashed, cached)

Three lines to a reusable bed::

    spec = PackingSpec(container=BoxRegion((0, 0, 0), (2, 2, 3)), materials=(mat,),
                       layers=(LayerSpec(thickness=2.0),), radius=RadiusDistribution(0.05, 0.2))
    bed = cached(spec, "~/.cache/crashdem/packings")

Every length is in m, every angle in rad, forces in N.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np

from .portable import sphere_volume

jit = functools.partial(numba.njit, cache=True)

#: Version of the HDF5 layout and of the spec hashing; bump when either changes.
FORMAT_VERSION = 1

#: Porosity assumed when estimating how many particles fill a layer (densest random loose
#: packing of spheres, so the estimate over-fills and the excess is carved away).
_FILL_POROSITY = 0.36
#: Over-fill factor on the particle count of a layer (the excess is carved off the top).
_OVERFILL = 1.12
#: Height added above a cylinder container's wall so that a cloud above the rim stays inside [m].
_WALL_EXTENSION = 1000.0


def _check_positive(owner: str, name: str, value: float, unit: str) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{owner}.{name}={value!r}: must be > 0 [{unit}]")


# ---------------------------------------------------------------------------------------------
# Regions and radius distributions
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BoxRegion:
    """Axis-aligned box ``lo <= x <= hi``: a container or a control volume.

    Parameters
    ----------
    lo, hi : tuple of 3 float
        Opposite corners [m]; ``hi > lo`` component-wise.
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def __post_init__(self) -> None:
        lo = tuple(float(v) for v in self.lo)
        hi = tuple(float(v) for v in self.hi)
        if len(lo) != 3 or len(hi) != 3:
            raise ValueError(
                f"BoxRegion.lo={self.lo!r}, hi={self.hi!r}: must have 3 components [m]"
            )
        for k in range(3):
            if not hi[k] > lo[k]:
                raise ValueError(
                    f"BoxRegion.hi[{k}]={hi[k]!r}: must be > lo[{k}]={lo[k]!r} [m]"
                )
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    @property
    def volume(self) -> float:
        """Volume [m^3]."""
        lo, hi = self.lo, self.hi
        return (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2])

    @property
    def area(self) -> float:
        """Horizontal cross-section [m^2]."""
        return (self.hi[0] - self.lo[0]) * (self.hi[1] - self.lo[1])

    def with_z(self, z_min: float, z_max: float) -> BoxRegion:
        """Same footprint, new vertical extent [m]."""
        return BoxRegion((self.lo[0], self.lo[1], z_min), (self.hi[0], self.hi[1], z_max))

    def shrunk(self, margin: float) -> BoxRegion:
        """Box moved inwards by ``margin`` [m] on every face."""
        return BoxRegion(tuple(v + margin for v in self.lo), tuple(v - margin for v in self.hi))

    def _kernel_params(self) -> tuple[int, np.ndarray]:
        return 0, np.array([*self.lo, *self.hi], dtype=np.float64)


@dataclass(frozen=True)
class CylinderRegion:
    """Vertical circular cylinder (the test tank): a container or a control volume.

    Parameters
    ----------
    center : tuple of 2 float
        Axis position (x, y) [m].
    radius : float
        Radius [m], > 0.
    z_min, z_max : float
        Bottom and top [m], ``z_max > z_min``.
    """

    center: tuple[float, float]
    radius: float
    z_min: float
    z_max: float

    def __post_init__(self) -> None:
        c = tuple(float(v) for v in self.center)
        if len(c) != 2:
            raise ValueError(f"CylinderRegion.center={self.center!r}: must be (x, y) [m]")
        object.__setattr__(self, "center", c)
        _check_positive("CylinderRegion", "radius", self.radius, "m")
        if not self.z_max > self.z_min:
            raise ValueError(
                f"CylinderRegion.z_max={self.z_max!r}: must be > z_min={self.z_min!r} [m]"
            )

    @property
    def volume(self) -> float:
        """Volume [m^3]."""
        return math.pi * self.radius**2 * (self.z_max - self.z_min)

    @property
    def area(self) -> float:
        """Horizontal cross-section [m^2]."""
        return math.pi * self.radius**2

    @property
    def lo(self) -> tuple[float, float, float]:
        """Lower corner of the bounding box [m]."""
        return (self.center[0] - self.radius, self.center[1] - self.radius, self.z_min)

    @property
    def hi(self) -> tuple[float, float, float]:
        """Upper corner of the bounding box [m]."""
        return (self.center[0] + self.radius, self.center[1] + self.radius, self.z_max)

    def with_z(self, z_min: float, z_max: float) -> CylinderRegion:
        """Same footprint, new vertical extent [m]."""
        return CylinderRegion(self.center, self.radius, z_min, z_max)

    def shrunk(self, margin: float) -> CylinderRegion:
        """Cylinder moved inwards by ``margin`` [m] on every face."""
        return CylinderRegion(
            self.center, self.radius - margin, self.z_min + margin, self.z_max - margin
        )

    def _kernel_params(self) -> tuple[int, np.ndarray]:
        cx, cy = self.center
        return 1, np.array([cx, cy, self.radius, self.z_min, self.z_max, 0.0], dtype=np.float64)


Region = BoxRegion | CylinderRegion


def as_region(obj: Any) -> Region:
    """Accept a region, or an engine ``soil.Box`` / ``soil.Cylinder`` (duck-typed)."""
    if isinstance(obj, (BoxRegion, CylinderRegion)):
        return obj
    if hasattr(obj, "lo") and hasattr(obj, "hi"):
        return BoxRegion(tuple(obj.lo), tuple(obj.hi))
    if all(hasattr(obj, a) for a in ("center", "radius", "z_min", "z_max")):
        return CylinderRegion(tuple(obj.center), obj.radius, obj.z_min, obj.z_max)
    raise TypeError(
        f"region={obj!r}: must be a BoxRegion, a CylinderRegion, soil.Box or soil.Cylinder"
    )


@dataclass(frozen=True)
class RadiusDistribution:
    """Particle radius distribution.

    ``kind="uniform"``: radii uniform in ``mean * (1 - spread) .. mean * (1 + spread)``
    (the thesis's "r = 0.05 m +/- 20 %" is ``RadiusDistribution(0.05, 0.2)``).
    ``kind="discrete"``: radii drawn from ``values`` with number fractions ``fractions``.

    Parameters
    ----------
    mean : float
        Mean radius [m], > 0 (ignored for ``discrete``: the number-weighted mean is used).
    spread : float
        Relative half-width, in [0, 1).
    kind : str
        ``"uniform"`` or ``"discrete"``.
    values, fractions : tuple of float
        For ``discrete``: radii [m] (> 0) and number fractions (>= 0, normalised here).
    """

    mean: float
    spread: float = 0.0
    kind: str = "uniform"
    values: tuple[float, ...] = ()
    fractions: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in ("uniform", "discrete"):
            raise ValueError(
                f"RadiusDistribution.kind={self.kind!r}: must be one of 'uniform', 'discrete'"
            )
        if self.kind == "uniform":
            _check_positive("RadiusDistribution", "mean", self.mean, "m")
            if not 0.0 <= self.spread < 1.0:
                raise ValueError(
                    f"RadiusDistribution.spread={self.spread!r}: must be in [0, 1) [-]"
                )
        else:
            vals = tuple(float(v) for v in self.values)
            fr = tuple(float(v) for v in self.fractions)
            if not vals or len(vals) != len(fr):
                raise ValueError(
                    f"RadiusDistribution.values={self.values!r}: needs one fraction per value "
                    f"(got {len(fr)} fractions)"
                )
            if min(vals) <= 0:
                raise ValueError(f"RadiusDistribution.values={vals!r}: must all be > 0 [m]")
            if min(fr) < 0 or sum(fr) <= 0:
                raise ValueError(
                    f"RadiusDistribution.fractions={fr!r}: must be >= 0 with a positive sum [-]"
                )
            s = sum(fr)
            fr = tuple(v / s for v in fr)
            object.__setattr__(self, "values", vals)
            object.__setattr__(self, "fractions", fr)
            object.__setattr__(self, "mean", float(sum(v * f for v, f in zip(vals, fr))))

    @classmethod
    def discrete(cls, values, fractions) -> RadiusDistribution:
        """Sieve-like distribution: radii ``values`` [m] with number ``fractions``."""
        return cls(mean=1.0, kind="discrete", values=tuple(values), fractions=tuple(fractions))

    @property
    def r_min(self) -> float:
        """Smallest radius [m]."""
        return self.mean * (1 - self.spread) if self.kind == "uniform" else min(self.values)

    @property
    def r_max(self) -> float:
        """Largest radius [m]."""
        return self.mean * (1 + self.spread) if self.kind == "uniform" else max(self.values)

    @property
    def mean_volume(self) -> float:
        """Expected sphere volume E[4/3 pi r^3] [m^3].

        Notes
        -----
        Uniform r on [a, b]: E[r^3] = (b^4 - a^4) / (4 (b - a)).
        """
        if self.kind == "discrete":
            return sum(4 / 3 * math.pi * v**3 * f for v, f in zip(self.values, self.fractions))
        a, b = self.r_min, self.r_max
        er3 = self.mean**3 if b == a else (b**4 - a**4) / (4 * (b - a))
        return 4 / 3 * math.pi * er3

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``n`` radii [m]."""
        if self.kind == "uniform":
            if self.spread == 0:
                return np.full(n, self.mean)
            return rng.uniform(self.r_min, self.r_max, size=n)
        idx = rng.choice(len(self.values), size=n, p=np.asarray(self.fractions))
        return np.asarray(self.values)[idx]


# ---------------------------------------------------------------------------------------------
# Loose clouds
# ---------------------------------------------------------------------------------------------


def _radii(radius: RadiusDistribution | np.ndarray, n: int | None, rng) -> np.ndarray:
    if isinstance(radius, RadiusDistribution):
        if n is None:
            raise ValueError("n=None: give the number of particles when radius is a distribution")
        return radius.sample(int(n), rng)
    r = np.asarray(radius, dtype=np.float64).ravel()
    if n is not None and len(r) != n:
        raise ValueError(f"radius: {len(r)} given radii but n={n}")
    if len(r) == 0 or r.min() <= 0 or not np.all(np.isfinite(r)):
        raise ValueError("radius: given radii must be finite and > 0 [m]")
    return r


def lattice_sites(
    region: Region,
    spacing: float,
    up: tuple[float, float, float] = (0.0, 0.0, 1.0),
    planes: list[tuple[np.ndarray, np.ndarray]] | None = None,
    h_min: float = -np.inf,
) -> np.ndarray:
    """Centres of the cubic cells of size ``spacing`` that lie wholly inside a region.

    Cells are sorted by height along ``up`` (then x, y), so taking the first n fills the region
    from the bottom.  ``planes`` (point, inward normal) and ``h_min`` (minimum height of the cell
    bottom along ``up``) restrict the cells further.

    Returns
    -------
    ndarray (M, 3)
        Cell centres [m].
    """
    region = as_region(region)
    lo = np.asarray(region.lo)
    hi = np.asarray(region.hi)
    counts = np.floor((hi - lo) / spacing + 1e-9).astype(np.int64)
    if np.any(counts < 1):
        return np.empty((0, 3))
    axes = [lo[k] + spacing * (0.5 + np.arange(counts[k])) for k in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    c = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    half = 0.5 * spacing
    keep = np.ones(len(c), dtype=bool)
    if isinstance(region, CylinderRegion):
        d = np.hypot(c[:, 0] - region.center[0], c[:, 1] - region.center[1])
        keep &= d + half * math.sqrt(2.0) <= region.radius
    for p, nrm in planes or []:
        nrm = np.asarray(nrm, float) / np.linalg.norm(nrm)
        keep &= (c - np.asarray(p, float)) @ nrm >= half * np.abs(nrm).sum()
    u = np.asarray(up, float) / np.linalg.norm(up)
    h = c @ u
    keep &= h - half * np.abs(u).sum() >= h_min
    c, h = c[keep], h[keep]
    order = np.lexsort((c[:, 1], c[:, 0], np.round(h / spacing, 6)))
    return c[order]


def lattice_cloud(
    region: Region,
    radius: RadiusDistribution | np.ndarray,
    n: int | None = None,
    seed: int = 0,
    gap: float = 0.05,
    **site_options,
) -> tuple[np.ndarray, np.ndarray]:
    """Non-overlapping polydisperse spheres on a jittered cubic lattice, filled from the bottom.

    Each sphere sits inside its own cubic cell of edge ``2 r_max (1 + gap)`` with a random offset
    that keeps it inside the cell, so no two spheres overlap whatever the radii.  The solid
    fraction is about ``pi/6 E[r^3] / (r_max^3 (1 + gap)^3)`` (0.3 for +/-20 %), dense enough that
    a deposition only falls about half the cloud height.

    Parameters
    ----------
    region : BoxRegion or CylinderRegion
        Where the cloud may be [m].
    radius : RadiusDistribution or ndarray
        Distribution, or the radii themselves [m].
    n : int, optional
        Number of spheres (required with a distribution).
    seed : int
        Seed of ``numpy.random.default_rng``; the result is deterministic.
    gap : float
        Relative clearance of the cells, >= 0.
    **site_options
        Passed to :func:`lattice_sites` (``up``, ``planes``, ``h_min``).

    Returns
    -------
    x : ndarray (n, 3)
        Centres [m].
    r : ndarray (n,)
        Radii [m].
    """
    if gap < 0:
        raise ValueError(f"lattice_cloud.gap={gap!r}: must be >= 0 [-]")
    rng = np.random.default_rng(seed)
    r = _radii(radius, n, rng)
    spacing = 2.0 * float(r.max()) * (1.0 + gap)
    sites = lattice_sites(region, spacing, **site_options)
    if len(sites) < len(r):
        raise ValueError(
            f"lattice_cloud: region {region} holds {len(sites)} cells of {spacing:.4g} m, "
            f"{len(r)} spheres requested; enlarge the region or reduce n"
        )
    jitter = (0.5 * spacing - r)[:, None] * rng.uniform(-1.0, 1.0, size=(len(r), 3))
    return sites[: len(r)] + jitter, r


@jit
def _rsa_kernel(kind, prm, r, seed, max_attempts, cell, x_out):
    np.random.seed(seed)
    if kind == 0:
        lo0, lo1, lo2, hi0, hi1, hi2 = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5]
    else:
        lo0, lo1, lo2 = prm[0] - prm[2], prm[1] - prm[2], prm[3]
        hi0, hi1, hi2 = prm[0] + prm[2], prm[1] + prm[2], prm[4]
    nx = max(1, int((hi0 - lo0) / cell) + 1)
    ny = max(1, int((hi1 - lo1) / cell) + 1)
    nz = max(1, int((hi2 - lo2) / cell) + 1)
    head = -np.ones(nx * ny * nz, dtype=np.int64)
    nxt = -np.ones(len(r), dtype=np.int64)
    placed = 0
    for i in range(len(r)):
        ri = r[i]
        ok = False
        for _ in range(max_attempts):
            px = lo0 + ri + (hi0 - lo0 - 2 * ri) * np.random.random()
            py = lo1 + ri + (hi1 - lo1 - 2 * ri) * np.random.random()
            pz = lo2 + ri + (hi2 - lo2 - 2 * ri) * np.random.random()
            if kind == 1:
                if math.hypot(px - prm[0], py - prm[1]) + ri > prm[2]:
                    continue
            cx = min(nx - 1, int((px - lo0) / cell))
            cy = min(ny - 1, int((py - lo1) / cell))
            cz = min(nz - 1, int((pz - lo2) / cell))
            free = True
            for ix in range(max(0, cx - 1), min(nx, cx + 2)):
                for iy in range(max(0, cy - 1), min(ny, cy + 2)):
                    for iz in range(max(0, cz - 1), min(nz, cz + 2)):
                        j = head[(ix * ny + iy) * nz + iz]
                        while j >= 0:
                            dx = px - x_out[j, 0]
                            dy = py - x_out[j, 1]
                            dz = pz - x_out[j, 2]
                            rr = ri + r[j]
                            if dx * dx + dy * dy + dz * dz < rr * rr:
                                free = False
                                break
                            j = nxt[j]
                        if not free:
                            break
                    if not free:
                        break
                if not free:
                    break
            if free:
                x_out[i, 0] = px
                x_out[i, 1] = py
                x_out[i, 2] = pz
                c = (cx * ny + cy) * nz + cz
                nxt[i] = head[c]
                head[c] = i
                ok = True
                break
        if not ok:
            return placed
        placed += 1
    return placed


def rsa_cloud(
    region: Region,
    radius: RadiusDistribution | np.ndarray,
    n: int | None = None,
    seed: int = 0,
    max_attempts: int = 2000,
) -> tuple[np.ndarray, np.ndarray]:
    """Non-overlapping random spheres by random sequential addition (largest first).

    Fully random positions (no lattice memory), up to a solid fraction of about 0.3; RSA jams
    near 0.38.  Deterministic for a seed (Numba's generator seeded inside the kernel).

    Parameters
    ----------
    region, radius, n, seed
        As :func:`lattice_cloud`.
    max_attempts : int
        Trial positions per sphere before giving up (then a ValueError names the count placed).

    Returns
    -------
    x : ndarray (n, 3)
        Centres [m], in the order of decreasing radius.
    r : ndarray (n,)
        Radii [m].
    """
    region = as_region(region)
    rng = np.random.default_rng(seed)
    r = np.sort(_radii(radius, n, rng))[::-1].copy()
    kind, prm = region._kernel_params()
    x = np.zeros((len(r), 3))
    placed = _rsa_kernel(kind, prm, r, int(seed) % (2**31), int(max_attempts), 2.0 * r.max(), x)
    if placed < len(r):
        frac = float(np.sum(sphere_volume(r[:placed])) / region.volume)
        raise ValueError(
            f"rsa_cloud: placed {placed} of {len(r)} spheres in {region} (solid fraction "
            f"{frac:.3f}; RSA jams near 0.38); enlarge the region or use lattice_cloud"
        )
    return x, r


def random_cloud(region, radius, n=None, seed=0, method="lattice", **options):
    """Loose non-overlapping cloud: ``method="lattice"`` (fast, dense) or ``"rsa"`` (random).

    See :func:`lattice_cloud` and :func:`rsa_cloud`.
    """
    if method == "lattice":
        return lattice_cloud(region, radius, n, seed, **options)
    if method == "rsa":
        return rsa_cloud(region, radius, n, seed, **options)
    raise ValueError(f"random_cloud.method={method!r}: must be one of 'lattice', 'rsa'")


# ---------------------------------------------------------------------------------------------
# Porosity: exact sphere volumes inside a box or a cylinder
# ---------------------------------------------------------------------------------------------


@jit
def _prim_s(X, rho):
    # antiderivative of sqrt(rho^2 - X^2), X clamped to [-rho, rho]
    X = min(max(X, -rho), rho)
    return 0.5 * (X * math.sqrt(max(rho * rho - X * X, 0.0)) + rho * rho * math.asin(X / rho))


@jit
def _int_s(lo, hi, rho):
    if hi <= lo:
        return 0.0
    return _prim_s(hi, rho) - _prim_s(lo, rho)


@jit
def _disk_quadrant_area(a, b, rho):
    # area of the disk (0, rho) intersected with {X <= a, Y <= b}
    if rho <= 0.0 or a <= -rho or b <= -rho:
        return 0.0
    a = min(a, rho)
    if b >= rho:
        return 2.0 * _int_s(-rho, a, rho)
    c = math.sqrt(rho * rho - b * b)
    area = 0.0
    if b >= 0.0:
        area += 2.0 * _int_s(-rho, min(a, -c), rho)
        hi = min(a, c)
        if hi > -c:
            area += b * (hi + c) + _int_s(-c, hi, rho)
        area += 2.0 * _int_s(c, a, rho)
    else:
        hi = min(a, c)
        if hi > -c:
            area += b * (hi + c) + _int_s(-c, hi, rho)
    return area


@jit
def _disk_rect_area(xc, yc, rho, x1, y1, x2, y2):
    # area of the disk (xc, yc, rho) inside the rectangle [x1, x2] x [y1, y2]
    return (
        _disk_quadrant_area(x2 - xc, y2 - yc, rho)
        - _disk_quadrant_area(x1 - xc, y2 - yc, rho)
        - _disk_quadrant_area(x2 - xc, y1 - yc, rho)
        + _disk_quadrant_area(x1 - xc, y1 - yc, rho)
    )


@jit
def _disk_disk_area(d, r1, r2):
    # lens area of two disks of radii r1, r2 with centres d apart
    if r1 <= 0.0 or r2 <= 0.0 or d >= r1 + r2:
        return 0.0
    if d <= abs(r1 - r2):
        rm = min(r1, r2)
        return math.pi * rm * rm
    c1 = min(1.0, max(-1.0, (d * d + r1 * r1 - r2 * r2) / (2.0 * d * r1)))
    c2 = min(1.0, max(-1.0, (d * d + r2 * r2 - r1 * r1) / (2.0 * d * r2)))
    k = (-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2)
    return r1 * r1 * math.acos(c1) + r2 * r2 * math.acos(c2) - 0.5 * math.sqrt(max(k, 0.0))


@jit
def _slab_volume(R, u0, u1):
    # int_{u0}^{u1} pi (R^2 - u^2) du : sphere volume between two planes (cap formula)
    return math.pi * (R * R * (u1 - u0) - (u1**3 - u0**3) / 3.0)


@jit
def _section_area(kind, prm, xc, yc, rho):
    if kind == 0:
        return _disk_rect_area(xc, yc, rho, prm[0], prm[1], prm[3], prm[4])
    return _disk_disk_area(math.hypot(xc - prm[0], yc - prm[1]), rho, prm[2])


@jit
def _sphere_region_volume(kind, prm, xc, yc, zc, R, gl_t, gl_w):
    if kind == 0:
        z_lo, z_hi = prm[2], prm[5]
    else:
        z_lo, z_hi = prm[3], prm[4]
    u0 = max(z_lo - zc, -R)
    u1 = min(z_hi - zc, R)
    if u1 <= u0:
        return 0.0
    # distances from the footprint centre to the features of the cross-section
    feats = np.empty(9)
    nf = 0
    if kind == 0:
        dx1 = xc - prm[0]
        dx2 = prm[3] - xc
        dy1 = yc - prm[1]
        dy2 = prm[4] - yc
        if min(dx1, dx2, dy1, dy2) >= R:
            return _slab_volume(R, u0, u1)  # footprint inside: exact caps only
        if xc + R <= prm[0] or xc - R >= prm[3] or yc + R <= prm[1] or yc - R >= prm[4]:
            return 0.0
        feats[0] = abs(dx1)
        feats[1] = abs(dx2)
        feats[2] = abs(dy1)
        feats[3] = abs(dy2)
        feats[4] = math.hypot(dx1, dy1)
        feats[5] = math.hypot(dx1, dy2)
        feats[6] = math.hypot(dx2, dy1)
        feats[7] = math.hypot(dx2, dy2)
        nf = 8
    else:
        d = math.hypot(xc - prm[0], yc - prm[1])
        if d + R <= prm[2]:
            return _slab_volume(R, u0, u1)
        if d - R >= prm[2]:
            return 0.0
        feats[0] = abs(prm[2] - d)
        feats[1] = prm[2] + d
        nf = 2
    # breakpoints in u where the section radius sqrt(R^2 - u^2) crosses a feature distance
    bps = np.empty(2 * nf + 2)
    nb = 0
    bps[nb] = u0
    nb += 1
    bps[nb] = u1
    nb += 1
    for k in range(nf):
        if feats[k] < R:
            h = math.sqrt(R * R - feats[k] * feats[k])
            for s in (-h, h):
                if u0 < s < u1:
                    bps[nb] = s
                    nb += 1
    b = np.sort(bps[:nb])
    vol = 0.0
    for k in range(nb - 1):
        a0, a1 = b[k], b[k + 1]
        L = a1 - a0
        if L <= 0.0:
            continue
        for q in range(len(gl_t)):
            t = 0.5 * (gl_t[q] + 1.0)
            # smoothstep substitution: clusters nodes at the kinks of the section area
            s = t * t * (3.0 - 2.0 * t)
            jac = 6.0 * t * (1.0 - t) * L * 0.5
            u = a0 + L * s
            rho = math.sqrt(max(R * R - u * u, 0.0))
            vol += gl_w[q] * jac * _section_area(kind, prm, xc, yc, rho)
    return vol


@jit
def _solid_volume_kernel(kind, prm, x, r, gl_t, gl_w):
    total = 0.0
    for i in range(len(r)):
        total += _sphere_region_volume(kind, prm, x[i, 0], x[i, 1], x[i, 2], r[i], gl_t, gl_w)
    return total


_GL_ORDER = 32


def sphere_volumes_in_region(x: np.ndarray, radius: np.ndarray, region: Region) -> np.ndarray:
    """Volume of each sphere inside a box or vertical cylinder [m^3].

    Notes
    -----
    The sphere is sliced normal to z.  A sphere whose footprint lies inside the cross-section and
    is cut only by the top/bottom planes gets the exact cap formula
    ``int pi (R^2 - u^2) du`` (sphere-plane cap volume).  A sphere cut by a side face is integrated
    over z of the exact disk-rectangle (inclusion-exclusion of disk-quadrant areas) or
    disk-disk (lens) section area, split at the heights where the section changes formula,
    32-point Gauss-Legendre per piece with a smoothstep substitution (relative error < 1e-9).
    """
    region = as_region(region)
    kind, prm = region._kernel_params()
    t, w = np.polynomial.legendre.leggauss(_GL_ORDER)
    x = np.ascontiguousarray(x, dtype=np.float64)
    r = np.ascontiguousarray(radius, dtype=np.float64)
    out = np.empty(len(r))
    for i in range(len(r)):
        out[i] = _solid_volume_kernel(kind, prm, x[i : i + 1], r[i : i + 1], t, w)
    return out


def solid_volume(x: np.ndarray, radius: np.ndarray, region: Region) -> float:
    """Total sphere volume inside a box or vertical cylinder [m^3].

    Notes
    -----
    Exact cut-sphere volumes, see :func:`sphere_volumes_in_region`.
    """
    region = as_region(region)
    kind, prm = region._kernel_params()
    t, w = np.polynomial.legendre.leggauss(_GL_ORDER)
    return float(
        _solid_volume_kernel(
            kind,
            prm,
            np.ascontiguousarray(x, dtype=np.float64),
            np.ascontiguousarray(radius, dtype=np.float64),
            t,
            w,
        )
    )


def porosity(x: np.ndarray, radius: np.ndarray, region: Region) -> float:
    """Porosity ``1 - V_solid / V_region`` of a control box or cylinder [-].

    Notes
    -----
    Exact sphere volumes cut by the control-volume boundary, see :func:`sphere_volumes_in_region`.
    """
    region = as_region(region)
    return 1.0 - solid_volume(x, radius, region) / region.volume


def porosity_profile(x, radius, region: Region, edges) -> np.ndarray:
    """Porosity of horizontal slices ``edges[k] .. edges[k+1]`` of a region [-]."""
    region = as_region(region)
    e = np.asarray(edges, dtype=float)
    return np.array([porosity(x, radius, region.with_z(e[k], e[k + 1])) for k in range(len(e) - 1)])


def free_surface_height(z, radius, area: float) -> float:
    """Height [m] of a deposited bed's free surface: the level at which the solid fraction of
    horizontal sections falls for the last time to half of the bed's own, the bed's being its
    mean from 5 to 2 mean radii below the highest centre.

    ``z`` and ``radius`` are the centre heights and radii of the grains whose centre lies in a
    footprint of ``area`` [m^2] (e.g. a central cylinder, away from the walls); a section's
    solid fraction is the grains' cross-section area in it over ``area``. For a bed cut where
    the grain centres pass a height (what :func:`build` does at every layer top) this level is
    that height to within a fraction of a radius; for a bed whose grains' tops were cut, about
    a radius lower. "The last time" matters: a regular bed's fraction dips between its tiers.
    Applied to the grains of the lower layer of a layered bed it gives the interface.
    """
    z = np.asarray(z, dtype=float)
    r = np.asarray(radius, dtype=float)
    if z.shape != r.shape or z.ndim != 1:
        raise ValueError(f"free_surface_height: z {z.shape} and radius {r.shape} must be "
                         "equal-length vectors")
    if len(z) < 10:
        raise ValueError(f"free_surface_height: {len(z)} grains in the footprint; need at least 10")
    if not area > 0.0:
        raise ValueError(f"free_surface_height: area={area!r}: must be > 0 [m^2]")
    r_mean = float(np.mean(r))

    def solid(level: float) -> float:
        d = np.abs(z - level)
        m = d < r
        return float(np.sum(math.pi * (r[m] ** 2 - d[m] ** 2))) / area

    z_top = float(np.max(z))
    lo = max(z_top - 5.0 * r_mean, float(np.min(z)))
    bulk = float(np.mean([solid(h) for h in np.linspace(lo, z_top - 2.0 * r_mean, 31)]))
    zs = np.linspace(z_top - 2.0 * r_mean, float(np.max(z + r)), 241)
    f = np.array([solid(h) for h in zs]) - 0.5 * bulk
    k = int(np.nonzero(f >= 0.0)[0][-1]) if np.any(f >= 0.0) else 0
    if k == len(zs) - 1:
        return float(zs[k])
    return float(zs[k] + (zs[k + 1] - zs[k]) * f[k] / (f[k] - f[k + 1]))


# ---------------------------------------------------------------------------------------------
# Gravity deposition
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DepositionSettings:
    """How a cloud is settled.

    Parameters
    ----------
    damping : float
        Global (Cundall) damping during deposition, in [0, 1) (Yade NewtonIntegrator.damping).
    threshold : float
        Stop when Yade's unbalanced-force ratio is below this, in (0, 1).  0.01 follows the
        thesis's deposition procedure (Fig 4.2).
    check_every : int
        Steps between two checks of the stop criterion (run inside the engine's loop), >= 1.
    max_steps : int
        Guard: after this many steps ``on_max_steps`` decides (raise or warn), >= 1.
    on_max_steps : str
        ``"raise"`` or ``"warn"``.
    settle_steps : int
        Undamped steps after the threshold, over which the kinetic energy is checked, >= 0.
    ke_tolerance : float
        After ``settle_steps`` undamped steps the kinetic energy must be below
        ``ke_tolerance * W * d_mean`` (W bed weight, d_mean mean diameter), > 0.  The default
        5e-3 is an rms grain speed of sqrt(2 * 5e-3 * g * d_mean), 0.1 m/s for d = 0.1 m: the
        elastic ringing left when the damping is removed, negligible beside an impact.
    dt : float or None
        Time step [s]; None = the engine's stable step.
    safety : float
        Engine's safety factor on the critical step when ``dt`` is None, in (0, 1].
    rotation_blocked : bool
        Block particle rotations (thesis, Calvetti et al. 2005).
    wall_friction_angle : float or None
        Friction of the container walls [rad]; None = the soil's.
    threads : int or None
        Engine threads (None = engine default).
    """

    damping: float = 0.4
    threshold: float = 0.01
    check_every: int = 100
    max_steps: int = 200_000
    on_max_steps: str = "raise"
    settle_steps: int = 100
    ke_tolerance: float = 5e-3
    dt: float | None = None
    safety: float = 0.3
    rotation_blocked: bool = True
    wall_friction_angle: float | None = None
    threads: int | None = None

    def __post_init__(self) -> None:
        if not 0.0 <= self.damping < 1.0:
            raise ValueError(f"DepositionSettings.damping={self.damping!r}: must be in [0, 1) [-]")
        if not 0.0 < self.threshold < 1.0:
            raise ValueError(
                f"DepositionSettings.threshold={self.threshold!r}: must be in (0, 1) [-]"
            )
        for name in ("check_every", "max_steps"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"DepositionSettings.{name}={getattr(self, name)!r}: must be >= 1")
        if self.settle_steps < 0:
            raise ValueError(f"DepositionSettings.settle_steps={self.settle_steps!r}: must be >= 0")
        if self.on_max_steps not in ("raise", "warn"):
            raise ValueError(
                f"DepositionSettings.on_max_steps={self.on_max_steps!r}: must be one of "
                f"'raise', 'warn'"
            )
        _check_positive("DepositionSettings", "ke_tolerance", self.ke_tolerance, "-")
        if self.dt is not None:
            _check_positive("DepositionSettings", "dt", self.dt, "s")
        if not 0.0 < self.safety <= 1.0:
            raise ValueError(f"DepositionSettings.safety={self.safety!r}: must be in (0, 1] [-]")
        w = self.wall_friction_angle
        if w is not None and not 0.0 <= w < math.pi / 2:
            raise ValueError(
                f"DepositionSettings.wall_friction_angle={w!r}: must be in [0, pi/2) [rad]"
            )


class DepositionError(RuntimeError):
    """Deposition did not reach the unbalanced-force threshold within ``max_steps``."""


@dataclass
class DepositionResult:
    """Outcome of :func:`deposit` (arrays are copies; SI units)."""

    x: np.ndarray  #: centres [m]
    radius: np.ndarray  #: radii [m]
    material: np.ndarray  #: material ids (as given to deposit)
    steps: int  #: steps taken, damped + undamped
    time: float  #: simulated time [s]
    dt: float  #: time step [s]
    unbalanced: float  #: unbalanced-force ratio when damping was removed [-]
    unbalanced_final: float  #: after the undamped settle steps [-]
    kinetic_energy: float  #: after the undamped settle steps [J]
    kinetic_energy_limit: float  #: ke_tolerance * W * d_mean [J]
    weight: float  #: bed weight along gravity [N]
    floor_force: float  #: force of the particles on the floor along gravity [N]
    wall_force: float  #: force of the particles on the side walls along gravity [N]
    converged: bool  #: threshold reached and kinetic energy below the limit
    history: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))  #: (step, unbalanced)


def _container_bodies(container, wall_material: int, gravity, open_front: bool = False):
    """Boundary bodies (floor, walls) of a box or cylinder container for the engine."""
    import soil

    g = np.asarray(gravity, float)
    if isinstance(container, BoxRegion):
        lo, hi = np.asarray(container.lo), np.asarray(container.hi)
        floor = soil.BoundaryBody(
            shapes=[soil.Plane(point=tuple(lo), normal=(0.0, 0.0, 1.0))], material=wall_material
        )
        planes = []
        if not open_front:
            planes.append(soil.Plane(point=tuple(lo), normal=(1.0, 0.0, 0.0)))
        planes += [
            soil.Plane(point=tuple(hi), normal=(-1.0, 0.0, 0.0)),
            soil.Plane(point=tuple(lo), normal=(0.0, 1.0, 0.0)),
            soil.Plane(point=tuple(hi), normal=(0.0, -1.0, 0.0)),
        ]
        walls = soil.BoundaryBody(shapes=planes, material=wall_material)
    elif isinstance(container, CylinderRegion):
        floor = soil.BoundaryBody(
            shapes=[soil.Plane(point=(*container.center, container.z_min), normal=(0.0, 0.0, 1.0))],
            material=wall_material,
        )
        walls = soil.BoundaryBody(
            shapes=[
                soil.Cylinder(
                    center=container.center,
                    radius=container.radius,
                    z_min=container.z_min,
                    # the wall only acts on centres within [z_min, z_max]: extend it over the cloud
                    z_max=container.z_max + _WALL_EXTENSION,
                )
            ],
            material=wall_material,
        )
    else:
        raise TypeError(f"container={container!r}: must be a BoxRegion or a CylinderRegion")
    del g
    return [floor, walls]


def _set_damping(sim, value: float) -> None:
    # the engine exposes global damping as a plain attribute (soil.Simulation.global_damping)
    sim.global_damping = float(value)


def deposit(
    x: np.ndarray,
    radius: np.ndarray,
    material: np.ndarray,
    materials,
    container,
    settings: DepositionSettings = DepositionSettings(),
    gravity=(0.0, 0.0, -9.81),
    open_front: bool = False,
    progress=None,
) -> DepositionResult:
    """Settle a cloud under gravity with global damping until it is in static equilibrium.

    Runs ``check_every`` steps at a time inside the engine until Yade's unbalanced-force ratio
    is below ``settings.threshold``, then removes the damping, runs ``settle_steps`` undamped
    steps and checks that the kinetic energy stays below ``ke_tolerance * W * d_mean``.
    Deposit at the stiffness the packing will be used with (anchors §8: changing E afterwards
    locks in lateral stress).

    Parameters
    ----------
    x, radius, material : ndarray
        Centres (N, 3) [m], radii (N,) [m], material ids (N,) into ``materials``.
    materials : sequence of soil.Material
        Materials used during deposition (e.g. the final ones with a deposition friction).
    container : BoxRegion, CylinderRegion or list of soil.BoundaryBody
        Box (floor + 4 walls, open top), cylinder (floor + wall) or a scene's own bodies (then
        the first body is taken as the floor).
    settings : DepositionSettings
    gravity : 3 floats
        [m/s^2].
    open_front : bool
        Box only: leave out the wall at ``x = lo[0]`` (slope containers).
    progress : callable or None
        Called with a short text every 20 checks.

    Returns
    -------
    DepositionResult

    Notes
    -----
    Unbalanced-force ratio: Yade ``utils.unbalancedForce`` (mean resultant force on the
    particles over the mean contact force), computed by the engine.  Cundall global damping:
    Yade ``NewtonIntegrator.damping``.
    """
    import soil

    x = np.ascontiguousarray(x, dtype=np.float64)
    r = np.ascontiguousarray(radius, dtype=np.float64)
    mat = np.ascontiguousarray(material, dtype=np.int32)
    materials = list(materials)
    if isinstance(container, (BoxRegion, CylinderRegion)):
        phi_w = settings.wall_friction_angle
        base = materials[int(mat[0])] if len(mat) else materials[0]
        wall_mat = dataclasses.replace(
            base,
            friction_angle=base.friction_angle if phi_w is None else phi_w,
            name="container_wall",
        )
        bodies = _container_bodies(container, len(materials), gravity, open_front)
        all_materials = materials + [wall_mat]
    else:
        bodies = list(container)
        all_materials = materials
    p = soil.Particles(x=x, radius=r, material=mat, rotation_blocked=settings.rotation_blocked)
    sim = soil.Simulation(
        p,
        materials=all_materials,
        boundaries=bodies,
        gravity=tuple(gravity),
        dt=settings.dt,
        safety=settings.safety,
        global_damping=settings.damping,
        threads=settings.threads,
    )
    g = np.asarray(gravity, float)
    g_norm = float(np.linalg.norm(g))
    g_hat = g / g_norm
    mass = np.asarray(sim.particles.mass)
    weight = float(mass.sum() * g_norm)
    history = []
    ub = math.inf
    reached = False
    while sim.step_count < settings.max_steps:
        sim.step(settings.check_every)
        ub = float(sim.unbalanced_force())
        history.append((sim.step_count, ub))
        if progress is not None and len(history) % 20 == 0:
            progress(f"  deposit: step {sim.step_count}, unbalanced {ub:.3g}")
        if np.isfinite(ub) and ub < settings.threshold:
            reached = True
            break
    if not reached:
        msg = (
            f"deposit: unbalanced force {ub:.3g} still above threshold {settings.threshold} after "
            f"max_steps={settings.max_steps} ({len(r)} particles, dt={sim.dt:.3g} s); raise "
            f"DepositionSettings.max_steps or damping, or start from a denser cloud"
        )
        if settings.on_max_steps == "raise":
            raise DepositionError(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    ub_stop = ub
    _set_damping(sim, 0.0)
    f_floor = np.zeros(3)
    f_wall = np.zeros(3)
    n_avg = 0
    if settings.settle_steps > 0:
        # average the support forces over the undamped window (rattling averages out)
        chunk = max(1, settings.settle_steps // 10)
        done = 0
        while done < settings.settle_steps:
            k = min(chunk, settings.settle_steps - done)
            sim.step(k)
            done += k
            f_floor += np.asarray(bodies[0].force, float)
            f_wall += sum((np.asarray(b.force, float) for b in bodies[1:]), np.zeros(3))
            n_avg += 1
    else:
        f_floor = np.asarray(bodies[0].force, float).copy()
        f_wall = sum((np.asarray(b.force, float) for b in bodies[1:]), np.zeros(3))
        n_avg = 1
    f_floor /= n_avg
    f_wall /= n_avg
    e = sim.energy()
    ke = float(e["kinetic_translational"] + e.get("kinetic_rotational", 0.0))
    ke_limit = settings.ke_tolerance * weight * 2.0 * float(r.mean())
    ub_final = float(sim.unbalanced_force())
    converged = reached and ke <= ke_limit
    if reached and ke > ke_limit:
        warnings.warn(
            f"deposit: kinetic energy {ke:.3g} J after {settings.settle_steps} undamped steps "
            f"exceeds {ke_limit:.3g} J (ke_tolerance={settings.ke_tolerance} x W x d_mean); the "
            f"bed is not at rest: lower DepositionSettings.threshold",
            RuntimeWarning,
            stacklevel=2,
        )
    parts = sim.particles
    return DepositionResult(
        x=np.array(parts.x, dtype=np.float64),
        radius=np.array(parts.radius, dtype=np.float64),
        material=mat.copy(),
        steps=int(sim.step_count),
        time=float(sim.time),
        dt=float(sim.dt),
        unbalanced=ub_stop,
        unbalanced_final=ub_final,
        kinetic_energy=ke,
        kinetic_energy_limit=ke_limit,
        weight=weight,
        floor_force=float(f_floor @ g_hat),
        wall_force=float(f_wall @ g_hat),
        converged=converged,
        history=np.asarray(history, dtype=float).reshape(-1, 2),
    )


# ---------------------------------------------------------------------------------------------
# Specs: layers, slope, whole packing
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LayerSpec:
    """One horizontal (or slope-parallel) layer, listed bottom to top.

    Parameters
    ----------
    thickness : float
        Final thickness after carving [m], > 0.
    material : int
        Material id of the layer's particles (index into ``PackingSpec.materials``), >= 0.
    deposition_friction : float or None
        Friction angle used while depositing this layer [rad] in [0, pi/2); lower friction gives
        a denser layer.  None = the material's own.  The packing keeps the final material.
    target_porosity : float or None
        If given, ``deposition_friction`` is found by a short bracketing search on a trial
        column (see :func:`friction_for_porosity`), in (0.2, 0.7).
    """

    thickness: float
    material: int = 0
    deposition_friction: float | None = None
    target_porosity: float | None = None

    def __post_init__(self) -> None:
        _check_positive("LayerSpec", "thickness", self.thickness, "m")
        if int(self.material) < 0:
            raise ValueError(f"LayerSpec.material={self.material!r}: must be >= 0")
        f = self.deposition_friction
        if f is not None and not 0.0 <= f < math.pi / 2:
            raise ValueError(f"LayerSpec.deposition_friction={f!r}: must be in [0, pi/2) [rad]")
        t = self.target_porosity
        if t is not None and not 0.2 < t < 0.7:
            raise ValueError(f"LayerSpec.target_porosity={t!r}: must be in (0.2, 0.7) [-]")


@dataclass(frozen=True)
class SlopeSpec:
    """Inclined free surface (the glider's soil container, thesis §2.2.2, §2.4).

    The free surface is the plane through ``(x_lo, *, z_lo)`` of the container rising along +x
    at ``angle``; soil is kept below it.

    Parameters
    ----------
    angle : float
        Inclination [rad], in (0, pi/2).
    compaction : str
        ``"horizontal"``: horizontal layers deposited under vertical gravity, then carved (what
        the laboratory did).  ``"normal"``: layers deposited with gravity along the inward slope
        normal (layers parallel to the slope, compaction normal to it, the real-terrain case of
        thesis §2.4), then carved.
    """

    angle: float = math.pi / 4
    compaction: str = "horizontal"

    def __post_init__(self) -> None:
        if not 0.0 < self.angle < math.pi / 2:
            raise ValueError(f"SlopeSpec.angle={self.angle!r}: must be in (0, pi/2) [rad]")
        if self.compaction not in ("horizontal", "normal"):
            raise ValueError(
                f"SlopeSpec.compaction={self.compaction!r}: must be one of 'horizontal', 'normal'"
            )

    def normal(self) -> np.ndarray:
        """Outward unit normal of the free surface."""
        return np.array([-math.sin(self.angle), 0.0, math.cos(self.angle)])


@dataclass(frozen=True)
class PackingSpec:
    """Everything that determines a packing (its hash keys the cache).

    Parameters
    ----------
    container : BoxRegion or CylinderRegion
        Container inner volume [m]; the bed rests on ``z_min``.
    materials : tuple of soil.Material
        Final materials (deposition uses them, with each layer's deposition friction).
    layers : tuple of LayerSpec
        Bottom to top; the bed surface is at ``z_min + sum(thickness)``.
    radius : RadiusDistribution
    seed : int
        Master seed (each layer derives its own).
    deposition : DepositionSettings
    slope : SlopeSpec or None
        Box containers only.
    gravity : float
        Magnitude [m/s^2] > 0.
    cloud : str
        ``"rsa"`` (random sequential addition, default) or ``"lattice"``.  A jittered cubic
        lattice of frictional grains with blocked rotations settles into stable vertical columns
        (lattice memory, porosity near 0.55), so the default is the fully random cloud.
    cloud_solid_fraction : float
        Solid fraction of the RSA cloud, in [0.05, 0.3].
    """

    container: Region
    materials: tuple
    layers: tuple[LayerSpec, ...]
    radius: RadiusDistribution
    seed: int = 0
    deposition: DepositionSettings = DepositionSettings()
    slope: SlopeSpec | None = None
    gravity: float = 9.81
    cloud: str = "rsa"
    cloud_solid_fraction: float = 0.22

    def __post_init__(self) -> None:
        if self.cloud not in ("rsa", "lattice"):
            raise ValueError(f"PackingSpec.cloud={self.cloud!r}: must be one of 'rsa', 'lattice'")
        if not 0.05 <= self.cloud_solid_fraction <= 0.3:
            raise ValueError(
                f"PackingSpec.cloud_solid_fraction={self.cloud_solid_fraction!r}: must be in "
                f"[0.05, 0.3] [-] (random sequential addition jams near 0.38)"
            )
        object.__setattr__(self, "container", as_region(self.container))
        object.__setattr__(self, "materials", tuple(self.materials))
        object.__setattr__(self, "layers", tuple(self.layers))
        if not self.materials:
            raise ValueError("PackingSpec.materials=(): needs at least one soil.Material")
        if not self.layers:
            raise ValueError("PackingSpec.layers=(): needs at least one LayerSpec")
        for k, layer in enumerate(self.layers):
            if layer.material >= len(self.materials):
                raise ValueError(
                    f"PackingSpec.layers[{k}].material={layer.material}: must be < "
                    f"len(materials)={len(self.materials)}"
                )
        _check_positive("PackingSpec", "gravity", self.gravity, "m/s^2")
        depth = sum(layer.thickness for layer in self.layers)
        c = self.container
        if depth > c.hi[2] - c.lo[2]:
            raise ValueError(
                f"PackingSpec.layers: total thickness {depth:.4g} m exceeds the container height "
                f"{c.hi[2] - c.lo[2]:.4g} m"
            )
        if self.slope is not None and not isinstance(c, BoxRegion):
            raise ValueError("PackingSpec.slope: needs a BoxRegion container")
        if int(self.seed) < 0:
            raise ValueError(f"PackingSpec.seed={self.seed!r}: must be >= 0")

    @property
    def surface_height(self) -> float:
        """Height of the flat bed surface [m] (for slopes, the top of the horizontal layers)."""
        return self.container.lo[2] + sum(layer.thickness for layer in self.layers)

    def to_dict(self) -> dict:
        """JSON-ready dict of every parameter (materials as their fields)."""
        return _to_jsonable(self)

    def hash(self) -> str:
        """SHA-256 of the canonical JSON of the spec and the format version (hex).

        The engine thread count is left out: results are bit-identical for any thread count,
        so a packing deposited with 1 thread serves a run with 2.
        """
        d = self.to_dict()
        dep = d.get("deposition")
        if isinstance(dep, dict):
            dep = {k: v for k, v in dep.items() if k != "threads"}
            d = {**d, "deposition": dep}
        return _sha256_json({"format": FORMAT_VERSION, "spec": d})


def _to_jsonable(obj):
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        d = {"__type__": type(obj).__name__}
        for f in dataclasses.fields(obj):
            d[f.name] = _to_jsonable(getattr(obj, f.name))
        return d
    if isinstance(obj, dict):
        return {str(k): _to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _to_jsonable(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return repr(obj)
    return obj


def _sha256_json(obj) -> str:
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


# ---------------------------------------------------------------------------------------------
# The packing object, HDF5 I/O, hashing, cache
# ---------------------------------------------------------------------------------------------


@dataclass(eq=False)
class Packing:
    """A settled packing.

    Attributes
    ----------
    x : ndarray (N, 3)
        Centres [m].
    radius : ndarray (N,)
        Radii [m].
    material : ndarray (N,) int32
        Material ids into ``materials``.
    materials : tuple of soil.Material
        Final materials.
    spec : dict
        Generation parameters (``PackingSpec.to_dict()`` or a free dict).
    seed : int
        Master seed.
    porosity : float
        Achieved porosity of ``porosity_region`` [-].
    porosity_region : BoxRegion or CylinderRegion or None
        Control volume of ``porosity``.
    info : dict
        Scalars from the generation (steps, unbalanced force, kinetic energy, floor force, layer
        porosities...).
    """

    x: np.ndarray
    radius: np.ndarray
    material: np.ndarray
    materials: tuple
    spec: dict
    seed: int = 0
    porosity: float = float("nan")
    porosity_region: Region | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.x = np.ascontiguousarray(self.x, dtype=np.float64)
        self.radius = np.ascontiguousarray(self.radius, dtype=np.float64)
        self.material = np.ascontiguousarray(self.material, dtype=np.int32)
        n = len(self.radius)
        if self.x.shape != (n, 3) or self.material.shape != (n,):
            raise ValueError(
                f"Packing: x {self.x.shape}, radius {self.radius.shape}, material "
                f"{self.material.shape} must be (N, 3), (N,), (N,)"
            )
        self.materials = tuple(self.materials)

    def __len__(self) -> int:
        return len(self.radius)

    @property
    def content_hash(self) -> str:
        """SHA-256 over the arrays, materials, spec and seed (hex)."""
        h = hashlib.sha256()
        for a in (self.x, self.radius, self.material):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(
            _sha256_json(
                {
                    "materials": _to_jsonable(list(self.materials)),
                    "spec": _to_jsonable(self.spec),
                    "seed": int(self.seed),
                }
            ).encode()
        )
        return h.hexdigest()

    def particles(self, rotation_blocked: bool = True):
        """``soil.Particles`` of this packing (at rest)."""
        import soil

        return soil.Particles(
            x=self.x.copy(),
            radius=self.radius.copy(),
            material=self.material.copy(),
            rotation_blocked=rotation_blocked,
        )

    def measure_porosity(self, region: Region) -> float:
        """Porosity of a control box or cylinder [-] (exact cut-sphere volumes)."""
        return porosity(self.x, self.radius, region)

    def save(self, path: str | os.PathLike, engine: str | None = None) -> Path:
        """Write to HDF5 (datasets ``x``, ``radius``, ``material`` with ``unit``; JSON attributes
        ``materials``, ``spec``, ``info``, ``porosity_region``; ``seed``, ``porosity``,
        ``content_hash``, ``spec_hash``, ``format_version``; ``engine`` when given: the
        :func:`code_fingerprint` of the engine that deposited the bed, which :func:`cached`
        checks).  Written to a temporary file and renamed, so a crash never leaves a half file
        under the final name."""
        import h5py

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + f".tmp{os.getpid()}")
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = "crashdem.packing"
            f.attrs["format_version"] = FORMAT_VERSION
            for name, arr, unit in (
                ("x", self.x, "m"),
                ("radius", self.radius, "m"),
                ("material", self.material, "1"),
            ):
                ds = f.create_dataset(name, data=arr)
                ds.attrs["unit"] = unit
            f.attrs["materials"] = json.dumps(_to_jsonable(list(self.materials)))
            f.attrs["spec"] = json.dumps(_to_jsonable(self.spec), sort_keys=True)
            spec_hash = self.spec.get("__hash__", "") if isinstance(self.spec, dict) else ""
            f.attrs["spec_hash"] = spec_hash
            f.attrs["info"] = json.dumps(_to_jsonable(self.info), sort_keys=True)
            f.attrs["porosity_region"] = json.dumps(_to_jsonable(self.porosity_region))
            f.attrs["seed"] = int(self.seed)
            f.attrs["porosity"] = float(self.porosity)
            f.attrs["content_hash"] = self.content_hash
            if engine is not None:
                f.attrs["engine"] = str(engine)
        os.replace(tmp, path)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, verify: bool = True) -> Packing:
        """Read a packing written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            A dataset or attribute is missing or malformed (the message names file and field),
            or ``verify`` and the stored content hash does not match the data (corruption).
        """
        import h5py

        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"packing file {path} does not exist")
        try:
            f = h5py.File(path, "r")
        except OSError as exc:
            raise ValueError(f"packing file {path}: not a readable HDF5 file ({exc})") from exc
        with f:

            def ds(name, ndim):
                if name not in f:
                    raise ValueError(f"packing file {path}: missing dataset '{name}'")
                a = f[name][()]
                if a.ndim != ndim:
                    raise ValueError(
                        f"packing file {path}: dataset '{name}' has {a.ndim} dimensions, "
                        f"expected {ndim}"
                    )
                return a

            def attr(name):
                if name not in f.attrs:
                    raise ValueError(f"packing file {path}: missing attribute '{name}'")
                v = f.attrs[name]
                return v.decode() if isinstance(v, bytes) else v

            def jattr(name):
                text = attr(name)
                try:
                    return json.loads(text)
                except (TypeError, json.JSONDecodeError) as exc:
                    raise ValueError(
                        f"packing file {path}: attribute '{name}' is not valid JSON ({exc})"
                    ) from exc

            if attr("format") != "crashdem.packing":
                raise ValueError(f"packing file {path}: attribute 'format' is not crashdem.packing")
            version = int(attr("format_version"))
            if version != FORMAT_VERSION:
                raise ValueError(
                    f"packing file {path}: format_version={version}, this code reads "
                    f"{FORMAT_VERSION}"
                )
            x = ds("x", 2)
            r = ds("radius", 1)
            m = ds("material", 1)
            materials = tuple(_material_from_json(d, path) for d in jattr("materials"))
            spec = jattr("spec")
            info = jattr("info")
            region = _region_from_json(jattr("porosity_region"), path)
            seed = int(attr("seed"))
            por = float(attr("porosity"))
            stored = str(attr("content_hash"))
        try:
            pk = cls(x, r, m, materials, spec, seed, por, region, info)
        except ValueError as exc:
            raise ValueError(f"packing file {path}: {exc}") from exc
        if verify and pk.content_hash != stored:
            raise ValueError(
                f"packing file {path}: field 'content_hash' {stored[:16]}... does not match the "
                f"data ({pk.content_hash[:16]}...): the file is corrupted or was edited"
            )
        return pk


def _material_from_json(d: dict, path) -> Any:
    from soil import params

    if not isinstance(d, dict) or d.get("__type__") is None:
        raise ValueError(f"packing file {path}: attribute 'materials' has a malformed entry {d!r}")
    if getattr(params, d["__type__"], None) is None:
        raise ValueError(f"packing file {path}: unknown material type {d['__type__']!r}")
    try:
        return _from_jsonable(d, params)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"packing file {path}: attribute 'materials': {exc}") from exc


def _from_jsonable(d, namespace):
    if isinstance(d, dict) and "__type__" in d:
        cls = getattr(namespace, d["__type__"], None) or globals().get(d["__type__"])
        if cls is None:
            raise ValueError(f"unknown type {d['__type__']!r}")
        kwargs = {}
        names = {f.name for f in dataclasses.fields(cls)}
        for k, v in d.items():
            if k == "__type__" or k not in names:
                continue
            kwargs[k] = _from_jsonable(v, namespace)
        return cls(**kwargs)
    if isinstance(d, list):
        return tuple(_from_jsonable(v, namespace) for v in d)
    return d


def _region_from_json(d, path) -> Region | None:
    if d is None:
        return None
    try:
        if d["__type__"] == "BoxRegion":
            return BoxRegion(tuple(d["lo"]), tuple(d["hi"]))
        if d["__type__"] == "CylinderRegion":
            return CylinderRegion(tuple(d["center"]), d["radius"], d["z_min"], d["z_max"])
    except (KeyError, TypeError) as exc:
        raise ValueError(
            f"packing file {path}: attribute 'porosity_region' malformed ({exc})"
        ) from exc
    raise ValueError(f"packing file {path}: attribute 'porosity_region' has unknown type")


def save_packing(packing: Packing, path) -> Path:
    """Write ``packing`` to HDF5 (see :meth:`Packing.save`)."""
    return packing.save(path)


def load_packing(path, verify: bool = True) -> Packing:
    """Read a packing from HDF5 (see :meth:`Packing.load`)."""
    return Packing.load(path, verify)


def code_fingerprint() -> str:
    """16 hex digits that change whenever a bed deposited from the same spec could differ: the
    bytes of every module of the ``soil`` package (the deposition and the contact kernels it
    runs), ``FORMAT_VERSION`` and the numpy and numba versions (the compiled kernels' floating
    point). A cache shared across installs or versions (``crashdem diagnose --packing-cache``)
    keeps its beds under this name, so that a changed engine never reuses another engine's
    beds; ``spec.hash()`` alone does not see code changes."""
    h = hashlib.sha256()
    h.update(json.dumps({"format": FORMAT_VERSION, "numpy": np.__version__,
                         "numba": numba.__version__}, sort_keys=True).encode())
    for f in sorted(Path(__file__).resolve().parent.glob("*.py")):
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@contextlib.contextmanager
def _build_lock(path: Path):
    """An exclusive ``flock`` on ``<path>.lock`` while the packing ``path`` is built, so that
    processes (or threads) sharing a cache deposit each bed once: the others wait and then
    load it. The lock file stays (removing it would race with a waiter). No lock without
    ``fcntl`` (Windows): concurrent builders then deposit the same bed each, and the atomic
    rename of :meth:`Packing.save` keeps the file whole."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on Linux/macOS
        yield
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path.with_suffix(".lock"), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def stored_engine(path: str | os.PathLike) -> str | None:
    """The ``engine`` attribute of a packing file (the :func:`code_fingerprint` of the engine
    that deposited it, written by :func:`cached`), None when the file has none or cannot be
    read."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            v = f.attrs.get("engine")
    except OSError:
        return None
    if v is None:
        return None
    return v.decode() if isinstance(v, bytes) else str(v)


def _load_cached(path: Path, h: str, engine: str) -> Packing | None:
    if not path.exists():
        return None
    try:
        stored = stored_engine(path)
        if stored != engine:
            # a bed deposited by another engine (or before beds recorded theirs) is another
            # realisation of the same spec: reusing it would make this run differ from the same
            # run on a fresh machine
            warnings.warn(f"cached: {path} was deposited by "
                          f"{'soil engine ' + stored if stored else 'an unrecorded soil engine'}"
                          f", this is {engine}; rebuilding", RuntimeWarning, 3)
            return None
        pk = Packing.load(path)
        if pk.spec.get("__hash__") == h:
            return pk
        warnings.warn(f"cached: {path} has another spec hash, rebuilding", RuntimeWarning, 3)
    except FileNotFoundError:  # removed (pruned) between the test and the read
        return None
    except ValueError as exc:
        warnings.warn(f"cached: {exc}; rebuilding", RuntimeWarning, stacklevel=3)
    return None


def cached(
    spec: PackingSpec, directory: str | os.PathLike, rebuild: bool = False, progress=None
) -> Packing:
    """Return the packing of ``spec``, building and saving it only when not already cached.

    The file is ``<directory>/packing-<spec hash[:20]>.h5``; a file is reused only when it was
    deposited by this soil engine (its ``engine`` attribute equals :func:`code_fingerprint`:
    the same spec deposited by another version of the engine, or by this one on NumPy's SIMD
    paths before ``soil.portable``, is another realisation), its stored spec hash equals
    ``spec.hash()`` and its content hash verifies; otherwise it is rebuilt with a warning. A
    load refreshes the file's modification time, the last use ``crashdem cache prune`` goes
    by. A build holds
    ``packing-<hash>.lock`` (``_build_lock``), so concurrent callers sharing ``directory``
    deposit the bed once.

    Parameters
    ----------
    spec : PackingSpec
    directory : path
        Cache directory (created if needed; keep it out of git).
    rebuild : bool
        Ignore an existing file.
    progress : callable or None
        Passed to :func:`build`.
    """
    h = spec.hash()
    engine = code_fingerprint()
    path = Path(directory).expanduser() / f"packing-{h[:20]}.h5"
    if not rebuild and (pk := _load_cached(path, h, engine)) is not None:
        _touch(path)
        return pk
    with _build_lock(path):
        # another process may have built it while this one waited for the lock
        if not rebuild and (pk := _load_cached(path, h, engine)) is not None:
            _touch(path)
            return pk
        pk = build(spec, progress=progress)
        pk.save(path, engine=engine)
    return pk


def _touch(path: Path) -> None:
    """Mark a cached bed as used now (its modification time), for ``crashdem cache prune``."""
    try:
        os.utime(path)
    except OSError:  # read-only cache or removed meanwhile: the bed was still served
        pass


# ---------------------------------------------------------------------------------------------
# Building a packing from a spec
# ---------------------------------------------------------------------------------------------


def _deposition_materials(spec: PackingSpec, frictions: list[float | None]):
    """One deposition material per layer: the layer's material with its deposition friction."""
    out = []
    for layer, phi in zip(spec.layers, frictions):
        base = spec.materials[layer.material]
        if phi is not None:
            base = dataclasses.replace(base, friction_angle=float(phi))
        out.append(base)
    return out


def _interior_region(spec: PackingSpec, z0: float, z1: float, r_max: float) -> Region:
    """Control volume of a layer: the container footprint inset by 2 r_max, heights z0..z1."""
    c = spec.container.shrunk(2.0 * r_max)
    return c.with_z(z0, z1)


def _up_and_planes(spec: PackingSpec):
    """Up direction, container planes (point, inward normal), base height along up."""
    c = spec.container
    lo, hi = np.asarray(c.lo), np.asarray(c.hi)
    normal_mode = spec.slope is not None and spec.slope.compaction == "normal"
    if normal_mode:
        up = spec.slope.normal()
        planes = [
            (lo, np.array([0.0, 0.0, 1.0])),
            (hi, np.array([-1.0, 0.0, 0.0])),
            (lo, np.array([0.0, 1.0, 0.0])),
            (hi, np.array([0.0, -1.0, 0.0])),
        ]
        base = float(np.array([hi[0], 0.0, lo[2]]) @ up)  # the deep corner
    else:
        up = np.array([0.0, 0.0, 1.0])
        planes = []
        base = float(lo[2])
    return up, planes, base


def _layer_tops(spec: PackingSpec, base: float) -> list[float]:
    c = spec.container
    if spec.slope is not None and spec.slope.compaction == "normal":
        # layers parallel to the slope; the last top is the free surface through (x_lo, z_lo)
        up = spec.slope.normal()
        top = float(np.array([c.lo[0], 0.0, c.lo[2]]) @ up)
        total = top - base
        scale = total / sum(layer.thickness for layer in spec.layers)
    else:
        scale = 1.0
    tops, h = [], base
    for layer in spec.layers:
        h += layer.thickness * scale
        tops.append(h)
    return tops


def _layer_cloud(spec, r_new, seed, up, planes, h_surf, normal_mode):
    """Cloud of the given radii just above the current surface (along ``up``), inside the
    container planes, lowest particles first."""
    c = spec.container
    r_max = spec.radius.r_max
    h_min = h_surf + 0.5 * r_max
    solids = float(np.sum(sphere_volume(r_new)))
    grow = 1.0
    for _ in range(12):
        if normal_mode:
            lx = grow * 2.0 * (c.hi[0] - c.lo[0])
            lz = grow * 2.0 * (c.hi[2] - c.lo[2])
            region = BoxRegion((c.hi[0] - lx, c.lo[1], c.lo[2]), (c.hi[0], c.hi[1], c.lo[2] + lz))
        else:
            height = grow * (solids / (spec.cloud_solid_fraction * c.area) + 4.0 * r_max)
            region = c.with_z(h_surf, h_surf + height)
        try:
            if spec.cloud == "lattice":
                return lattice_cloud(region, r_new, seed=seed, up=tuple(up), planes=planes,
                                     h_min=h_min)
            if not normal_mode:
                return rsa_cloud(region, r_new, seed=seed)
            # tilted trough: RSA in a box, keep what lies inside the trough above the surface
            n_box = int(len(r_new) * region.volume / max(_trough_volume(spec, region, h_min), 1e-9))
            n_box = max(n_box, len(r_new))
            vol_box = n_box * float(np.mean(sphere_volume(r_new)))
            if vol_box / region.volume > spec.cloud_solid_fraction:
                raise ValueError("region too small")
            rng = np.random.default_rng(seed)
            r_all = np.concatenate([r_new, rng.choice(r_new, n_box - len(r_new))])
            xb, rb = rsa_cloud(region, r_all, seed=seed)
            ok = (xb @ up - rb) >= h_min
            for p, nrm in planes:
                nrm = np.asarray(nrm, float)
                ok &= (xb - np.asarray(p, float)) @ nrm >= rb
            idx = np.flatnonzero(ok)
            if len(idx) < len(r_new):
                raise ValueError("region too small")
            idx = idx[np.argsort(xb[idx] @ up, kind="stable")[: len(r_new)]]
            return xb[idx], rb[idx]
        except ValueError:
            grow *= 1.4
    raise ValueError(
        f"build: could not place a cloud of {len(r_new)} particles above h={h_surf:.3f} m"
    )


def _in_footprint(region: Region, x: np.ndarray) -> np.ndarray:
    """Whether each centre lies in the horizontal footprint of a box or an upright cylinder."""
    if isinstance(region, CylinderRegion):
        cx, cy = region.center
        return np.hypot(x[:, 0] - cx, x[:, 1] - cy) < region.radius
    lo, hi = region.lo, region.hi
    return (x[:, 0] > lo[0]) & (x[:, 0] < hi[0]) & (x[:, 1] > lo[1]) & (x[:, 1] < hi[1])


def _trough_volume(spec, region, h_min) -> float:
    """Volume of ``region`` inside the slope trough above height ``h_min`` (Monte Carlo, 4096
    deterministic points: only used to size a cloud)."""
    up, planes, _ = _up_and_planes(spec)
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(region.lo), np.asarray(region.hi)
    pts = lo + rng.random((4096, 3)) * (hi - lo)
    ok = pts @ up >= h_min
    for p, nrm in planes:
        ok &= (pts - np.asarray(p, float)) @ np.asarray(nrm, float) >= 0.0
    return region.volume * float(ok.mean())


def build(spec: PackingSpec, progress=None) -> Packing:
    """Deposit the layers of ``spec`` one after the other and carve flat tops (and the slope).

    For each layer, bottom to top: a lattice cloud with about 12 % more particles than the layer
    needs at porosity 0.36 between the carved top of the layer below and its own top is placed
    just above the current surface, the whole bed is deposited (:func:`deposit`) with the
    layer's deposition friction, and the particles whose centre lies above the layer top are
    removed; if the layer came out short, more particles are added.  The result is a sharp
    interface at each layer top, and each layer as thick as specified to a fraction of a grain
    radius (:func:`free_surface_height`), down to a layer one grain diameter thick.  With a slope, the particles above the
    inclined plane are then removed (``compaction="horizontal"``), or the whole procedure runs
    with gravity along the inward slope normal in a trough formed by the floor and the back
    wall (``compaction="normal"``).

    Parameters
    ----------
    spec : PackingSpec
    progress : callable or None
        Called with a short text after each deposition.

    Returns
    -------
    Packing
        With ``info["layers"]`` holding each layer's deposition friction, porosity and
        deposition statistics.
    """
    settings = spec.deposition
    dist = spec.radius
    r_max = dist.r_max
    up, planes, base = _up_and_planes(spec)
    normal_mode = spec.slope is not None and spec.slope.compaction == "normal"
    gravity = tuple(-spec.gravity * up)
    tops = _layer_tops(spec, base)
    c = spec.container
    seeds = np.random.SeedSequence(int(spec.seed)).spawn(len(spec.layers) * 8)

    frictions: list[float | None] = []
    for k, layer in enumerate(spec.layers):
        if layer.target_porosity is not None:
            phi, _ = friction_for_porosity(
                spec.materials[layer.material], dist, layer.target_porosity, settings,
                seed=int(seeds[k * 8 + 7].generate_state(1)[0]), gravity=spec.gravity,
            )
            frictions.append(phi)
        else:
            frictions.append(layer.deposition_friction)
    dep_materials = _deposition_materials(spec, frictions)

    x = np.empty((0, 3))
    r = np.empty(0)
    layer_id = np.empty(0, dtype=np.int32)
    info_layers = []
    total_steps = 0
    last = None
    width_y = c.hi[1] - c.lo[1]
    for k, layer in enumerate(spec.layers):
        h_top = tops[k]
        carved = tops[k - 1] if k else base  # the carved top of the layer below
        attempt = 0
        while True:
            h_surf = float(np.max((x @ up) + r)) if len(r) else carved
            # the level the new grains fill up from: the carved top below (its mean surface)
            # on the first attempt, not its highest grain, which stands up to a grain above it
            # (filling from there left thin layers a grain short)
            h_fill = carved if attempt == 0 else h_surf
            if normal_mode:
                # right-angle trough (floor + back wall): the section below height h (along up,
                # from the corner) is a right triangle of area h^2 / sin(2 alpha)
                a0, a1 = h_fill - base, h_top - base
                vol = max(a1 * a1 - a0 * a0, 0.0) * width_y / math.sin(2.0 * spec.slope.angle)
            else:
                vol = c.area * max(h_top - h_fill, 0.0)
            n_new = int(math.ceil(_OVERFILL * vol * (1 - _FILL_POROSITY) / dist.mean_volume))
            n_new = max(n_new, 1)
            seed_k = int(seeds[k * 8 + attempt].generate_state(1)[0])
            rng = np.random.default_rng(seed_k)
            r_new = dist.sample(n_new, rng)
            x_new, r_new = _layer_cloud(spec, r_new, seed_k, up, planes, h_surf, normal_mode)
            x = np.vstack([x, x_new])
            r = np.concatenate([r, r_new])
            layer_id = np.concatenate([layer_id, np.full(n_new, k, dtype=np.int32)])
            res = deposit(
                x, r, layer_id, dep_materials, c, settings, gravity, open_front=normal_mode,
                progress=progress,
            )
            total_steps += res.steps
            last = res
            x = res.x
            h = x @ up
            if progress:
                progress(
                    f"layer {k}: {len(r)} particles, {res.steps} steps, unbalanced "
                    f"{res.unbalanced:.3g}, surface {float(np.max(h + r)):.3f}"
                )
            if float(np.max(h)) >= h_top or attempt >= 6:
                break
            attempt += 1
        keep = h <= h_top
        x, r, layer_id = x[keep], r[keep], layer_id[keep]
        info_layers.append(
            {
                "index": k,
                "material": layer.material,
                "deposition_friction": (
                    frictions[k] if frictions[k] is not None
                    else spec.materials[layer.material].friction_angle
                ),
                "top": h_top,
                "steps": res.steps,
                "unbalanced": res.unbalanced,
                "kinetic_energy": res.kinetic_energy,
                "floor_force": res.floor_force,
                "wall_force": res.wall_force,
                "weight": res.weight,
            }
        )
    # final settle after the last carve (short: the bed is already at rest)
    res = deposit(x, r, layer_id, dep_materials, c, settings, gravity, open_front=normal_mode,
                  progress=progress)
    total_steps += res.steps
    x = res.x
    if spec.slope is not None:
        n_out = spec.slope.normal()
        p0 = np.array([c.lo[0], 0.0, c.lo[2]])
        keep = (x - p0) @ n_out <= 0.0
        keep &= (x[:, 0] >= c.lo[0] + 0.0) & (x[:, 2] <= c.hi[2])
        x, r, layer_id = x[keep], r[keep], layer_id[keep]
    material = np.array([spec.layers[k].material for k in layer_id], dtype=np.int32)

    # porosity of each layer (interior control volume, one r_max away from the layer tops) and
    # the level its top is realised at (its grains and those below it, away from the walls;
    # free_surface_height), next to the requested "top"
    if not normal_mode:
        bottoms = [base] + tops[:-1]
        foot = spec.container.shrunk(2.0 * r_max)
        inside = _in_footprint(foot, x)
        for k, info in enumerate(info_layers):
            if spec.slope is not None:
                info["porosity"] = info["realised_top"] = float("nan")
                continue
            z0 = bottoms[k] + (2.0 * r_max if k == 0 else r_max)
            z1 = tops[k] - r_max
            info["porosity"] = (
                porosity(x, r, _interior_region(spec, z0, z1, r_max)) if z1 > z0 else float("nan")
            )
            sel = inside & (layer_id <= k)
            info["realised_top"] = (
                free_surface_height(x[sel, 2], r[sel], foot.area) if sel.sum() >= 10
                else float("nan")
            )
        region = _interior_region(spec, base + 2.0 * r_max, tops[-1] - r_max, r_max)
        por = porosity(x, r, region) if spec.slope is None else float("nan")
    else:
        region = None
        por = float("nan")
    spec_dict = spec.to_dict()
    spec_dict["__hash__"] = spec.hash()
    info = {
        "layers": info_layers,
        "steps": total_steps,
        "dt": res.dt,
        "unbalanced": res.unbalanced,
        "unbalanced_final": res.unbalanced_final,
        "kinetic_energy": res.kinetic_energy,
        "kinetic_energy_limit": res.kinetic_energy_limit,
        "floor_force": res.floor_force,
        "wall_force": res.wall_force,
        "weight": res.weight,
        "surface": float(np.max(x[:, 2] + r)) if len(r) else float("nan"),
    }
    del last
    return Packing(x, r, material, spec.materials, spec_dict, int(spec.seed), por,
                   region if spec.slope is None else None, info)


# ---------------------------------------------------------------------------------------------
# Reaching a target porosity
# ---------------------------------------------------------------------------------------------


def _trial_porosity(material, dist, phi, settings, seed, gravity, n_side, height_d):
    """Deposit a trial column with friction ``phi`` and return its interior porosity."""
    d = 2.0 * dist.mean
    side = n_side * d
    height = height_d * d
    mat = dataclasses.replace(material, friction_angle=float(phi))
    n = int(math.ceil(side * side * height * (1 - _FILL_POROSITY) / dist.mean_volume))
    cloud_height = n * dist.mean_volume / (0.22 * side * side) + 4.0 * dist.r_max
    container = BoxRegion((0.0, 0.0, 0.0), (side, side, cloud_height))
    x, r = rsa_cloud(container, dist, n, seed=seed)
    res = deposit(x, r, np.zeros(n, np.int32), [mat], container, settings, (0, 0, -gravity))
    top = float(np.quantile(res.x[:, 2], 0.95))
    region = BoxRegion(
        (2 * dist.r_max, 2 * dist.r_max, 2 * dist.r_max),
        (side - 2 * dist.r_max, side - 2 * dist.r_max, top - 2 * dist.r_max),
    )
    return porosity(res.x, res.radius, region)


def friction_for_porosity(
    material,
    radius: RadiusDistribution,
    target: float,
    settings: DepositionSettings = DepositionSettings(),
    seed: int = 0,
    gravity: float = 9.81,
    n_side: int = 10,
    height_d: int = 10,
    tolerance: float = 0.005,
    max_iter: int = 6,
) -> tuple[float, dict]:
    """Deposition friction angle that gives a requested porosity (bracketing + secant).

    Deposits a trial column (``n_side`` x ``n_side`` x ``height_d`` mean diameters, walls at
    the material's friction) at friction 0 and at the material's friction; if the target lies
    between, refines with regula falsi on (friction, porosity) until within ``tolerance``.
    Lower friction gives a denser packing.

    Returns
    -------
    phi : float
        Friction angle [rad].
    report : dict
        ``{"target", "achieved", "history": [(phi, porosity), ...]}``; if the target is outside
        the reachable range, the nearest end is returned and ``achieved`` says how far it is.

    Notes
    -----
    Friction-controlled deposition density: e.g. Salot, Gotteland & Villard (2009), Yade
    ``examples/triax-tutorial`` ("compactionFrictionDeg").
    """
    phi_hi = float(material.friction_angle)
    hist = []

    def f(phi):
        p = _trial_porosity(material, radius, phi, settings, seed, gravity, n_side, height_d)
        hist.append((float(phi), float(p)))
        return p

    a, pa = 0.0, f(0.0)
    b, pb = phi_hi, f(phi_hi)
    best = min(hist, key=lambda t: abs(t[1] - target))
    if not (min(pa, pb) <= target <= max(pa, pb)):
        return best[0], {"target": target, "achieved": best[1], "history": hist}
    for _ in range(max_iter):
        if abs(best[1] - target) <= tolerance:
            break
        phi = a + (target - pa) * (b - a) / (pb - pa) if pb != pa else 0.5 * (a + b)
        phi = min(max(phi, a + 0.1 * (b - a)), b - 0.1 * (b - a))
        p = f(phi)
        if (p - target) * (pa - target) > 0:
            a, pa = phi, p
        else:
            b, pb = phi, p
        best = min(hist, key=lambda t: abs(t[1] - target))
    return best[0], {"target": target, "achieved": best[1], "history": hist}
