"""Planar 3-DOF (x, z, pitch) reduced-order impactor for the glider crash (issue 7, part b).

A rigid body of mass m and pitch inertia J carries a spherical nose of radius R_n at a distance
d ahead of the CG along the body x-axis. It hits a soil surface inclined by ``slope`` (the
thesis's 45 deg container face). The soil reaction on the nose is the *same* resistance law as
the vertical drop ROM (``_rom_kernels._soil_update``: Poncelet cap, elastic-plastic spring,
layering, floor/wall proximity, cohesion, rotation, damping) applied to the penetration along the
surface normal, plus Coulomb friction along the surface (regularised with ``tanh``). The body
moves under the nose force and gravity; the torque about the CG turns it in pitch.

Channels (body axes at the CG, specific force like an accelerometer): ``accel_x``, ``accel_z``
[m/s^2] (mount resonance and CFC applied like the drop ROM) and ``pitch_rate`` [rad/s].

Status: a complete model with its own tests; not yet wired into the catalogue fits (those use
the drop ROM's parameter names); structural crush along the body axis is not represented here.

Notes
-----
Rigid-body planar dynamics (Newton-Euler), semi-implicit Euler; Coulomb friction regularised by
``tanh(v_t / v_reg)``. Soil law and sources: ``rom.py``. Glider mass 343 kg (thesis section 2.2),
pitch inertia 250 kg m^2 (exudyn_coupling.md test body) are defaults, not measured values.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from crashdem.diagnosis import _dsp
from crashdem.diagnosis import _rom_kernels as _k
from crashdem.diagnosis.rom import RomParams, RomSettings, _check, sample_grid
from crashdem.signal import Signal

__all__ = ["PlanarParams", "simulate_planar", "run_planar_raw"]

#: tangential velocity scale of the friction regularisation [m/s]
FRICTION_V_REG = 0.05


def _glider_soil() -> RomParams:
    return RomParams(mass=343.0, radius=0.15, impact_speed=18.33)


@dataclass(frozen=True)
class PlanarParams:
    """Planar impactor (SI, angles in rad).

    soil : the soil law and its effects (``RomParams``; ``mass``, ``radius`` = nose radius and
        ``impact_speed`` are the body's)
    pitch_inertia : J [kg m^2] > 0
    nose_offset : d, CG to nose-sphere centre along body x [m] (may be 0 or negative)
    slope : inclination of the soil surface [rad] in [0, pi/2]
    path_angle : flight-path angle below horizontal at contact [rad] in [-pi/2, pi/2]
    pitch : pitch attitude at contact, nose up positive [rad] in [-pi/2, pi/2]
    friction : Coulomb coefficient nose/soil [-] >= 0
    angle_offset, pitch_offset : initial-condition offsets [rad]
    """

    soil: RomParams = field(default_factory=_glider_soil)
    pitch_inertia: float = 250.0
    nose_offset: float = 1.5
    slope: float = math.radians(45.0)
    path_angle: float = 0.0
    pitch: float = 0.0
    friction: float = 0.5
    angle_offset: float = 0.0
    pitch_offset: float = 0.0

    def __post_init__(self) -> None:
        _check("PlanarParams.pitch_inertia", self.pitch_inertia, 0.0, math.inf, "kg*m^2",
               lo_open=True, hi_open=True)
        _check("PlanarParams.nose_offset", self.nose_offset, -20.0, 20.0, "m")
        _check("PlanarParams.slope", self.slope, 0.0, math.pi / 2, "rad")
        _check("PlanarParams.path_angle", self.path_angle, -math.pi / 2, math.pi / 2, "rad")
        _check("PlanarParams.pitch", self.pitch, -math.pi / 2, math.pi / 2, "rad")
        _check("PlanarParams.friction", self.friction, 0.0, 5.0, "1")
        _check("PlanarParams.angle_offset", self.angle_offset, -0.6, 0.6, "rad")
        _check("PlanarParams.pitch_offset", self.pitch_offset, -0.6, 0.6, "rad")


@_k.jit
def _run_planar(p, mass, inertia, d, slope, gamma, theta0, mu, dt, n_steps):
    """Semi-implicit Euler of the planar impactor from first contact; arrays per step:
    t, specific force body-x, body-z [m/s^2], pitch rate [rad/s], penetration [m]."""
    n = n_steps + 1
    t_o = np.empty(n)
    fx_o = np.empty(n)
    fz_o = np.empty(n)
    w_o = np.empty(n)
    pen_o = np.empty(n)
    g = p[_k.P_G]
    rn = p[_k.P_RADIUS]
    nx, nz = math.sin(slope), -math.cos(slope)  # inward normal (into the soil)
    tx, tz = math.cos(slope), math.sin(slope)  # surface tangent (up-slope)
    th = theta0
    # nose centre touches the surface at the origin: c = -rn n
    cx, cz = -rn * nx, -rn * nz
    rx = cx - d * math.cos(th)
    rz = cz - d * math.sin(th)
    v0 = p[_k.P_V0]
    ux, uz = v0 * math.cos(gamma), -v0 * math.sin(gamma)
    w = 0.0
    fs = 0.0
    t_o[0] = 0.0
    fx_o[0] = 0.0
    fz_o[0] = 0.0
    w_o[0] = 0.0
    pen_o[0] = 0.0
    for k in range(n_steps):
        t = k * dt
        ex, ez = math.cos(th), math.sin(th)
        cx = rx + d * ex
        cz = rz + d * ez
        vcx = ux - w * d * ez
        vcz = uz + w * d * ex
        delta = rn + (cx * nx + cz * nz)
        vn = vcx * nx + vcz * nz
        fn, fs = _k._soil_update(delta, vn, fs, dt, t, p)
        vt = vcx * tx + vcz * tz
        ft = -mu * (fn if fn > 0.0 else 0.0) * math.tanh(vt / 0.05)
        fx = -fn * nx + ft * tx
        fz = -fn * nz + ft * tz
        tau = d * (ex * fz - ez * fx)
        ux += dt * fx / mass
        uz += dt * (fz / mass - g)
        w += dt * tau / inertia
        rx += dt * ux
        rz += dt * uz
        th += dt * w
        t_o[k + 1] = (k + 1) * dt
        fx_o[k + 1] = (fx * ex + fz * ez) / mass
        fz_o[k + 1] = (-fx * ez + fz * ex) / mass
        w_o[k + 1] = w
        # penetration after the step (as the drop ROM reports its depth)
        d_new = rn + ((rx + d * math.cos(th)) * nx + (rz + d * math.sin(th)) * nz)
        pen_o[k + 1] = d_new if d_new > 0.0 else 0.0
    return t_o, fx_o, fz_o, w_o, pen_o


def run_planar_raw(params: PlanarParams, settings: RomSettings = RomSettings()):
    """Integrate from first contact at the ROM step; returns (t, f_x, f_z, pitch rate, penetration)
    with the mount resonance applied to both specific forces when enabled."""
    s = params.soil
    n_steps = int(math.ceil(settings.t_end / settings.dt))
    t, fx, fz, w, pen = _run_planar(s.to_array(), s.mass, params.pitch_inertia, params.nose_offset,
                                    params.slope, params.path_angle + params.angle_offset,
                                    params.pitch + params.pitch_offset, params.friction,
                                    settings.dt, n_steps)
    if math.isfinite(s.mount_frequency):
        fx = _dsp.mount_filter_bilinear(fx, settings.dt, s.mount_frequency, s.mount_damping)
        fz = _dsp.mount_filter_bilinear(fz, settings.dt, s.mount_frequency, s.mount_damping)
    return t, fx, fz, w, pen


def simulate_planar(params: PlanarParams, settings: RomSettings = RomSettings()) -> dict[str, Signal]:
    """Acquired channels ``accel_x``, ``accel_z`` [m/s^2] (body axes), ``pitch_rate`` [rad/s]
    and ``penetration`` [m] on the acquisition grid (free flight before contact: specific force
    0, constant pitch rate 0)."""
    t_raw, fx, fz, w, pen = run_planar_raw(params, settings)
    ts = sample_grid(settings)
    post = ts >= 0.0
    out: dict[str, Signal] = {}
    meta = {"source": f"crashdem.diagnosis.rom_planar (dt={settings.dt:g} s)"}
    for name, raw, unit, filt in (("accel_x", fx, "m/s^2", True), ("accel_z", fz, "m/s^2", True),
                                  ("pitch_rate", w, "rad/s", True), ("penetration", pen, "m", False)):
        data = np.zeros_like(ts)
        data[post] = np.interp(ts[post], t_raw, raw)
        cfc = settings.cfc if filt else None
        if cfc is not None:
            data = _dsp.cfc(data, settings.sample_rate, cfc)
        out[name] = Signal(name, ts.copy(), data, unit, cfc, dict(meta))
    return out
