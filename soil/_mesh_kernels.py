"""Numba kernels for sphere--triangle-mesh contact detection (soil DEM boundaries).

Arrays and scalars only; the validating wrapper is :class:`soil.mesh.MeshCollider`.

Stable engine-facing signature (contract ARCHITECTURE.md section 1.1)
---------------------------------------------------------------------
::

    n_found = mesh_contacts(
        x,            # (N, 3) float64  particle centres, WORLD frame [m]
        radius,       # (N,)   float64  particle radii [m]
        rotation,     # (3, 3) float64  R of the mesh frame: x_world = R @ x_mesh + translation
        translation,  # (3,)   float64  origin of the mesh frame in the world [m]
        tri_v0,       # (T, 3) float64  triangle corners in the MESH frame [m] (body frame, or
        tri_v1,       # (T, 3) float64    world frame with rotation=I, translation=0); shared
        tri_v2,       # (T, 3) float64    corners must be bit-identical (gather them from one
                      #                   vertex array, e.g. TriangleMesh.vertices[triangles[:, k]])
        grid_lo,      # (3,)   float64  grid origin, mesh frame [m]       } from
        cell_size,    # float           grid cell edge [m]                 } build_triangle_grid
        grid_shape,   # (3,)   int64    cells per axis                     } (or MeshCollider,
        cell_start,   # (C+1,) int64    CSR offsets, C = prod(grid_shape)  }  which keeps them)
        cell_tris,    # (E,)   int32    triangle indices per cell          }
        out_particle, # (M,)   int32    particle index of each contact
        out_triangle, # (M,)   int32    triangle index
        out_feature,  # (M,)   int8     FEATURE_FACE, FEATURE_EDGE0..2 or FEATURE_VERTEX0..2
        out_normal,   # (M, 3) float64  unit normal, WORLD frame, mesh -> particle centre
        out_overlap,  # (M,)   float64  r - distance > 0 [m]
        out_point,    # (M, 3) float64  closest point on the triangle, WORLD frame [m]
    )

* Returns the exact number of contacts. If it exceeds ``len(out_particle)`` NOTHING is written:
  grow the output arrays to at least ``n_found`` and call again (``MeshCollider.contacts`` does
  this). Contacts are never silently dropped.
* Output is sorted by particle index, then triangle index, and is bit-identical for any thread
  count (each particle is processed independently; a count pass, a prefix sum and a fill pass).
* A rigid mesh keeps its grid in the body frame: build it once, pass the body pose each step.
  The grid only sets which triangles are tested; any particle radius gives the exact contact set.

Contact definition and de-duplication (per particle and mesh)
-------------------------------------------------------------
For every triangle the closest point ``q`` to the centre ``c`` is found (Ericson 2005, section
5.1.5) with its feature (face interior, edge k = corners (k, k+1 mod 3), vertex k). The triangle
touches the sphere if ``d = |c - q| < r``; ``overlap = r - d``; ``normal = (c - q) / d`` (for a
face contact: the face normal signed towards ``c``; if ``d == 0`` on an edge or vertex: the face
normal). Of all touching triangles of one particle, a contact is dropped when

1. another contact has the same closest point (within ``tol = 1e-9 r``) and a better rank
   (face < edge < vertex, then lower triangle index): one physical point is one contact, e.g. a
   sphere centred exactly above a shared edge or vertex of a flat patch; or
2. it is an edge (vertex) contact, another touching triangle contains that edge (vertex) --
   shared corners are recognised by bit-identical coordinates -- and is not farther
   (``d_b <= d_a + tol``): the distance does not increase across the feature, so the point is
   not a strict local minimum of the distance to the surface and the neighbour explains it.
   When two contacts explain each other (the same edge or vertex seen from both of its
   triangles) the better-ranked one is kept.

The tolerance only absorbs round-off in the distances: a real difference below ``tol`` changes
the overlap by less than ``tol``. If the rules leave no contact (a cycle of explanations inside
the tolerance, not observed in the tests) the closest one is kept.

Both rules compare a contact only with touching triangles sharing one of its corners (by
coordinates), so the mesh must be conforming: a T-junction (a vertex lying inside another
triangle's edge) or duplicated, overlapping surfaces can give two contacts near the junction.
Weld STL soups (``TriangleMesh.read`` does). Cost: O(candidates + m log m) per particle, m the
number of touching triangles.

A sphere on a flat or convex region therefore gets exactly one contact (continuous across edges
and vertices: same overlap and normal as the analytic plane); a concave crease gives one face
contact per face; a sphere touching a free (boundary) edge keeps its edge contact.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import prange

FEATURE_FACE = 0
FEATURE_EDGE0 = 1  # corners (0, 1)
FEATURE_EDGE1 = 2  # corners (1, 2)
FEATURE_EDGE2 = 3  # corners (2, 0)
FEATURE_VERTEX0 = 4
FEATURE_VERTEX1 = 5
FEATURE_VERTEX2 = 6

#: relative tolerance (times the particle radius) under which two closest points coincide
COINCIDENT_REL_TOL = 1e-9

#: particles processed per parallel work item (fixed, so the work split never depends on threads)
_CHUNK = 256


@numba.njit(cache=True)
def closest_point_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Closest point on triangle ABC to point P, with the feature that contains it.

    Parameters
    ----------
    px, py, pz : float
        Query point [m].
    ax, ..., cz : float
        Triangle corners A, B, C [m] (non-degenerate).

    Returns
    -------
    qx, qy, qz : float
        Closest point [m].
    feature : int
        ``FEATURE_FACE`` (0), ``FEATURE_EDGE0..2`` (1..3, edge k joins corners k and k+1 mod 3)
        or ``FEATURE_VERTEX0..2`` (4..6).

    Notes
    -----
    Voronoi-region walk of Ericson, *Real-Time Collision Detection* (2005), section 5.1.5,
    ``ClosestPtPointTriangle``; points on a region boundary go to the lower-dimensional feature.
    """
    abx = bx - ax
    aby = by - ay
    abz = bz - az
    acx = cx - ax
    acy = cy - ay
    acz = cz - az
    apx = px - ax
    apy = py - ay
    apz = pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, 4
    bpx = px - bx
    bpy = py - by
    bpz = pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, 5
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, 1
    cpx = px - cx
    cpy = py - cy
    cpz = pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, 6
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, 3
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz), 2
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (
        ax + abx * v + acx * w,
        ay + aby * v + acy * w,
        az + abz * v + acz * w,
        0,
    )


@numba.njit(cache=True)
def closest_points(points, tri_v0, tri_v1, tri_v2):
    """Closest point on triangle k to point k, element-wise (array version for tests/tools).

    Parameters
    ----------
    points, tri_v0, tri_v1, tri_v2 : (K, 3) float64
        Query points and triangle corners [m].

    Returns
    -------
    q : (K, 3) float64
        Closest points [m].
    feature : (K,) int8
        Feature codes as in :func:`closest_point_triangle`.

    Notes
    -----
    Ericson (2005), section 5.1.5.
    """
    k = points.shape[0]
    q = np.empty((k, 3))
    feature = np.empty(k, np.int8)
    for i in range(k):
        qx, qy, qz, f = closest_point_triangle(
            points[i, 0], points[i, 1], points[i, 2],
            tri_v0[i, 0], tri_v0[i, 1], tri_v0[i, 2],
            tri_v1[i, 0], tri_v1[i, 1], tri_v1[i, 2],
            tri_v2[i, 0], tri_v2[i, 1], tri_v2[i, 2],
        )
        q[i, 0] = qx
        q[i, 1] = qy
        q[i, 2] = qz
        feature[i] = f
    return q, feature


# ----------------------------------------------------------------------------------------------
# broad phase: uniform grid over the triangles (CSR), built in the mesh frame
# ----------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _cell_range(lo, hi, grid_lo, cell_size, grid_shape, out):
    """Clipped integer cell range [out[0:3], out[3:6]] covering the box [lo, hi]; False if empty."""
    for a in range(3):
        i0 = int(np.floor((lo[a] - grid_lo[a]) / cell_size))
        i1 = int(np.floor((hi[a] - grid_lo[a]) / cell_size))
        if i1 < 0 or i0 >= grid_shape[a]:
            return False
        out[a] = max(i0, 0)
        out[3 + a] = min(i1, grid_shape[a] - 1)
    return True


@numba.njit(cache=True)
def _sphere_cell_range(cx, cy, cz, r, grid_lo, cell_size, grid_shape, out):
    """Clipped cell range of the sphere's AABB (no allocation); False if outside the grid."""
    for a in range(3):
        c = cx if a == 0 else (cy if a == 1 else cz)
        i0 = int(np.floor((c - r - grid_lo[a]) / cell_size))
        i1 = int(np.floor((c + r - grid_lo[a]) / cell_size))
        if i1 < 0 or i0 >= grid_shape[a]:
            return False
        out[a] = max(i0, 0)
        out[3 + a] = min(i1, grid_shape[a] - 1)
    return True


@numba.njit(cache=True)
def _triangle_cells(t, tri_v0, tri_v1, tri_v2, grid_lo, cell_size, grid_shape, cells_out, fill):
    """Count (fill=False) or list the cells whose box meets the plane slab of triangle t."""
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = min(tri_v0[t, a], tri_v1[t, a], tri_v2[t, a])
        hi[a] = max(tri_v0[t, a], tri_v1[t, a], tri_v2[t, a])
    rng = np.empty(6, np.int64)
    _cell_range(lo, hi, grid_lo, cell_size, grid_shape, rng)
    # face normal (unnormalised): a cell box meets the triangle's plane iff the centre-to-plane
    # distance is below the box's support |n_x| h + |n_y| h + |n_z| h (Akenine-Moller 2001).
    e1x = tri_v1[t, 0] - tri_v0[t, 0]
    e1y = tri_v1[t, 1] - tri_v0[t, 1]
    e1z = tri_v1[t, 2] - tri_v0[t, 2]
    e2x = tri_v2[t, 0] - tri_v0[t, 0]
    e2y = tri_v2[t, 1] - tri_v0[t, 1]
    e2z = tri_v2[t, 2] - tri_v0[t, 2]
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    h = 0.5 * cell_size
    support = (abs(nx) + abs(ny) + abs(nz)) * h * (1.0 + 1e-9)
    count = 0
    for i in range(rng[0], rng[3] + 1):
        cxp = grid_lo[0] + (i + 0.5) * cell_size - tri_v0[t, 0]
        for j in range(rng[1], rng[4] + 1):
            cyp = grid_lo[1] + (j + 0.5) * cell_size - tri_v0[t, 1]
            for k in range(rng[2], rng[5] + 1):
                czp = grid_lo[2] + (k + 0.5) * cell_size - tri_v0[t, 2]
                if abs(nx * cxp + ny * cyp + nz * czp) <= support:
                    if fill:
                        cells_out[count] = (i * grid_shape[1] + j) * grid_shape[2] + k
                    count += 1
    return count


@numba.njit(cache=True)
def build_triangle_grid(tri_v0, tri_v1, tri_v2, cell_size):
    """Uniform-grid broad phase over the triangles (CSR layout).

    Parameters
    ----------
    tri_v0, tri_v1, tri_v2 : (T, 3) float64
        Triangle corners in the mesh frame [m].
    cell_size : float
        Cell edge [m]; typically the largest particle diameter.

    Returns
    -------
    grid_lo : (3,) float64
        Lower corner of the grid (the triangles' AABB) [m].
    grid_shape : (3,) int64
        Cells per axis.
    cell_start : (C + 1,) int64
        Offsets into ``cell_tris`` per linear cell ``(i * ny + j) * nz + k``.
    cell_tris : (E,) int32
        Triangle indices, ascending within each cell.

    Notes
    -----
    A triangle is entered in every cell of its AABB whose box meets the triangle's plane
    (separating-axis test on the face normal, Akenine-Moller 2001, "Fast 3D triangle-box overlap
    testing"); a superset of the cells the triangle meets, so no contact can be missed.
    """
    n_tri = tri_v0.shape[0]
    grid_lo = np.empty(3)
    grid_hi = np.empty(3)
    for a in range(3):
        grid_lo[a] = np.inf
        grid_hi[a] = -np.inf
    for t in range(n_tri):
        for a in range(3):
            grid_lo[a] = min(grid_lo[a], tri_v0[t, a], tri_v1[t, a], tri_v2[t, a])
            grid_hi[a] = max(grid_hi[a], tri_v0[t, a], tri_v1[t, a], tri_v2[t, a])
    grid_shape = np.empty(3, np.int64)
    for a in range(3):
        grid_shape[a] = max(int(np.floor((grid_hi[a] - grid_lo[a]) / cell_size)) + 1, 1)
    n_cells = grid_shape[0] * grid_shape[1] * grid_shape[2]
    counts = np.zeros(n_tri, np.int64)
    dummy = np.empty(0, np.int64)
    for t in range(n_tri):
        counts[t] = _triangle_cells(t, tri_v0, tri_v1, tri_v2, grid_lo, cell_size, grid_shape,
                                    dummy, False)
    tri_start = np.zeros(n_tri + 1, np.int64)
    for t in range(n_tri):
        tri_start[t + 1] = tri_start[t] + counts[t]
    n_entries = tri_start[n_tri]
    entry_cell = np.empty(n_entries, np.int64)
    for t in range(n_tri):
        _triangle_cells(t, tri_v0, tri_v1, tri_v2, grid_lo, cell_size, grid_shape,
                        entry_cell[tri_start[t]:tri_start[t + 1]], True)
    cell_start = np.zeros(n_cells + 1, np.int64)
    for e in range(n_entries):
        cell_start[entry_cell[e] + 1] += 1
    for c in range(n_cells):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    cell_tris = np.empty(n_entries, np.int32)
    for t in range(n_tri):  # ascending t, so each cell's list is sorted
        for e in range(tri_start[t], tri_start[t + 1]):
            c = entry_cell[e]
            cell_tris[fill[c]] = t
            fill[c] += 1
    return grid_lo, grid_shape, cell_start, cell_tris


@numba.njit(cache=True)
def grid_entry_count(tri_v0, tri_v1, tri_v2, cell_size):
    """Number of cells and of (cell, triangle) entries a grid of this cell size would need."""
    n_tri = tri_v0.shape[0]
    grid_lo = np.empty(3)
    grid_hi = np.empty(3)
    for a in range(3):
        grid_lo[a] = np.inf
        grid_hi[a] = -np.inf
    for t in range(n_tri):
        for a in range(3):
            grid_lo[a] = min(grid_lo[a], tri_v0[t, a], tri_v1[t, a], tri_v2[t, a])
            grid_hi[a] = max(grid_hi[a], tri_v0[t, a], tri_v1[t, a], tri_v2[t, a])
    grid_shape = np.empty(3, np.int64)
    n_cells = 1
    for a in range(3):
        grid_shape[a] = max(int(np.floor((grid_hi[a] - grid_lo[a]) / cell_size)) + 1, 1)
        n_cells *= grid_shape[a]
    total = 0
    dummy = np.empty(0, np.int64)
    for t in range(n_tri):
        total += _triangle_cells(t, tri_v0, tri_v1, tri_v2, grid_lo, cell_size, grid_shape,
                                 dummy, False)
    return n_cells, total


# ----------------------------------------------------------------------------------------------
# narrow phase + de-duplication for one particle
# ----------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _has_corner(t, px, py, pz, tri_v0, tri_v1, tri_v2):
    """True if triangle t has a corner bit-identical to (px, py, pz)."""
    if tri_v0[t, 0] == px and tri_v0[t, 1] == py and tri_v0[t, 2] == pz:
        return True
    if tri_v1[t, 0] == px and tri_v1[t, 1] == py and tri_v1[t, 2] == pz:
        return True
    if tri_v2[t, 0] == px and tri_v2[t, 1] == py and tri_v2[t, 2] == pz:
        return True
    return False


@numba.njit(cache=True)
def _corner(t, k, tri_v0, tri_v1, tri_v2):
    if k == 0:
        return tri_v0[t, 0], tri_v0[t, 1], tri_v0[t, 2]
    if k == 1:
        return tri_v1[t, 0], tri_v1[t, 1], tri_v1[t, 2]
    return tri_v2[t, 0], tri_v2[t, 1], tri_v2[t, 2]


@numba.njit(cache=True)
def _shares_feature(t_a, feat_a, t_b, tri_v0, tri_v1, tri_v2):
    """True if triangle t_b contains the edge/vertex feature feat_a of triangle t_a."""
    if feat_a >= FEATURE_VERTEX0:
        px, py, pz = _corner(t_a, feat_a - FEATURE_VERTEX0, tri_v0, tri_v1, tri_v2)
        return _has_corner(t_b, px, py, pz, tri_v0, tri_v1, tri_v2)
    k = feat_a - FEATURE_EDGE0
    px, py, pz = _corner(t_a, k, tri_v0, tri_v1, tri_v2)
    qx, qy, qz = _corner(t_a, (k + 1) % 3, tri_v0, tri_v1, tri_v2)
    return _has_corner(t_b, px, py, pz, tri_v0, tri_v1, tri_v2) and _has_corner(
        t_b, qx, qy, qz, tri_v0, tri_v1, tri_v2
    )


@numba.njit(cache=True)
def _rank_before(f_b, t_b, f_a, t_a):
    """True if feature b ranks before a: face < edge < vertex, then lower triangle index."""
    r_b = 0 if f_b == FEATURE_FACE else (1 if f_b < FEATURE_VERTEX0 else 2)
    r_a = 0 if f_a == FEATURE_FACE else (1 if f_a < FEATURE_VERTEX0 else 2)
    if r_b != r_a:
        return r_b < r_a
    return t_b < t_a


@numba.njit(cache=True)
def _explains(b, a, s_tri, s_feat, s_d, tol, tri_v0, tri_v1, tri_v2):
    """True if contact a is on an edge/vertex that triangle b contains and b is not farther."""
    if s_feat[a] == FEATURE_FACE or s_d[b] > s_d[a] + tol:
        return False
    return _shares_feature(s_tri[a], s_feat[a], s_tri[b], tri_v0, tri_v1, tri_v2)


@numba.njit(cache=True)
def _particle_contacts(cx, cy, cz, r, tri_v0, tri_v1, tri_v2, grid_lo, cell_size, grid_shape,
                       cell_start, cell_tris, stamp, stamp_id, rng,
                       s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key, s_owner):
    """Narrow phase and de-duplication of one particle (centre in the mesh frame).

    Writes the kept contacts, sorted by triangle, to the front of the scratch arrays and returns
    their number; returns -m (m = touching triangles) if the scratch capacity is too small.
    The de-duplication compares each contact only with the touching triangles that share one of
    its corners (found through a sorted hash of the corner coordinates): O(m log m), so a
    particle much larger than the triangles (hundreds touching) stays cheap.
    """
    if not _sphere_cell_range(cx, cy, cz, r, grid_lo, cell_size, grid_shape, rng):
        return 0
    cap = s_tri.shape[0]
    m = 0
    r2 = r * r
    for i in range(rng[0], rng[3] + 1):
        for j in range(rng[1], rng[4] + 1):
            for k in range(rng[2], rng[5] + 1):
                c = (i * grid_shape[1] + j) * grid_shape[2] + k
                for e in range(cell_start[c], cell_start[c + 1]):
                    t = cell_tris[e]
                    if stamp[t] == stamp_id:
                        continue
                    stamp[t] = stamp_id
                    qx, qy, qz, f = closest_point_triangle(
                        cx, cy, cz,
                        tri_v0[t, 0], tri_v0[t, 1], tri_v0[t, 2],
                        tri_v1[t, 0], tri_v1[t, 1], tri_v1[t, 2],
                        tri_v2[t, 0], tri_v2[t, 1], tri_v2[t, 2],
                    )
                    dx = cx - qx
                    dy = cy - qy
                    dz = cz - qz
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 >= r2:
                        continue
                    if m < cap:
                        # face normal (unit)
                        e1x = tri_v1[t, 0] - tri_v0[t, 0]
                        e1y = tri_v1[t, 1] - tri_v0[t, 1]
                        e1z = tri_v1[t, 2] - tri_v0[t, 2]
                        e2x = tri_v2[t, 0] - tri_v0[t, 0]
                        e2y = tri_v2[t, 1] - tri_v0[t, 1]
                        e2z = tri_v2[t, 2] - tri_v0[t, 2]
                        nx = e1y * e2z - e1z * e2y
                        ny = e1z * e2x - e1x * e2z
                        nz = e1x * e2y - e1y * e2x
                        nn = np.sqrt(nx * nx + ny * ny + nz * nz)
                        nx /= nn
                        ny /= nn
                        nz /= nn
                        side = ((cx - tri_v0[t, 0]) * nx + (cy - tri_v0[t, 1]) * ny
                                + (cz - tri_v0[t, 2]) * nz)
                        if side < 0.0:
                            nx = -nx
                            ny = -ny
                            nz = -nz
                        if f == FEATURE_FACE:
                            d = abs(side)
                        else:
                            d = np.sqrt(d2)
                            if d > 0.0:
                                nx = dx / d
                                ny = dy / d
                                nz = dz / d
                        s_tri[m] = t
                        s_feat[m] = f
                        s_d[m] = d
                        s_p[m, 0] = qx
                        s_p[m, 1] = qy
                        s_p[m, 2] = qz
                        s_n[m, 0] = nx
                        s_n[m, 1] = ny
                        s_n[m, 2] = nz
                    m += 1
    if m > cap:
        return -m
    # group the touching triangles' corners by identical coordinates
    nk = 3 * m
    for a in range(m):
        t = s_tri[a]
        for k in range(3):
            e = 3 * a + k
            px, py, pz = _corner(t, k, tri_v0, tri_v1, tri_v2)
            s_c[e, 0] = px + 0.0  # -0.0 -> +0.0: equal values get equal bits
            s_c[e, 1] = py + 0.0
            s_c[e, 2] = pz + 0.0
            s_owner[e] = a
    bits = s_c[:nk].view(np.int64)
    for e in range(nk):
        s_key[e] = (bits[e, 0] * 73856093) ^ (bits[e, 1] * 19349663) ^ (bits[e, 2] * 83492791)
    order = np.argsort(s_key[:nk], kind="mergesort")
    sorted_keys = s_key[:nk][order]
    tol = COINCIDENT_REL_TOL * r
    tol2 = tol * tol
    n_kept = 0
    for a in range(m):
        keep = True
        f_a = s_feat[a]
        # corner groups to visit: a neighbour that can remove a contains the first corner of
        # a's edge/vertex feature; a face contact can only lose to a coincident face contact
        # of lower index, which shares an edge with it (corner 0 or 1) in a conforming mesh
        if f_a == FEATURE_FACE:
            k_first = 0
            k_last = 1
        elif f_a >= FEATURE_VERTEX0:
            k_first = f_a - FEATURE_VERTEX0
            k_last = k_first
        else:
            k_first = f_a - FEATURE_EDGE0
            k_last = k_first
        for k in range(k_first, k_last + 1):
            e = 3 * a + k
            lo = np.searchsorted(sorted_keys, s_key[e], side="left")
            hi = np.searchsorted(sorted_keys, s_key[e], side="right")
            for g in range(lo, hi):
                f = order[g]
                b = s_owner[f]
                if b == a:
                    continue
                if f_a == FEATURE_FACE and (s_feat[b] != FEATURE_FACE or s_tri[b] > s_tri[a]):
                    continue
                if s_c[f, 0] != s_c[e, 0] or s_c[f, 1] != s_c[e, 1] or s_c[f, 2] != s_c[e, 2]:
                    continue
                # b shares corner k of a
                # rule 1: same physical point -> keep the best-ranked feature only
                ddx = s_p[a, 0] - s_p[b, 0]
                ddy = s_p[a, 1] - s_p[b, 1]
                ddz = s_p[a, 2] - s_p[b, 2]
                if ddx * ddx + ddy * ddy + ddz * ddz <= tol2 and _rank_before(
                    s_feat[b], s_tri[b], f_a, s_tri[a]
                ):
                    keep = False
                    break
                # rule 2: an edge/vertex contact explained by a neighbour containing that feature
                if _explains(b, a, s_tri, s_feat, s_d, tol, tri_v0, tri_v1, tri_v2):
                    if not _explains(a, b, s_tri, s_feat, s_d, tol, tri_v0, tri_v1, tri_v2):
                        keep = False
                        break
                    # mutual (same edge or vertex seen from both sides): one of them survives
                    if _rank_before(s_feat[b], s_tri[b], f_a, s_tri[a]):
                        keep = False
                        break
            if not keep:
                break
        s_keep[a] = keep
        if keep:
            n_kept += 1
    if n_kept == 0 and m > 0:
        # safety net (a cycle of explanations within the tolerance): keep the closest one
        best = 0
        for a in range(1, m):
            if s_d[a] < s_d[best] or (s_d[a] == s_d[best]
                                      and _rank_before(s_feat[a], s_tri[a], s_feat[best],
                                                       s_tri[best])):
                best = a
        s_keep[best] = True
    # compact and sort the kept ones by triangle index (insertion sort; m is small)
    n = 0
    for a in range(m):
        if s_keep[a]:
            if n != a:
                s_tri[n] = s_tri[a]
                s_feat[n] = s_feat[a]
                s_d[n] = s_d[a]
                for q in range(3):
                    s_p[n, q] = s_p[a, q]
                    s_n[n, q] = s_n[a, q]
            n += 1
    for a in range(1, n):
        b = a
        while b > 0 and s_tri[b - 1] > s_tri[b]:
            s_tri[b - 1], s_tri[b] = s_tri[b], s_tri[b - 1]
            s_feat[b - 1], s_feat[b] = s_feat[b], s_feat[b - 1]
            s_d[b - 1], s_d[b] = s_d[b], s_d[b - 1]
            for q in range(3):
                s_p[b - 1, q], s_p[b, q] = s_p[b, q], s_p[b - 1, q]
                s_n[b - 1, q], s_n[b, q] = s_n[b, q], s_n[b - 1, q]
            b -= 1
    return n


@numba.njit(cache=True)
def _scratch(cap):
    """Per-work-item scratch arrays of one particle's touching triangles (capacity cap)."""
    return (np.empty(cap, np.int32), np.empty(cap, np.int8), np.empty(cap), np.empty((cap, 3)),
            np.empty((cap, 3)), np.empty(cap, np.bool_), np.empty((3 * cap, 3)),
            np.empty(3 * cap, np.int64), np.empty(3 * cap, np.int32))


@numba.njit(cache=True)
def _to_mesh_frame(x, i, rotation, translation):
    """R^T (x_i - translation): particle centre in the mesh frame."""
    dx = x[i, 0] - translation[0]
    dy = x[i, 1] - translation[1]
    dz = x[i, 2] - translation[2]
    return (
        rotation[0, 0] * dx + rotation[1, 0] * dy + rotation[2, 0] * dz,
        rotation[0, 1] * dx + rotation[1, 1] * dy + rotation[2, 1] * dz,
        rotation[0, 2] * dx + rotation[1, 2] * dy + rotation[2, 2] * dz,
    )


@numba.njit(cache=True, parallel=True)
def _near_mask(x, radius, rotation, translation, grid_lo, grid_hi, near):
    for i in prange(x.shape[0]):
        cx, cy, cz = _to_mesh_frame(x, i, rotation, translation)
        r = radius[i]
        near[i] = (
            cx + r >= grid_lo[0] and cx - r <= grid_hi[0]
            and cy + r >= grid_lo[1] and cy - r <= grid_hi[1]
            and cz + r >= grid_lo[2] and cz - r <= grid_hi[2]
        )


@numba.njit(cache=True, parallel=True)
def _count_pass(near_idx, x, radius, rotation, translation, tri_v0, tri_v1, tri_v2, grid_lo,
                cell_size, grid_shape, cell_start, cell_tris, counts):
    n_near = near_idx.shape[0]
    n_chunks = (n_near + _CHUNK - 1) // _CHUNK
    n_tri = tri_v0.shape[0]
    for ch in prange(n_chunks):
        stamp = np.full(n_tri, -1, np.int64)
        rng = np.empty(6, np.int64)
        s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key, s_owner = _scratch(16)
        for a in range(ch * _CHUNK, min((ch + 1) * _CHUNK, n_near)):
            i = near_idx[a]
            cx, cy, cz = _to_mesh_frame(x, i, rotation, translation)
            while True:
                n = _particle_contacts(cx, cy, cz, radius[i], tri_v0, tri_v1, tri_v2, grid_lo,
                                       cell_size, grid_shape, cell_start, cell_tris, stamp, i,
                                       rng, s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key,
                                       s_owner)
                if n >= 0:
                    break
                s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key, s_owner = _scratch(2 * (-n))
                stamp[:] = -1
            counts[a] = n


@numba.njit(cache=True, parallel=True)
def _fill_pass(near_idx, offsets, x, radius, rotation, translation, tri_v0, tri_v1, tri_v2,
               grid_lo, cell_size, grid_shape, cell_start, cell_tris, out_particle,
               out_triangle, out_feature, out_normal, out_overlap, out_point):
    n_near = near_idx.shape[0]
    n_chunks = (n_near + _CHUNK - 1) // _CHUNK
    n_tri = tri_v0.shape[0]
    for ch in prange(n_chunks):
        stamp = np.full(n_tri, -1, np.int64)
        rng = np.empty(6, np.int64)
        s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key, s_owner = _scratch(16)
        for a in range(ch * _CHUNK, min((ch + 1) * _CHUNK, n_near)):
            o0 = offsets[a]
            if offsets[a + 1] == o0:
                continue
            i = near_idx[a]
            cx, cy, cz = _to_mesh_frame(x, i, rotation, translation)
            while True:
                n = _particle_contacts(cx, cy, cz, radius[i], tri_v0, tri_v1, tri_v2, grid_lo,
                                       cell_size, grid_shape, cell_start, cell_tris, stamp, i,
                                       rng, s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key,
                                       s_owner)
                if n >= 0:
                    break
                s_tri, s_feat, s_d, s_p, s_n, s_keep, s_c, s_key, s_owner = _scratch(2 * (-n))
                stamp[:] = -1
            for q in range(n):
                o = o0 + q
                out_particle[o] = i
                out_triangle[o] = s_tri[q]
                out_feature[o] = s_feat[q]
                out_overlap[o] = radius[i] - s_d[q]
                for u in range(3):
                    out_normal[o, u] = (rotation[u, 0] * s_n[q, 0] + rotation[u, 1] * s_n[q, 1]
                                        + rotation[u, 2] * s_n[q, 2])
                    out_point[o, u] = (rotation[u, 0] * s_p[q, 0] + rotation[u, 1] * s_p[q, 1]
                                       + rotation[u, 2] * s_p[q, 2] + translation[u])


@numba.njit(cache=True)
def mesh_contacts(x, radius, rotation, translation, tri_v0, tri_v1, tri_v2, grid_lo, cell_size,
                  grid_shape, cell_start, cell_tris, out_particle, out_triangle, out_feature,
                  out_normal, out_overlap, out_point):
    """All de-duplicated sphere--triangle contacts of one mesh (see the module docstring).

    Parameters
    ----------
    x : (N, 3) float64
        Particle centres, world frame [m].
    radius : (N,) float64
        Particle radii [m].
    rotation : (3, 3) float64
        Mesh-frame rotation, ``x_world = rotation @ x_mesh + translation``.
    translation : (3,) float64
        Mesh-frame origin in the world [m].
    tri_v0, tri_v1, tri_v2 : (T, 3) float64
        Triangle corners, mesh frame [m].
    grid_lo, cell_size, grid_shape, cell_start, cell_tris
        Broad-phase grid from :func:`build_triangle_grid` on the same corners.
    out_particle, out_triangle, out_feature, out_normal, out_overlap, out_point
        Output arrays of equal capacity M (see the module docstring for dtypes and shapes).

    Returns
    -------
    n_found : int
        Number of contacts; nothing is written if ``n_found > M`` (grow and call again).

    Notes
    -----
    Closest point: Ericson (2005) section 5.1.5. Broad phase: uniform grid, prefiltered with the
    grid's box inflated by each particle radius. De-duplication rules: module docstring.
    """
    n = x.shape[0]
    grid_hi = np.empty(3)
    for a in range(3):
        grid_hi[a] = grid_lo[a] + grid_shape[a] * cell_size
    near = np.empty(n, np.bool_)
    _near_mask(x, radius, rotation, translation, grid_lo, grid_hi, near)
    near_idx = np.flatnonzero(near)
    counts = np.zeros(near_idx.shape[0], np.int64)
    _count_pass(near_idx, x, radius, rotation, translation, tri_v0, tri_v1, tri_v2, grid_lo,
                cell_size, grid_shape, cell_start, cell_tris, counts)
    offsets = np.zeros(near_idx.shape[0] + 1, np.int64)
    for a in range(near_idx.shape[0]):
        offsets[a + 1] = offsets[a] + counts[a]
    total = offsets[near_idx.shape[0]]
    if total > out_particle.shape[0]:
        return total
    _fill_pass(near_idx, offsets, x, radius, rotation, translation, tri_v0, tri_v1, tri_v2,
               grid_lo, cell_size, grid_shape, cell_start, cell_tris, out_particle, out_triangle,
               out_feature, out_normal, out_overlap, out_point)
    return total


@numba.njit(cache=True, parallel=True)
def brute_force_distances(points, tri_v0, tri_v1, tri_v2):
    """Unsigned distance from each point to the nearest triangle (all triangles tested) [m].

    Notes
    -----
    Ericson (2005) section 5.1.5 per triangle; O(N T), for carving and test oracles.
    """
    n = points.shape[0]
    out = np.empty(n)
    for i in prange(n):
        best = np.inf
        for t in range(tri_v0.shape[0]):
            qx, qy, qz, f = closest_point_triangle(
                points[i, 0], points[i, 1], points[i, 2],
                tri_v0[t, 0], tri_v0[t, 1], tri_v0[t, 2],
                tri_v1[t, 0], tri_v1[t, 1], tri_v1[t, 2],
                tri_v2[t, 0], tri_v2[t, 1], tri_v2[t, 2],
            )
            d2 = (points[i, 0] - qx) ** 2 + (points[i, 1] - qy) ** 2 + (points[i, 2] - qz) ** 2
            if d2 < best:
                best = d2
        out[i] = np.sqrt(best)
    return out


@numba.njit(cache=True, parallel=True)
def winding_numbers(points, tri_v0, tri_v1, tri_v2):
    """Generalised winding number of a triangle mesh at each point (1 inside, 0 outside).

    Notes
    -----
    Sum of signed solid angles of the triangles seen from the point, each by the formula of
    Van Oosterom & Strackee (1983), divided by 4 pi (Jacobson et al. 2013, "Robust
    inside-outside segmentation using generalized winding numbers"). Points outside the mesh's
    AABB get 0 without the sum.
    """
    n = points.shape[0]
    out = np.zeros(n)
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):
        lo[a] = min(tri_v0[:, a].min(), tri_v1[:, a].min(), tri_v2[:, a].min())
        hi[a] = max(tri_v0[:, a].max(), tri_v1[:, a].max(), tri_v2[:, a].max())
    for i in prange(n):
        px = points[i, 0]
        py = points[i, 1]
        pz = points[i, 2]
        if px < lo[0] or px > hi[0] or py < lo[1] or py > hi[1] or pz < lo[2] or pz > hi[2]:
            continue
        total = 0.0
        for t in range(tri_v0.shape[0]):
            ax = tri_v0[t, 0] - px
            ay = tri_v0[t, 1] - py
            az = tri_v0[t, 2] - pz
            bx = tri_v1[t, 0] - px
            by = tri_v1[t, 1] - py
            bz = tri_v1[t, 2] - pz
            cx = tri_v2[t, 0] - px
            cy = tri_v2[t, 1] - py
            cz = tri_v2[t, 2] - pz
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb)
            total += 2.0 * np.arctan2(det, den)
        out[i] = total / (4.0 * np.pi)
    return out
