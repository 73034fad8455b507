"""Model-free check of the accelerometer against an independently measured velocity.

An ideal accelerometer on the impactor reads the specific force ``f = dv/dt + g`` (z up; 0 in
free fall), whatever the soil does. When the recording also holds the impactor's velocity from an
independent measurement (a displacement transducer, photogrammetry, the simulation state of
another code) the two channels must agree through ``f = dv/dt + g`` after the same acquisition
filter (SAE J211 filters are linear and time-invariant: differentiation commutes with them). A
mount resonance or a seismic-transducer response between the body and the sensing element breaks
that relation in a way no soil physics can: the accelerometer channel becomes ``H(s) f``.

:func:`accel_velocity_check` fits, to the recorded acceleration ``a``, the velocity-derived
specific force ``u = dv/dt + g`` through

* the ideal sensor: ``a = c u`` (gain ``c``: calibration / unit error), and
* each sensor form of ``catalogue`` ``sensor_dynamics`` (``_dsp.mount_filter_bilinear``:
  ``form`` 1 resonant-mount transmissibility, 0 seismic low-pass) with natural frequency ``fn``
  and damping ratio ``zeta``: ``a = c H(fn, zeta, form) u``,

by least squares over the event, weighted by the noise of the difference ``a - u`` measured on
the quiet pre-event segment (free fall: both read 0). Evidence: the Bayesian information
criterion with ``n_eff`` independent samples of the CFC-filtered noise (``_dsp.
effective_samples``), plus ``ln 2`` for choosing the form. No soil model enters, so the evidence
is not diluted by the screening model's model-form error, which is why this check is decisive
where the soil-model fit is not.

When the velocity was *integrated from the same accelerometer* (common lab practice) the two
channels agree by construction, the check finds nothing and says so (``"detected": False``); the
diagnosis then relies on the soil-model fit alone.

Notes
-----
Variable projection for the gain (Golub & Pereyra 1973): for given filter parameters the optimal
``c`` is linear least squares. Differentiation of the sampled velocity: second-order central
differences (``numpy.gradient``); at the CFC 60 bandwidth and 12.5 kHz its gain error is below
1e-3.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from crashdem.diagnosis import _dsp
from crashdem.diagnosis.mismatch import MAD_TO_SIGMA, estimate_noise
from crashdem.signal import Signal

__all__ = ["accel_velocity_check", "FORMS", "GAIN_RANGE"]

#: sensor forms: label -> ``mount_form`` of the ROM / ``_dsp`` filters
FORMS = {"mount": 1.0, "lowpass": 0.0}
#: search box of the filter parameters (the catalogue's ``sensor_dynamics`` ranges)
FN_RANGE = (20.0, 1000.0)
ZETA_RANGE = (0.02, 1.0)
#: a fitted gain outside this range means the channels do not measure the same thing (sign
#: convention, unit, another body): the check is not applicable
GAIN_RANGE = (0.5, 2.0)
#: the event window: from this long before the acceleration onset to the end of the record [s]
PRE_ONSET = 0.005
#: widest channel class the check is validated for [Hz]. Measured on Yade null recordings
#: acquired at 10-20 kHz: CFC 60 and 180 never detect a sensor (Delta BIC -21 to -1), CFC 600 and
#: 1000 do (Delta BIC 28-93, fitted gain 0.89-0.98), also after an extra CFC 60/180 filter of both
#: channels; the cause (the DEM's kHz contact chatter in the acquisition) is not resolved, so
#: wider-band channels are reported "not applicable"
MAX_CFC = 180.0
#: minimum quiet samples for the noise of the difference
MIN_QUIET = 32


def _filtered(u: np.ndarray, dt: float, fn: float, zeta: float, form: float) -> np.ndarray:
    return _dsp.mount_filter_bilinear(u, dt, fn, zeta, form)


def _gain_fit(a: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    den = float(np.dot(y, y))
    c = float(np.dot(a, y)) / den if den > 0 else 1.0
    return c, a - c * y


def accel_velocity_check(acc: Signal, vel: Signal, *, gravity: float = 9.81,
                         quiet: tuple[float, float] | None = None,
                         accept_margin: float = 10.0) -> dict[str, Any]:
    """Test whether the accelerometer channel is the velocity's derivative seen through a sensor.

    Parameters
    ----------
    acc : specific force along +z [m/s^2 or convertible] (0 in free fall)
    vel : velocity along +z [m/s or convertible], independently measured, same acquisition
    gravity : [m/s^2]
    quiet : pre-event window [s] for the noise of the difference (default: from the start of
        the record to 5 ms before the acceleration onset)
    accept_margin : Delta BIC over the ideal sensor needed to report sensor dynamics

    Returns
    -------
    dict: ``applicable`` (and ``reason`` when not), ``detected``, ``delta_bic``, ``form``,
    ``mount_frequency`` [Hz], ``mount_damping`` [-], their ``uncertainty``, ``gain`` (ideal and
    fitted), ``rms_sigma_ideal`` / ``rms_sigma_fitted`` (difference RMS in noise sigma),
    ``n``, ``n_eff``, ``sigma`` [m/s^2].
    """
    a_s, v_s = acc.to_si(), vel.to_si()
    t = a_s.t
    if a_s.t.size < 64:
        return {"applicable": False, "reason": "record too short"}
    v = v_s.data if (v_s.t.shape == t.shape and np.allclose(v_s.t, t)) else \
        np.interp(t, v_s.t, v_s.data)
    a = a_s.data
    ok = np.isfinite(a) & np.isfinite(v)
    if not ok.all():  # failed channel: use the valid prefix
        last = int(np.argmin(ok)) if not ok[0] else 0
        t, a, v = t[:last], a[:last], v[:last]
        if t.size < 64:
            return {"applicable": False, "reason": "no valid samples"}
    dt = float(np.median(np.diff(t)))
    u = np.gradient(v, t) + gravity
    cfc = a_s.cfc
    if cfc is None or cfc > MAX_CFC:
        return {"applicable": False,
                "reason": f"channel class CFC {cfc} above CFC {MAX_CFC:g}: the check is validated "
                          f"up to CFC {MAX_CFC:g} only (wider-band Yade recordings gave false "
                          "detections)"}
    d = a - u
    # noise of the difference on the quiet pre-event segment
    if quiet is None:  # the acceleration's own quiet pre-event segment (what diagnose passes)
        quiet = estimate_noise(a_s).window
        if quiet is None:
            return {"applicable": False, "reason": "no quiet pre-event segment in the acceleration"}
    q = (t >= quiet[0]) & (t <= quiet[1])
    if q.sum() < MIN_QUIET:
        return {"applicable": False, "reason": f"quiet pre-event segment too short "
                                              f"({int(q.sum())} samples < {MIN_QUIET})"}
    dq = d[q] - np.median(d[q])
    sigma = MAD_TO_SIGMA * float(np.median(np.abs(dq)))
    sigma = max(sigma, 1e-6 * float(np.max(np.abs(a))))
    t0 = quiet[1]
    w = t >= t0
    if w.sum() < 64:
        return {"applicable": False, "reason": "event window too short"}
    band = _dsp.noise_bandwidth(1.0 / dt, cfc)
    stride = max(1, int(1.0 / dt / (2.0 * 8.0 * band)))
    idx = np.flatnonzero(w)[::stride]
    n = idx.size
    n_eff = float(min(n, _dsp.effective_samples(int(w.sum()), 1.0 / dt, cfc)))

    c0, r0 = _gain_fit(a[idx], u[idx])
    rss0 = float(np.sum((r0 / sigma) ** 2))
    out: dict[str, Any] = {"applicable": True, "sigma": sigma, "n": n, "n_eff": n_eff,
                           "gain_ideal": c0, "rms_sigma_ideal": math.sqrt(rss0 / n)}
    if not GAIN_RANGE[0] <= c0 <= GAIN_RANGE[1]:
        out.update(applicable=False, detected=False,
                   reason=f"gain {c0:.3g} between the channels outside {GAIN_RANGE}: they do not "
                          "measure the same motion with the same convention")
        return out
    # a resonance the sampling resolves: below the mount design's limit (``_dsp``)
    fn_hi = min(FN_RANGE[1], _dsp.MOUNT_NYQUIST_FRACTION * 0.5 / dt)
    if fn_hi <= FN_RANGE[0]:
        return {**out, "applicable": False, "detected": False,
                "reason": f"sampled at {1.0 / dt:.4g} Hz: no mount resonance from "
                          f"{FN_RANGE[0]:g} Hz up is resolved"}
    lf = (math.log(FN_RANGE[0]), math.log(fn_hi))
    lz = (math.log(ZETA_RANGE[0]), math.log(ZETA_RANGE[1]))

    def unpack(x):
        return (math.exp(lf[0] + x[0] * (lf[1] - lf[0])), math.exp(lz[0] + x[1] * (lz[1] - lz[0])))

    best: dict[str, Any] | None = None
    for label, form in FORMS.items():
        def res(x, form=form):
            fn, z = unpack(x)
            y = _filtered(u, dt, fn, z, form)[idx]
            _, r = _gain_fit(a[idx], y)
            return r / sigma

        grid = [(i, j) for i in np.linspace(0.0, 1.0, 25) for j in np.linspace(0.0, 1.0, 9)]
        costs = [float(np.sum(res(np.array(x)) ** 2)) for x in grid]
        x0 = np.array(grid[int(np.argmin(costs))])
        sol = least_squares(res, x0, bounds=(0.0, 1.0), diff_step=1e-3, max_nfev=200,
                            ftol=1e-8, xtol=1e-8)
        rss = float(np.sum(sol.fun ** 2))
        if best is None or rss < best["rss"]:
            best = {"form": label, "x": sol.x, "rss": rss, "jac": sol.jac}
    assert best is not None
    fn, z = unpack(best["x"])
    y = _filtered(u, dt, fn, z, FORMS[best["form"]])[idx]
    c1, _ = _gain_fit(a[idx], y)
    # BIC with unknown variance scale: ideal (gain) vs sensor (gain, fn, zeta) + the form choice
    bic0 = n_eff * math.log(max(rss0, 1e-300) / n) + 1 * math.log(n_eff)
    bic1 = n_eff * math.log(max(best["rss"], 1e-300) / n) + 3 * math.log(n_eff) + math.log(len(FORMS))
    jac = best["jac"]
    s2 = best["rss"] / max(1, n - 3)
    cov = np.linalg.pinv(jac.T @ jac) * s2 * (n / n_eff)
    unc_fn = fn * (lf[1] - lf[0]) * math.sqrt(max(cov[0, 0], 0.0))
    unc_z = z * (lz[1] - lz[0]) * math.sqrt(max(cov[1, 1], 0.0))
    delta = bic0 - bic1
    at_bound = bool(best["x"][0] > 1 - 1e-3)  # fn at the top of the range: no resonance seen
    out.update({
        "detected": bool(delta > accept_margin and not at_bound),
        "delta_bic": delta, "form": best["form"], "mount_frequency": fn, "mount_damping": z,
        "uncertainty": {"mount_frequency": unc_fn, "mount_damping": unc_z},
        "gain": c1, "rms_sigma_fitted": math.sqrt(best["rss"] / n),
        "window_s": [float(t0), float(t[-1])],
    })
    return out
