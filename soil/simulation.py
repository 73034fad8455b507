"""The soil DEM simulation: neighbour lists, contact forces, boundaries, integration, ledger."""

from __future__ import annotations

import copy
import math
import types
from collections.abc import Sequence

import numba
import numpy as np

from soil import _kernels as K
from soil import _kernels_loop as L
from soil.boundaries import BoundaryBody
from soil.contact_laws import CONTACT_LAWS, damping_ratio
from soil.energy import balance, kinetic
from soil.params import Material
from soil.particles import Particles
from soil.timestep import pwave_time_step, stiffness_time_step

__all__ = ["Simulation"]

#: particles with radius > LARGE_FACTOR * median radius get their own neighbour pass
LARGE_FACTOR = 4.0
#: below this many particles (and threads=None) steps run on one Numba thread: thread wake-up
#: costs more than it saves (results are bit-identical for any thread count anyway)
PARALLEL_MIN_PARTICLES = 4000
#: run step(n) inside Numba when no prescribed motion or mesh needs Python each step
FUSED_LOOP = True
#: use the serial kernel variants (prange compiled as range); for verification only
FORCE_SERIAL = False
#: initial width of the neighbour scan buffer (rows with more neighbours are re-scanned; the
#: width doubles when more than 1/64 of the rows overflow, see _kernels_loop.buffer_width)
NEIGHBOUR_BUFFER = 12
#: default Verlet skin as a fraction of the median radius
DEFAULT_SKIN_FRACTION = 0.4


def _material_table(materials: Sequence[Material]) -> np.ndarray:
    tab = np.zeros((len(materials), K.M_NCOL))
    for m, mat in enumerate(materials):
        tab[m, K.M_YOUNG] = mat.young
        tab[m, K.M_RATIO] = mat.stiffness_ratio
        tab[m, K.M_TANPHI] = math.tan(mat.friction_angle)
        tab[m, K.M_RESTITUTION] = 1.0 if mat.restitution is None else mat.restitution
        tab[m, K.M_TENSION] = 1.0 if mat.dashpot_tension else 0.0
        tab[m, K.M_SHEAR_RESTITUTION] = (1.0 if mat.shear_restitution is None
                                         else mat.shear_restitution)
        # the kernels read the damping ratios of these (the same compiled function: same bits)
        tab[m, K.M_ZETA] = damping_ratio(tab[m, K.M_RESTITUTION])
        tab[m, K.M_SHEAR_ZETA] = damping_ratio(tab[m, K.M_SHEAR_RESTITUTION])
        tab[m, K.M_DENSITY] = mat.density
        tab[m, K.M_LAW] = CONTACT_LAWS.index(mat.contact_law)
        tab[m, K.M_POISSON] = mat.poisson
        tab[m, K.M_ETA_R] = -1.0
        tab[m, K.M_ETA_T] = -1.0
        tab[m, K.M_MU_R] = -1.0
        c = mat.cohesion
        if c is not None:
            tab[m, K.M_COHESIVE] = 1.0
            tab[m, K.M_SN] = c.normal_strength
            tab[m, K.M_SS] = c.shear_strength
            tab[m, K.M_AKR] = c.bending_modulus_factor
            tab[m, K.M_AKTW] = c.twisting_modulus_factor
            tab[m, K.M_ETA_R] = -1.0 if c.bending_cap is None else c.bending_cap
            tab[m, K.M_ETA_T] = -1.0 if c.twisting_cap is None else c.twisting_cap
            tab[m, K.M_PLASTIC] = 1.0 if c.plastic else 0.0
            tab[m, K.M_MOMENTS] = 1.0 if c.moments else 0.0
        if mat.rolling is not None:
            tab[m, K.M_MU_R] = mat.rolling.coefficient
    return tab


def _pair_view(buf: str, dtype):
    """Live view ``self.<buf>[:self._m]`` of a pair buffer (the first ``_m`` rows: the pairs of
    the half list); assigning stores a contiguous ``dtype`` copy as the buffer."""
    return property(lambda self: getattr(self, buf)[:self._m],
                    lambda self, a: setattr(self, buf, np.ascontiguousarray(a, dtype)))


class Simulation:
    """Discrete-element soil of spheres with rigid boundary bodies.

    Parameters
    ----------
    particles : soil.Particles
    materials : sequence of soil.Material
    boundaries : sequence of soil.BoundaryBody
    gravity : (3,) [m/s^2]
    dt : float or None
        Time step [s]; None = safety * dt_critical. A value above dt_critical is refused.
    safety : float
        Fraction of the critical step used when dt is None, in (0, 1].
    global_damping : float
        Cundall non-viscous damping lambda in [0, 1) (deposition only; 0 for impacts).
    skin : float or None
        Verlet skin [m]; None = 0.4 x median radius.
    threads : int or None
        Numba threads (None = Numba's current setting).

    Notes
    -----
    Leapfrog integration; forces at t_n from the state at t_n (ARCHITECTURE section 1).
    dt_critical = min(P-wave step, stiffness step) (Yade ``PWaveTimeStep``,
    ``GlobalStiffnessTimeStepper``).
    """

    def __init__(
        self,
        particles: Particles,
        materials: Sequence[Material],
        boundaries: Sequence[BoundaryBody] = (),
        gravity=(0.0, 0.0, -9.81),
        dt: float | None = None,
        safety: float = 0.3,
        global_damping: float = 0.0,
        skin: float | None = None,
        threads: int | None = None,
    ):
        self._configure(particles, materials, boundaries, gravity, safety, global_damping, skin,
                        threads)
        self._init_state()
        self._build()
        self._compute_forces()
        # critical step from the P-wave estimate and the initial contact stiffness
        ksum = np.zeros(self.particles.n)
        self._K.stiffness_sum(self.particles.x, self.particles.radius, self.particles.material,
                        self._mat, self._row_start, self._nbr, self._c_p, self._bhist[:, 7], ksum)
        p = self.particles
        dt_p = pwave_time_step(p.radius, self._mat[p.material, K.M_YOUNG],
                               self._mat[p.material, K.M_DENSITY])
        dt_k = stiffness_time_step(p.mass, ksum)
        self.dt_pwave = dt_p
        self.dt_stiffness = dt_k
        self.dt_critical = min(dt_p, dt_k)
        if dt is None:
            if not math.isfinite(self.dt_critical):
                raise ValueError("Simulation.dt=None: no particles, give dt explicitly [s]")
            dt = self.safety * self.dt_critical
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"Simulation.dt={dt!r}: must be > 0 [s]")
        if dt > self.dt_critical:
            raise ValueError(
                f"Simulation.dt={dt!r}: above the stable limit dt_critical={self.dt_critical!r} "
                f"[s] (P-wave {dt_p!r}, stiffness {dt_k!r}); use dt <= dt_critical"
            )
        self.dt = dt
        # the given velocities are v(t=0); the leapfrog stores v_{-1/2} = v_0 - dt F_0 / (2 m)
        # (velocity-Verlet start, keeps the scheme second order)
        p.v -= (0.5 * dt) * p.f * p.inv_mass[:, None]
        p.w -= (0.5 * dt) * p.t * p.inv_inertia[:, None]
        self._total0 = 0.0
        self._total0 = self.energy()["total"]

    # ------------------------------------------------------------------------------------------
    # set-up
    # ------------------------------------------------------------------------------------------
    def _configure(self, particles, materials, boundaries, gravity, safety, global_damping, skin,
                   threads):
        if not isinstance(particles, Particles):
            raise ValueError(f"Simulation.particles={type(particles)!r}: must be soil.Particles")
        materials = list(materials)
        if not materials or not all(isinstance(m, Material) for m in materials):
            raise ValueError("Simulation.materials: must be a non-empty list of soil.Material")
        boundaries = list(boundaries)
        for b in boundaries:
            if not isinstance(b, BoundaryBody):
                raise ValueError(f"Simulation.boundaries: {b!r} is not a soil.BoundaryBody")
            if b.material >= len(materials):
                raise ValueError(
                    f"BoundaryBody.material={b.material}: must be < number of materials "
                    f"({len(materials)})"
                )
        g = np.asarray(gravity, np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f"Simulation.gravity={gravity!r}: must be a finite 3-vector [m/s^2]")
        if not (0.0 < safety <= 1.0):
            raise ValueError(f"Simulation.safety={safety!r}: must be in (0, 1] [-]")
        if not (0.0 <= global_damping < 1.0):
            raise ValueError(f"Simulation.global_damping={global_damping!r}: must be in [0, 1)")
        if threads is not None and not (1 <= int(threads) <= numba.config.NUMBA_NUM_THREADS):
            raise ValueError(
                f"Simulation.threads={threads!r}: must be in [1, {numba.config.NUMBA_NUM_THREADS}]"
            )
        self.particles = particles
        self.materials = materials
        self.boundaries = boundaries
        self.gravity = g.copy()
        self.safety = float(safety)
        self.global_damping = float(global_damping)
        self.threads = None if threads is None else int(threads)
        self.particles = particles
        # the prange variants are the faster ones even on one thread (LLVM optimises the outlined
        # parfor bodies better than the plain loops); the serial variants remain for checks
        use_par = not FORCE_SERIAL
        self._parallel = use_par
        self._K = types.SimpleNamespace(**{
            name: (obj.parallel if use_par else obj.serial) if isinstance(obj, K._Dual) else obj
            for name, obj in vars(K).items() if callable(obj) and not name.startswith("__")})
        p = particles
        self._mat = _material_table(materials)
        p.set_masses(self._mat[:, K.M_DENSITY])
        n = p.n
        r_med = float(np.median(p.radius)) if n else 1.0
        if skin is None:
            skin = DEFAULT_SKIN_FRACTION * r_med
        if not (math.isfinite(skin) and skin > 0.0):
            raise ValueError(f"Simulation.skin={skin!r}: must be > 0 [m]")
        self.skin = float(skin)
        self._is_large = np.ascontiguousarray(p.radius > LARGE_FACTOR * r_med)
        self._large_idx = np.flatnonzero(self._is_large).astype(np.int32)
        small = ~self._is_large
        self._r_small = float(p.radius[small].max()) if np.any(small) else (
            float(p.radius.max()) if n else 1.0)
        self._has_rot = bool(np.any(~p.rotation_blocked))
        self._has_coh = any(m.cohesion is not None for m in materials)
        self._has_roll = self._has_rot and any(m.rolling is not None for m in materials)
        svisc = any(m.shear_restitution is not None and m.shear_restitution < 1.0
                    for m in materials)
        self._has_visc = svisc or any(
            m.restitution is not None and m.restitution < 1.0 for m in materials)
        self._has_mom = self._has_rot and (self._has_coh or self._has_roll)
        self._has_hertz = any(m.contact_law == "hertz_mindlin" for m in materials)
        # Hertz-Mindlin: one more column, the last step's overlap (the kernels' last column)
        base = K.H_NCOL_FULL if (self._has_coh or self._has_roll) else K.H_NCOL_BASIC
        # a shear dashpot: three columns of the pairs' viscous shear forces after the layout
        self._fv = base if svisc else -1
        self._ncol = base + 3 * int(svisc) + int(self._has_hertz)
        self._nicol = 1 if self._has_coh else 0
        # boundary elements (analytic first, then mesh triangles)
        etype, ebody, ep, en, er, ea0, ea1 = [], [], [], [], [], [], []
        meshes = []
        for b_idx, b in enumerate(boundaries):
            for s in b.shapes:
                if hasattr(s, "elements"):
                    for t_, p_, n_, r_, a0, a1 in s.elements():
                        etype.append(t_)
                        ebody.append(b_idx)
                        ep.append(p_)
                        en.append(n_)
                        er.append(r_)
                        ea0.append(a0)
                        ea1.append(a1)
                elif hasattr(s, "vertices") and hasattr(s, "triangles"):
                    meshes.append((b_idx, s))
                else:
                    raise ValueError(f"BoundaryBody.shapes: unsupported shape {s!r}")
        self._n_analytic = len(etype)
        self._meshes = []
        off = self._n_analytic
        if meshes:
            from soil.mesh import MeshCollider  # noqa: PLC0415  (other engineer's module)
        r_max = float(particles.radius.max()) if particles.n else 1.0
        for b_idx, s in meshes:
            nt = int(np.asarray(s.triangles).shape[0])
            self._meshes.append((b_idx, MeshCollider(s, r_max), off))
            etype += [K.E_FACET] * nt
            ebody += [b_idx] * nt
            off += nt
        ne = len(etype)
        self._etype = np.asarray(etype, np.int64).reshape(ne)
        self._ebody = np.asarray(ebody, np.int64).reshape(ne)
        na = self._n_analytic
        self._ep_body = np.asarray(ep, np.float64).reshape(na, 3)
        self._en_body = np.asarray(en, np.float64).reshape(na, 3)
        self._er = np.zeros(ne)
        self._er[:na] = er
        self._ea0 = np.asarray(ea0, np.float64).reshape(na)
        self._ea1 = np.asarray(ea1, np.float64).reshape(na)
        self._key_mult = max(ne, 1)
        nb = len(boundaries)
        self._b_mat = np.asarray([b.material for b in boundaries], np.int64).reshape(nb)
        self._moving = [b for b in boundaries if b.motion != "fixed"]
        self._update_elements()

    def _set_threads(self):
        """Apply the thread count for a step; returns the previous count to restore."""
        prev = numba.get_num_threads()
        want = self.threads
        if want is None and self.particles.n < PARALLEL_MIN_PARTICLES:
            want = 1
        if want is not None and prev != want:
            numba.set_num_threads(want)
        return prev

    def _init_state(self):
        p = self.particles
        n = p.n
        nb = len(self.boundaries)
        self.time = 0.0
        self.step_count = 0
        self.n_builds = 0
        self.bonds_lost_to_skin = 0
        self._x_ref = p.x.copy()
        self._row_start = np.zeros(n + 1, np.int64)
        self._t_start = np.zeros(n + 1, np.int64)
        # pair buffers (capacity >= number of pairs self._m; the live part is [:self._m])
        self._m = 0
        self._nbr_buf = np.zeros(0, np.int32)
        self._hf_buf = np.zeros((0, self._ncol))
        self._hi_buf = np.zeros((0, self._nicol), np.int32)
        self._tq_buf = np.zeros((0, 6))
        self._tp_buf = np.zeros(0, np.int32)
        # rebuild scratch: history store, cell grid, scan buffer (persistent, see _build)
        self._s_j = np.zeros(0, np.int32)
        self._s_f = np.zeros((0, self._ncol))
        self._s_i = np.zeros((0, self._nicol), np.int32)
        self._cell_of = np.zeros(n, np.int32)
        self._cell_start = np.zeros(0, np.int64)
        self._cell_list = np.zeros(n, np.int32)
        self._nbuf = np.zeros((n, NEIGHBOUR_BUFFER), np.int32)
        self._b_start = np.zeros(n + 1, np.int64)
        self._e_fric = np.zeros(n)
        self._e_visc = np.zeros(n)
        self._e_glob = np.zeros(n)
        self._e_bond = np.zeros(n)
        self._mx0 = (p.mass[:, None] * p.x).sum(axis=0)
        self._bkey = np.zeros(0, np.int64)
        self._bhist = np.zeros((0, K.B_NCOL))
        self._c_p = np.zeros(0, np.int64)
        self._c_e = np.zeros(0, np.int64)
        self._c_n = np.zeros((0, 3))
        self._c_d = np.zeros(0)
        self._c_pt = np.zeros((0, 3))
        self._b_force = np.zeros((nb, 3))
        self._b_torque = np.zeros((nb, 3))
        self._b_power = np.zeros(nb)
        self._b_diss = np.zeros((nb, 2))

    # live views of the pair buffers (length = number of pairs in the half list)
    @property
    def _nbr(self):
        return self._nbr_buf[:self._m]

    @_nbr.setter
    def _nbr(self, a):
        self._nbr_buf = np.ascontiguousarray(a, np.int32)
        self._m = self._nbr_buf.shape[0]

    _hf = _pair_view("_hf_buf", np.float64)
    _hi = _pair_view("_hi_buf", np.int32)
    _tq = _pair_view("_tq_buf", np.float64)
    _t_pair = _pair_view("_tp_buf", np.int32)

    def _update_elements(self):
        """World-frame element geometry and body kinematic arrays from the body poses."""
        nb = len(self.boundaries)
        self._b_pos = np.zeros((nb, 3))
        self._b_rot = np.zeros((nb, 3, 3))
        self._b_vel = np.zeros((nb, 3))
        self._b_omg = np.zeros((nb, 3))
        self._b_refb = np.zeros((nb, 3))
        self._b_ref = np.zeros((nb, 3))
        for b_idx, b in enumerate(self.boundaries):
            self._b_pos[b_idx] = b.position
            self._b_rot[b_idx] = b.rotation
            self._b_vel[b_idx] = b.velocity
            self._b_omg[b_idx] = b.angular_velocity
            if b.reference_point is not None:
                self._b_refb[b_idx] = b.reference_point
        na = self._n_analytic
        if not hasattr(self, "_ep") or self._ep.shape != (na, 3):
            self._ep = np.zeros((na, 3))
            self._en = np.zeros((na, 3))
        L.update_elements(self._ebody[:na], self._ep_body, self._en_body, self._b_pos,
                          self._b_rot, self._b_refb, self._ep, self._en, self._b_ref)

    # ------------------------------------------------------------------------------------------
    # neighbour list
    # ------------------------------------------------------------------------------------------
    def _build(self):
        """Neighbour-list rebuild in the persistent buffers; the same sequence as
        ``_kernels_loop.rebuild`` with this simulation's kernel variants (serial or prange)."""
        p = self.particles
        n = p.n
        x = p.x
        if n == 0:
            return
        K_ = self._K
        rs, ts = self._row_start, self._t_start
        hf, hi = self._hf_buf, self._hi_buf
        # 1. pairs that carry history -> store (row starts in t_start)
        K_.count_history(rs, hf, hi, ts[1:])
        ts[0] = 0
        a = int(K_.prefix_sum(ts))
        if a > self._s_j.shape[0]:
            cap = int(L.grow(a))
            self._s_j = np.empty(cap, np.int32)
            self._s_f = np.empty((cap, hf.shape[1]))
            self._s_i = np.empty((cap, hi.shape[1]), np.int32)
        K_.save_history(rs, self._nbr_buf, hf, hi, ts, self._s_j, self._s_f, self._s_i)
        # 2. cells
        lo, hi_ = K_.bounds(x, self._is_large)
        cell, nx, ny, nz = L.grid_dims(lo, hi_, 2.0 * self._r_small + self.skin, n)
        if self._cell_start.shape[0] < nx * ny * nz + 2:
            self._cell_start = np.empty(int(L.grow(nx * ny * nz + 2)), np.int64)
        K_.cell_sort_into(x, self._is_large, lo, 1.0 / cell, nx, ny, nz, self._cell_of,
                          self._cell_start, self._cell_list)
        # 3. scan
        buf = self._nbuf
        K_.scan_neighbours(x, p.radius, self._is_large, self._large_idx, self._cell_start,
                           self._cell_list, self._cell_of, nx, ny, nz, self.skin, buf, rs[1:])
        rs[0] = 0
        width = int(L.buffer_width(rs[1:], buf.shape[1]))
        m = int(K_.prefix_sum(rs))
        if m > self._nbr_buf.shape[0]:
            cap = int(L.grow(m))
            self._nbr_buf = np.empty(cap, np.int32)
            self._hf_buf = np.empty((cap, hf.shape[1]))
            self._hi_buf = np.empty((cap, hi.shape[1]), np.int32)
            self._tp_buf = np.empty(cap, np.int32)
            if self._has_rot:
                self._tq_buf = np.empty((cap, 6))
        self._m = m
        # 4. rows
        K_.place_neighbours(x, p.radius, self._is_large, self._large_idx, self._cell_start,
                            self._cell_list, self._cell_of, nx, ny, nz, self.skin, buf, rs,
                            self._nbr_buf)
        if width != buf.shape[1]:
            self._nbuf = np.empty((n, width), np.int32)
        # 5. history
        K_.restore_history(ts, self._s_j, self._s_f, self._s_i, rs, self._nbr_buf,
                           self._hf_buf, self._hi_buf)
        if self._has_coh:
            self.bonds_lost_to_skin += int(K_.lost_bonds(ts, self._s_j, self._s_i, rs,
                                                         self._nbr_buf))
        if self._has_rot:
            self._tq_buf[:m] = 0.0
        # 6. transposed list
        K_.transpose_into(rs, self._nbr_buf, ts, self._tp_buf, self._cell_of)
        self._x_ref[:] = x
        self.n_builds += 1

    # ------------------------------------------------------------------------------------------
    # forces
    # ------------------------------------------------------------------------------------------
    def _compute_forces(self):
        p = self.particles
        self._K.pair_forces(p.x, p.v, p.w, p.radius, p.mass, p.material, self._mat, self._row_start,
                      self._nbr, self._hf, self._hi, self._tq, self.dt if hasattr(self, "dt")
                      else 0.0, self._has_rot, self._has_coh, self._has_roll, self._has_visc,
                      self._e_fric, self._e_visc, self._e_bond, self._fv)
        self._K.gather(p.mass, self.gravity, self._row_start, self._t_start, self._t_pair,
                       self._nbr,
                 self._hf, self._tq, p.f, p.t, self._has_rot, self._fv)
        if self.boundaries:
            self._boundary_forces()

    def _mesh_contacts(self):
        """Sphere-triangle contacts of all meshes (particle, element, normal, overlap, point)."""
        out = []
        if not self._meshes:
            return out
        p = self.particles
        for b_idx, collider, off in self._meshes:
            b = self.boundaries[b_idx]
            mc = collider.contacts(p.x, p.radius, b.rotation, b.position)
            # contact point moved from the facet surface to mid-overlap (as for walls)
            pt = mc.point + (0.5 * mc.overlap)[:, None] * mc.normal
            out.append((mc.particle.astype(np.int64), mc.triangle.astype(np.int64) + off,
                        mc.normal, mc.overlap, pt))
        return out

    def _boundary_forces(self):
        p = self.particles
        n = p.n
        na = self._n_analytic
        start = self._b_start
        sl = slice(0, na)
        self._K.analytic_contacts_count(p.x, p.radius, self._etype[sl], self._ep, self._en,
                                        self._er[sl], self._ea0, self._ea1, start[1:])
        start[0] = 0
        nc = int(self._K.prefix_sum(start))
        c_p = np.empty(nc, np.int64)
        c_e = np.empty(nc, np.int64)
        c_n = np.empty((nc, 3))
        c_d = np.empty(nc)
        c_pt = np.empty((nc, 3))
        self._K.analytic_contacts_fill(p.x, p.radius, self._etype[sl], self._ep, self._en,
                                 self._er[sl], self._ea0, self._ea1, start, c_p, c_e, c_n, c_d,
                                 c_pt)
        extra = self._mesh_contacts()
        if extra:
            c_p = np.concatenate([c_p] + [a[0] for a in extra])
            c_e = np.concatenate([c_e] + [a[1] for a in extra])
            c_n = np.concatenate([c_n] + [a[2] for a in extra])
            c_d = np.concatenate([c_d] + [a[3] for a in extra])
            c_pt = np.concatenate([c_pt] + [a[4] for a in extra])
            order = np.argsort(c_p * self._key_mult + c_e, kind="stable")
            c_p, c_e, c_n, c_d, c_pt = c_p[order], c_e[order], c_n[order], c_d[order], c_pt[order]
            c_n = np.ascontiguousarray(c_n)
            c_pt = np.ascontiguousarray(c_pt)
        nc = c_p.shape[0]
        new_key = np.empty(nc, np.int64)
        new_hist = np.empty((nc, K.B_NCOL))
        self._b_force[:] = 0.0
        self._b_torque[:] = 0.0
        self._b_power[:] = 0.0
        self._K.boundary_forces(p.x, p.v, p.w, p.radius, p.mass, p.material, self._mat, c_p, c_e,
                                c_n,
                          c_d, c_pt, self._key_mult, self._etype, self._er, self._ebody,
                          self._b_mat, self._b_pos, self._b_vel, self._b_omg, self._b_ref,
                          self._bkey, self._bhist, new_key, new_hist, p.f, p.t, self._b_force,
                          self._b_torque, self._b_power, self._b_diss,
                          self.dt if hasattr(self, "dt") else 0.0, self._has_rot,
                          self._has_visc, self._has_roll)
        self._bkey = new_key
        self._bhist = new_hist
        self._c_p, self._c_e, self._c_n, self._c_d, self._c_pt = c_p, c_e, c_n, c_d, c_pt
        for b_idx, b in enumerate(self.boundaries):
            b.force[:] = self._b_force[b_idx]
            b.torque[:] = self._b_torque[b_idx]
            b._power = float(self._b_power[b_idx])

    # ------------------------------------------------------------------------------------------
    # stepping
    # ------------------------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps.

        Each step: bodies accumulate impulse/work of the wrench that drives the step; particles
        move by leapfrog; moving bodies advance (constant velocity or prescribed); the neighbour
        list is rebuilt when some particle moved more than skin/2; forces are evaluated at the
        new state.
        """
        n = int(n)
        if n < 0:
            raise ValueError(f"Simulation.step n={n}: must be >= 0")
        prev_threads = self._set_threads()
        try:
            if self._fused_ok():
                self._steps_fused(n)
            else:
                self._steps(n)
        finally:
            numba.set_num_threads(prev_threads)

    def _fused_ok(self) -> bool:
        return (FUSED_LOOP and self._parallel and not self._meshes
                and all(b.motion != "prescribed" for b in self.boundaries)
                and self._uniform_time())

    def _steps_fused(self, n: int) -> None:
        """n steps inside Numba (soil._kernels_loop.run_steps): same bits as ``_steps``."""
        if n == 0:
            return
        p = self.particles
        self._update_elements()  # poses may have been set by set_kinematics
        bodies = self.boundaries
        nb = len(bodies)
        moving = np.array([b.motion != "fixed" for b in bodies], dtype=np.bool_).reshape(nb)
        b_force = np.array([b.force for b in bodies], np.float64).reshape(nb, 3)
        b_torque = np.array([b.torque for b in bodies], np.float64).reshape(nb, 3)
        b_power = np.array([getattr(b, "_power", 0.0) for b in bodies], np.float64).reshape(nb)
        b_imp = np.array([b.impulse for b in bodies], np.float64).reshape(nb, 3)
        b_aimp = np.array([b.angular_impulse for b in bodies], np.float64).reshape(nb, 3)
        b_work = np.array([b.work for b in bodies], np.float64).reshape(nb)
        out = L.run_steps(
            n, self.dt, p.x, p.v, p.w, p.f, p.t, p.radius, p.mass, p.inv_mass, p.inv_inertia,
            p.material, self._mat, self.gravity, self.global_damping, self._e_glob, self._e_fric,
            self._e_visc, self._e_bond, self._x_ref, self.skin, self._is_large, self._large_idx,
            self._r_small, self._row_start, self._t_start, self._nbr_buf, self._hf_buf,
            self._hi_buf, self._tq_buf, self._tp_buf, self._s_j, self._s_f, self._s_i,
            self._cell_of, self._cell_start, self._cell_list, self._nbuf, self._b_start, self._m,
            self._n_analytic, self._etype, self._ebody,
            self._ep_body, self._en_body, self._er, self._ea0, self._ea1, self._ep, self._en,
            self._key_mult, self._b_mat, moving, self._b_pos, self._b_rot, self._b_vel,
            self._b_omg, self._b_refb, self._b_ref, b_force, b_torque, b_power, self._b_diss,
            b_imp, b_aimp, b_work, self._bkey, self._bhist, self._c_p, self._c_e, self._c_n,
            self._c_d, self._c_pt, self._has_rot, self._has_coh, self._has_roll, self._has_visc,
            self._fv)
        (self._nbr_buf, self._hf_buf, self._hi_buf, self._tq_buf, self._tp_buf, self._s_j,
         self._s_f, self._s_i, self._cell_start, self._nbuf, m, self._bkey, self._bhist,
         self._c_p, self._c_e, self._c_n, self._c_d, self._c_pt, nbuild, lost) = out
        self._m = int(m)
        self.n_builds += int(nbuild)
        self.bonds_lost_to_skin += int(lost)
        for k, b in enumerate(bodies):
            b.position[:] = self._b_pos[k]
            b.rotation[:] = self._b_rot[k]
            b.force[:] = b_force[k]
            b.torque[:] = b_torque[k]
            b._power = float(b_power[k])
            b.impulse[:] = b_imp[k]
            b.angular_impulse[:] = b_aimp[k]
            b.work = float(b_work[k])
        self.step_count += n
        self.time = self.step_count * self.dt

    def _steps(self, n: int) -> None:
        p = self.particles
        dt = self.dt
        half_skin2 = (0.5 * self.skin) ** 2
        for _ in range(n):
            for b in self.boundaries:
                b.impulse += b.force * dt
                b.angular_impulse += b.torque * dt
                b.work += getattr(b, "_power", 0.0) * dt
            moved = self._K.integrate(p.x, p.v, p.w, p.f, p.t, p.inv_mass, p.inv_inertia, dt,
                                self.global_damping, self._e_glob, self._x_ref, half_skin2,
                                self._has_rot)
            t_new = (self.step_count + 1) * dt if self._uniform_time() else self.time + dt
            if self._moving:
                for b in self._moving:
                    b.advance(dt, t_new)
            if self._moving or self._kin_dirty:
                self._update_elements()
                self._kin_dirty = bool(self._moving)
            if moved:
                self._build()
            self._compute_forces()
            self.time = t_new
            self.step_count += 1

    _kin_dirty = True

    def _uniform_time(self) -> bool:
        return getattr(self, "_t_uniform", True)

    def set_dt(self, dt: float) -> None:
        """Change the time step (checked against dt_critical)."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"Simulation.dt={dt!r}: must be > 0 [s]")
        if dt > self.dt_critical:
            raise ValueError(
                f"Simulation.dt={dt!r}: above the stable limit dt_critical={self.dt_critical!r} [s]"
            )
        self.dt = dt
        self._t_uniform = False

    def bodies_changed(self) -> None:
        """Call after editing body poses/velocities by hand (set_kinematics does not need it
        when the body is moving; fixed bodies do)."""
        self._kin_dirty = True

    # ------------------------------------------------------------------------------------------
    # bonds
    # ------------------------------------------------------------------------------------------
    def bond_contacts(self, tolerance: float = 0.0) -> int:
        """Bond all touching particle pairs of cohesive materials now (Yade setCohesionNow).

        Parameters
        ----------
        tolerance : float
            Pairs whose gap is <= tolerance [m] are bonded (0 = touching only).

        Returns
        -------
        int
            Number of bonds created.
        """
        if not self._has_coh:
            raise ValueError("Simulation.bond_contacts: no material has a soil.Cohesion")
        if tolerance < 0.0 or tolerance > 0.5 * self.skin:
            raise ValueError(
                f"Simulation.bond_contacts tolerance={tolerance!r}: must be in [0, skin/2="
                f"{0.5 * self.skin!r}] [m]"
            )
        p = self.particles
        return int(self._K.bond_touching(p.x, p.radius, p.material, self._mat, self._row_start,
                                   self._nbr, self._hf, self._hi, tolerance))

    # ------------------------------------------------------------------------------------------
    # diagnostics
    # ------------------------------------------------------------------------------------------
    def synchronized_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """Velocities at the current time t_n: v_n = v_{n-1/2} + dt F_n / (2 m) (and omega).

        ``particles.v`` / ``particles.w`` hold the leapfrog half-step values.
        """
        p = self.particles
        v = p.v + (0.5 * self.dt) * p.f * p.inv_mass[:, None]
        w = p.w + (0.5 * self.dt) * p.t * p.inv_inertia[:, None]
        return v, w

    def energy(self) -> dict:
        """Energy ledger [J] at the current time.

        Kinetic energies use the synchronised velocity v_n = v_{n-1/2} + dt F_n / (2 m)
        (velocity Verlet), consistent with positions and springs at t_n.

        Returns
        -------
        dict
            Keys of :data:`soil.energy.ENERGY_KEYS`.

        Notes
        -----
        Friction (and moment caps): centred capped-spring dissipation
        (``contact_laws.spring_dissipation``), equal to Yade's ((trial - capped)/ks) . capped in
        steady sliding but second order in dt when the cap varies; viscous: trapezoidal dashpot
        work (``contact_laws.normal_dissipation``); global damping: lambda |F| |v| (Yade
        NewtonIntegrator); gravity work: g . sum m (x - x_0).
        """
        p = self.particles
        dt = getattr(self, "dt", 0.0)
        v_sync = p.v + (0.5 * dt) * p.f * p.inv_mass[:, None]
        ke_t = kinetic(p.mass, v_sync)
        ke_r = 0.0
        if self._has_rot:
            w_sync = p.w + (0.5 * dt) * p.t * p.inv_inertia[:, None]
            ke_r = kinetic(p.inertia, w_sync)
        e_n, e_s, e_m = self._K.pair_elastic_energy(p.x, p.radius, p.material, self._mat,
                                              self._row_start, self._nbr, self._hf, self._hi,
                                              self._has_coh, self._has_mom)
        bh = self._bhist
        if bh.shape[0]:
            e_n += float(np.sum(bh[:, 13]))
            ks = bh[:, 8]
            fs2 = np.einsum("ij,ij->i", bh[:, :3], bh[:, :3])
            e_s += float(0.5 * np.sum(np.divide(fs2, ks, out=np.zeros_like(fs2), where=ks > 0)))
            kr = bh[:, 12]
            m2 = np.einsum("ij,ij->i", bh[:, 9:12], bh[:, 9:12])
            e_m += float(0.5 * np.sum(np.divide(m2, kr, out=np.zeros_like(m2), where=kr > 0)))
        visc = float(self._e_visc.sum() + self._b_diss[:, 1].sum())
        glob = float(self._e_glob.sum())
        mx = (p.mass[:, None] * p.x).sum(axis=0)
        e = {
            "kinetic_translational": ke_t,
            "kinetic_rotational": ke_r,
            "elastic": e_n + e_s + e_m,
            "elastic_normal": e_n,
            "elastic_shear": e_s,
            "elastic_moment": e_m,
            "dissipated_friction": float(self._e_fric.sum() + self._b_diss[:, 0].sum()),
            "dissipated_damping": visc + glob,
            "dissipated_viscous": visc,
            "dissipated_global": glob,
            "bond_dissipated": float(self._e_bond.sum()),
            "work_gravity": float(np.dot(self.gravity, mx - self._mx0)),
            "work_boundaries": float(sum(b.work for b in self.boundaries)),
        }
        return balance(e, getattr(self, "_total0", 0.0))

    def unbalanced_force(self) -> float:
        """Mean resultant force on the particles / mean contact force (Yade unbalancedForce).

        Notes
        -----
        Yade ``Shop::unbalancedForce`` (mean over dynamic bodies of |F + m g| divided by the mean
        over real interactions of |F_n + F_s|). Returns nan without contacts.
        """
        p = self.particles
        if p.n == 0:
            return float("nan")
        mean_f = float(np.mean(np.linalg.norm(p.f, axis=1)))
        c = self.contacts()
        if c["i"].shape[0] == 0:
            return float("nan")
        fc = np.linalg.norm(c["fn"][:, None] * c["normal"] + c["fs"], axis=1)
        return mean_f / float(np.mean(fc))

    def contacts(self) -> dict:
        """Active contacts for post-processing.

        Returns
        -------
        dict of arrays
            ``i`` particle, ``j`` second particle (-1 for a boundary), ``body`` (-1 for particle
            pairs), ``element`` (boundary element id, -1 for pairs), ``normal`` (from i/the wall
            towards j/the particle), ``fn`` normal force [N] (compression > 0), ``fs`` shear force
            on j/the particle [N] (the spring's plus a shear dashpot's), ``overlap`` [m],
            ``point`` [m], ``bonded`` (bool), ``moment`` contact moment (bending/rolling +
            twisting) acting on j [N m].
        """
        p = self.particles
        hf = self._hf
        touching = (hf[:, K.H_N] != 0.0) | (hf[:, K.H_N + 1] != 0.0) | (hf[:, K.H_N + 2] != 0.0)
        ks = np.flatnonzero(touching)
        rows = np.repeat(np.arange(p.n), np.diff(self._row_start))
        i = rows[ks]
        j = self._nbr[ks].astype(np.int64)
        nrm = hf[ks, K.H_N:K.H_N + 3]
        d = np.linalg.norm(p.x[j] - p.x[i], axis=1)
        ov = p.radius[i] + p.radius[j] - d
        pt = p.x[i] + (p.radius[i] - 0.5 * ov)[:, None] * nrm
        bonded = (self._hi[ks, K.I_BOND] == K.BOND_ACTIVE) if self._has_coh else np.zeros(
            ks.shape[0], bool)
        if hf.shape[1] >= K.H_NCOL_FULL:
            mom = hf[ks, K.H_MB:K.H_MB + 3] + hf[ks, K.H_MT:K.H_MT + 3]
        else:
            mom = np.zeros((ks.shape[0], 3))
        nb = self._c_p.shape[0]
        # the shear force: the spring's and, with a shear dashpot, the dashpot's of the step
        fs = hf[ks, K.H_FS:K.H_FS + 3]
        if self._fv >= 0:
            fs = fs + hf[ks, self._fv:self._fv + 3]
        bfs = self._bhist[:, :3]
        # a state restored from a checkpoint written before B_FV keeps its narrower history
        # until the next step
        if self._bhist.shape[1] >= K.B_FV + 3:
            bfs = bfs + self._bhist[:, K.B_FV:K.B_FV + 3]
        return {
            "i": np.concatenate([i, self._c_p]),
            "j": np.concatenate([j, -np.ones(nb, np.int64)]),
            "body": np.concatenate([-np.ones(i.shape[0], np.int64), self._ebody[self._c_e]]),
            "element": np.concatenate([-np.ones(i.shape[0], np.int64), self._c_e]),
            "normal": np.concatenate([nrm, self._c_n]),
            "fn": np.concatenate([hf[ks, K.H_FN], self._bhist[:, 6]]),
            "fs": np.concatenate([fs, bfs]),
            "overlap": np.concatenate([ov, self._c_d]),
            "point": np.concatenate([pt, self._c_pt]),
            "bonded": np.concatenate([bonded, np.zeros(nb, bool)]),
            "moment": np.concatenate([mom, np.zeros((nb, 3))]),
        }

    def n_contacts(self) -> int:
        """Number of active contacts (particle pairs in contact + boundary contacts), without
        building the post-processing arrays of :meth:`contacts`."""
        hf = self._hf
        touching = (hf[:, K.H_N] != 0.0) | (hf[:, K.H_N + 1] != 0.0) | (hf[:, K.H_N + 2] != 0.0)
        return int(np.count_nonzero(touching)) + int(self._c_p.shape[0])

    def memory_bytes(self) -> dict:
        """Memory held by the engine's arrays [bytes], buffers counted at their capacity.

        Returns
        -------
        dict
            ``particles`` (per-particle state and ledgers), ``pairs`` (neighbour list, history,
            transposed list: capacity), ``scratch`` (rebuild store of the pairs that carry
            history, cell grid, scan buffer, boundary scratch), ``boundary`` (boundary
            contacts), ``total``, ``per_particle`` (total / N), ``pairs_per_particle``
            (live pairs / N), ``pair_capacity``.

        Notes
        -----
        A rebuild allocates nothing while the capacities suffice, so ``total`` is the engine's
        peak: peak RSS = interpreter/Numba baseline + ``total`` + allocator slack
        (docs/performance.md).
        """
        p = self.particles
        per_particle = p.nbytes() + sum(
            a.nbytes for a in (self._x_ref, self._row_start, self._t_start, self._e_fric,
                               self._e_visc, self._e_glob, self._e_bond, self._is_large)
        )
        per_pair = sum(a.nbytes for a in (self._nbr_buf, self._hf_buf, self._hi_buf,
                                          self._tq_buf, self._tp_buf))
        scratch = sum(a.nbytes for a in (self._s_j, self._s_f, self._s_i, self._cell_of,
                                         self._cell_start, self._cell_list, self._nbuf,
                                         self._b_start))
        boundary = sum(a.nbytes for a in (self._bkey, self._bhist, self._c_p, self._c_e,
                                          self._c_n, self._c_d, self._c_pt))
        total = per_particle + per_pair + scratch + boundary
        return {"particles": per_particle, "pairs": per_pair, "scratch": scratch,
                "boundary": boundary, "total": total, "per_particle": total / max(p.n, 1),
                "pairs_per_particle": self._m / max(p.n, 1),
                "pair_capacity": int(self._nbr_buf.shape[0])}

    # ------------------------------------------------------------------------------------------
    # restart
    # ------------------------------------------------------------------------------------------
    _STATE = ("time", "step_count", "n_builds", "bonds_lost_to_skin", "dt", "dt_critical",
              "dt_pwave", "dt_stiffness", "_total0", "_x_ref", "_row_start", "_nbr", "_hf",
              "_hi", "_tq", "_t_start", "_t_pair", "_e_fric", "_e_visc", "_e_glob", "_e_bond",
              "_mx0", "_bkey", "_bhist", "_c_p", "_c_e", "_c_n", "_c_d", "_c_pt", "_b_force",
              "_b_torque", "_b_power", "_b_diss")

    def state_dict(self) -> dict:
        """Full restart state (copies). ``Simulation.from_state_dict`` restores it bit-exactly.

        Prescribed-motion callables are kept by reference (the dict is not meant for pickling
        across processes when they are lambdas).
        """
        d = {k: copy.deepcopy(getattr(self, k)) for k in self._STATE}
        d["_t_uniform"] = self._uniform_time()
        d["particles"] = self.particles.state_dict()
        d["materials"] = [m.to_dict() for m in self.materials]
        d["boundaries"] = [copy.copy(b) for b in self.boundaries]
        d["boundary_states"] = [b.state_dict() for b in self.boundaries]
        d["boundary_power"] = [getattr(b, "_power", 0.0) for b in self.boundaries]
        d["config"] = {"gravity": self.gravity.copy(), "safety": self.safety,
                       "global_damping": self.global_damping, "skin": self.skin,
                       "threads": self.threads}
        return d

    @classmethod
    def from_state_dict(cls, d: dict) -> "Simulation":
        """Rebuild a simulation from :meth:`state_dict` without re-evaluating any force."""
        sim = cls.__new__(cls)
        particles = Particles.from_state_dict(d["particles"])
        materials = [Material.from_dict(m) for m in d["materials"]]
        bodies = []
        for b, st, pw in zip(d["boundaries"], d["boundary_states"], d["boundary_power"]):
            nb = copy.copy(b)
            nb.position = np.zeros(3)
            nb.rotation = np.eye(3)
            nb.velocity = np.zeros(3)
            nb.angular_velocity = np.zeros(3)
            nb.force = np.zeros(3)
            nb.torque = np.zeros(3)
            nb.impulse = np.zeros(3)
            nb.angular_impulse = np.zeros(3)
            nb.load_state_dict(st)
            nb._power = pw
            bodies.append(nb)
        c = d["config"]
        sim._configure(particles, materials, bodies, c["gravity"], c["safety"],
                       c["global_damping"], c["skin"], c["threads"])
        # restore the exact arrays (set_masses recomputed identical values from the same inputs)
        for k, v in d["particles"].items():
            getattr(particles, k)[...] = v
        sim._init_state()
        for k in cls._STATE:
            setattr(sim, k, copy.deepcopy(d[k]))
        sim._t_uniform = d["_t_uniform"]
        sim._update_elements()
        return sim
