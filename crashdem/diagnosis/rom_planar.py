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

Also: a crushable nose (a nose mass sliding along the body x axis behind the drop model's
force-limited element; the axial soil load reaches the body through it, the lateral load
directly), a penalty contact of the nose sphere on a vertical rear wall, and the
accelerometer's position (its rigid-body rotation terms). It is the screening model of glider
scenarios (``PlanarSimulator``, ``catalogue.planar_catalogue``, ``cli.planar_from_scenario``;
docs/diagnosis.md "Glider scenarios").

Notes
-----
Rigid-body planar dynamics (Newton-Euler), semi-implicit Euler; Coulomb friction regularised by
``tanh(v_t / v_reg)``. Soil law and sources: ``rom.py``. Glider mass 343 kg (thesis section 2.2),
pitch inertia 250 kg m^2 (exudyn_coupling.md test body) are defaults, not measured values.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np

from crashdem.diagnosis import _dsp
from crashdem.diagnosis import _rom_kernels as _k
from crashdem.diagnosis.rom import RomParams, RomSettings, _check, sample_grid
from crashdem.signal import Signal

__all__ = ["PlanarParams", "simulate_planar", "run_planar_raw", "PlanarSimulator", "PLANAR_CHANNELS"]

#: channels of the planar model that a diagnosis compares (primary first)
PLANAR_CHANNELS = ("accel_x", "accel_z", "pitch_rate")

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
    nose_height : height of the nose-sphere centre above the CG along body z [m]
    wall_distance : horizontal distance from the first contact point to a vertical rigid wall
        ahead (the container's rear wall) [m] > 0 (inf = no wall)
    wall_stiffness : wall contact stiffness [N/m] > 0 (the panel's generalised stiffness)
    wall_damping : damping ratio of the wall contact [-] in [0, 2]
    mount_x, mount_z : accelerometer position from the CG in body axes [m] (the channels
        ``accel_x`` / ``accel_z`` include its rigid-body rotation terms)
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
    nose_height: float = 0.0
    wall_distance: float = math.inf
    wall_stiffness: float = 2.0e6
    wall_damping: float = 0.2
    mount_x: float = 0.0
    mount_z: float = 0.0

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
        _check("PlanarParams.nose_height", self.nose_height, -5.0, 5.0, "m")
        _check("PlanarParams.wall_distance", self.wall_distance, 0.0, math.inf, "m", lo_open=True)
        _check("PlanarParams.wall_stiffness", self.wall_stiffness, 0.0, 1e12, "N/m", lo_open=True)
        _check("PlanarParams.wall_damping", self.wall_damping, 0.0, 2.0, "1")
        _check("PlanarParams.mount_x", self.mount_x, -20.0, 20.0, "m")
        _check("PlanarParams.mount_z", self.mount_z, -5.0, 5.0, "m")

    @property
    def v0(self) -> float:
        """Actual impact speed [m/s] (the soil record's speed plus its offset)."""
        return self.soil.v0

    def with_values(self, values: dict[str, float]) -> "PlanarParams":
        """A copy with planar fields, soil fields (``RomParams``) or recalibration scales
        (``rom.SCALE_KEYS``) replaced by ``values``."""
        own = {f.name for f in fields(self)} - {"soil"}
        mine = {k: float(v) for k, v in values.items() if k in own}
        rest = {k: v for k, v in values.items() if k not in own}
        return replace(self, soil=self.soil.with_values(rest) if rest else self.soil, **mine)


@_k.jit
def _run_planar(p, mass, inertia, d, h, slope, gamma, theta0, mu, dt, n_steps, wall_x, wall_k,
                wall_zeta, mx, mz):
    """Semi-implicit Euler of the planar impactor from first contact; arrays per step:
    t, specific force body-x, body-z at the mount (mx, mz) [m/s^2], pitch rate [rad/s],
    penetration [m].

    Nose-sphere centre at (d, h) in body axes from the CG. Crush (``p[P_FC]`` finite): a nose
    mass ``p[P_NOSE] mass`` slides along the body x axis behind a force-limited element
    (``_crush_update``); the soil's axial load reaches the body through it, the lateral load
    directly. Rear wall (``wall_x`` < 1e299): a vertical plane ``wall_x`` ahead of the first
    contact point, penalty contact of stiffness ``wall_k`` and damping ratio ``wall_zeta`` on
    the nose sphere (compression only)."""
    n = n_steps + 1
    t_o = np.empty(n)
    fx_o = np.empty(n)
    fz_o = np.empty(n)
    w_o = np.empty(n)
    pen_o = np.empty(n)
    g = p[_k.P_G]
    rn = p[_k.P_RADIUS]
    crush = p[_k.P_FC] < 1e15
    m_n = p[_k.P_NOSE] * mass if crush else 0.0
    m_b = mass - m_n
    wall = wall_x < 1e299
    c_w = 2.0 * wall_zeta * math.sqrt(wall_k * mass) if wall else 0.0
    nx, nz = math.sin(slope), -math.cos(slope)  # inward normal (into the soil)
    tx, tz = math.cos(slope), math.sin(slope)  # surface tangent (up-slope)
    th = theta0
    # nose centre touches the surface at the origin: c = -rn n
    cx, cz = -rn * nx, -rn * nz
    rx = cx - d * math.cos(th) + h * math.sin(th)
    rz = cz - d * math.sin(th) - h * math.cos(th)
    v0 = p[_k.P_V0]
    ux, uz = v0 * math.cos(gamma), -v0 * math.sin(gamma)
    w = 0.0
    fs = 0.0
    sr = 0.0  # crush: axial compression of the element [m] and its rate [m/s]
    vr = 0.0
    fcr = 0.0
    sp = 0.0
    t_o[0] = 0.0
    fx_o[0] = 0.0
    fz_o[0] = 0.0
    w_o[0] = 0.0
    pen_o[0] = 0.0
    for k in range(n_steps):
        t = k * dt
        ex, ez = math.cos(th), math.sin(th)
        dd = d - sr
        cx = rx + dd * ex - h * ez
        cz = rz + dd * ez + h * ex
        vcx = ux - w * (dd * ez + h * ex) - vr * ex
        vcz = uz + w * (dd * ex - h * ez) - vr * ez
        delta = rn + (cx * nx + cz * nz)
        vn = vcx * nx + vcz * nz
        fn, fs = _k._soil_update(delta, vn, fs, dt, t, p)
        vt = vcx * tx + vcz * tz
        ft = -mu * (fn if fn > 0.0 else 0.0) * math.tanh(vt / FRICTION_V_REG)
        fx = -fn * nx + ft * tx
        fz = -fn * nz + ft * tz
        if wall:
            pw = cx + rn - wall_x
            if pw > 0.0:
                fw = wall_k * pw + c_w * vcx
                if fw > 0.0:
                    fx -= fw
        if crush:
            fa = fx * ex + fz * ez  # axial (on the nose)
            fl = -fx * ez + fz * ex  # lateral (straight to the body)
            fcr, sp = _k._crush_update(fcr, sp, vr, dt, p)
            bx = -fcr * ex - fl * ez
            bz = -fcr * ez + fl * ex
            tau = dd * fl - h * (-fcr)
            vr += dt * (-fcr / m_b - (fa + fcr) / m_n)
            sr += dt * vr
        else:
            bx, bz = fx, fz
            tau = dd * (ex * fz - ez * fx) - h * (ex * fx + ez * fz)
        ux += dt * bx / m_b
        uz += dt * (bz / m_b - g)
        alpha = tau / inertia
        w += dt * alpha
        rx += dt * ux
        rz += dt * uz
        th += dt * w
        t_o[k + 1] = (k + 1) * dt
        ax_b = (bx * ex + bz * ez) / m_b
        az_b = (-bx * ez + bz * ex) / m_b
        if mx != 0.0 or mz != 0.0:  # rigid-body acceleration of the mount relative to the CG
            ax_b += -alpha * mz - w * w * mx
            az_b += alpha * mx - w * w * mz
        fx_o[k + 1] = ax_b
        fz_o[k + 1] = az_b
        w_o[k + 1] = w
        # penetration after the step (as the drop ROM reports its depth)
        e2x, e2z = math.cos(th), math.sin(th)
        d_new = rn + ((rx + (d - sr) * e2x - h * e2z) * nx + (rz + (d - sr) * e2z + h * e2x) * nz)
        pen_o[k + 1] = d_new if d_new > 0.0 else 0.0
    return t_o, fx_o, fz_o, w_o, pen_o


def run_planar_raw(params: PlanarParams, settings: RomSettings = RomSettings()):
    """Integrate from first contact at the ROM step; returns (t, f_x, f_z, pitch rate, penetration)
    with the mount resonance applied to both specific forces when enabled."""
    s = params.soil
    n_steps = int(math.ceil(settings.t_end / settings.dt))
    wall_x = params.wall_distance if math.isfinite(params.wall_distance) else 1e300
    t, fx, fz, w, pen = _run_planar(s.to_array(), s.mass, params.pitch_inertia, params.nose_offset,
                                    params.nose_height, params.slope,
                                    params.path_angle + params.angle_offset,
                                    params.pitch + params.pitch_offset, params.friction,
                                    settings.dt, n_steps, wall_x, params.wall_stiffness,
                                    params.wall_damping, params.mount_x, params.mount_z)
    if math.isfinite(s.mount_frequency):
        fx = _dsp.mount_filter_bilinear(fx, settings.dt, s.mount_frequency, s.mount_damping,
                                          s.mount_form)
        fz = _dsp.mount_filter_bilinear(fz, settings.dt, s.mount_frequency, s.mount_damping,
                                          s.mount_form)
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


class PlanarSimulator:
    """The planar ROM behind the diagnosis's simulator interface
    ``simulate(values: dict) -> dict[str, Signal]``: ``values`` may hold ``PlanarParams``
    fields, ``RomParams`` (soil) fields and the recalibration scales; ``catalogue`` is the
    hypothesis set whose parameters it understands (``catalogue.planar_catalogue``)."""

    def __init__(self, base: PlanarParams = PlanarParams(), settings: RomSettings = RomSettings(),
                 catalogue=None):
        from crashdem.diagnosis import catalogue as _cat

        self.base = base
        self.settings = settings
        self.catalogue = catalogue if catalogue is not None else _cat.planar_catalogue(base)
        self.calls = 0

    def __call__(self, params: dict[str, float] | None = None) -> dict[str, Signal]:
        self.calls += 1
        return simulate_planar(self.base.with_values(params or {}), self.settings)
