"""Fused time loop: n DEM steps inside Numba (fixed and coupled bodies, analytic shapes).

The Python ``Simulation.step`` loop calls the same kernels one by one (needed for prescribed
motions and triangle meshes); this loop runs them without returning to Python and gives the same
bits.

Numba's on-disk cache is invalidated per source file only: the compiled functions here inline
``_kernels``'s, so a change of a kernel this loop calls must change this file too.
``NUMBA_CACHE_DEPENDS`` is the digest of those sources; tests/test_numba_cache_deps.py fails
until it is renewed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from soil import _kernels as K

#: digest of the jitted sources compiled in (see the module docstring)
NUMBA_CACHE_DEPENDS = "0d15053699de72bb"

_integrate = K.integrate.parallel
_scan = K.scan_neighbours.parallel
_place = K.place_neighbours.parallel
_count_hist = K.count_history.parallel
_save_hist = K.save_history.parallel
_restore_hist = K.restore_history.parallel
_pair = K.pair_forces.parallel
_gather = K.gather.parallel
_acount = K.analytic_contacts_count.parallel
_afill = K.analytic_contacts_fill.parallel
_cell_sort = K.cell_sort_into
_bounds = K.bounds
_transpose = K.transpose_into
_lost = K.lost_bonds
_prefix = K.prefix_sum
_bforces = K.boundary_forces

#: rows longer than the scan buffer are re-scanned; when more than 1/BUF_GROW_RATIO of the rows
#: overflow, the buffer is widened for the next rebuild
BUF_GROW_RATIO = 64
BUF_MAX_COLS = 64

@numba.njit(cache=True)
def advance_rotation(rot, omega, dt):
    """R <- expm(skew(omega) dt) R (Rodrigues), explicit loops (same bits everywhere).

    Notes
    -----
    Rodrigues' formula exp(K) = I + sin(a)/a K + (1 - cos a)/a^2 K^2, a = |omega| dt.
    """
    wx = omega[0] * dt
    wy = omega[1] * dt
    wz = omega[2] * dt
    a = math.sqrt(wx * wx + wy * wy + wz * wz)
    if a == 0.0:
        return
    s1 = math.sin(a) / a
    s2 = (1.0 - math.cos(a)) / (a * a)
    kk = np.empty((3, 3))
    kk[0, 0] = 0.0
    kk[0, 1] = -wz
    kk[0, 2] = wy
    kk[1, 0] = wz
    kk[1, 1] = 0.0
    kk[1, 2] = -wx
    kk[2, 0] = -wy
    kk[2, 1] = wx
    kk[2, 2] = 0.0
    d = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            k2 = kk[i, 0] * kk[0, j] + kk[i, 1] * kk[1, j] + kk[i, 2] * kk[2, j]
            d[i, j] = (1.0 if i == j else 0.0) + s1 * kk[i, j] + s2 * k2
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = d[i, 0] * rot[0, j] + d[i, 1] * rot[1, j] + d[i, 2] * rot[2, j]
    for i in range(3):
        for j in range(3):
            rot[i, j] = out[i, j]


@numba.njit(cache=True)
def to_world(pos, rot, p_body, out):
    """out = pos + rot @ p_body (explicit sums)."""
    for i in range(3):
        out[i] = pos[i] + (rot[i, 0] * p_body[0] + rot[i, 1] * p_body[1] + rot[i, 2] * p_body[2])


@numba.njit(cache=True)
def update_elements(ebody, ep_body, en_body, b_pos, b_rot, b_refb, ep, en, b_ref):
    """World-frame analytic elements and body reference points from the body poses."""
    zero = np.zeros(3)
    for e in range(ep_body.shape[0]):
        b = ebody[e]
        to_world(b_pos[b], b_rot[b], ep_body[e], ep[e])
        to_world(zero, b_rot[b], en_body[e], en[e])
    for b in range(b_pos.shape[0]):
        to_world(b_pos[b], b_rot[b], b_refb[b], b_ref[b])


@numba.njit(cache=True)
def grid_dims(lo, hi, cell, n):
    """Cell grid covering [lo, hi] with at most max(8 n, 64) cells (cell grown by 1.26)."""
    max_cells = max(8 * n, 64)
    while True:
        tot = 1.0
        for k in range(3):
            tot *= math.ceil(max(hi[k] - lo[k], cell) / cell) + 1.0
        if tot <= max_cells:
            break
        cell *= 1.26
    nx = int(math.ceil(max(hi[0] - lo[0], cell) / cell) + 1.0)
    ny = int(math.ceil(max(hi[1] - lo[1], cell) / cell) + 1.0)
    nz = int(math.ceil(max(hi[2] - lo[2], cell) / cell) + 1.0)
    return cell, nx, ny, nz


@numba.njit(cache=True)
def grow(size):
    """Capacity for ``size`` entries (+25 %, integer arithmetic: same in Python and Numba)."""
    return size + size // 4 + 16


@numba.njit(cache=True)
def buffer_width(counts, width):
    """Scan-buffer width for the next rebuild: doubled (up to BUF_MAX_COLS) when more than
    1/BUF_GROW_RATIO of the rows overflowed this one."""
    n = counts.shape[0]
    over = 0
    for i in range(n):
        if counts[i] > width:
            over += 1
    if over * BUF_GROW_RATIO > n and width < BUF_MAX_COLS:
        return min(2 * width, BUF_MAX_COLS)
    return width


@numba.njit(cache=True)
def rebuild(x, radius, is_large, large_idx, r_small, skin, row_start, t_start, nbr, hf, hi, tq,
            t_pair, s_j, s_f, s_i, cell_of, cell_start, cell_list, buf, has_coh, has_rot):
    """Neighbour-list rebuild in the persistent buffers (no allocation while capacities suffice).

    1. the pairs that carry history are saved into the store (``s_*``; ``t_start`` serves as
       its row starts); 2. cell sort; 3. single-pass scan into ``buf`` with the row counts
    written to ``row_start[1:]``; 4. rows placed into ``nbr``; 5. history restored from the
    store; 6. transposed list (``cell_of`` as scratch).  Buffers too small are replaced by
    larger ones (``grow``).  Returns the (possibly new) buffers, the number of pairs and the
    number of bonds lost to the skin.
    """
    n = x.shape[0]
    # 1. history store
    _count_hist(row_start, hf, hi, t_start[1:])
    t_start[0] = 0
    a = _prefix(t_start)
    if a > s_j.shape[0]:
        cap = grow(a)
        s_j = np.empty(cap, np.int32)
        s_f = np.empty((cap, hf.shape[1]))
        s_i = np.empty((cap, hi.shape[1]), np.int32)
    _save_hist(row_start, nbr, hf, hi, t_start, s_j, s_f, s_i)
    # 2. cells
    lo, hi_ = _bounds(x, is_large)
    cell, nx, ny, nz = grid_dims(lo, hi_, 2.0 * r_small + skin, n)
    if cell_start.shape[0] < nx * ny * nz + 2:
        cell_start = np.empty(grow(nx * ny * nz + 2), np.int64)
    _cell_sort(x, is_large, lo, 1.0 / cell, nx, ny, nz, cell_of, cell_start, cell_list)
    # 3. scan
    _scan(x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny, nz, skin, buf,
          row_start[1:])
    row_start[0] = 0
    width = buffer_width(row_start[1:], buf.shape[1])
    m = _prefix(row_start)
    if m > nbr.shape[0]:
        cap = grow(m)
        nbr = np.empty(cap, np.int32)
        hf = np.empty((cap, hf.shape[1]))
        hi = np.empty((cap, hi.shape[1]), np.int32)
        t_pair = np.empty(cap, np.int32)
        if has_rot:
            tq = np.empty((cap, 6))
    # 4. rows
    _place(x, radius, is_large, large_idx, cell_start, cell_list, cell_of, nx, ny, nz, skin, buf,
           row_start, nbr)
    if width != buf.shape[1]:
        buf = np.empty((n, width), np.int32)
    # 5. history
    _restore_hist(t_start, s_j, s_f, s_i, row_start, nbr, hf, hi)
    lost = 0
    if has_coh:
        lost = _lost(t_start, s_j, s_i, row_start, nbr)
    if has_rot:
        tq[:m] = 0.0
    # 6. transpose
    _transpose(row_start, nbr, t_start, t_pair, cell_of)
    return nbr, hf, hi, tq, t_pair, s_j, s_f, s_i, cell_start, buf, m, lost


@numba.njit(cache=True)
def boundary_step(x, v, w, radius, mass, mat_id, mat, n_analytic, etype, ep, en, er, ea0, ea1,
                  key_mult, ebody, b_mat, b_pos, b_vel, b_omg, b_ref, bkey, bhist, f, t,
                  b_force, b_torque, b_power, b_diss, dt, has_rot, has_visc, has_roll, start):
    """Analytic boundary contacts and forces; ``start`` (n + 1 integers) is scratch."""
    n = x.shape[0]
    et = etype[:n_analytic]
    er_a = er[:n_analytic]
    _acount(x, radius, et, ep, en, er_a, ea0, ea1, start[1:])
    start[0] = 0
    nc = _prefix(start)
    c_p = np.empty(nc, np.int64)
    c_e = np.empty(nc, np.int64)
    c_n = np.empty((nc, 3))
    c_d = np.empty(nc)
    c_pt = np.empty((nc, 3))
    _afill(x, radius, et, ep, en, er_a, ea0, ea1, start, c_p, c_e, c_n, c_d, c_pt)
    new_key = np.empty(nc, np.int64)
    new_hist = np.empty((nc, K.B_NCOL))
    b_force[:] = 0.0
    b_torque[:] = 0.0
    b_power[:] = 0.0
    _bforces(x, v, w, radius, mass, mat_id, mat, c_p, c_e, c_n, c_d, c_pt, key_mult, etype, er,
             ebody, b_mat, b_pos, b_vel, b_omg, b_ref, bkey, bhist, new_key, new_hist, f, t,
             b_force, b_torque, b_power, b_diss, dt, has_rot, has_visc, has_roll)
    return new_key, new_hist, c_p, c_e, c_n, c_d, c_pt


@numba.njit(cache=True)
def run_steps(nsteps, dt, x, v, w, f, t, radius, mass, inv_mass, inv_inertia, mat_id, mat,
              gravity, damping, e_glob, e_fric, e_visc, e_bond, x_ref, skin, is_large, large_idx,
              r_small, row_start, t_start, nbr, hf, hi, tq, t_pair, s_j, s_f, s_i, cell_of,
              cell_start, cell_list, buf, b_start, m, n_analytic, etype, ebody, ep_body, en_body,
              er, ea0, ea1, ep, en, key_mult, b_mat, b_moving, b_pos, b_rot, b_vel, b_omg, b_refb,
              b_ref, b_force, b_torque, b_power, b_diss, b_impulse, b_ang_impulse, b_work, bkey,
              bhist, c_p, c_e, c_n, c_d, c_pt, has_rot, has_coh, has_roll, has_visc, fv):
    """``nsteps`` DEM steps (same sequence as ``Simulation._steps``); returns the buffers that a
    rebuild may replace (grown), the number of pairs, the boundary contact arrays, plus
    (#builds, #bonds lost to the skin)."""
    nb = b_pos.shape[0]
    half_skin2 = (0.5 * skin) ** 2
    n_builds = 0
    lost = 0
    any_moving = False
    for b in range(nb):
        if b_moving[b]:
            any_moving = True
    for _s in range(nsteps):
        for b in range(nb):
            for k in range(3):
                b_impulse[b, k] += b_force[b, k] * dt
                b_ang_impulse[b, k] += b_torque[b, k] * dt
            b_work[b] += b_power[b] * dt
        moved = _integrate(x, v, w, f, t, inv_mass, inv_inertia, dt, damping, e_glob, x_ref,
                           half_skin2, has_rot)
        if any_moving:
            for b in range(nb):
                if b_moving[b]:
                    for k in range(3):
                        b_pos[b, k] += b_vel[b, k] * dt
                    advance_rotation(b_rot[b], b_omg[b], dt)
            update_elements(ebody[:n_analytic], ep_body, en_body, b_pos, b_rot, b_refb, ep, en,
                            b_ref)
        if moved:
            nbr, hf, hi, tq, t_pair, s_j, s_f, s_i, cell_start, buf, m, lo_ = rebuild(
                x, radius, is_large, large_idx, r_small, skin, row_start, t_start, nbr, hf, hi,
                tq, t_pair, s_j, s_f, s_i, cell_of, cell_start, cell_list, buf, has_coh, has_rot)
            lost += lo_
            x_ref[:] = x
            n_builds += 1
        _pair(x, v, w, radius, mass, mat_id, mat, row_start, nbr, hf, hi, tq, dt, has_rot,
              has_coh, has_roll, has_visc, e_fric, e_visc, e_bond, fv)
        _gather(mass, gravity, row_start, t_start, t_pair, nbr, hf, tq, f, t, has_rot, fv)
        if nb > 0:
            bkey, bhist, c_p, c_e, c_n, c_d, c_pt = boundary_step(
                x, v, w, radius, mass, mat_id, mat, n_analytic, etype, ep, en, er, ea0, ea1,
                key_mult, ebody, b_mat, b_pos, b_vel, b_omg, b_ref, bkey, bhist, f, t, b_force,
                b_torque, b_power, b_diss, dt, has_rot, has_visc, has_roll, b_start)
    return (nbr, hf, hi, tq, t_pair, s_j, s_f, s_i, cell_start, buf, m, bkey, bhist, c_p, c_e,
            c_n, c_d, c_pt, n_builds, lost)
