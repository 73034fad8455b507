"""Numba kernels of the reduced-order impact model (ROM): arrays and scalars only.

The parameter vector layout is defined by the ``P_*`` indices below and filled by
``crashdem.diagnosis.rom.RomParams.to_array``; the physics of each term is documented there.

Two integrators share the force law ``_soil_update``:

* ``METHOD_SYMPLECTIC`` (0): semi-implicit Euler (forces at t_n, then v, then x) -- the
  diagnosing ROM;
* ``METHOD_MIDPOINT`` (1): explicit midpoint (RK2) with the history variables committed with the
  midpoint velocity -- used by the concealed-effect generator so that the "truth" numerics differ
  from the diagnosing ROM (different scheme and time step).

Notes
-----
Resistance law: Poncelet / Katsuragi & Durian (2007) form F = F_static(z) + k z + C rho A v^2
(anchors.md section 6), capped elastic-plastic return mapping (Simo & Hughes 1998, ch. 1, 1-D
plasticity). Flat-punch stiffness K = 2 E* a (Sneddon 1965). Bearing-capacity factor N_c
(Skempton 1951). Floor stiffening ~ a/h (Poulos & Davis 1974, elastic layer on a rigid base).
"""
from __future__ import annotations

import functools
import math

import numba
import numpy as np

jit = functools.partial(numba.njit, cache=True)

METHOD_SYMPLECTIC = 0
METHOD_MIDPOINT = 1

P_MASS = 0
P_RADIUS = 1
P_V0 = 2
P_G = 3
P_RHO = 4
P_Q0 = 5
P_KP = 6
P_CD = 7
P_ES = 8
P_H = 9
P_C = 10
P_RW = 11
P_KAPPA = 12
P_ZD = 13
P_LRATIO = 14
P_LWIDTH = 15
P_COH = 16
P_NC = 17
P_FRATIO = 18
P_MOB = 19
P_ZETA = 20
P_FC = 21
P_SMAX = 22
P_NOSE = 23
P_KC = 24
P_SIZE = 25

#: smallest gap to the floor used in the stiffening term [m] (keeps 1/gap finite)
MIN_FLOOR_GAP = 0.02


@jit
def _contact_radius(z, radius):
    """Radius [m] of the spherical cap of depth z [m] (0 outside the soil, R beyond the equator)."""
    if z <= 0.0:
        return 0.0
    if z >= radius:
        return radius
    return math.sqrt(2.0 * radius * z - z * z)


@jit
def _soil_update(z, v, fs, dt, t, p):
    """One return-mapping update of the soil reaction on the impactor tip.

    Parameters
    ----------
    z : tip depth below the free surface [m] (positive down)
    v : tip velocity [m/s] (positive down)
    fs : elastic-plastic soil force carried over from the previous step [N] (upward positive)
    dt : step [s]; t : time since first contact [s]; p : parameter vector (``P_*`` layout)

    Returns
    -------
    (total upward force on the tip [N], new elastic-plastic state fs [N])
    """
    radius = p[P_RADIUS]
    a_c = _contact_radius(z, radius)
    area = math.pi * a_c * a_c
    # depth multipliers: layering (smoothed step), floor proximity, rotation softening
    m_layer = 1.0
    if p[P_ZD] < 1e9:
        m_layer = 1.0 + (p[P_LRATIO] - 1.0) * 0.5 * (1.0 + math.tanh((z - p[P_ZD]) / p[P_LWIDTH]))
    gap = p[P_H] - z
    if gap < MIN_FLOOR_GAP:
        gap = MIN_FLOOR_GAP
    f_floor = 1.0 + p[P_KAPPA] * a_c / gap
    m_rot = 1.0
    if p[P_FRATIO] < 1.0:
        zz = z if z > 0.0 else 0.0
        m_rot = p[P_FRATIO] + (1.0 - p[P_FRATIO]) * math.exp(-zz / p[P_MOB])
    q_static = (p[P_Q0] + p[P_KP] * (z if z > 0.0 else 0.0)) * m_layer * f_floor * m_rot
    q_static += p[P_NC] * p[P_COH]
    q_drag = 0.0
    if v > 0.0:
        q_drag = p[P_CD] * p[P_RHO] * v * v * m_rot
    cap = area * (q_static + q_drag)
    stiff = 2.0 * p[P_ES] * a_c * m_layer * f_floor
    tension = -p[P_COH] * area
    # Kelvin-Voigt element (spring K, dashpot eta) in series with a plastic slider bounded by
    # [tension, cap]: v_e is the elastic deformation rate, v - v_e the plastic flow
    eta = 0.0
    if p[P_ZETA] > 0.0 and area > 0.0:
        eta = 2.0 * p[P_ZETA] * math.sqrt(stiff * p[P_MASS])
    v_e = v
    f_tot = fs + stiff * v * dt + eta * v
    if f_tot > cap:
        v_e = (cap - fs) / (stiff * dt + eta) if stiff * dt + eta > 0.0 else 0.0
        f_tot = cap
    elif f_tot < tension:
        v_e = (tension - fs) / (stiff * dt + eta) if stiff * dt + eta > 0.0 else 0.0
        f_tot = tension
    fs_new = fs + stiff * v_e * dt
    if area > 0.0 and p[P_RW] > 0.0:
        t_ref = 2.0 * p[P_H] / p[P_C]
        tau = radius / p[P_C]
        amp = p[P_RW] * p[P_RHO] * p[P_C] * p[P_V0] * a_c / (2.0 * p[P_H]) * area
        f_tot += amp * math.exp(-0.5 * ((t - t_ref) / tau) ** 2)
    if area == 0.0:
        f_tot = 0.0
        fs_new = 0.0
    return f_tot, fs_new


@jit
def _crush_update(fc_state, sp, dv, dt, p):
    """Elastic-plastic crush element between nose and body (compression positive).

    Returns (force [N], plastic stroke used [m]). Bottomed out (no further yield) once the
    plastic stroke reaches ``s_max``.
    """
    f = fc_state + p[P_KC] * dv * dt
    fc = p[P_FC]
    if sp < p[P_SMAX]:
        if f > fc:
            sp += (f - fc) / p[P_KC]
            f = fc
        elif f < -fc:
            f = -fc
    return f, sp


@jit
def run_rom(p, dt, n_steps, method):
    """Integrate the drop from first contact for ``n_steps`` steps of ``dt`` [s].

    Returns
    -------
    t [s], specific force of the body along +z (up) [m/s^2], body velocity along +z [m/s],
    tip depth [m]; all of length n_steps + 1, sample k at t = k dt.
    """
    n = n_steps + 1
    t_out = np.empty(n)
    acc_out = np.empty(n)
    vel_out = np.empty(n)
    dep_out = np.empty(n)
    g = p[P_G]
    m = p[P_MASS]
    crush = p[P_FC] < 1e15
    m_nose = p[P_NOSE] * m if crush else 0.0
    m_body = m - m_nose
    zt = 0.0
    vt = p[P_V0]
    zb = 0.0
    vb = p[P_V0]
    fs = 0.0
    fcr = 0.0
    sp = 0.0
    t = 0.0
    t_out[0] = 0.0
    acc_out[0] = 0.0
    vel_out[0] = -vb
    dep_out[0] = 0.0
    for k in range(n_steps):
        if method == METHOD_SYMPLECTIC:
            if crush:
                f_tip, fs = _soil_update(zt, vt, fs, dt, t, p)
                fcr, sp = _crush_update(fcr, sp, vb - vt, dt, p)
                vt += dt * (g + (fcr - f_tip) / m_nose)
                vb += dt * (g - fcr / m_body)
                zt += dt * vt
                zb += dt * vb
                spec = fcr / m_body
            else:
                f_tip, fs = _soil_update(zt, vt, fs, dt, t, p)
                vt += dt * (g - f_tip / m)
                zt += dt * vt
                vb = vt
                zb = zt
                spec = f_tip / m
        else:
            h = 0.5 * dt
            if crush:
                f1, _ = _soil_update(zt, vt, fs, h, t, p)
                c1, _ = _crush_update(fcr, sp, vb - vt, h, p)
                vt_m = vt + h * (g + (c1 - f1) / m_nose)
                vb_m = vb + h * (g - c1 / m_body)
                zt_m = zt + h * vt
                # commit history with the midpoint velocities over the full step
                f2, fs = _soil_update(zt_m, vt_m, fs, dt, t + h, p)
                fcr, sp = _crush_update(fcr, sp, vb_m - vt_m, dt, p)
                vt += dt * (g + (fcr - f2) / m_nose)
                vb += dt * (g - fcr / m_body)
                zt += dt * vt_m
                zb += dt * vb_m
                spec = fcr / m_body
            else:
                f1, _ = _soil_update(zt, vt, fs, h, t, p)
                v_m = vt + h * (g - f1 / m)
                z_m = zt + h * vt
                f2, fs = _soil_update(z_m, v_m, fs, dt, t + h, p)
                vt += dt * (g - f2 / m)
                zt += dt * v_m
                vb = vt
                zb = zt
                spec = f2 / m
        t = (k + 1) * dt
        t_out[k + 1] = t
        acc_out[k + 1] = spec
        vel_out[k + 1] = -vb
        dep_out[k + 1] = zt
    return t_out, acc_out, vel_out, dep_out
