"""Numba kernels of the soil DEM engine (arrays and scalars only).

Determinism: every ``prange`` iteration writes only its own index. Pair forces are stored per
pair (half list, row i holds j > i) and gathered per particle in a fixed order (own row, then the
transposed list sorted by pair index), so the result is bit-identical for any thread count.
"""

from __future__ import annotations

import functools
import math
import types

import numba
import numpy as np
from numba import prange

from soil.contact_laws import (
    coulomb_cap,
    cohesive_normal_force,
    cohesive_shear_cap,
    LAW_HERTZ_MINDLIN,
    damping_coefficient,
    hertz_coefficients,
    hertz_damping_coefficient,
    hertz_normal_dissipation,
    linear_normal_force,
    normal_dissipation,
    moment_cap,
    normal_stiffness,
    rolling_stiffness,
    rotate_shear,
    shear_stiffness,
    spring_dissipation,
    varying_spring_dissipation,
)

#: digest of the jitted sources compiled into these kernels (Numba's disk cache is per file;
#: tests/test_numba_cache_deps.py names the new value when one of them changes)
NUMBA_CACHE_DEPENDS = "b43a798ee4cde0ad"

jit = functools.partial(numba.njit, cache=True)


class _Dual:
    """A kernel compiled twice: ``parallel=True`` (prange over threads) and serial (prange runs
    as range; used for small systems or one thread, where thread start-up dominates)."""

    def __init__(self, py_func):
        self.parallel = numba.njit(cache=True, parallel=True)(py_func)
        serial = types.FunctionType(py_func.__code__, py_func.__globals__,
                                    py_func.__name__ + "_serial", py_func.__defaults__,
                                    py_func.__closure__)
        serial.__qualname__ = py_func.__qualname__ + "_serial"
        serial.__module__ = py_func.__module__
        self.serial = numba.njit(cache=True)(serial)
        self.__doc__ = py_func.__doc__
        self.__name__ = py_func.__name__

    def __call__(self, *args):
        return self.parallel(*args)


def pjit(py_func):
    return _Dual(py_func)

# material table columns
M_YOUNG = 0
M_RATIO = 1
M_TANPHI = 2
M_RESTITUTION = 3  # 1.0 = no viscous damping
M_COHESIVE = 4
M_SN = 5
M_SS = 6
M_AKR = 7
M_AKTW = 8
M_ETA_R = 9  # < 0 = no cap
M_ETA_T = 10
M_PLASTIC = 11
M_MOMENTS = 12
M_MU_R = 13  # < 0 = no rolling resistance
M_DENSITY = 14
M_TENSION = 15  # > 0: the normal dashpot may pull while the contact opens
M_LAW = 16  # contact_laws.LAW_LINEAR / LAW_HERTZ_MINDLIN
M_POISSON = 17  # Poisson's ratio (Hertz-Mindlin)
M_SHEAR_RESTITUTION = 18  # shear dashpot; 1.0 = none
# contact_laws.damping_ratio of M_RESTITUTION / M_SHEAR_RESTITUTION (the same compiled function,
# so the same bits as evaluating it per contact; 0.0 for 1.0 = none)
M_ZETA = 19
M_SHEAR_ZETA = 20
M_NCOL = 21

# pair state flags
BOND_NONE = 0
BOND_ACTIVE = 1

# boundary contact history columns: Fs[3], n[3], fn, kn, ks, M_roll[3], kr, normal elastic
# energy (kn: the tangent normal stiffness, for the time step), the shear dashpot's force[3]
# (the step's, not history: Fs is the elastic spring)
B_NCOL = 17
B_FV = 14

# boundary element types
E_PLANE = 0
E_CYLINDER = 1
E_SPHERE = 2
E_FACET = 3


# ----------------------------------------------------------------------------------------------
# integration
# ----------------------------------------------------------------------------------------------
@numba.njit(cache=True, inline="always")
def _cundall_damped(fk, vk, inv_m, dt, damping, e_glob, i):
    """One component of a force (or torque) under Cundall non-viscous damping: ``fk`` reduced
    (increased) by ``damping |fk|`` when it drives (opposes) the mid-step velocity
    ``vk + dt fk inv_m / 2``; the dissipated work ``damping |fk v_mid| dt`` goes to
    ``e_glob[i]``."""
    vm = vk + 0.5 * dt * fk * inv_m
    s = fk * vm
    if s > 0.0:
        e_glob[i] += damping * abs(fk * vm) * dt
        return fk * (1.0 - damping)
    if s < 0.0:
        e_glob[i] += damping * abs(fk * vm) * dt
        return fk * (1.0 + damping)
    return fk


@pjit
def integrate(x, v, w, f, t, inv_mass, inv_inertia, dt, damping, e_glob, x_ref, half_skin2,
              has_rot):
    """Leapfrog update v += dt F/m, x += dt v (and w += dt T/I); returns #particles that moved
    more than skin/2 since the last neighbour build.

    Notes
    -----
    Leapfrog/velocity Verlet (ARCHITECTURE section 1). Cundall non-viscous damping
    F <- F - lambda sign(F v_mid) |F| per component, v_mid = v + dt F / (2m) (Yade
    ``NewtonIntegrator.damping``); its power lambda |F||v_mid| is accumulated in ``e_glob``.
    """
    n = x.shape[0]
    moved = 0
    for i in prange(n):
        im = inv_mass[i]
        for k in range(3):
            fk = f[i, k]
            if damping > 0.0:
                fk = _cundall_damped(fk, v[i, k], im, dt, damping, e_glob, i)
            v[i, k] += dt * fk * im
            x[i, k] += dt * v[i, k]
        if has_rot:
            ii = inv_inertia[i]
            if ii > 0.0:
                for k in range(3):
                    tk = t[i, k]
                    if damping > 0.0:
                        tk = _cundall_damped(tk, w[i, k], ii, dt, damping, e_glob, i)
                    w[i, k] += dt * tk * ii
        dx = x[i, 0] - x_ref[i, 0]
        dy = x[i, 1] - x_ref[i, 1]
        dz = x[i, 2] - x_ref[i, 2]
        if dx * dx + dy * dy + dz * dz > half_skin2:
            moved += 1
    return moved


# ----------------------------------------------------------------------------------------------
# neighbour search
# ----------------------------------------------------------------------------------------------
# Memory layout (see docs/performance.md): the rebuild works in persistent buffers owned by the
# Simulation and allocates nothing while their capacities suffice.  The contact history of the
# pairs that carry any (touching or bonded pairs; the other rows are all-zero) is first saved
# into a compact store (CSR by row, ``s_start``), the new half list is written into the same
# pair buffers, and the history is restored from the store.  Peak = the pair buffers + the
# store of the active pairs (about a third of the Verlet pairs), instead of two full lists.
@jit
def cell_sort_into(x, is_large, lo, inv_cell, nx, ny, nz, cell_of, cell_start, cell_list):
    """Counting sort of the small particles into cells, in place.

    ``cell_start`` needs at least ncell + 2 entries; on return cell c holds
    ``cell_list[cell_start[c]:cell_start[c + 1]]`` in increasing particle index.
    """
    n = x.shape[0]
    ncell = nx * ny * nz
    for c in range(ncell + 2):
        cell_start[c] = 0
    for i in range(n):
        if is_large[i]:
            cell_of[i] = -1
            continue
        cx = int((x[i, 0] - lo[0]) * inv_cell)
        cy = int((x[i, 1] - lo[1]) * inv_cell)
        cz = int((x[i, 2] - lo[2]) * inv_cell)
        cx = min(max(cx, 0), nx - 1)
        cy = min(max(cy, 0), ny - 1)
        cz = min(max(cz, 0), nz - 1)
        c = (cz * ny + cy) * nx + cx
        cell_of[i] = c
        cell_start[c + 2] += 1
    for c in range(1, ncell + 1):
        cell_start[c + 1] += cell_start[c]
    # cell_start[c + 1] is now the start of cell c; placing advances it to the start of c + 1
    for i in range(n):
        c = cell_of[i]
        if c >= 0:
            q = cell_start[c + 1]
            cell_list[q] = i
            cell_start[c + 1] = q + 1


@numba.njit(cache=True, inline="always")
def _row_scan(i, x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny, nz,
              skin, out, write, cap):
    """Neighbours j > i of particle i within r_i + r_j + skin; writes them to ``out`` if
    ``write``; returns the count (unsorted)."""
    cnt = 0
    xi = x[i, 0]
    yi = x[i, 1]
    zi = x[i, 2]
    ri = radius[i] + skin
    n = x.shape[0]
    if is_large[i]:
        for j in range(i + 1, n):
            dx = x[j, 0] - xi
            dy = x[j, 1] - yi
            dz = x[j, 2] - zi
            rc = ri + radius[j]
            if dx * dx + dy * dy + dz * dz < rc * rc:
                if write and cnt < cap:
                    out[cnt] = j
                cnt += 1
        return cnt
    c = cell_of[i]
    cx = c % nx
    cy = (c // nx) % ny
    cz = c // (nx * ny)
    for kz in range(max(cz - 1, 0), min(cz + 2, nz)):
        for ky in range(max(cy - 1, 0), min(cy + 2, ny)):
            base = (kz * ny + ky) * nx
            for kx in range(max(cx - 1, 0), min(cx + 2, nx)):
                cc = base + kx
                for q in range(cell_start[cc], cell_start[cc + 1]):
                    j = cell_list[q]
                    if j <= i:
                        continue
                    dx = x[j, 0] - xi
                    dy = x[j, 1] - yi
                    dz = x[j, 2] - zi
                    rc = ri + radius[j]
                    if dx * dx + dy * dy + dz * dz < rc * rc:
                        if write and cnt < cap:
                            out[cnt] = j
                        cnt += 1
    for q in range(large_idx.shape[0]):
        j = large_idx[q]
        if j <= i:
            continue
        dx = x[j, 0] - xi
        dy = x[j, 1] - yi
        dz = x[j, 2] - zi
        rc = ri + radius[j]
        if dx * dx + dy * dy + dz * dz < rc * rc:
            if write and cnt < cap:
                out[cnt] = j
            cnt += 1
    return cnt


@numba.njit(cache=True, inline="always")
def _sort_row(row, m):
    """Insertion sort of row[:m] (rows are short)."""
    for p in range(1, m):
        key = row[p]
        q = p - 1
        while q >= 0 and row[q] > key:
            row[q + 1] = row[q]
            q -= 1
        row[q + 1] = key


@pjit
def scan_neighbours(x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny, nz,
                    skin, buf, counts):
    """Single pass: neighbours of row i into ``buf[i, :cap]`` (sorted) and the full count
    into ``counts[i]``."""
    n = x.shape[0]
    cap = buf.shape[1]
    # particles in cell order (the small ones, then the large): neighbouring iterations read
    # the same cells, so the candidates come from cache (the scan of the 40,667-grain benchmark
    # bed: 25.3 -> 22.1 ms on 1 thread, 17.3 -> 12.7 ms on 2; docs/performance.md); each row
    # is still sorted, so the rows do not depend on the order
    n_small = cell_start[nx * ny * nz]
    for q in prange(n):
        i = cell_list[q] if q < n_small else large_idx[q - n_small]
        row = buf[i]
        c = _row_scan(i, x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny,
                      nz, skin, row, True, cap)
        counts[i] = c
        _sort_row(row, min(c, cap))


@pjit
def place_neighbours(x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny,
                     nz, skin, buf, row_start, nbr):
    """Rows into the CSR list: copied from ``buf``, or re-scanned when longer than its
    width."""
    n = buf.shape[0]
    cap = buf.shape[1]
    for i in prange(n):
        a = row_start[i]
        m = row_start[i + 1] - a
        if m <= cap:
            for k in range(m):
                nbr[a + k] = buf[i, k]
        else:
            row = nbr[a:a + m]
            _row_scan(i, x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny,
                      nz, skin, row, True, m)
            _sort_row(row, m)


@jit
def bounds(x, is_large):
    """Lower and upper corners of the small particles' centres (all if none is small)."""
    n = x.shape[0]
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    any_small = False
    for i in range(n):
        if is_large[i]:
            continue
        any_small = True
        for k in range(3):
            v = x[i, k]
            if v < lo[k]:
                lo[k] = v
            if v > hi[k]:
                hi[k] = v
    if not any_small:
        for i in range(n):
            for k in range(3):
                lo[k] = min(lo[k], x[i, k])
                hi[k] = max(hi[k], x[i, k])
    return lo, hi


@jit
def _find(nbr, a, b, j):
    """Binary search of j in the sorted slice nbr[a:b]; returns the index or -1."""
    lo = a
    hi = b
    while lo < hi:
        mid = (lo + hi) >> 1
        v = nbr[mid]
        if v < j:
            lo = mid + 1
        else:
            hi = mid
    if lo < b and nbr[lo] == j:
        return lo
    return -1


@numba.njit(cache=True, inline="always")
def _carries_history(hf, hi, k):
    """True when pair k's history row is not all +0.0 / 0 (exact bit test: -0.0 counts)."""
    for c in range(hf.shape[1]):
        v = hf[k, c]
        if v != 0.0 or math.copysign(1.0, v) < 0.0:
            return True
    for c in range(hi.shape[1]):
        if hi[k, c] != 0:
            return True
    return False


#: row chunks of the per-row pair kernels (``balanced_rows``): a row holds the pairs (i, j > i),
#: so with the rows in index order the first half of them holds about three quarters of the
#: pairs, and a prange split by rows left one of two threads with 80 % of the work (measured on
#: the 40,667-grain benchmark bed: 113,727 pairs in the first half, 27,656 in the second)
ROW_CHUNKS = 256


@jit
def balanced_rows(row_start, n, n_chunks):
    """Row boundaries of ``n_chunks`` consecutive chunks of rows 0..n-1 with about equal work
    (pairs + rows, from the CSR ``row_start``); empty chunks where rows are few. Each row is
    still computed whole, in order, by one iteration: the result does not depend on the
    chunks."""
    out = np.empty(n_chunks + 1, np.int64)
    out[0] = 0
    total = row_start[n] - row_start[0] + n
    i = 0
    for c in range(1, n_chunks):
        target = (total * c) // n_chunks
        while i < n and row_start[i] - row_start[0] + i < target:
            i += 1
        out[c] = i
    out[n_chunks] = n
    return out


@pjit
def count_history(row_start, hf, hi, counts):
    """Number of pairs of each row that carry history (``counts[i]``)."""
    n = counts.shape[0]
    chunks = balanced_rows(row_start, n, ROW_CHUNKS)
    for ch in prange(ROW_CHUNKS):
        for i in range(chunks[ch], chunks[ch + 1]):
            c = 0
            for k in range(row_start[i], row_start[i + 1]):
                if _carries_history(hf, hi, k):
                    c += 1
            counts[i] = c


@pjit
def save_history(row_start, nbr, hf, hi, s_start, s_j, s_f, s_i):
    """Copy the pairs that carry history into the store (row i at s_start[i]:s_start[i+1])."""
    n = s_start.shape[0] - 1
    kf = hf.shape[1]
    ki = hi.shape[1]
    chunks = balanced_rows(row_start, n, ROW_CHUNKS)
    for ch in prange(ROW_CHUNKS):
        for i in range(chunks[ch], chunks[ch + 1]):
            w = s_start[i]
            for k in range(row_start[i], row_start[i + 1]):
                if _carries_history(hf, hi, k):
                    s_j[w] = nbr[k]
                    for c in range(kf):
                        s_f[w, c] = hf[k, c]
                    for c in range(ki):
                        s_i[w, c] = hi[k, c]
                    w += 1


@pjit
def restore_history(s_start, s_j, s_f, s_i, row_start, nbr, hf, hi):
    """History of the new list from the store (sorted merge per row); other pairs get zeros.

    Same result as copying the old row of every surviving pair: a pair absent from the store
    had an all-zero row.
    """
    n = row_start.shape[0] - 1
    kf = hf.shape[1]
    ki = hi.shape[1]
    chunks = balanced_rows(row_start, n, ROW_CHUNKS)
    for ch in prange(ROW_CHUNKS):
        for i in range(chunks[ch], chunks[ch + 1]):
            q = s_start[i]
            qe = s_start[i + 1]
            for k in range(row_start[i], row_start[i + 1]):
                j = nbr[k]
                while q < qe and s_j[q] < j:
                    q += 1  # stored pair no longer in the list (only bonds can: lost_bonds)
                if q < qe and s_j[q] == j:
                    for c in range(kf):
                        hf[k, c] = s_f[q, c]
                    for c in range(ki):
                        hi[k, c] = s_i[q, c]
                    q += 1
                else:
                    for c in range(kf):
                        hf[k, c] = 0.0
                    for c in range(ki):
                        hi[k, c] = 0


@jit
def lost_bonds(s_start, s_j, s_i, row_start, nbr):
    """Number of active bonds of the store that are absent from the new list."""
    n = row_start.shape[0] - 1
    lost = 0
    if s_i.shape[1] == 0:
        return 0
    for i in range(n):
        for q in range(s_start[i], s_start[i + 1]):
            if s_i[q, 0] == BOND_ACTIVE:
                if _find(nbr, row_start[i], row_start[i + 1], s_j[q]) < 0:
                    lost += 1
    return lost


@jit
def transpose_into(row_start, nbr, t_start, t_pair, fill):
    """CSR of pair indices by second particle j, each list in increasing pair index.

    ``fill`` is an (n,) integer scratch array."""
    n = row_start.shape[0] - 1
    m = row_start[n]
    for i in range(n + 1):
        t_start[i] = 0
    for k in range(m):
        t_start[nbr[k] + 1] += 1
    for i in range(n):
        t_start[i + 1] += t_start[i]
    for i in range(n):
        fill[i] = t_start[i]
    for k in range(m):
        j = nbr[k]
        t_pair[fill[j]] = k
        fill[j] += 1


@jit
def prefix_sum(a):
    """In place: a[0] = 0 is kept, a[k + 1] += a[k] (counts in a[1:] -> CSR starts)."""
    for k in range(a.shape[0] - 1):
        a[k + 1] += a[k]
    return a[a.shape[0] - 1]


# ----------------------------------------------------------------------------------------------
# pair forces
# ----------------------------------------------------------------------------------------------
# per-pair float history columns
H_FS = 0  # 0..2 shear spring (force on j) [N]
H_N = 3  # 3..5 unit normal of the last step (0 = new contact)
H_FN = 6  # normal force [N] (compression > 0)
H_NCOL_BASIC = 7
# cohesive / moment extension columns
H_AN = 7  # normal adhesion [N]
H_AT = 8  # shear adhesion [N]
H_UNP = 9  # plastic normal displacement [m]
H_MB = 10  # 10..12 bending / rolling moment on j [N m]
H_MT = 13  # 13..15 twisting moment on j [N m]
H_NCOL_FULL = 16
# shear dashpot (a material with ``shear_restitution``): three more columns after the basic or
# full layout, the viscous shear force on j of the step [N] (``fv`` = their first index; the
# shear spring in H_FS stays elastic)
# Hertz-Mindlin pairs: one more column, the last (``hf.shape[1] - 1``): the overlap of the last
# step [m], the stiffness the shear spring was made with (basic layout 8, full 17 columns)
# per-pair int history columns
I_BOND = 0


@numba.njit(cache=True, inline="always")
def _pair_mean(a1, a2):
    """Harmonic mean 2 a1 a2 / (a1 + a2) of two materials' coefficients (0 if both are 0)."""
    return 2.0 * a1 * a2 / (a1 + a2) if a1 + a2 > 0.0 else 0.0


@numba.njit(cache=True, inline="always")
def _clear_pair(hf, tq, k, has_rot):
    """Pair k carries no contact any more: its history (and its torques) set to zero."""
    for c in range(hf.shape[1]):
        hf[k, c] = 0.0
    if has_rot:
        for c in range(6):
            tq[k, c] = 0.0


@numba.njit(cache=True, inline="always")
def _is_hertz(mat, ma, mb):
    """A contact of materials ``ma`` and ``mb`` follows the Hertz-Mindlin law (either has it)."""
    return mat[ma, M_LAW] == LAW_HERTZ_MINDLIN or mat[mb, M_LAW] == LAW_HERTZ_MINDLIN


@numba.njit(cache=True, inline="always")
def _soften(tx, ty, tz, ox, oy, oz, k, k_old):
    """Thornton's unloading rule on a trial spring ``t = o - k du``: when the stiffness fell
    from ``k_old`` to ``k`` the stored part ``o`` is scaled by k / k_old (the spring sheds
    energy instead of making it); unchanged otherwise."""
    if k < k_old:
        sc = k / k_old - 1.0
        return tx + sc * ox, ty + sc * oy, tz + sc * oz
    return tx, ty, tz


@numba.njit(cache=True, inline="always")
def _shear_trial(vrx, vry, vrz, nx, ny, nz, fx, fy, fz, n0x, n0y, n0z, twist, ks, dt):
    """The step's trial shear force of a contact (Cundall-Strack, shared by the particle pairs
    and the boundary contacts): the normal approach rate ``delta_dot = -v_r . n``, the stored
    shear force ``(fx, fy, fz)`` rotated from the old normal and twisted (``rotate_shear``) as
    ``(ox, oy, oz)``, the tangential displacement ``du = (v_r - (v_r . n) n) dt`` and the trial
    force ``o - k_s du``; returns ``(delta_dot, ox, oy, oz, dux, duy, duz, fsx, fsy, fsz)``."""
    vn = vrx * nx + vry * ny + vrz * nz
    ox, oy, oz = rotate_shear(fx, fy, fz, n0x, n0y, n0z, nx, ny, nz, twist)
    dux = (vrx - vn * nx) * dt
    duy = (vry - vn * ny) * dt
    duz = (vrz - vn * nz) * dt
    return -vn, ox, oy, oz, dux, duy, duz, ox - ks * dux, oy - ks * duy, oz - ks * duz


@numba.njit(cache=True, inline="always")
def _pair_damping(mat, a, b, e_col, z_col):
    """Restitution and damping ratio of a contact between materials ``a`` and ``b``: the lower
    restitution ``e = min(mat[a, e_col], mat[b, e_col])`` and ``damping_ratio(e)``, read from
    the table's column ``z_col`` of the material that has it (``M_ZETA`` / ``M_SHEAR_ZETA``,
    filled by the same compiled ``damping_ratio``: the same bits as evaluating it here, without
    its log and square root per contact and step); returns ``(e, zeta)``."""
    ea = mat[a, e_col]
    eb = mat[b, e_col]
    if ea <= eb:
        return ea, mat[a, z_col]
    return eb, mat[b, z_col]


@numba.njit(cache=True, inline="always")
def _shear_dashpot(zeta, m_eff, ks, hertz, dux, duy, duz, dt):
    """Viscous shear force of a sticking contact whose shear restitution e_s < 1 has the damping
    ratio ``zeta`` = ``damping_ratio(e_s)`` (``_pair_damping``) and the energy it dissipates over
    the step: ``f_v = -c_s du / dt`` with c_s the critical damping of the shear spring ``ks``
    (tangent, Hertz-Mindlin: Tsuji's form, as the normal dashpot's) scaled by ``zeta``, and
    ``c_s |du|^2 / dt`` [J]; returns ``(fvx, fvy, fvz, dissipated)``."""
    if dt <= 0.0:
        # the force evaluation before the first step (no displacement, no rate yet)
        return 0.0, 0.0, 0.0, 0.0
    if hertz:
        cs = hertz_damping_coefficient(zeta, m_eff, ks)
    else:
        cs = damping_coefficient(zeta, m_eff, ks)
    c = cs / dt
    return -c * dux, -c * duy, -c * duz, c * (dux * dux + duy * duy + duz * duz)


@pjit
def pair_forces(x, v, w, radius, mass, mat_id, mat, row_start, nbr, hf, hi, tq, dt, has_rot,
                has_coh, has_roll, has_visc, e_fric, e_visc, e_bond, fv):
    """Contact forces of the half neighbour list, written per pair.

    For each pair k = (i, j): ``hf[k]`` holds the shear spring, normal and normal force (the
    force on j is fn n + Fs; on i its opposite). With rotations, ``tq[k, 0:3]`` / ``tq[k, 3:6]``
    receive the torques on i / j. Dissipation is accumulated on the row owner i. ``fv`` >= 0:
    the first of the three columns of ``hf`` that receive the viscous shear force of a shear
    dashpot (``Material.shear_restitution``; -1: no material has one).

    Notes
    -----
    Cundall-Strack linear law (Yade ``Law2_ScGeom_FrictPhys_CundallStrack``), cohesive moment
    law (Yade ``Law2_ScGeom6D_CohFrictPhys_CohesionMoment``), rolling resistance (Ai et al. 2011
    type C); stiffness from ``soil.contact_laws``. A pair of which either material has
    ``M_LAW`` = Hertz-Mindlin and no bond: F_n = k_no delta^1.5, k_s = k_so sqrt(delta) with the
    stored shear (and rolling) spring scaled by k_new / k_old when it softens (Thornton),
    Tsuji's dashpot, the overlap kept in the last column of ``hf`` (Yade
    ``Law2_ScGeom_MindlinPhys_Mindlin``, which does not scale).
    """
    n = x.shape[0]
    dn = hf.shape[1] - 1  # Hertz-Mindlin: the last step's overlap
    chunks = balanced_rows(row_start, n, ROW_CHUNKS)
    for ch in prange(ROW_CHUNKS):
        for i in range(chunks[ch], chunks[ch + 1]):
            ri = radius[i]
            mi = mat_id[i]
            ei = mat[mi, M_YOUNG]
            nui = mat[mi, M_RATIO]
            tpi = mat[mi, M_TANPHI]
            xi0 = x[i, 0]
            xi1 = x[i, 1]
            xi2 = x[i, 2]
            fric_acc = 0.0
            visc_acc = 0.0
            bond_acc = 0.0
            for k in range(row_start[i], row_start[i + 1]):
                j = nbr[k]
                dx = x[j, 0] - xi0
                dy = x[j, 1] - xi1
                dz = x[j, 2] - xi2
                rj = radius[j]
                d2 = dx * dx + dy * dy + dz * dz
                rs = ri + rj
                bonded = False
                if has_coh:
                    bonded = hi[k, I_BOND] == BOND_ACTIVE
                if not bonded and d2 >= rs * rs:
                    if hf[k, H_N] != 0.0 or hf[k, H_N + 1] != 0.0 or hf[k, H_N + 2] != 0.0:
                        _clear_pair(hf, tq, k, has_rot)
                    continue
                dist = math.sqrt(d2)
                inv_d = 1.0 / dist
                nx = dx * inv_d
                ny = dy * inv_d
                nz = dz * inv_d
                delta = rs - dist
                mj = mat_id[j]
                ej = mat[mj, M_YOUNG]
                n0x = hf[k, H_N]
                n0y = hf[k, H_N + 1]
                n0z = hf[k, H_N + 2]
                fresh = n0x == 0.0 and n0y == 0.0 and n0z == 0.0
                if fresh:
                    n0x = nx
                    n0y = ny
                    n0z = nz
                # a bond is the cohesive law's linear springs; a contact without one is Hertz's
                hertz_pair = _is_hertz(mat, mi, mj)
                hertz = hertz_pair and not bonded
                kno = 0.0
                sd = 0.0
                d_old = delta
                if hertz:
                    # delta > 0: an unbonded pair apart was skipped above
                    kno, kso = hertz_coefficients(ei, mat[mi, M_POISSON], ej, mat[mj, M_POISSON],
                                                  ri * rj / (ri + rj))
                    sd = math.sqrt(delta)
                    kn = 1.5 * kno * sd  # tangent normal stiffness
                    ks = kso * sd
                    if not fresh:
                        d_old = hf[k, dn]
                    ks_old = kso * math.sqrt(d_old)
                else:
                    kn = normal_stiffness(ei, ri, ej, rj)
                    ks = shear_stiffness(ei, ri, nui, ej, rj, mat[mj, M_RATIO])
                    ks_old = ks
                tan_phi = min(tpi, mat[mj, M_TANPHI])
                # relative velocity of j w.r.t. i at the contact point
                vrx = v[j, 0] - v[i, 0]
                vry = v[j, 1] - v[i, 1]
                vrz = v[j, 2] - v[i, 2]
                twist = 0.0
                ai = ri - 0.5 * delta
                aj = rj - 0.5 * delta
                if has_rot:
                    # w_j x (-aj n) - w_i x (ai n)
                    sx = -(aj * w[j, 0] + ai * w[i, 0])
                    sy = -(aj * w[j, 1] + ai * w[i, 1])
                    sz = -(aj * w[j, 2] + ai * w[i, 2])
                    vrx += sy * nz - sz * ny
                    vry += sz * nx - sx * nz
                    vrz += sx * ny - sy * nx
                    twist = 0.5 * dt * (nx * (w[i, 0] + w[j, 0]) + ny * (w[i, 1] + w[j, 1])
                                        + nz * (w[i, 2] + w[j, 2]))
                delta_dot, ox, oy, oz, dux, duy, duz, fsx, fsy, fsz = _shear_trial(
                    vrx, vry, vrz, nx, ny, nz, hf[k, H_FS], hf[k, H_FS + 1], hf[k, H_FS + 2],
                    n0x, n0y, n0z, twist, ks, dt)
                fsx, fsy, fsz = _soften(fsx, fsy, fsz, ox, oy, oz, ks, ks_old)
                fvx = 0.0
                fvy = 0.0
                fvz = 0.0
                if bonded:
                    an = hf[k, H_AN]
                    at = hf[k, H_AT]
                    plastic = mat[mi, M_PLASTIC] > 0.0 and mat[mj, M_PLASTIC] > 0.0
                    unp = hf[k, H_UNP]
                    fn, unp_new, broken_n, wp = cohesive_normal_force(kn, delta, unp, an, plastic)
                    bond_acc += wp
                    if broken_n:
                        # elastic energy released by the broken tensile spring
                        bond_acc += 0.5 * an * an / kn
                        bonded = False
                        hi[k, I_BOND] = BOND_NONE
                        at = 0.0
                        hf[k, H_AN] = 0.0
                        hf[k, H_AT] = 0.0
                        unp_new = 0.0
                    hf[k, H_UNP] = unp_new
                    fsx, fsy, fsz, _d, broken_s = cohesive_shear_cap(fsx, fsy, fsz, fn, tan_phi,
                                                                     at, bonded, ks)
                    fric_acc += spring_dissipation(ox, oy, oz, fsx, fsy, fsz, dux, duy, duz, ks)
                    if broken_s:
                        bonded = False
                        hi[k, I_BOND] = BOND_NONE
                        hf[k, H_AN] = 0.0
                        hf[k, H_AT] = 0.0
                        hf[k, H_UNP] = 0.0
                        if fn < 0.0:
                            bond_acc += 0.5 * fn * fn / kn
                            fn = 0.0
                    if not bonded and delta <= 0.0:
                        # bond gone and spheres apart: the contact no longer exists
                        _clear_pair(hf, tq, k, has_rot)
                        continue
                    if hertz_pair:
                        # the overlap a Hertz contact starts from if the bond breaks
                        hf[k, dn] = delta if delta > 0.0 else 0.0
                else:
                    cn = 0.0
                    pulls = False
                    if has_visc:
                        e_pair, zeta = _pair_damping(mat, mi, mj, M_RESTITUTION, M_ZETA)
                        if e_pair < 1.0:
                            m_eff = mass[i] * mass[j] / (mass[i] + mass[j])
                            if hertz:
                                cn = hertz_damping_coefficient(zeta, m_eff, kn)
                            else:
                                cn = damping_coefficient(zeta, m_eff, kn)
                            pulls = mat[mi, M_TENSION] > 0.0 or mat[mj, M_TENSION] > 0.0
                    fn_old = hf[k, H_FN]
                    if hertz:
                        # secant stiffness k_no sqrt(delta): the elastic force k_no delta^1.5
                        fn, f_visc = linear_normal_force(kno * sd, delta, cn, delta_dot, pulls)
                        if cn > 0.0:
                            d_prev = delta - delta_dot * dt if fresh else d_old
                            visc_acc += hertz_normal_dissipation(fn_old, fn, delta, d_prev, kno)
                        hf[k, dn] = delta
                    else:
                        fn, f_visc = linear_normal_force(kn, delta, cn, delta_dot, pulls)
                        if cn > 0.0:
                            visc_acc += normal_dissipation(fn_old, fn, delta, delta_dot * dt, kn)
                    fsx, fsy, fsz, _d, slid = coulomb_cap(fsx, fsy, fsz, fn * tan_phi, ks)
                    if hertz:
                        fric_acc += varying_spring_dissipation(ox, oy, oz, fsx, fsy, fsz, dux,
                                                               duy, duz, ks_old, ks)
                    else:
                        fric_acc += spring_dissipation(ox, oy, oz, fsx, fsy, fsz, dux, duy, duz,
                                                       ks)
                    if fv >= 0 and not slid:
                        e_s, zeta_s = _pair_damping(mat, mi, mj, M_SHEAR_RESTITUTION,
                                                    M_SHEAR_ZETA)
                        if e_s < 1.0:
                            fvx, fvy, fvz, wv = _shear_dashpot(
                                zeta_s, mass[i] * mass[j] / (mass[i] + mass[j]), ks, hertz, dux,
                                duy, duz, dt)
                            visc_acc += wv
                hf[k, H_FS] = fsx
                hf[k, H_FS + 1] = fsy
                hf[k, H_FS + 2] = fsz
                if fv >= 0:
                    # the spring keeps its elastic force; the step's force adds the dashpot's
                    hf[k, fv] = fvx
                    hf[k, fv + 1] = fvy
                    hf[k, fv + 2] = fvz
                    fsx += fvx
                    fsy += fvy
                    fsz += fvz
                hf[k, H_N] = nx
                hf[k, H_N + 1] = ny
                hf[k, H_N + 2] = nz
                hf[k, H_FN] = fn
                if has_rot:
                    fx = fn * nx + fsx
                    fy = fn * ny + fsy
                    fz = fn * nz + fsz
                    # torque on j: (-aj n) x F ; on i: (ai n) x (-F)
                    tjx = -aj * (ny * fz - nz * fy)
                    tjy = -aj * (nz * fx - nx * fz)
                    tjz = -aj * (nx * fy - ny * fx)
                    tix = -ai * (ny * fz - nz * fy)
                    tiy = -ai * (nz * fx - nx * fz)
                    tiz = -ai * (nx * fy - ny * fx)
                    mx = 0.0
                    my = 0.0
                    mz = 0.0
                    use_coh_m = bonded and mat[mi, M_MOMENTS] > 0.0 and mat[mj, M_MOMENTS] > 0.0
                    mu_ri = mat[mi, M_MU_R]
                    mu_rj = mat[mj, M_MU_R]
                    use_roll = has_roll and (not use_coh_m) and (mu_ri >= 0.0 or mu_rj >= 0.0)
                    if use_coh_m or use_roll:
                        wrx = w[j, 0] - w[i, 0]
                        wry = w[j, 1] - w[i, 1]
                        wrz = w[j, 2] - w[i, 2]
                        wn = wrx * nx + wry * ny + wrz * nz
                        mox, moy, moz = rotate_shear(hf[k, H_MB], hf[k, H_MB + 1], hf[k, H_MB + 2],
                                                     n0x, n0y, n0z, nx, ny, nz, twist)
                        dtx = (wrx - wn * nx) * dt
                        dty = (wry - wn * ny) * dt
                        dtz = (wrz - wn * nz) * dt
                        if use_coh_m:
                            akr = _pair_mean(mat[mi, M_AKR], mat[mj, M_AKR])
                            aktw = _pair_mean(mat[mi, M_AKTW], mat[mj, M_AKTW])
                            kb = akr * ks * ri * rj
                            kt = aktw * ks * ri * rj
                            mbx = mox - kb * dtx
                            mby = moy - kb * dty
                            mbz = moz - kb * dtz
                            mt_old = (hf[k, H_MT] * nx + hf[k, H_MT + 1] * ny
                                      + hf[k, H_MT + 2] * nz)
                            mt = mt_old - kt * wn * dt
                            cap_b = -1.0
                            e1 = mat[mi, M_ETA_R]
                            e2 = mat[mj, M_ETA_R]
                            if e1 >= 0.0 and e2 >= 0.0:
                                cap_b = min(e1 * ri, e2 * rj) * abs(fn)
                            cap_t = -1.0
                            e1 = mat[mi, M_ETA_T]
                            e2 = mat[mj, M_ETA_T]
                            if e1 >= 0.0 and e2 >= 0.0:
                                cap_t = min(e1 * ri, e2 * rj) * abs(fn)
                            if kb > 0.0:
                                mbx, mby, mbz, _d = moment_cap(mbx, mby, mbz, cap_b, kb)
                                fric_acc += spring_dissipation(mox, moy, moz, mbx, mby, mbz,
                                                               dtx, dty, dtz, kb)
                            if kt > 0.0 and cap_t >= 0.0 and abs(mt) > cap_t:
                                mc = cap_t if mt > 0.0 else -cap_t
                                fric_acc += spring_dissipation(mt_old, 0.0, 0.0, mc, 0.0, 0.0,
                                                               wn * dt, 0.0, 0.0, kt)
                                mt = mc
                            hf[k, H_MT] = mt * nx
                            hf[k, H_MT + 1] = mt * ny
                            hf[k, H_MT + 2] = mt * nz
                            mx = mbx + mt * nx
                            my = mby + mt * ny
                            mz = mbz + mt * nz
                        else:
                            mu_r = mu_ri
                            if mu_r < 0.0 or (mu_rj >= 0.0 and mu_rj < mu_r):
                                mu_r = mu_rj
                            r_eff = ri * rj / (ri + rj)
                            kr = rolling_stiffness(kn, mu_r, r_eff)
                            kr_old = kr
                            if hertz:
                                kr_old = rolling_stiffness(1.5 * kno * math.sqrt(d_old), mu_r,
                                                           r_eff)
                            mbx = mox - kr * dtx
                            mby = moy - kr * dty
                            mbz = moz - kr * dtz
                            mbx, mby, mbz = _soften(mbx, mby, mbz, mox, moy, moz, kr, kr_old)
                            if kr > 0.0:
                                mbx, mby, mbz, _d = moment_cap(mbx, mby, mbz,
                                                               mu_r * r_eff * abs(fn), kr)
                                if hertz:
                                    fric_acc += varying_spring_dissipation(
                                        mox, moy, moz, mbx, mby, mbz, dtx, dty, dtz, kr_old, kr)
                                else:
                                    fric_acc += spring_dissipation(mox, moy, moz, mbx, mby, mbz,
                                                                   dtx, dty, dtz, kr)
                            mx = mbx
                            my = mby
                            mz = mbz
                        hf[k, H_MB] = mbx
                        hf[k, H_MB + 1] = mby
                        hf[k, H_MB + 2] = mbz
                    tq[k, 0] = tix - mx
                    tq[k, 1] = tiy - my
                    tq[k, 2] = tiz - mz
                    tq[k, 3] = tjx + mx
                    tq[k, 4] = tjy + my
                    tq[k, 5] = tjz + mz
            e_fric[i] += fric_acc
            e_visc[i] += visc_acc
            e_bond[i] += bond_acc


@pjit
def gather(mass, gravity, row_start, t_start, t_pair, nbr, hf, tq, f, t, has_rot, fv):
    """Per-particle sum of gravity and pair forces (and torques) in a fixed order; ``fv`` >= 0:
    the columns of ``hf`` holding the pairs' viscous shear forces (``pair_forces``)."""
    n = mass.shape[0]
    g0 = gravity[0]
    g1 = gravity[1]
    g2 = gravity[2]
    for i in prange(n):
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for k in range(row_start[i], row_start[i + 1]):
            fn = hf[k, H_FN]
            fx -= fn * hf[k, H_N] + hf[k, H_FS]
            fy -= fn * hf[k, H_N + 1] + hf[k, H_FS + 1]
            fz -= fn * hf[k, H_N + 2] + hf[k, H_FS + 2]
            if fv >= 0:
                fx -= hf[k, fv]
                fy -= hf[k, fv + 1]
                fz -= hf[k, fv + 2]
            if has_rot:
                tx += tq[k, 0]
                ty += tq[k, 1]
                tz += tq[k, 2]
        for q in range(t_start[i], t_start[i + 1]):
            k = t_pair[q]
            fn = hf[k, H_FN]
            fx += fn * hf[k, H_N] + hf[k, H_FS]
            fy += fn * hf[k, H_N + 1] + hf[k, H_FS + 1]
            fz += fn * hf[k, H_N + 2] + hf[k, H_FS + 2]
            if fv >= 0:
                fx += hf[k, fv]
                fy += hf[k, fv + 1]
                fz += hf[k, fv + 2]
            if has_rot:
                tx += tq[k, 3]
                ty += tq[k, 4]
                tz += tq[k, 5]
        m = mass[i]
        f[i, 0] = fx + m * g0
        f[i, 1] = fy + m * g1
        f[i, 2] = fz + m * g2
        t[i, 0] = tx
        t[i, 1] = ty
        t[i, 2] = tz


# ----------------------------------------------------------------------------------------------
# boundary contacts
# ----------------------------------------------------------------------------------------------
@numba.njit(cache=True, inline="always")
def _elem_contact(xp, yp, zp, r, etype, ep, en, er, ea0, ea1, e):
    """Geometry of analytic element ``e``: returns (touch, nx, ny, nz, delta)."""
    ty = etype[e]
    if ty == E_PLANE:
        dist = (xp - ep[e, 0]) * en[e, 0] + (yp - ep[e, 1]) * en[e, 1] + (zp - ep[e, 2]) * en[e, 2]
        delta = r - dist
        if delta > 0.0:
            return True, en[e, 0], en[e, 1], en[e, 2], delta
        return False, 0.0, 0.0, 0.0, 0.0
    if ty == E_CYLINDER:
        rx = xp - ep[e, 0]
        ry = yp - ep[e, 1]
        rz = zp - ep[e, 2]
        ax = rx * en[e, 0] + ry * en[e, 1] + rz * en[e, 2]
        if ax < ea0[e] or ax > ea1[e]:
            return False, 0.0, 0.0, 0.0, 0.0
        px = rx - ax * en[e, 0]
        py = ry - ax * en[e, 1]
        pz = rz - ax * en[e, 2]
        rho2 = px * px + py * py + pz * pz
        lim = er[e] - r
        if lim > 0.0 and rho2 <= lim * lim:
            return False, 0.0, 0.0, 0.0, 0.0
        rho = math.sqrt(rho2)
        delta = r - (er[e] - rho)
        if delta > 0.0 and rho > 0.0:
            return True, -px / rho, -py / rho, -pz / rho, delta
        return False, 0.0, 0.0, 0.0, 0.0
    if ty == E_SPHERE:
        rx = xp - ep[e, 0]
        ry = yp - ep[e, 1]
        rz = zp - ep[e, 2]
        d2 = rx * rx + ry * ry + rz * rz
        rs = r + er[e]
        if d2 < rs * rs and d2 > 0.0:
            d = math.sqrt(d2)
            return True, rx / d, ry / d, rz / d, rs - d
        return False, 0.0, 0.0, 0.0, 0.0
    return False, 0.0, 0.0, 0.0, 0.0


@pjit
def analytic_contacts_count(x, radius, etype, ep, en, er, ea0, ea1, counts):
    n = x.shape[0]
    ne = etype.shape[0]
    for i in prange(n):
        c = 0
        xp = x[i, 0]
        yp = x[i, 1]
        zp = x[i, 2]
        r = radius[i]
        for e in range(ne):
            ok, _a, _b, _c, _d = _elem_contact(xp, yp, zp, r, etype, ep, en, er, ea0, ea1, e)
            if ok:
                c += 1
        counts[i] = c


@pjit
def analytic_contacts_fill(x, radius, etype, ep, en, er, ea0, ea1, start, c_p, c_e, c_n, c_d,
                           c_pt):
    """Fill contacts in (particle, element) order; normal from the wall to the particle; the
    contact point sits mid-overlap, x - (r - delta/2) n."""
    n = x.shape[0]
    ne = etype.shape[0]
    for i in prange(n):
        q = start[i]
        if q == start[i + 1]:
            continue
        xp = x[i, 0]
        yp = x[i, 1]
        zp = x[i, 2]
        r = radius[i]
        for e in range(ne):
            ok, nx, ny, nz, delta = _elem_contact(xp, yp, zp, r, etype, ep, en, er, ea0, ea1, e)
            if ok:
                c_p[q] = i
                c_e[q] = e
                c_n[q, 0] = nx
                c_n[q, 1] = ny
                c_n[q, 2] = nz
                c_d[q] = delta
                a = r - 0.5 * delta
                c_pt[q, 0] = xp - a * nx
                c_pt[q, 1] = yp - a * ny
                c_pt[q, 2] = zp - a * nz
                q += 1


@jit
def boundary_forces(x, v, w, radius, mass, mat_id, mat, c_p, c_e, c_n, c_d, c_pt, key_mult,
                    etype, er, ebody, b_mat, b_pos, b_vel, b_omg, b_ref, old_key, old_hist,
                    new_key, new_hist, f, t, b_force, b_torque, b_power, b_diss, dt, has_rot,
                    has_visc, has_roll):
    """Forces of boundary contacts (sorted by key), history carried by key (particle, element).

    ``new_hist[c]`` = (Fs[3], n[3], fn, kn, ks, M_roll[3], kr, E_n). Adds forces/torques to
    particles, the wrench (about the body's reference point) and power to bodies, dissipation
    to ``b_diss[body]`` (friction, viscous).

    Notes
    -----
    Cundall-Strack law on walls (Yade ``Law2_ScGeom_FrictPhys_CundallStrack`` with
    ``Ig2_Wall_Sphere_ScGeom`` / ``Ig2_Facet_Sphere_ScGeom``); wall side stiffness radius: r for
    planes/cylinders, 2r for facets, R for a rigid sphere. Hertz-Mindlin (as ``pair_forces``):
    R* = r on planes, cylinders and facets, r R / (r + R) on a sphere; the overlap of the last
    step from the stored k_s (= k_so sqrt(delta)).
    """
    nc = c_p.shape[0]
    n_old = old_key.shape[0]
    for c in range(nc):
        i = c_p[c]
        e = c_e[c]
        key = i * key_mult + e
        new_key[c] = key
        # binary search in the old keys
        lo = 0
        hi = n_old
        while lo < hi:
            mid = (lo + hi) >> 1
            if old_key[mid] < key:
                lo = mid + 1
            else:
                hi = mid
        nx = c_n[c, 0]
        ny = c_n[c, 1]
        nz = c_n[c, 2]
        known = lo < n_old and old_key[lo] == key
        if known:
            fsx0 = old_hist[lo, 0]
            fsy0 = old_hist[lo, 1]
            fsz0 = old_hist[lo, 2]
            n0x = old_hist[lo, 3]
            n0y = old_hist[lo, 4]
            n0z = old_hist[lo, 5]
        else:
            fsx0 = 0.0
            fsy0 = 0.0
            fsz0 = 0.0
            n0x = nx
            n0y = ny
            n0z = nz
        b = ebody[e]
        ri = radius[i]
        delta = c_d[c]
        mi = mat_id[i]
        mb = b_mat[b]
        ty = etype[e]
        if ty == E_SPHERE:
            rw = er[e]
        elif ty == E_FACET:
            rw = 2.0 * ri
        else:
            rw = ri
        hertz = _is_hertz(mat, mb, mi)
        kno = 0.0
        sd = 0.0
        d_old = delta
        if hertz:
            # R* of the sphere on a plane, a cylinder's inside or a facet: its own radius
            r_eff = ri * er[e] / (ri + er[e]) if ty == E_SPHERE else ri
            kno, kso = hertz_coefficients(mat[mb, M_YOUNG], mat[mb, M_POISSON], mat[mi, M_YOUNG],
                                          mat[mi, M_POISSON], r_eff)
            sd = math.sqrt(delta)
            kn = 1.5 * kno * sd
            ks = kso * sd
            ks_old = ks
            if known:
                ks_old = old_hist[lo, 8]
                d_old = (ks_old / kso) ** 2
        else:
            kn = normal_stiffness(mat[mb, M_YOUNG], rw, mat[mi, M_YOUNG], ri)
            ks = shear_stiffness(mat[mb, M_YOUNG], rw, mat[mb, M_RATIO], mat[mi, M_YOUNG], ri,
                                 mat[mi, M_RATIO])
            ks_old = ks
        tan_phi = min(mat[mb, M_TANPHI], mat[mi, M_TANPHI])
        px = c_pt[c, 0]
        py = c_pt[c, 1]
        pz = c_pt[c, 2]
        # body velocity at the contact point
        qx = px - b_pos[b, 0]
        qy = py - b_pos[b, 1]
        qz = pz - b_pos[b, 2]
        vbx = b_vel[b, 0] + b_omg[b, 1] * qz - b_omg[b, 2] * qy
        vby = b_vel[b, 1] + b_omg[b, 2] * qx - b_omg[b, 0] * qz
        vbz = b_vel[b, 2] + b_omg[b, 0] * qy - b_omg[b, 1] * qx
        # particle velocity at the contact point
        vrx = v[i, 0] - vbx
        vry = v[i, 1] - vby
        vrz = v[i, 2] - vbz
        ax = px - x[i, 0]
        ay = py - x[i, 1]
        az = pz - x[i, 2]
        twist = 0.0
        if has_rot:
            vrx += w[i, 1] * az - w[i, 2] * ay
            vry += w[i, 2] * ax - w[i, 0] * az
            vrz += w[i, 0] * ay - w[i, 1] * ax
            twist = 0.5 * dt * (nx * (w[i, 0] + b_omg[b, 0]) + ny * (w[i, 1] + b_omg[b, 1])
                                + nz * (w[i, 2] + b_omg[b, 2]))
        delta_dot, ox, oy, oz, dux, duy, duz, fsx, fsy, fsz = _shear_trial(
            vrx, vry, vrz, nx, ny, nz, fsx0, fsy0, fsz0, n0x, n0y, n0z, twist, ks, dt)
        fsx, fsy, fsz = _soften(fsx, fsy, fsz, ox, oy, oz, ks, ks_old)
        cn = 0.0
        pulls = False
        if has_visc:
            e_pair, zeta = _pair_damping(mat, mb, mi, M_RESTITUTION, M_ZETA)
            if e_pair < 1.0:
                if hertz:
                    cn = hertz_damping_coefficient(zeta, mass[i], kn)
                else:
                    cn = damping_coefficient(zeta, mass[i], kn)
                pulls = mat[mb, M_TENSION] > 0.0 or mat[mi, M_TENSION] > 0.0
        fn_old = 0.0
        mox = 0.0
        moy = 0.0
        moz = 0.0
        kr_old = -1.0
        if known:
            fn_old = old_hist[lo, 6]
            mox = old_hist[lo, 9]
            moy = old_hist[lo, 10]
            moz = old_hist[lo, 11]
            kr_old = old_hist[lo, 12]
        if hertz:
            fn, f_visc = linear_normal_force(kno * sd, delta, cn, delta_dot, pulls)
        else:
            fn, f_visc = linear_normal_force(kn, delta, cn, delta_dot, pulls)
        fsx, fsy, fsz, _d, slid = coulomb_cap(fsx, fsy, fsz, fn * tan_phi, ks)
        fvx = 0.0
        fvy = 0.0
        fvz = 0.0
        if has_visc and not slid:
            e_s, zeta_s = _pair_damping(mat, mb, mi, M_SHEAR_RESTITUTION, M_SHEAR_ZETA)
            if e_s < 1.0:
                fvx, fvy, fvz, wv = _shear_dashpot(zeta_s, mass[i], ks, hertz, dux, duy, duz, dt)
                b_diss[b, 1] += wv
        if hertz:
            b_diss[b, 0] += varying_spring_dissipation(ox, oy, oz, fsx, fsy, fsz, dux, duy, duz,
                                                       ks_old, ks)
            if cn > 0.0:
                d_prev = d_old if known else delta - delta_dot * dt
                b_diss[b, 1] += hertz_normal_dissipation(fn_old, fn, delta, d_prev, kno)
        else:
            b_diss[b, 0] += spring_dissipation(ox, oy, oz, fsx, fsy, fsz, dux, duy, duz, ks)
            if cn > 0.0:
                b_diss[b, 1] += normal_dissipation(fn_old, fn, delta, delta_dot * dt, kn)
        new_hist[c, 0] = fsx
        new_hist[c, 1] = fsy
        new_hist[c, 2] = fsz
        new_hist[c, 3] = nx
        new_hist[c, 4] = ny
        new_hist[c, 5] = nz
        new_hist[c, 6] = fn
        new_hist[c, 7] = kn
        new_hist[c, 8] = ks
        new_hist[c, B_FV] = fvx
        new_hist[c, B_FV + 1] = fvy
        new_hist[c, B_FV + 2] = fvz
        # rolling resistance on the wall (Ai et al. 2011 type C), moment acting on the particle
        mrx = 0.0
        mry = 0.0
        mrz = 0.0
        kr = 0.0
        if has_roll and has_rot:
            mu_r = mat[mi, M_MU_R]
            mu_b = mat[mb, M_MU_R]
            if mu_r < 0.0 or (mu_b >= 0.0 and mu_b < mu_r):
                mu_r = mu_b
            if mu_r >= 0.0:
                r_eff = ri * er[e] / (ri + er[e]) if ty == E_SPHERE else ri
                kr = rolling_stiffness(kn, mu_r, r_eff)
                wrx = w[i, 0] - b_omg[b, 0]
                wry = w[i, 1] - b_omg[b, 1]
                wrz = w[i, 2] - b_omg[b, 2]
                wn = wrx * nx + wry * ny + wrz * nz
                rox, roy, roz = rotate_shear(mox, moy, moz, n0x, n0y, n0z, nx, ny, nz, twist)
                dtx = (wrx - wn * nx) * dt
                dty = (wry - wn * ny) * dt
                dtz = (wrz - wn * nz) * dt
                mrx = rox - kr * dtx
                mry = roy - kr * dty
                mrz = roz - kr * dtz
                if not hertz or kr_old < 0.0:
                    kr_old = kr
                mrx, mry, mrz = _soften(mrx, mry, mrz, rox, roy, roz, kr, kr_old)
                if kr > 0.0:
                    mrx, mry, mrz, _d = moment_cap(mrx, mry, mrz, mu_r * r_eff * abs(fn), kr)
                    if hertz:
                        b_diss[b, 0] += varying_spring_dissipation(rox, roy, roz, mrx, mry, mrz,
                                                                   dtx, dty, dtz, kr_old, kr)
                    else:
                        b_diss[b, 0] += spring_dissipation(rox, roy, roz, mrx, mry, mrz, dtx,
                                                           dty, dtz, kr)
        new_hist[c, 9] = mrx
        new_hist[c, 10] = mry
        new_hist[c, 11] = mrz
        new_hist[c, 12] = kr
        if hertz:
            new_hist[c, 13] = 0.4 * kno * delta * delta * sd
        else:
            new_hist[c, 13] = 0.5 * kn * delta * delta
        fx = fn * nx + fsx + fvx
        fy = fn * ny + fsy + fvy
        fz = fn * nz + fsz + fvz
        f[i, 0] += fx
        f[i, 1] += fy
        f[i, 2] += fz
        if has_rot:
            t[i, 0] += ay * fz - az * fy + mrx
            t[i, 1] += az * fx - ax * fz + mry
            t[i, 2] += ax * fy - ay * fx + mrz
        b_force[b, 0] -= fx
        b_force[b, 1] -= fy
        b_force[b, 2] -= fz
        hx = px - b_ref[b, 0]
        hy = py - b_ref[b, 1]
        hz = pz - b_ref[b, 2]
        b_torque[b, 0] -= hy * fz - hz * fy + mrx
        b_torque[b, 1] -= hz * fx - hx * fz + mry
        b_torque[b, 2] -= hx * fy - hy * fx + mrz
        b_power[b] += (fx * vbx + fy * vby + fz * vbz
                       + mrx * b_omg[b, 0] + mry * b_omg[b, 1] + mrz * b_omg[b, 2])


# ----------------------------------------------------------------------------------------------
# diagnostics
# ----------------------------------------------------------------------------------------------
@jit
def pair_elastic_energy(x, radius, mat_id, mat, row_start, nbr, hf, hi, has_coh, has_mom):
    """Elastic energy stored in the pair springs: normal + shear (+ moment) [J].

    Notes
    -----
    Linear springs: kn delta^2 / 2 (bonds: kn (delta - u_p)^2 / 2), |Fs|^2 / (2 ks),
    |M|^2 / (2 k_M). Hertz-Mindlin pairs: 2/5 k_no delta^(5/2), and the shear and rolling
    springs over the stiffness of the overlap they were last made at (the last column of ``hf``).
    """
    n = x.shape[0]
    dn = hf.shape[1] - 1  # Hertz-Mindlin: the last step's overlap
    e_n = 0.0
    e_s = 0.0
    e_m = 0.0
    for i in range(n):
        ri = radius[i]
        mi = mat_id[i]
        for k in range(row_start[i], row_start[i + 1]):
            if hf[k, H_N] == 0.0 and hf[k, H_N + 1] == 0.0 and hf[k, H_N + 2] == 0.0:
                continue
            j = nbr[k]
            rj = radius[j]
            mj = mat_id[j]
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            dz = x[j, 2] - x[i, 2]
            delta = ri + rj - math.sqrt(dx * dx + dy * dy + dz * dz)
            bonded = has_coh and hi[k, I_BOND] == BOND_ACTIVE
            if not bonded and _is_hertz(mat, mi, mj):
                # Hertz: 2/5 k_no delta^(5/2); the springs of the stiffness they were made with
                # (the last step's overlap)
                kno, kso = hertz_coefficients(mat[mi, M_YOUNG], mat[mi, M_POISSON],
                                              mat[mj, M_YOUNG], mat[mj, M_POISSON],
                                              ri * rj / (ri + rj))
                if delta > 0.0:
                    e_n += 0.4 * kno * delta * delta * math.sqrt(delta)
                sd = math.sqrt(hf[k, dn])
                kn = 1.5 * kno * sd
                ks = kso * sd
            else:
                kn = normal_stiffness(mat[mi, M_YOUNG], ri, mat[mj, M_YOUNG], rj)
                ks = shear_stiffness(mat[mi, M_YOUNG], ri, mat[mi, M_RATIO], mat[mj, M_YOUNG],
                                     rj, mat[mj, M_RATIO])
                if bonded:
                    u = delta - hf[k, H_UNP]
                    e_n += 0.5 * kn * u * u
                elif delta > 0.0:
                    e_n += 0.5 * kn * delta * delta
            if ks > 0.0:
                e_s += 0.5 * (hf[k, 0] ** 2 + hf[k, 1] ** 2 + hf[k, 2] ** 2) / ks
            if has_mom:
                mb2 = hf[k, H_MB] ** 2 + hf[k, H_MB + 1] ** 2 + hf[k, H_MB + 2] ** 2
                mt2 = hf[k, H_MT] ** 2 + hf[k, H_MT + 1] ** 2 + hf[k, H_MT + 2] ** 2
                if mb2 > 0.0 or mt2 > 0.0:
                    if bonded and mat[mi, M_MOMENTS] > 0.0 and mat[mj, M_MOMENTS] > 0.0:
                        akr = _pair_mean(mat[mi, M_AKR], mat[mj, M_AKR])
                        aktw = _pair_mean(mat[mi, M_AKTW], mat[mj, M_AKTW])
                        if akr > 0.0:
                            e_m += 0.5 * mb2 / (akr * ks * ri * rj)
                        if aktw > 0.0:
                            e_m += 0.5 * mt2 / (aktw * ks * ri * rj)
                    else:
                        mu_r = mat[mi, M_MU_R]
                        mu_rj = mat[mj, M_MU_R]
                        if mu_r < 0.0 or (mu_rj >= 0.0 and mu_rj < mu_r):
                            mu_r = mu_rj
                        r_eff = ri * rj / (ri + rj)
                        kr = rolling_stiffness(kn, mu_r, r_eff)
                        if kr > 0.0:
                            e_m += 0.5 * mb2 / kr
    return e_n, e_s, e_m


@jit
def stiffness_sum(x, radius, mat_id, mat, row_start, nbr, c_p, c_kn, ksum):
    """Sum of normal stiffnesses of touching contacts per particle (for the time step)."""
    n = x.shape[0]
    for i in range(n):
        ri = radius[i]
        for k in range(row_start[i], row_start[i + 1]):
            j = nbr[k]
            rj = radius[j]
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            dz = x[j, 2] - x[i, 2]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 < (ri + rj) ** 2:
                mi = mat_id[i]
                mj = mat_id[j]
                if _is_hertz(mat, mi, mj):
                    kno, _kso = hertz_coefficients(mat[mi, M_YOUNG], mat[mi, M_POISSON],
                                                   mat[mj, M_YOUNG], mat[mj, M_POISSON],
                                                   ri * rj / (ri + rj))
                    kn = 1.5 * kno * math.sqrt(ri + rj - math.sqrt(d2))
                else:
                    kn = normal_stiffness(mat[mi, M_YOUNG], ri, mat[mj, M_YOUNG], rj)
                ksum[i] += kn
                ksum[j] += kn
    for c in range(c_p.shape[0]):
        ksum[c_p[c]] += c_kn[c]


@jit
def bond_touching(x, radius, mat_id, mat, row_start, nbr, hf, hi, tol):
    """Create bonds on touching (gap <= tol) pairs of cohesive materials (Yade setCohesionNow).

    Returns the number of bonds created.

    Notes
    -----
    Yade ``Ip2_CohFrictMat_CohFrictMat_CohFrictPhys``: a_n = min(sn_i, sn_j) min(R_i, R_j)^2,
    a_t = min(ss_i, ss_j) min(R_i, R_j)^2; the current overlap is kept as the reference (u_p = 0
    keeps the present normal force).
    """
    n = x.shape[0]
    made = 0
    for i in range(n):
        ri = radius[i]
        mi = mat_id[i]
        for k in range(row_start[i], row_start[i + 1]):
            j = nbr[k]
            mj = mat_id[j]
            if mat[mi, M_COHESIVE] <= 0.0 or mat[mj, M_COHESIVE] <= 0.0:
                continue
            rj = radius[j]
            dx = x[j, 0] - x[i, 0]
            dy = x[j, 1] - x[i, 1]
            dz = x[j, 2] - x[i, 2]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            if d - (ri + rj) > tol:
                continue
            rmin = min(ri, rj)
            hi[k, I_BOND] = BOND_ACTIVE
            hf[k, H_AN] = min(mat[mi, M_SN], mat[mj, M_SN]) * rmin * rmin
            hf[k, H_AT] = min(mat[mi, M_SS], mat[mj, M_SS]) * rmin * rmin
            hf[k, H_UNP] = 0.0
            if hf[k, H_N] == 0.0 and hf[k, H_N + 1] == 0.0 and hf[k, H_N + 2] == 0.0:
                hf[k, H_N] = dx / d
                hf[k, H_N + 1] = dy / d
                hf[k, H_N + 2] = dz / d
            made += 1
    return made
