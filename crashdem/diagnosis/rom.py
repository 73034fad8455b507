"""Reduced-order impact model (ROM) of a rigid (or nose-crushable) impactor entering a granular
layer over a rigid floor, with every physics term of the diagnosis catalogue switchable.

The ROM is the cheap screening model of the diagnosis: one call integrates a 0.15 s impact in
well under a millisecond (Numba), so hundreds of fits per recording are affordable.

Model (z = tip depth below the free surface, positive down; v = dz/dt; forces upward positive)
------------------------------------------------------------------------------------------------
* contact cap of a sphere of radius R: ``a(z) = sqrt(2 R z - z^2)`` (``R`` beyond the equator),
  ``A(z) = pi a^2``;
* plastic resistance (Poncelet / Katsuragi-Durian form, anchors.md section 6)
  ``F_cap = A(z) [ (q0 + k_p z) m_layer f_floor m_rot + N_c c ] + C_d rho A(z) v^2 m_rot``;
* elastic loading / unloading of the soil under the impactor, flat-punch stiffness
  ``K(z) = 2 E_s a(z) m_layer f_floor`` (Sneddon 1965), return-mapped onto ``[-c A, F_cap]``:
  the stored elastic energy drives the rebound;
* rigid floor at depth H: stiffening ``f_floor = 1 + kappa a / (H - z)`` (elastic layer on a
  rigid base, Poulos & Davis 1974, first-order term in a/h) and the wave reflected by the floor,
  returning at ``t = 2H/c`` as a lift pulse ``r_w rho c v0 (a / 2H) A exp(-((t - 2H/c) / (R/c))^2 / 2)``
  (plane-wave impedance rho c v0, spherical spreading a/2H, reflection coefficient r_w);
* ``soil_layering``: ``m_layer = 1 + (ratio - 1) (1 + tanh((z - z_d)/w)) / 2`` -- resistance and
  stiffness jump by ``ratio`` at depth ``z_d`` (thesis section 2.1.2: compacted deep layer gives
  the double peak);
* ``cohesion``: bulk cohesion c adds ``N_c c`` to the bearing pressure (deep circular footing,
  N_c = 9, Skempton 1951) and allows tension down to ``-c A`` (adhesion on rebound);
* ``particle_rotation``: free rotation with rolling resistance lowers the mobilised friction to a
  residual fraction r of the blocked-rotation value over a mobilisation depth delta:
  ``m_rot = r + (1 - r) exp(-z/delta)`` (applied to the frictional and the inertial term, whose
  prefactor depends on friction, Katsuragi & Durian 2013);
* ``contact_damping``: a dashpot ``eta = 2 zeta sqrt(K m)`` in parallel with the soil spring,
  ``zeta = -ln e / sqrt(pi^2 + ln^2 e)`` from the restitution coefficient e (the linear
  spring-dashpot relation used by Yade's ``Ip2_FrictMat_FrictMat_MindlinPhys`` / Cundall-Strack
  damping);
* ``structural_crush``: a nose mass (fraction of the total) joined to the body by an
  elastic-perfectly-plastic element of strength F_c, bottoming out after a stroke s_max;
* ``sensor_dynamics``: the body acceleration seen through a mount resonance fn, zeta
  (``mount_form`` 1: base-excitation transmissibility of a resonant mount; 0: seismic-transducer
  low-pass) before sampling and CFC filtering;
* ``initial_conditions``: an offset of the impact speed.

The "acceleration" channel is the specific force along +z (what an accelerometer on the body
reads, 0 in free fall), the velocity channel is the body velocity along +z (negative while
descending).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from crashdem.diagnosis import _dsp
from crashdem.diagnosis import _rom_kernels as _k
from crashdem.signal import Signal

__all__ = ["RomParams", "RomSettings", "simulate", "RomSimulator", "restitution_to_zeta",
           "ACCEL", "VELOCITY", "PENETRATION", "SCALE_KEYS"]

ACCEL = "accel_z"
VELOCITY = "velocity_z"
PENETRATION = "penetration"
INF = math.inf

#: multiplicative recalibration keys understood by :class:`RomSimulator`
SCALE_KEYS = {
    "strength_scale": ("surface_strength", "strength_gradient"),
    "drag_scale": ("drag_coefficient",),
    "stiffness_scale": ("soil_modulus",),
}


def restitution_to_zeta(e: float) -> float:
    """Damping ratio of a linear spring-dashpot with restitution coefficient e (0 < e <= 1).

    Notes
    -----
    ``zeta = -ln e / sqrt(pi^2 + ln^2 e)`` (linear spring-dashpot, e.g. Schwager & Poeschel 2007).
    """
    if not 0.0 < e <= 1.0:
        raise ValueError(f"restitution={e!r}: must be in (0, 1] [-]")
    le = math.log(e)
    return -le / math.sqrt(math.pi**2 + le * le)


def _check(name: str, value: float, lo: float, hi: float, unit: str, lo_open: bool = False,
           hi_open: bool = False) -> None:
    bad = (value < lo or value > hi or (lo_open and value == lo) or (hi_open and value == hi)
           or math.isnan(value))
    if bad:
        lb = "(" if lo_open else "["
        rb = ")" if hi_open else "]"
        field_name = name if "." in name else f"RomParams.{name}"
        raise ValueError(f"{field_name}={value!r}: must be in {lb}{lo:g}, {hi:g}{rb} [{unit}]")


@dataclass(frozen=True)
class RomParams:
    """Parameters of the reduced-order drop model (SI). Effects are off at their defaults.

    Defaults: the 850 kg, 0.90 m sphere of the PoliMi drop tests (thesis Table 2.1, 13.7 m drop,
    16.4 m/s) on a 2 m loose layer; soil constants chosen so the baseline gives ~70 g peak and
    ~0.4 m penetration, the magnitudes measured with Yade on a loose bed (anchors.md section 8).
    """

    mass: float = 850.0  # [kg] > 0
    radius: float = 0.45  # [m] > 0
    impact_speed: float = 16.4  # [m/s] > 0, model value (before any initial-condition offset)
    gravity: float = 9.81  # [m/s^2] >= 0
    # soil calibration (the "existing" parameters: a wrong value is a recalibration)
    density: float = 1600.0  # [kg/m^3] bulk density, > 0
    surface_strength: float = 5.0e4  # [Pa] q0 >= 0
    strength_gradient: float = 2.5e6  # [Pa/m] k_p >= 0
    drag_coefficient: float = 1.2  # [-] C_d >= 0
    soil_modulus: float = 8.0e7  # [Pa] E_s > 0 (unloading/loading modulus of the bulk)
    floor_depth: float = 2.0  # [m] H: soil thickness above the rigid floor, > 0
    wave_speed: float = 90.0  # [m/s] c > 0 (loose gravel; Yade reflection at ~45 ms for 2 m)
    wave_reflection: float = 0.5  # [-] r_w in [0, 1]
    floor_stiffening: float = 0.5  # [-] kappa >= 0
    # soil_layering
    interface_depth: float = INF  # [m] z_d > 0 (inf = homogeneous)
    strength_ratio: float = 1.0  # [-] lower/upper resistance and stiffness, in [0.1, 10]
    interface_width: float = 0.02  # [m] smoothing width of the interface, > 0
    # cohesion
    cohesion: float = 0.0  # [Pa] bulk cohesion c >= 0
    bearing_factor: float = 9.0  # [-] N_c (Skempton deep circular footing)
    # particle_rotation
    friction_ratio: float = 1.0  # [-] r in (0, 1]; 1 = blocked rotation
    mobilisation_depth: float = 0.1  # [m] delta > 0
    # contact_damping
    restitution: float = 1.0  # [-] e in (0, 1]; 1 = no viscous damping
    # structural_crush
    crush_strength: float = INF  # [N] F_c > 0 (inf = rigid impactor)
    crush_stroke: float = 0.0  # [m] s_max >= 0
    nose_mass_fraction: float = 0.03  # [-] in (0, 0.5)
    crush_stiffness: float = 2.0e8  # [N/m] > 0, elastic stiffness of the nose before crushing
    # sensor_dynamics
    mount_frequency: float = INF  # [Hz] fn > 0 (inf = ideal mount)
    mount_damping: float = 0.1  # [-] zeta_m in (0, 2]
    mount_form: float = 1.0  # [-] 1 = mount transmissibility, 0 = seismic low-pass (in [0, 1])
    # initial_conditions
    speed_offset: float = 0.0  # [m/s] added to impact_speed

    def __post_init__(self) -> None:
        _check("mass", self.mass, 0.0, INF, "kg", lo_open=True, hi_open=True)
        _check("radius", self.radius, 0.0, INF, "m", lo_open=True, hi_open=True)
        _check("impact_speed", self.impact_speed, 0.0, 200.0, "m/s", lo_open=True)
        _check("gravity", self.gravity, 0.0, 100.0, "m/s^2")
        _check("density", self.density, 0.0, 2.0e4, "kg/m^3", lo_open=True)
        _check("surface_strength", self.surface_strength, 0.0, 1e9, "Pa")
        _check("strength_gradient", self.strength_gradient, 0.0, 1e10, "Pa/m")
        _check("drag_coefficient", self.drag_coefficient, 0.0, 100.0, "1")
        _check("soil_modulus", self.soil_modulus, 0.0, 1e11, "Pa", lo_open=True)
        _check("floor_depth", self.floor_depth, 0.0, 100.0, "m", lo_open=True)
        _check("wave_speed", self.wave_speed, 0.0, 1e4, "m/s", lo_open=True)
        _check("wave_reflection", self.wave_reflection, 0.0, 1.0, "1")
        _check("floor_stiffening", self.floor_stiffening, 0.0, 10.0, "1")
        _check("interface_depth", self.interface_depth, 0.0, INF, "m", lo_open=True)
        _check("strength_ratio", self.strength_ratio, 0.1, 10.0, "1")
        _check("interface_width", self.interface_width, 0.0, 1.0, "m", lo_open=True)
        _check("cohesion", self.cohesion, 0.0, 1e8, "Pa")
        _check("bearing_factor", self.bearing_factor, 0.0, 100.0, "1")
        _check("friction_ratio", self.friction_ratio, 0.0, 1.0, "1", lo_open=True)
        _check("mobilisation_depth", self.mobilisation_depth, 0.0, 10.0, "m", lo_open=True)
        _check("restitution", self.restitution, 0.0, 1.0, "1", lo_open=True)
        _check("crush_strength", self.crush_strength, 0.0, INF, "N", lo_open=True)
        _check("crush_stroke", self.crush_stroke, 0.0, 10.0, "m")
        _check("nose_mass_fraction", self.nose_mass_fraction, 0.0, 0.5, "1", lo_open=True,
               hi_open=True)
        _check("crush_stiffness", self.crush_stiffness, 0.0, INF, "N/m", lo_open=True,
               hi_open=True)
        _check("mount_frequency", self.mount_frequency, 0.0, INF, "Hz", lo_open=True)
        _check("mount_damping", self.mount_damping, 0.0, 2.0, "1", lo_open=True)
        _check("mount_form", self.mount_form, 0.0, 1.0, "1")
        _check("speed_offset", self.speed_offset, -0.9 * self.impact_speed, 100.0, "m/s")

    @property
    def v0(self) -> float:
        """Actual impact speed [m/s] (model value plus initial-condition offset)."""
        return self.impact_speed + self.speed_offset

    def with_values(self, values: dict[str, float]) -> "RomParams":
        """A copy with fields (or ``SCALE_KEYS`` multipliers) replaced by ``values``."""
        direct: dict[str, Any] = {}
        names = {f.name for f in fields(self)}
        for key, val in values.items():
            if key in SCALE_KEYS:
                for fname in SCALE_KEYS[key]:
                    direct[fname] = direct.get(fname, getattr(self, fname)) * float(val)
            elif key in names:
                direct[key] = float(val)
            else:
                raise ValueError(f"RomParams: unknown parameter {key!r}; known: "
                                 f"{sorted(names | set(SCALE_KEYS))}")
        return replace(self, **direct)

    def to_array(self) -> np.ndarray:
        """Kernel parameter vector (``_rom_kernels.P_*`` layout)."""
        p = np.zeros(_k.P_SIZE)
        p[_k.P_MASS] = self.mass
        p[_k.P_RADIUS] = self.radius
        p[_k.P_V0] = self.v0
        p[_k.P_G] = self.gravity
        p[_k.P_RHO] = self.density
        p[_k.P_Q0] = self.surface_strength
        p[_k.P_KP] = self.strength_gradient
        p[_k.P_CD] = self.drag_coefficient
        p[_k.P_ES] = self.soil_modulus
        p[_k.P_H] = self.floor_depth
        p[_k.P_C] = self.wave_speed
        p[_k.P_RW] = self.wave_reflection
        p[_k.P_KAPPA] = self.floor_stiffening
        p[_k.P_ZD] = self.interface_depth if math.isfinite(self.interface_depth) else 1e10
        p[_k.P_LRATIO] = self.strength_ratio
        p[_k.P_LWIDTH] = self.interface_width
        p[_k.P_COH] = self.cohesion
        p[_k.P_NC] = self.bearing_factor
        p[_k.P_FRATIO] = self.friction_ratio
        p[_k.P_MOB] = self.mobilisation_depth
        p[_k.P_ZETA] = restitution_to_zeta(self.restitution)
        p[_k.P_FC] = self.crush_strength if math.isfinite(self.crush_strength) else 1e300
        p[_k.P_SMAX] = self.crush_stroke
        p[_k.P_NOSE] = self.nose_mass_fraction
        p[_k.P_KC] = self.crush_stiffness
        return p

    def as_dict(self) -> dict[str, float]:
        """All fields as a dict (SI)."""
        return asdict(self)


@dataclass(frozen=True)
class RomSettings:
    """Numerics and acquisition of a ROM run.

    dt : integration step [s] (> 0); t_pre : free-fall record before first contact [s] (>= 0);
    t_end : record after first contact [s] (> 0); sample_rate : acquisition rate [Hz];
    cfc : channel frequency class applied to the sampled channels [Hz] (None = raw);
    method : "symplectic" (diagnosing ROM) or "midpoint" (truth generator)
    """

    dt: float = 2.0e-5
    t_pre: float = 0.02
    t_end: float = 0.15
    sample_rate: float = 12500.0
    cfc: float | None = 60.0
    method: str = "symplectic"

    def __post_init__(self) -> None:
        _check("RomSettings.dt", self.dt, 0.0, 1e-3, "s", lo_open=True)
        _check("RomSettings.t_pre", self.t_pre, 0.0, 10.0, "s")
        _check("RomSettings.t_end", self.t_end, 0.0, 10.0, "s", lo_open=True)
        _check("RomSettings.sample_rate", self.sample_rate, 0.0, 1e7, "Hz", lo_open=True)
        if self.method not in ("symplectic", "midpoint"):
            raise ValueError(f"RomSettings.method={self.method!r}: must be 'symplectic' or 'midpoint'")
        if self.dt > 0.5 / self.sample_rate:
            raise ValueError(f"RomSettings.dt={self.dt!r}: must be <= half the sample interval "
                             f"{0.5 / self.sample_rate:g} [s]")


def run_raw(params: RomParams, settings: RomSettings = RomSettings()
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integrate from first contact; returns (t, specific force, velocity, depth) at the ROM step,
    with the mount resonance applied to the specific force when enabled."""
    n_steps = int(math.ceil(settings.t_end / settings.dt))
    method = _k.METHOD_SYMPLECTIC if settings.method == "symplectic" else _k.METHOD_MIDPOINT
    t, acc, vel, dep = _k.run_rom(params.to_array(), settings.dt, n_steps, method)
    if math.isfinite(params.mount_frequency):
        if settings.method == "symplectic":
            acc = _dsp.mount_filter_bilinear(acc, settings.dt, params.mount_frequency,
                                              params.mount_damping, params.mount_form)
        else:
            acc = _dsp.mount_filter_exact(acc, settings.dt, params.mount_frequency,
                                           params.mount_damping, params.mount_form)
    return t, acc, vel, dep


def sample_grid(settings: RomSettings) -> np.ndarray:
    """Acquisition times [s] from -t_pre to t_end (0 = first contact)."""
    dts = 1.0 / settings.sample_rate
    n0 = int(round(settings.t_pre / dts))
    n1 = int(math.floor(settings.t_end / dts + 1e-9))
    return np.arange(-n0, n1 + 1) * dts


def simulate(params: RomParams, settings: RomSettings = RomSettings()) -> dict[str, Signal]:
    """Run the ROM and return acquired channels ``accel_z`` [m/s^2], ``velocity_z`` [m/s] and
    ``penetration`` [m], sampled at ``settings.sample_rate`` and CFC-filtered (accel, velocity).

    Notes
    -----
    Before first contact the body is in free fall: specific force 0, velocity
    ``-(v0 + g t)`` for t < 0.
    """
    t_raw, acc, vel, dep = run_raw(params, settings)
    ts = sample_grid(settings)
    pre = ts < 0.0
    post = ~pre
    acc_s = np.zeros_like(ts)
    vel_s = -(params.v0 + params.gravity * ts)
    dep_s = np.zeros_like(ts)  # the tip is above the surface before contact
    acc_s[post] = np.interp(ts[post], t_raw, acc)
    vel_s[post] = np.interp(ts[post], t_raw, vel)
    dep_s[post] = np.interp(ts[post], t_raw, dep)
    meta = {"source": f"crashdem.diagnosis.rom ({settings.method}, dt={settings.dt:g} s)"}
    out = {}
    for name, data, unit in ((ACCEL, acc_s, "m/s^2"), (VELOCITY, vel_s, "m/s")):
        if settings.cfc is not None:
            data = _dsp.cfc(data, settings.sample_rate, settings.cfc)
        out[name] = Signal(name, ts.copy(), data, unit, settings.cfc, dict(meta))
    out[PENETRATION] = Signal(PENETRATION, ts.copy(), dep_s, "m", None, dict(meta))
    return out


class RomSimulator:
    """The ROM behind the generic simulator interface ``simulate(params: dict) -> dict[str, Signal]``.

    Parameters
    ----------
    base : the baseline model (what the diagnosed simulation assumed)
    settings : numerics and acquisition (sample rate, CFC) matching the recording
    """

    def __init__(self, base: RomParams = RomParams(), settings: RomSettings = RomSettings()):
        self.base = base
        self.settings = settings
        self.calls = 0

    def __call__(self, params: dict[str, float] | None = None) -> dict[str, Signal]:
        self.calls += 1
        p = self.base.with_values(params or {})
        return simulate(p, self.settings)
