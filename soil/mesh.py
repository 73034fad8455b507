"""Triangle-mesh boundaries for the soil DEM: geometry, I/O, mass properties and contact search.

Public names
------------
``TriangleMesh``
    Vertices ``(V, 3)`` float64 in the BODY frame [m] and triangles ``(T, 3)`` int32; read/write
    through meshio, primitive builders, normals/areas, closed-ness and orientation, enclosed
    volume and solid/shell mass properties, inside test and signed distance.
``MeshCollider``
    Broad-phase grid of one mesh (kept in the mesh frame, so a rigid body never rebuilds it) and
    the de-duplicated sphere--triangle contact search ``contacts(x, radius, rotation,
    translation)`` around the Numba kernel :func:`soil._mesh_kernels.mesh_contacts`.
``MeshContacts``
    Result arrays of one search; ``world_contacts(mesh, x, r, R, X)`` is a one-shot search.
``MassProperties``
    Mass [kg], centroid [m], inertia tensor about the centroid [kg m^2], volume or area.
``point_in_closed_mesh``, ``signed_distance``, ``spheres_touching_mesh``
    Carving helpers (remove soil particles that overlap an impactor at start).
``continue_contacts``
    Maps this step's contacts to last step's across triangle switches, so the engine can carry
    the tangential spring of a sphere rolling or sliding over the mesh to the next triangle.

The engine (``soil/simulation.py``) calls ``MeshCollider.contacts`` (or the kernel directly, see
the contract in ``soil/_mesh_kernels.py``) once per mesh shape and step, and applies the
contact law itself; the facet side of the series stiffness uses 2 r (Yade
``Ig2_Facet_Sphere_ScGeom``, ARCHITECTURE.md section 1).
"""

from __future__ import annotations

import os
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from soil import _mesh_kernels as _mk

__all__ = [
    "TriangleMesh",
    "MeshCollider",
    "MeshContacts",
    "MassProperties",
    "point_in_closed_mesh",
    "signed_distance",
    "spheres_touching_mesh",
    "continue_contacts",
    "world_contacts",
    "FEATURE_FACE",
    "FEATURE_EDGE0",
    "FEATURE_EDGE1",
    "FEATURE_EDGE2",
    "FEATURE_VERTEX0",
    "FEATURE_VERTEX1",
    "FEATURE_VERTEX2",
]

FEATURE_FACE = _mk.FEATURE_FACE
FEATURE_EDGE0 = _mk.FEATURE_EDGE0
FEATURE_EDGE1 = _mk.FEATURE_EDGE1
FEATURE_EDGE2 = _mk.FEATURE_EDGE2
FEATURE_VERTEX0 = _mk.FEATURE_VERTEX0
FEATURE_VERTEX1 = _mk.FEATURE_VERTEX1
FEATURE_VERTEX2 = _mk.FEATURE_VERTEX2

#: largest |R^T R - I| accepted for a rotation matrix (integrated rotations drift slowly)
ROTATION_TOL = 1e-6

#: a triangle with area below DEGENERATE_REL_AREA * (bounding-box diagonal)^2 is rejected
DEGENERATE_REL_AREA = 1e-14


def _rotation_matrix(rotation, name):
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3):
        raise ValueError(f"{name}: shape {r.shape}: must be (3, 3)")
    err = np.abs(r.T @ r - np.eye(3)).max()
    # 1e-6 admits the slow drift of a rotation integrated over millions of steps
    if not np.isfinite(err) or err > ROTATION_TOL or np.linalg.det(r) < 0.0:
        raise ValueError(f"{name}: |R^T R - I| = {err:.3g}, det = {np.linalg.det(r):.3g}: "
                         "must be a proper rotation (orthonormal, det +1)")
    return np.ascontiguousarray(r)


def _vec3(value, name):
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name}={value!r}: must be 3 finite numbers")
    return v


@dataclass(frozen=True)
class MassProperties:
    """Rigid-body mass properties of a mesh (solid or thin shell).

    Attributes
    ----------
    mass : float
        [kg].
    centroid : (3,) ndarray
        Centre of mass in the mesh frame [m].
    inertia : (3, 3) ndarray
        Inertia tensor about the centroid, mesh axes [kg m^2].
    measure : float
        Enclosed volume [m^3] (solid) or surface area [m^2] (shell).
    """

    mass: float
    centroid: np.ndarray
    inertia: np.ndarray
    measure: float


@dataclass(frozen=True, eq=False)
class TriangleMesh:
    """Triangle surface mesh in the body frame.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Corner coordinates, body frame [m]; finite.
    triangles : (T, 3) array_like of int
        Corner indices, counter-clockwise seen from the side the face normal points to.

    Raises
    ------
    ValueError
        Naming the field and the offending value: non-finite vertices, indices out of
        ``[0, V)``, or a degenerate triangle (index and area).

    Notes
    -----
    Arrays are stored as read-only contiguous copies (float64, int32). Face normal
    ``(v1 - v0) x (v2 - v0) / |...|``; for a closed, outward-oriented mesh the normals point out.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        v = np.array(self.vertices, dtype=np.float64, copy=True)
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3:
            raise ValueError(f"TriangleMesh.vertices: shape {v.shape}: must be (V >= 3, 3)")
        bad = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
        if bad.size:
            raise ValueError(f"TriangleMesh.vertices[{bad[0]}]={v[bad[0]]}: must be finite [m]")
        t_in = np.asarray(self.triangles)
        if t_in.ndim != 2 or t_in.shape[1] != 3 or t_in.shape[0] < 1:
            raise ValueError(f"TriangleMesh.triangles: shape {t_in.shape}: must be (T >= 1, 3)")
        if not np.issubdtype(t_in.dtype, np.integer):
            if not np.all(np.equal(np.mod(t_in, 1), 0)):
                raise ValueError("TriangleMesh.triangles: must be integer vertex indices")
        t = t_in.astype(np.int32)
        out = np.flatnonzero((t < 0).any(axis=1) | (t >= v.shape[0]).any(axis=1))
        if out.size:
            raise ValueError(f"TriangleMesh.triangles[{out[0]}]={t[out[0]].tolist()}: "
                             f"indices must be in [0, {v.shape[0] - 1}]")
        area = 0.5 * np.linalg.norm(
            np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
        diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
        bad = np.flatnonzero(area <= DEGENERATE_REL_AREA * diag * diag)
        if bad.size:
            raise ValueError(f"TriangleMesh.triangles[{bad[0]}]={t[bad[0]].tolist()}: degenerate, "
                             f"area {area[bad[0]]:.3g} m^2: must be > "
                             f"{DEGENERATE_REL_AREA:g} * bbox_diagonal^2 = "
                             f"{DEGENERATE_REL_AREA * diag * diag:.3g} m^2")
        v.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "triangles", t)

    # ------------------------------------------------------------------ basic geometry
    @property
    def n_vertices(self) -> int:
        return self.vertices.shape[0]

    @property
    def n_triangles(self) -> int:
        return self.triangles.shape[0]

    def corners(self, vertices: np.ndarray | None = None):
        """Per-triangle corner arrays ``(v0, v1, v2)``, each (T, 3) contiguous float64 [m].

        Parameters
        ----------
        vertices : (V, 3) ndarray, optional
            Vertex positions to gather from (e.g. :meth:`transformed`); default the body frame.
        """
        v = self.vertices if vertices is None else vertices
        t = self.triangles
        return (np.ascontiguousarray(v[t[:, 0]]), np.ascontiguousarray(v[t[:, 1]]),
                np.ascontiguousarray(v[t[:, 2]]))

    def _cross(self):
        v0, v1, v2 = self.corners()
        return np.cross(v1 - v0, v2 - v0)

    @property
    def face_normals(self) -> np.ndarray:
        """Unit face normals (T, 3), right-hand rule on (v0, v1, v2)."""
        c = self._cross()
        return c / np.linalg.norm(c, axis=1)[:, None]

    @property
    def areas(self) -> np.ndarray:
        """Triangle areas (T,) [m^2]."""
        return 0.5 * np.linalg.norm(self._cross(), axis=1)

    @property
    def area(self) -> float:
        """Total surface area [m^2]."""
        return float(self.areas.sum())

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box (lo, hi) in the body frame [m]."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def transformed(self, rotation, translation) -> np.ndarray:
        """World-frame vertices ``R @ v + x`` (V, 3) [m].

        Parameters
        ----------
        rotation : (3, 3) array_like
            Body-to-world rotation matrix.
        translation : (3,) array_like
            Body origin in the world [m].
        """
        r = _rotation_matrix(rotation, "TriangleMesh.transformed rotation")
        x = _vec3(translation, "TriangleMesh.transformed translation")
        return self.vertices @ r.T + x

    def scaled(self, factor: float) -> TriangleMesh:
        """Copy with all coordinates multiplied by ``factor`` (> 0), e.g. 1e-3 for mm."""
        if not (np.isfinite(factor) and factor > 0):
            raise ValueError(f"TriangleMesh.scale={factor}: must be > 0 and finite")
        return TriangleMesh(self.vertices * factor, self.triangles)

    def flipped(self) -> TriangleMesh:
        """Copy with every triangle's orientation reversed (normals negated)."""
        return TriangleMesh(self.vertices, self.triangles[:, ::-1])

    def welded(self) -> TriangleMesh:
        """Copy with bit-identical vertices merged and unreferenced vertices removed.

        STL files store each triangle's corners separately; welding restores the shared-edge
        topology that closed-ness, orientation and contact de-duplication rely on.
        """
        used = np.unique(self.triangles)
        # "+ 0.0" turns -0.0 into +0.0 so that both weld together
        uniq, inverse = np.unique(self.vertices[used] + 0.0, axis=0, return_inverse=True)
        remap = np.full(self.n_vertices, -1, np.int64)
        remap[used] = inverse.ravel()
        return TriangleMesh(uniq, remap[self.triangles])

    # ------------------------------------------------------------------ topology
    def _edges(self):
        """Directed edges (3T, 2) in triangle order: edge k of triangle t is row 3 t + k."""
        t = self.triangles.astype(np.int64)
        return np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)

    def edge_use_counts(self) -> np.ndarray:
        """Number of triangles using each undirected edge (per row of :meth:`_edges`)."""
        e = np.sort(self._edges(), axis=1)
        _, inv, cnt = np.unique(e, axis=0, return_inverse=True, return_counts=True)
        return cnt[inv.ravel()]

    def triangle_adjacency(self) -> tuple[np.ndarray, np.ndarray]:
        """Triangles sharing at least one vertex with each triangle (CSR, ascending, self excluded).

        For the engine's tangential-history transfer: when a particle's contact moves from
        triangle a to an adjacent triangle b of the same mesh (rolling or sliding across an edge
        or vertex), the history of (particle, a) can be carried over to (particle, b).

        Returns
        -------
        start : (T + 1,) int64
            Offsets: the neighbours of t are ``neighbours[start[t]:start[t + 1]]``.
        neighbours : (E,) int32
            Triangle indices.
        """
        key = "triangle_adjacency"
        if key not in self._cache:
            n_t = self.n_triangles
            tri = self.triangles.astype(np.int64)
            vert = tri.ravel()
            owner = np.repeat(np.arange(n_t), 3)
            order = np.argsort(vert, kind="stable")
            vert_s, owner_s = vert[order], owner[order]
            bounds = np.flatnonzero(np.r_[True, vert_s[1:] != vert_s[:-1], True])
            pairs = []
            for s0, s1 in zip(bounds[:-1], bounds[1:]):
                group = owner_s[s0:s1]
                if group.size > 1:
                    a, b = np.meshgrid(group, group, indexing="ij")
                    pairs.append(np.stack([a.ravel(), b.ravel()], axis=1))
            if pairs:
                pr = np.unique(np.concatenate(pairs), axis=0)
                pr = pr[pr[:, 0] != pr[:, 1]]
            else:
                pr = np.empty((0, 2), np.int64)
            start = np.zeros(n_t + 1, np.int64)
            np.add.at(start, pr[:, 0] + 1, 1)
            np.cumsum(start, out=start)
            nb = pr[:, 1].astype(np.int32)
            start.setflags(write=False)
            nb.setflags(write=False)
            self._cache[key] = (start, nb)
        return self._cache[key]

    @property
    def is_closed(self) -> bool:
        """True if every edge is shared by exactly two triangles (watertight 2-manifold edges)."""
        return bool(np.all(self.edge_use_counts() == 2))

    @property
    def is_consistently_oriented(self) -> bool:
        """True if no directed edge is used twice (neighbours traverse shared edges oppositely)."""
        e = self._edges()
        return np.unique(e, axis=0).shape[0] == e.shape[0]

    @property
    def is_outward(self) -> bool:
        """True for a closed, consistently oriented mesh enclosing a positive volume."""
        return self.is_closed and self.is_consistently_oriented and self.signed_volume() > 0.0

    def fix_orientation(self) -> TriangleMesh:
        """Copy with consistent winding, closed components oriented outward.

        Triangles are flipped by a breadth-first walk over edge neighbours (edges shared by
        exactly two triangles) so that each shared edge is traversed in opposite directions;
        then every closed connected component whose signed volume is negative is flipped, and a
        closed component nested inside an odd number of other closed components is oriented
        inward (a cavity), using the winding number of one of its vertices.

        Raises
        ------
        ValueError
            If a component cannot be oriented (non-orientable, e.g. a Moebius strip).
        """
        tri = self.triangles.astype(np.int64).copy()
        n_t = tri.shape[0]
        e = np.sort(self._edges(), axis=1)
        _, inv = np.unique(e, axis=0, return_inverse=True)
        inv = inv.ravel()
        order = np.argsort(inv, kind="stable")
        neighbours = [[] for _ in range(n_t)]
        inv_sorted = inv[order]
        starts = np.flatnonzero(np.r_[True, inv_sorted[1:] != inv_sorted[:-1], True])
        for s, f in zip(starts[:-1], starts[1:]):
            if f - s == 2:
                a, b = order[s], order[s + 1]
                neighbours[a // 3].append((b // 3, a % 3, b % 3))
                neighbours[b // 3].append((a // 3, b % 3, a % 3))
        comp = np.full(n_t, -1, np.int64)
        flip = np.zeros(n_t, bool)
        n_comp = 0
        for seed in range(n_t):
            if comp[seed] >= 0:
                continue
            comp[seed] = n_comp
            queue = deque([seed])
            while queue:
                a = queue.popleft()
                for b, ka, kb in neighbours[a]:
                    # directed edge ka of a (after its flip) vs edge kb of b
                    ea = (tri[a, ka], tri[a, (ka + 1) % 3])
                    eb = (tri[b, kb], tri[b, (kb + 1) % 3])
                    same = ea == eb
                    need_flip = same != (flip[a])  # a flipped reverses ea
                    if comp[b] < 0:
                        comp[b] = n_comp
                        flip[b] = need_flip
                        queue.append(b)
                    elif flip[b] != need_flip:
                        raise ValueError(f"TriangleMesh.fix_orientation: component containing "
                                         f"triangle {seed} is not orientable")
            n_comp += 1
        tri[flip] = tri[flip][:, ::-1]
        oriented = TriangleMesh(self.vertices, tri)
        # outward per closed component, cavities inward
        counts = oriented.edge_use_counts().reshape(-1, 3)
        closed_comps = [c for c in range(n_comp) if np.all(counts[comp == c] == 2)]
        subs = {c: TriangleMesh(self.vertices, tri[comp == c]) for c in closed_comps}
        for c in closed_comps:
            vol = subs[c].signed_volume()
            depth = 0
            probe = np.ascontiguousarray(self.vertices[tri[comp == c][0, 0]][None, :])
            for o in closed_comps:
                if o != c and abs(_mk.winding_numbers(probe, *subs[o].corners())[0]) > 0.5:
                    depth += 1
            want_positive = depth % 2 == 0
            if (vol > 0.0) != want_positive:
                sel = comp == c
                tri[sel] = tri[sel][:, ::-1]
        return TriangleMesh(self.vertices, tri)

    # ------------------------------------------------------------------ mass properties
    def signed_volume(self) -> float:
        """Signed enclosed volume [m^3] (> 0 for outward normals).

        Notes
        -----
        Divergence theorem, sum of signed tetrahedra (origin shifted to the vertex mean for
        round-off); Eberly, "Polyhedral Mass Properties (Revisited)", 2002.
        """
        o = self.vertices.mean(axis=0)
        v0, v1, v2 = (c - o for c in self.corners())
        return float(np.einsum("ij,ij->", v0, np.cross(v1, v2)) / 6.0)

    @property
    def volume(self) -> float:
        """Enclosed volume [m^3]; requires a closed mesh (``ValueError`` otherwise)."""
        self._require_closed("volume")
        return abs(self.signed_volume())

    def _require_closed(self, what):
        if not self.is_closed:
            n_open = int(np.sum(self.edge_use_counts() != 2))
            raise ValueError(f"TriangleMesh.{what}: mesh is not closed ({n_open} edge uses not "
                             "shared by exactly 2 triangles); use shell_mass_properties for "
                             "an open surface")
        if not self.is_consistently_oriented:
            raise ValueError(f"TriangleMesh.{what}: inconsistent triangle winding; call "
                             "fix_orientation() first")

    def mass_properties(self, density: float | None = None, mass: float | None = None
                        ) -> MassProperties:
        """Mass, centroid and central inertia of the solid enclosed by a closed mesh.

        Parameters
        ----------
        density : float, optional
            [kg/m^3] > 0. Exactly one of ``density`` and ``mass`` is given.
        mass : float, optional
            Total mass [kg] > 0 (uniform density ``mass / volume``).

        Returns
        -------
        MassProperties
            ``measure`` is the volume [m^3].

        Notes
        -----
        Volume, first and second moments by the divergence theorem over each triangle, with
        the closed-form face integrals of Eberly, "Polyhedral Mass Properties (Revisited)"
        (Geometric Tools, 2002), equivalent to Mirtich (1996); inertia moved to the centroid
        with the parallel-axis theorem. Orientation-independent (the sign of the volume is
        removed).
        """
        self._require_closed("mass_properties")
        o = self.vertices.mean(axis=0)
        v0, v1, v2 = (c - o for c in self.corners())
        d = np.cross(v1 - v0, v2 - v0)

        def sub(w0, w1, w2):
            temp0 = w0 + w1
            f1 = temp0 + w2
            temp1 = w0 * w0
            temp2 = temp1 + w1 * temp0
            f2 = temp2 + w2 * f1
            f3 = w0 * temp1 + w1 * temp2 + w2 * f2
            g0 = f2 + w0 * (f1 + w0)
            g1 = f2 + w1 * (f1 + w1)
            g2 = f2 + w2 * (f1 + w2)
            return f1, f2, f3, g0, g1, g2

        fx = sub(v0[:, 0], v1[:, 0], v2[:, 0])
        fy = sub(v0[:, 1], v1[:, 1], v2[:, 1])
        fz = sub(v0[:, 2], v1[:, 2], v2[:, 2])
        i0 = np.sum(d[:, 0] * fx[0]) / 6.0
        ix = np.sum(d[:, 0] * fx[1]) / 24.0
        iy = np.sum(d[:, 1] * fy[1]) / 24.0
        iz = np.sum(d[:, 2] * fz[1]) / 24.0
        ixx = np.sum(d[:, 0] * fx[2]) / 60.0
        iyy = np.sum(d[:, 1] * fy[2]) / 60.0
        izz = np.sum(d[:, 2] * fz[2]) / 60.0
        ixy = np.sum(d[:, 0] * (v0[:, 1] * fx[3] + v1[:, 1] * fx[4] + v2[:, 1] * fx[5])) / 120.0
        iyz = np.sum(d[:, 1] * (v0[:, 2] * fy[3] + v1[:, 2] * fy[4] + v2[:, 2] * fy[5])) / 120.0
        izx = np.sum(d[:, 2] * (v0[:, 0] * fz[3] + v1[:, 0] * fz[4] + v2[:, 0] * fz[5])) / 120.0
        sgn = 1.0 if i0 > 0 else -1.0
        vol = sgn * i0
        rho = _density_or_mass(density, mass, vol, "mass_properties", "volume")
        cm = np.array([ix, iy, iz]) / i0
        # second moments about o, per unit density, then about the centroid
        sxx, syy, szz = sgn * ixx, sgn * iyy, sgn * izz
        sxy, syz, szx = sgn * ixy, sgn * iyz, sgn * izx
        j = np.array([
            [syy + szz, -sxy, -szx],
            [-sxy, szz + sxx, -syz],
            [-szx, -syz, sxx + syy],
        ])
        j_c = j - vol * (np.dot(cm, cm) * np.eye(3) - np.outer(cm, cm))
        return MassProperties(mass=rho * vol, centroid=cm + o, inertia=rho * j_c, measure=vol)

    def shell_mass_properties(self, areal_density: float | None = None,
                              mass: float | None = None) -> MassProperties:
        """Mass properties of the surface as a thin shell of uniform areal density.

        Parameters
        ----------
        areal_density : float, optional
            [kg/m^2] > 0. Exactly one of ``areal_density`` and ``mass`` is given.
        mass : float, optional
            Total mass [kg] > 0.

        Returns
        -------
        MassProperties
            ``measure`` is the area [m^2].

        Notes
        -----
        Exact triangle integrals: first moment ``A (v0 + v1 + v2) / 3``, second moment
        ``A / 12 (sum_i v_i v_i^T + s s^T)`` with ``s = v0 + v1 + v2`` (linear interpolation
        over the triangle, e.g. Eberly 2002); inertia ``tr(S) I - S``, parallel-axis theorem to
        the centroid. Works for open surfaces.
        """
        o = self.vertices.mean(axis=0)
        v0, v1, v2 = (c - o for c in self.corners())
        a = 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1)
        area = float(a.sum())
        rho = _density_or_mass(areal_density, mass, area, "shell_mass_properties", "area")
        s = v0 + v1 + v2
        cm = (a[:, None] * s).sum(axis=0) / (3.0 * area)
        second = (np.einsum("t,ti,tj->ij", a, v0, v0) + np.einsum("t,ti,tj->ij", a, v1, v1)
                  + np.einsum("t,ti,tj->ij", a, v2, v2) + np.einsum("t,ti,tj->ij", a, s, s)) / 12.0
        j = np.trace(second) * np.eye(3) - second
        j_c = j - area * (np.dot(cm, cm) * np.eye(3) - np.outer(cm, cm))
        return MassProperties(mass=rho * area, centroid=cm + o, inertia=rho * j_c, measure=area)

    # ------------------------------------------------------------------ inside / distance
    def winding_number(self, points) -> np.ndarray:
        """Generalised winding number at points (body frame): ~1 inside, ~0 outside."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        return _mk.winding_numbers(p, *self.corners())

    def contains(self, points) -> np.ndarray:
        """Boolean mask of body-frame points inside the closed mesh (winding number > 1/2)."""
        self._require_closed("contains")
        return np.abs(self.winding_number(points)) > 0.5

    def signed_distance(self, points) -> np.ndarray:
        """Distance from body-frame points to the surface [m], negative inside (closed mesh)."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        d = _mk.brute_force_distances(p, *self.corners())
        return np.where(self.contains(p), -d, d)

    # ------------------------------------------------------------------ I/O
    @classmethod
    def read(cls, path, scale: float = 1.0, weld: bool = True,
             file_format: str | None = None, drop_degenerate: bool = False) -> TriangleMesh:
        """Read a surface mesh with meshio (STL, OBJ, PLY, VTU, VTK, OFF, ... ).

        Parameters
        ----------
        path : str or os.PathLike
            Mesh file.
        scale : float
            Factor applied to the coordinates, e.g. ``1e-3`` for a file in mm (> 0).
        weld : bool
            Merge bit-identical vertices (STL stores corners per triangle).
        file_format : str, optional
            meshio format name when the extension is ambiguous.
        drop_degenerate : bool
            Remove zero-area (sliver) triangles, as CAD exports sometimes contain, instead of
            raising; the rest of the mesh is kept.

        Raises
        ------
        ValueError
            Naming the file: unreadable, no triangle/quad/polygon cells (quads are split in two
            triangles along the 0-2 diagonal, polygons in a fan from their first corner), or an
            invalid mesh (the construction error, e.g. a degenerate triangle's index and area).
        """
        import meshio

        path = Path(os.fspath(path))
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"TriangleMesh.read scale={scale}: must be > 0 and finite")
        if not path.is_file():
            raise ValueError(f"TriangleMesh.read: no such file '{path}'")
        try:
            # meshio's binary-STL size probe multiplies a uint32 header word that overflows
            # for ASCII files (harmless; it then reads ASCII)
            with np.errstate(over="ignore"):
                m = meshio.read(path, file_format=file_format)
        except Exception as exc:  # meshio raises several types; report them with the file
            raise ValueError(f"TriangleMesh.read: cannot read '{path}': "
                             f"{type(exc).__name__}: {exc}") from exc
        blocks = []
        for cb in m.cells:
            data = np.asarray(cb.data)
            if cb.type == "triangle":
                blocks.append(data)
            elif cb.type == "quad":
                blocks.append(np.concatenate([data[:, [0, 1, 2]], data[:, [0, 2, 3]]]))
            elif cb.type.startswith("polygon") and data.ndim == 2 and data.shape[1] >= 3:
                # fan from corner 0 (planar convex polygons, as CAD exporters write them)
                k = data.shape[1]
                blocks.append(np.concatenate([data[:, [0, j, j + 1]] for j in range(1, k - 1)]))
        if not blocks:
            kinds = sorted({cb.type for cb in m.cells}) or ["none"]
            raise ValueError(f"TriangleMesh.read: '{path}' has no triangle, quad or polygon cells "
                             f"(found: {', '.join(kinds)})")
        pts = np.asarray(m.points, dtype=np.float64)[:, :3] * scale
        tri = np.concatenate(blocks).astype(np.int64)
        if drop_degenerate and tri.min() >= 0 and tri.max() < pts.shape[0]:
            used = pts[np.unique(tri)]
            diag = float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
            area = 0.5 * np.linalg.norm(np.cross(pts[tri[:, 1]] - pts[tri[:, 0]],
                                                 pts[tri[:, 2]] - pts[tri[:, 0]]), axis=1)
            tri = tri[area > DEGENERATE_REL_AREA * diag * diag]
        try:
            mesh = cls(pts, tri)
        except ValueError as exc:
            raise ValueError(f"TriangleMesh.read '{path}': {exc}") from exc
        return mesh.welded() if weld else mesh

    def write(self, path, file_format: str | None = None, **kwargs) -> None:
        """Write with meshio (format from the extension unless ``file_format`` is given).

        Extra keyword arguments go to meshio (e.g. ``binary=True`` for STL).
        """
        import meshio

        path = Path(os.fspath(path))
        try:
            meshio.write_points_cells(path, self.vertices, [("triangle", self.triangles)],
                                      file_format=file_format, **kwargs)
        except Exception as exc:
            raise ValueError(f"TriangleMesh.write: cannot write '{path}': "
                             f"{type(exc).__name__}: {exc}") from exc

    # ------------------------------------------------------------------ builders
    @classmethod
    def icosphere(cls, radius: float, subdivisions: int = 2, center=(0.0, 0.0, 0.0)
                  ) -> TriangleMesh:
        """Sphere approximated by a subdivided icosahedron, vertices on the sphere, outward.

        Parameters
        ----------
        radius : float
            [m] > 0.
        subdivisions : int
            Midpoint subdivisions in [0, 8]; 20 * 4**subdivisions triangles.
        center : (3,) array_like
            [m].
        """
        _positive(radius, "TriangleMesh.icosphere radius", "m")
        if not (isinstance(subdivisions, (int, np.integer)) and 0 <= subdivisions <= 8):
            raise ValueError(f"TriangleMesh.icosphere subdivisions={subdivisions}: "
                             "must be an int in [0, 8]")
        c = _vec3(center, "TriangleMesh.icosphere center")
        g = (1.0 + np.sqrt(5.0)) / 2.0
        v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0],
                      [0, -1, g], [0, 1, g], [0, -1, -g], [0, 1, -g],
                      [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], dtype=np.float64)
        f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                      [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                      [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                      [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int64)
        v /= np.linalg.norm(v, axis=1)[:, None]
        for _ in range(int(subdivisions)):
            edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
            uniq, inv = np.unique(edges, axis=0, return_inverse=True)
            inv = inv.ravel()
            mid = v[uniq[:, 0]] + v[uniq[:, 1]]
            mid /= np.linalg.norm(mid, axis=1)[:, None]
            n_f = f.shape[0]
            a = inv[:n_f] + v.shape[0]  # midpoint of (0, 1)
            b = inv[n_f:2 * n_f] + v.shape[0]  # (1, 2)
            cc = inv[2 * n_f:] + v.shape[0]  # (2, 0)
            v = np.concatenate([v, mid])
            f = np.concatenate([
                np.stack([f[:, 0], a, cc], axis=1), np.stack([f[:, 1], b, a], axis=1),
                np.stack([f[:, 2], cc, b], axis=1), np.stack([a, b, cc], axis=1)])
        mesh = cls(v * radius + c, f)
        return mesh if mesh.signed_volume() > 0 else mesh.flipped()

    @classmethod
    def box(cls, lo, hi, inward: bool = False) -> TriangleMesh:
        """Axis-aligned box surface, 12 triangles; normals outward (``inward=True``: a container).

        Parameters
        ----------
        lo, hi : (3,) array_like
            Opposite corners [m], ``lo < hi`` component-wise.
        """
        lo = _vec3(lo, "TriangleMesh.box lo")
        hi = _vec3(hi, "TriangleMesh.box hi")
        if np.any(hi <= lo):
            raise ValueError(f"TriangleMesh.box: lo={lo.tolist()}, hi={hi.tolist()}: "
                             "must satisfy lo < hi on every axis [m]")
        v = np.array([[lo[0] if i & 1 == 0 else hi[0], lo[1] if i & 2 == 0 else hi[1],
                       lo[2] if i & 4 == 0 else hi[2]] for i in range(8)])
        quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4],
                          [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
        f = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        mesh = cls(v, f)
        if mesh.signed_volume() < 0:
            mesh = mesh.flipped()
        return mesh.flipped() if inward else mesh

    @classmethod
    def cylinder(cls, radius: float, z_min: float, z_max: float, segments: int = 32,
                 center=(0.0, 0.0), bottom: bool = True, top: bool = True,
                 inward: bool = False, axial_divisions: int = 1) -> TriangleMesh:
        """Vertical (z-axis) cylinder surface: side polygon of ``segments`` sides, optional caps.

        Parameters
        ----------
        radius : float
            [m] > 0 (polygon vertices lie on the circle).
        z_min, z_max : float
            [m], ``z_min < z_max``.
        segments : int
            Sides of the polygon, >= 3.
        center : (2,) array_like
            Axis position (x, y) [m].
        bottom, top : bool
            Include the end caps (fan around a centre vertex).
        inward : bool
            Normals towards the axis (a tank); default outward.
        axial_divisions : int
            Rings of side quads along z (>= 1); more rings give better-shaped triangles
            (``2 * segments * axial_divisions`` side triangles).
        """
        _positive(radius, "TriangleMesh.cylinder radius", "m")
        if not (np.isfinite(z_min) and np.isfinite(z_max) and z_max > z_min):
            raise ValueError(f"TriangleMesh.cylinder z_min={z_min}, z_max={z_max}: "
                             "must be finite with z_min < z_max [m]")
        if not (isinstance(segments, (int, np.integer)) and segments >= 3):
            raise ValueError(f"TriangleMesh.cylinder segments={segments}: must be an int >= 3")
        if not (isinstance(axial_divisions, (int, np.integer)) and axial_divisions >= 1):
            raise ValueError(f"TriangleMesh.cylinder axial_divisions={axial_divisions}: "
                             "must be an int >= 1")
        cx, cy = (float(c) for c in center)
        ang = 2.0 * np.pi * np.arange(segments) / segments
        ring = np.stack([cx + radius * np.cos(ang), cy + radius * np.sin(ang)], axis=1)
        zs = z_min + (z_max - z_min) * np.arange(axial_divisions + 1) / axial_divisions
        zs[-1] = z_max
        v = [np.column_stack([ring, np.full(segments, z)]) for z in zs]
        i = np.arange(segments)
        j = (i + 1) % segments
        f = []
        for k in range(axial_divisions):
            lo_, hi_ = k * segments, (k + 1) * segments
            f += [np.stack([i + lo_, j + lo_, j + hi_], axis=1),
                  np.stack([i + lo_, j + hi_, i + hi_], axis=1)]
        n_v = (axial_divisions + 1) * segments
        top_ring = axial_divisions * segments
        if bottom:
            v.append([[cx, cy, z_min]])
            f.append(np.stack([np.full(segments, n_v), j, i], axis=1))
            n_v += 1
        if top:
            v.append([[cx, cy, z_max]])
            f.append(np.stack([np.full(segments, n_v), i + top_ring, j + top_ring], axis=1))
            n_v += 1
        mesh = cls(np.concatenate(v), np.concatenate(f))
        return mesh.flipped() if inward else mesh

    @classmethod
    def plane_patch(cls, size=(1.0, 1.0), divisions=(1, 1), center=(0.0, 0.0, 0.0),
                    normal=(0.0, 0.0, 1.0), u_axis=None) -> TriangleMesh:
        """Flat rectangular patch of ``2 * nx * ny`` triangles with face normals along ``normal``.

        Parameters
        ----------
        size : (2,) array_like
            Side lengths (Lu, Lv) [m] > 0.
        divisions : (2,) array_like of int
            Quads per side (nu, nv) >= 1; each quad is split along alternating diagonals.
        center : (3,) array_like
            Patch centre [m].
        normal : (3,) array_like
            Front-side direction (normalised here).
        u_axis : (3,) array_like, optional
            In-plane direction of the first side (projected onto the plane); default: the world
            axis least aligned with ``normal``, projected.
        """
        lu, lv = (float(s) for s in size)
        _positive(lu, "TriangleMesh.plane_patch size[0]", "m")
        _positive(lv, "TriangleMesh.plane_patch size[1]", "m")
        nu, nv = (int(d) for d in divisions)
        if nu < 1 or nv < 1:
            raise ValueError(f"TriangleMesh.plane_patch divisions={tuple(divisions)}: "
                             "must be ints >= 1")
        c = _vec3(center, "TriangleMesh.plane_patch center")
        n = _vec3(normal, "TriangleMesh.plane_patch normal")
        if np.linalg.norm(n) == 0:
            raise ValueError("TriangleMesh.plane_patch normal=(0, 0, 0): must be non-zero")
        n = n / np.linalg.norm(n)
        u = np.eye(3)[np.argmin(np.abs(n))] if u_axis is None else _vec3(
            u_axis, "TriangleMesh.plane_patch u_axis")
        u = u - np.dot(u, n) * n
        if np.linalg.norm(u) < 1e-12:
            raise ValueError(f"TriangleMesh.plane_patch u_axis={u_axis}: parallel to normal")
        u /= np.linalg.norm(u)
        w = np.cross(n, u)
        s = (np.arange(nu + 1) / nu - 0.5) * lu
        t = (np.arange(nv + 1) / nv - 0.5) * lv
        ss, tt = np.meshgrid(s, t, indexing="ij")
        v = c + ss.reshape(-1, 1) * u + tt.reshape(-1, 1) * w
        idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
        f = []
        for a in range(nu):
            for b in range(nv):
                p00, p10, p11, p01 = idx[a, b], idx[a + 1, b], idx[a + 1, b + 1], idx[a, b + 1]
                if (a + b) % 2 == 0:
                    f += [[p00, p10, p11], [p00, p11, p01]]
                else:
                    f += [[p00, p10, p01], [p10, p11, p01]]
        return cls(v, np.array(f))


def _positive(value, name, unit):
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name}={value}: must be > 0 [{unit}]")


def _density_or_mass(density, mass, measure, where, measure_name):
    if (density is None) == (mass is None):
        raise ValueError(f"TriangleMesh.{where}: give exactly one of density and mass "
                         f"(got density={density}, mass={mass})")
    if density is not None:
        _positive(density, f"TriangleMesh.{where} density", "kg/m^3 or kg/m^2")
        return float(density)
    _positive(mass, f"TriangleMesh.{where} mass", "kg")
    if measure <= 0:
        raise ValueError(f"TriangleMesh.{where}: {measure_name}={measure}: must be > 0")
    return float(mass) / measure


# ---------------------------------------------------------------------------------------------
# contact search
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class MeshContacts:
    """Sphere--triangle contacts of one mesh, sorted by particle then triangle.

    Attributes
    ----------
    particle : (M,) int32
    triangle : (M,) int32
    feature : (M,) int8
        ``FEATURE_FACE``, ``FEATURE_EDGE0..2`` or ``FEATURE_VERTEX0..2``.
    normal : (M, 3) float64
        Unit normal, world frame, from the mesh to the particle centre.
    overlap : (M,) float64
        ``r - distance`` > 0 [m].
    point : (M, 3) float64
        Closest point on the triangle, world frame [m].
    """

    particle: np.ndarray
    triangle: np.ndarray
    feature: np.ndarray
    normal: np.ndarray
    overlap: np.ndarray
    point: np.ndarray

    def __len__(self) -> int:
        return self.particle.shape[0]


class MeshCollider:
    """Broad-phase grid of one mesh and the de-duplicated sphere--triangle contact search.

    Parameters
    ----------
    mesh : TriangleMesh
        In its own (body) frame; the grid is built there once.
    max_radius : float
        Largest particle radius expected [m] > 0; sets the cell size ``2 * max_radius`` (enlarged
        if the grid would exceed ``max_cells`` cells or ``max_entries`` cell entries). Larger
        particles are still handled exactly, only less efficiently.
    max_cells, max_entries : int
        Memory caps of the grid.

    Notes
    -----
    Contact definition, de-duplication and ordering: :mod:`soil._mesh_kernels`. The search is
    parallel (Numba threads) and bit-identical for any thread count; one collider must not be
    called from two Python threads at once (it reuses its output buffers).
    """

    def __init__(self, mesh: TriangleMesh, max_radius: float, max_cells: int = 2_000_000,
                 max_entries: int = 8_000_000):
        if not isinstance(mesh, TriangleMesh):
            raise TypeError(f"MeshCollider.mesh: {type(mesh).__name__}: must be a TriangleMesh")
        _positive(max_radius, "MeshCollider.max_radius", "m")
        self.mesh = mesh
        self.tri_v0, self.tri_v1, self.tri_v2 = mesh.corners()
        cell = 2.0 * float(max_radius)
        lo, hi = mesh.bounds
        while True:
            # cheap cell count first: a huge grid is never enumerated
            n_cells = np.prod(np.floor((hi - lo) / cell) + 1.0)
            if n_cells <= max_cells:
                _, n_entries = _mk.grid_entry_count(self.tri_v0, self.tri_v1, self.tri_v2, cell)
                if n_entries <= max_entries:
                    break
            cell *= 1.25
        self.cell_size = cell
        (self.grid_lo, self.grid_shape, self.cell_start,
         self.cell_tris) = _mk.build_triangle_grid(self.tri_v0, self.tri_v1, self.tri_v2, cell)
        self._alloc(256)

    def _alloc(self, capacity):
        self._particle = np.empty(capacity, np.int32)
        self._triangle = np.empty(capacity, np.int32)
        self._feature = np.empty(capacity, np.int8)
        self._normal = np.empty((capacity, 3))
        self._overlap = np.empty(capacity)
        self._point = np.empty((capacity, 3))

    def contacts(self, x, radius, rotation=None, translation=None) -> MeshContacts:
        """All de-duplicated sphere contacts with the mesh placed at (rotation, translation).

        Parameters
        ----------
        x : (N, 3) array_like
            Sphere centres, world frame [m].
        radius : (N,) array_like
            Radii [m] > 0.
        rotation : (3, 3) array_like, optional
            Body-to-world rotation (default identity).
        translation : (3,) array_like, optional
            Body origin in the world [m] (default 0).

        Returns
        -------
        MeshContacts
            Fresh arrays (copies), world frame.
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        radius = np.ascontiguousarray(radius, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"MeshCollider.contacts x: shape {x.shape}: must be (N, 3)")
        if radius.shape != (x.shape[0],):
            raise ValueError(f"MeshCollider.contacts radius: shape {radius.shape}: must be "
                             f"({x.shape[0]},)")
        if radius.size and not (radius.min() > 0):
            raise ValueError(f"MeshCollider.contacts radius min={radius.min()}: must be > 0 [m]")
        rot = np.eye(3) if rotation is None else _rotation_matrix(
            rotation, "MeshCollider.contacts rotation")
        tr = np.zeros(3) if translation is None else _vec3(
            translation, "MeshCollider.contacts translation")
        while True:
            n = _mk.mesh_contacts(x, radius, rot, tr, self.tri_v0, self.tri_v1, self.tri_v2,
                                  self.grid_lo, self.cell_size, self.grid_shape, self.cell_start,
                                  self.cell_tris, self._particle, self._triangle, self._feature,
                                  self._normal, self._overlap, self._point)
            if n <= self._particle.shape[0]:
                break
            self._alloc(int(n * 1.5) + 16)
        return MeshContacts(self._particle[:n].copy(), self._triangle[:n].copy(),
                            self._feature[:n].copy(), self._normal[:n].copy(),
                            self._overlap[:n].copy(), self._point[:n].copy())


def world_contacts(mesh: TriangleMesh, x, radius, rotation=None, translation=None
                   ) -> MeshContacts:
    """One-shot contact search of spheres against a mesh placed at (rotation, translation).

    Convenience for scripts and checks; a time loop should keep one :class:`MeshCollider` per
    mesh (the grid is then built once) and call its ``contacts`` every step.

    Parameters
    ----------
    mesh : TriangleMesh
        Body-frame mesh.
    x : (N, 3) array_like
        Sphere centres, world frame [m].
    radius : (N,) array_like
        Radii [m] > 0.
    rotation, translation : optional
        Body pose, ``x_world = R x_body + translation`` (default identity / 0).

    Returns
    -------
    MeshContacts
        World-frame, de-duplicated contacts (see :mod:`soil._mesh_kernels`).
    """
    radius = np.ascontiguousarray(radius, dtype=np.float64)
    r_max = float(radius.max()) if radius.size else 1.0
    return MeshCollider(mesh, r_max).contacts(x, radius, rotation, translation)


def continue_contacts(previous: MeshContacts, current: MeshContacts,
                      mesh: TriangleMesh) -> np.ndarray:
    """Which previous contact each current contact continues (for tangential-history transfer).

    A contact (particle i, triangle t) continues the previous (i, t) if it existed; otherwise
    the previous contact (i, t') of the same particle on a triangle t' sharing a vertex with t
    that has disappeared (the sphere rolled or slid across an edge or vertex), choosing the one
    whose normal is closest to the current normal (then the lower t'). Each previous contact is
    continued at most once.

    Parameters
    ----------
    previous, current : MeshContacts
        Results of :meth:`MeshCollider.contacts` for the same mesh at consecutive steps.
    mesh : TriangleMesh
        The mesh (its :meth:`TriangleMesh.triangle_adjacency` is used).

    Returns
    -------
    (len(current),) int64
        Index into ``previous``, or -1 for a new contact.
    """
    n_t = np.int64(mesh.n_triangles)
    key_prev = previous.particle.astype(np.int64) * n_t + previous.triangle
    key_cur = current.particle.astype(np.int64) * n_t + current.triangle
    out = np.full(len(current), -1, np.int64)
    if len(previous) == 0 or len(current) == 0:
        return out
    pos = np.searchsorted(key_prev, key_cur)
    pos_c = np.minimum(pos, key_prev.size - 1)
    same = key_prev[pos_c] == key_cur
    out[same] = pos_c[same]
    used = np.zeros(len(previous), bool)
    used[out[same]] = True
    # previous contacts that vanished can hand their history to a new neighbour contact
    still = np.isin(key_prev, key_cur)
    start, nb = mesh.triangle_adjacency()
    for c in np.flatnonzero(~same):
        i, t = current.particle[c], current.triangle[c]
        lo = np.searchsorted(previous.particle, i, side="left")
        hi = np.searchsorted(previous.particle, i, side="right")
        best, best_dot = -1, -np.inf
        for q in range(lo, hi):
            if used[q] or still[q]:
                continue
            tq = previous.triangle[q]
            neigh = nb[start[t]:start[t + 1]]
            k = np.searchsorted(neigh, tq)
            if k < neigh.size and neigh[k] == tq:
                dot = float(previous.normal[q] @ current.normal[c])
                if dot > best_dot:
                    best, best_dot = q, dot
        if best >= 0:
            out[c] = best
            used[best] = True
    return out


# ---------------------------------------------------------------------------------------------
# carving helpers
# ---------------------------------------------------------------------------------------------


def _to_body(points, rotation, translation):
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if rotation is None and translation is None:
        return np.ascontiguousarray(p)
    r = np.eye(3) if rotation is None else _rotation_matrix(rotation, "rotation")
    t = np.zeros(3) if translation is None else _vec3(translation, "translation")
    return np.ascontiguousarray((p - t) @ r)


def point_in_closed_mesh(mesh: TriangleMesh, points, rotation=None, translation=None
                         ) -> np.ndarray:
    """Boolean mask: world points inside the closed mesh placed at (rotation, translation).

    Notes
    -----
    Generalised winding number > 1/2 (Jacobson et al. 2013); robust to the point lying on a
    ray through an edge or vertex, unlike ray-parity tests.
    """
    return mesh.contains(_to_body(points, rotation, translation))


def signed_distance(mesh: TriangleMesh, points, rotation=None, translation=None) -> np.ndarray:
    """Distance from world points to the placed closed mesh [m], negative inside.

    Notes
    -----
    Exact point--triangle distances (Ericson 2005, section 5.1.5) over all triangles, O(N T);
    sign from the generalised winding number.
    """
    return mesh.signed_distance(_to_body(points, rotation, translation))


def spheres_touching_mesh(mesh: TriangleMesh, x, radius, rotation=None, translation=None
                          ) -> np.ndarray:
    """Boolean mask of spheres overlapping the surface or (for a closed mesh) inside it.

    For carving a packing: ``keep = ~spheres_touching_mesh(fuselage, x, r, R, X)``.

    Notes
    -----
    Overlaps by :class:`MeshCollider` (exact, grid broad phase); centres inside by winding
    number (only for closed meshes).
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    radius = np.ascontiguousarray(radius, dtype=np.float64)
    mask = np.zeros(x.shape[0], bool)
    if x.shape[0] == 0:
        return mask
    c = MeshCollider(mesh, float(radius.max())).contacts(x, radius, rotation, translation)
    mask[c.particle] = True
    if mesh.is_closed:
        mask |= point_in_closed_mesh(mesh, x, rotation, translation)
    return mask
