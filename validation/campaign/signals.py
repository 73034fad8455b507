"""Impact metrics of a drop-mass record and a robust double-peak detector.

API
---
``detect_double_peak(t, a, ...) -> PeakReport``
``impact_metrics(record) -> dict``            (record: :class:`DropRecord`)
``read_drop_record(path) -> DropRecord``      (a crashdem HDF5 result of a drop test)
``impulse_balance(record) -> dict``           (momentum/impulse consistency of the channels)

Conventions: time in s from the start of the run, ``t_contact`` the first-contact time; the
accelerometer channel is the specific force along the body z axis (deceleration > 0 while the
soil pushes the mass up); ``v_z`` < 0 downwards; penetration > 0 below the initial free surface.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import find_peaks

#: Standard gravity for expressing accelerations in g [m/s^2] (SAE J211 / ISO 80000-3).
G0 = 9.80665
#: Fraction of the peak force that delimits the impact pulse (pulse-width convention).
PULSE_LEVEL = 0.10


@dataclass(frozen=True)
class PeakReport:
    """Outcome of :func:`detect_double_peak`.

    Attributes
    ----------
    double : bool
        At least two qualifying maxima.
    times, heights, prominences : tuple of float
        The qualifying maxima, in time order [s, signal unit, signal unit].
    noise : float
        Robust noise estimate of the signal [signal unit].
    threshold : float
        Prominence threshold that was applied [signal unit].
    """

    double: bool
    times: tuple[float, ...]
    heights: tuple[float, ...]
    prominences: tuple[float, ...]
    noise: float
    threshold: float


def robust_noise(a: np.ndarray) -> float:
    """Standard deviation of white noise on a smooth signal, from its second differences.

    ``sigma = 1.4826 MAD(d2) / sqrt(6)``: the second difference cancels a locally linear signal
    and has variance ``6 sigma^2`` for white noise; the MAD makes the estimate insensitive to
    the few samples where the signal itself curves sharply (the peaks).

    Notes
    -----
    MAD-to-sigma factor 1.4826 for a normal law (Hampel 1974); difference-based noise
    estimation: von Neumann (1941) / Rice (1984).
    """
    a = np.asarray(a, dtype=float)
    if a.size < 5:
        return 0.0
    d2 = np.diff(a, 2)
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


def detect_double_peak(t: np.ndarray, a: np.ndarray, *, min_separation: float = 5e-3,
                       rel_prominence: float = 0.10, noise_factor: float = 5.0,
                       rel_height: float = 0.30, window: tuple[float, float] | None = None
                       ) -> PeakReport:
    """Decide whether a deceleration pulse has two distinct maxima.

    Algorithm: (1) restrict to ``window`` (default: the whole record); (2) estimate the noise
    sigma with :func:`robust_noise`; (3) keep the local maxima that are at least
    ``rel_height`` times the global maximum high, whose topographic prominence is at least
    ``max(rel_prominence * peak, noise_factor * sigma)`` and that are at least
    ``min_separation`` apart (the higher one wins inside that distance); (4) the pulse is a
    double peak when two or more maxima qualify.

    Parameters
    ----------
    t : array
        Sample times [s], increasing, uniform.
    a : array
        Signal (e.g. deceleration) [any unit]; the peaks sought are maxima.
    min_separation : float
        Minimum time between two maxima [s] (5 ms: a CFC 60 channel cannot resolve closer
        features, its -3 dB point is 100 Hz).
    rel_prominence : float
        Minimum prominence as a fraction of the global maximum [-].
    noise_factor : float
        Minimum prominence in noise standard deviations [-].
    rel_height : float
        Minimum height of a maximum as a fraction of the global maximum [-].
    window : (float, float) or None
        Time interval searched [s].

    Returns
    -------
    PeakReport

    Notes
    -----
    Topographic prominence as in ``scipy.signal.find_peaks`` (peak height above the higher of
    the two lowest points that separate it from a higher peak).
    """
    t = np.asarray(t, dtype=float)
    a = np.asarray(a, dtype=float)
    if t.shape != a.shape or t.ndim != 1:
        raise ValueError(f"t.shape={t.shape}, a.shape={a.shape}: must be equal 1-D shapes")
    for name, v in (("min_separation", min_separation), ("rel_prominence", rel_prominence),
                    ("rel_height", rel_height)):
        if not v > 0:
            raise ValueError(f"{name}={v!r}: must be > 0")
    if window is not None:
        sel = (t >= window[0]) & (t <= window[1])
        t, a = t[sel], a[sel]
    empty = PeakReport(False, (), (), (), 0.0, 0.0)
    if a.size < 5:
        return empty
    peak = float(np.max(a))
    if peak <= 0:
        return empty
    dt = float(np.median(np.diff(t)))
    sigma = robust_noise(a)
    thr = max(rel_prominence * peak, noise_factor * sigma)
    dist = max(1, int(math.ceil(min_separation / dt)))
    idx, props = find_peaks(a, height=rel_height * peak, prominence=thr, distance=dist)
    # a maximum on the first or last sample is not seen by find_peaks; a pulse that is still
    # rising at the window end does not count as a second peak (it is unresolved)
    return PeakReport(len(idx) >= 2, tuple(float(x) for x in t[idx]),
                      tuple(float(x) for x in a[idx]),
                      tuple(float(x) for x in props["prominences"]), sigma, thr)


@dataclass
class DropRecord:
    """The channels of one drop test, on a common time base (SI units)."""

    t: np.ndarray  #: time from the run start [s]
    decel: np.ndarray  #: accelerometer z (specific force), filtered [m/s^2]
    v_z: np.ndarray  #: vertical velocity, filtered [m/s]
    penetration: np.ndarray  #: depth of the lowest point below the free surface [m]
    force: np.ndarray  #: vertical soil force on the mass, filtered [N]
    floor_force: np.ndarray  #: sum of the floor load cells, filtered [N]
    t_contact: float  #: first contact [s]
    mass: float  #: drop mass [kg]
    impact_velocity: float  #: speed at first contact [m/s]
    raw: dict = field(default_factory=dict)  #: unfiltered force / v_z / decel (name -> array)


def read_drop_record(path, mass: float | None = None) -> DropRecord:
    """Read a crashdem drop-test result (``crashdem.run.run_scenario`` output).

    Parameters
    ----------
    path : path-like
        HDF5 result.
    mass : float or None
        Drop mass [kg]; None = ``bodies.drop_sphere().mass``.
    """
    import h5py

    from crashdem.results import open_result

    with h5py.File(path, "r") as f:
        info = dict(f["run"].attrs)
    if mass is None:
        import bodies

        mass = float(bodies.drop_sphere().mass)
    with open_result(path) as res:
        names = res.channels()
        a = res["drop_mass_accel_z"]
        t = np.asarray(a.t, dtype=float)

        def on_t(sig):
            return np.interp(t, np.asarray(sig.t, float), np.asarray(sig.data, float))

        v = on_t(res["drop_mass_velocity_z"])
        bottom = on_t(res["drop_mass_bottom_z"])
        force = on_t(res["drop_mass_contact_force_z"])
        cells = [n for n in names if n.startswith("floor_load_cell_")]
        floor = np.sum([on_t(res[n]) for n in cells], axis=0) if cells else np.zeros_like(t)
        raw = {
            "force": on_t(res.channel("drop_mass_contact_force_z", filtered=False)),
            "v_z": on_t(res.channel("drop_mass_velocity_z", filtered=False)),
            "decel": on_t(res.channel("drop_mass_accel_z", filtered=False)),
        }
    surface = float(info["surface_z"])
    return DropRecord(t=t, decel=np.asarray(a.data, float), v_z=v, penetration=surface - bottom,
                      force=force, floor_force=floor, t_contact=float(info["t_contact"]),
                      mass=float(mass), impact_velocity=float(info["impact_velocity"]), raw=raw)


def first_upcrossing(t: np.ndarray, y: np.ndarray, after: float) -> float:
    """First time after ``after`` where ``y`` goes from < 0 to >= 0 (linear interpolation) [s];
    NaN when it never does."""
    sel = np.nonzero(t >= after)[0]
    if sel.size < 2:
        return float("nan")
    i0 = sel[0]
    yy = y[i0:]
    neg = yy < 0
    if not neg.any():
        return float("nan")
    start = int(np.argmax(neg))
    up = np.nonzero(neg[start:-1] & ~neg[start + 1:])[0]
    if up.size == 0:
        return float("nan")
    k = i0 + start + int(up[0])
    y0, y1 = y[k], y[k + 1]
    return float(t[k] + (t[k + 1] - t[k]) * (-y0) / (y1 - y0))


def impact_metrics(rec: DropRecord, **peak_options) -> dict:
    """Peak force and deceleration, maximum penetration, impact duration, rebound onset.

    Times are measured from first contact.  ``impact_duration_s`` is the time from contact to
    the moment the soil force falls below ``PULSE_LEVEL`` times its peak for the last time
    (the mass stays in its crater, so the force never returns to zero; the 10 % level is the
    pulse-width convention).  ``t_rebound_s`` is the first sign change of ``v_z`` from
    downward to upward (thesis §2.1.3), NaN when the mass still sinks at the end of the record
    (``t_last_s``, the last sample's time).  ``double_peak`` uses :func:`detect_double_peak` on the
    deceleration between contact and the maximum penetration (the loading phase).
    """
    t = rec.t - rec.t_contact
    after = t >= 0.0
    k_f = int(np.argmax(np.where(after, rec.force, -np.inf)))
    k_a = int(np.argmax(np.where(after, rec.decel, -np.inf)))
    k_p = int(np.argmax(np.where(after, rec.penetration, -np.inf)))
    f_peak = float(rec.force[k_f])
    above = np.nonzero(after & (rec.force >= PULSE_LEVEL * f_peak))[0]
    duration = float(t[above[-1]]) if above.size else float("nan")
    t_reb = first_upcrossing(t, rec.v_z, 0.0)
    reb_speed = float(np.max(rec.v_z[t >= t_reb])) if math.isfinite(t_reb) else 0.0
    t_end_load = t[k_p] if math.isfinite(t_reb) else t[-1]
    rep = detect_double_peak(t, rec.decel, window=(0.0, float(t_end_load)), **peak_options)
    return {
        "impact_velocity_m_s": rec.impact_velocity,
        "peak_force_N": f_peak,
        "t_peak_force_s": float(t[k_f]),
        "peak_decel_g": float(rec.decel[k_a] / G0),
        "t_peak_decel_s": float(t[k_a]),
        "max_penetration_m": float(rec.penetration[k_p]),
        "t_max_penetration_s": float(t[k_p]),
        "t_last_s": float(t[-1]),
        "impact_duration_s": duration,
        "t_rebound_s": t_reb,
        "rebound_speed_m_s": reb_speed,
        "peak_floor_force_N": float(np.max(rec.floor_force[after])) if after.any() else 0.0,
        "double_peak": bool(rep.double),
        "decel_peaks_s": list(rep.times),
        "decel_peaks_g": [h / G0 for h in rep.heights],
    }


def impulse_balance(rec: DropRecord, g: float = 9.81) -> dict:
    """Momentum balance of the raw channels over the record.

    ``m (v_end - v_0)`` against ``int (F_soil - m g) dt`` (force channel) and against
    ``m int (a_z - g) dt`` (accelerometer = specific force), trapezoidal rule.

    Notes
    -----
    Newton's second law integrated over time (impulse-momentum theorem).
    """
    t = rec.t
    v = rec.raw.get("v_z", rec.v_z)
    f = rec.raw.get("force", rec.force)
    a = rec.raw.get("decel", rec.decel)
    dp = rec.mass * (v[-1] - v[0])
    j_force = float(np.trapezoid(f, t) - rec.mass * g * (t[-1] - t[0]))
    j_accel = float(rec.mass * (np.trapezoid(a, t) - g * (t[-1] - t[0])))
    return {"momentum_change_Ns": float(dp), "impulse_force_Ns": j_force,
            "impulse_accel_Ns": j_accel, "initial_momentum_Ns": float(rec.mass * abs(v[0]))}
