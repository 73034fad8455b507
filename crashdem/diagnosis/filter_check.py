"""Model-free check of the filter class a recorded channel was processed with.

A lab channel is acquired with (near-)white electronic noise and then filtered with an SAE J211
/ ISO 6487 channel frequency class (CFC 60, 180, 600 or 1000). The quiet segment before the
impact therefore carries the filter's power response: its periodogram is
``S(f) = s0 |H_CFC(f)|^2 + s1`` (``|H_CFC|^2 = |H_2pole|^4`` for the forward-backward J211
filter; ``s1`` a white floor added after filtering: quantisation, a noisy reference), or flat
for an unfiltered channel. :func:`filter_class_check` fits that model for every class by the
Whittle likelihood and ranks the classes by BIC. No soil model and no impact physics enter, so
the answer does not depend on how well any simulation reproduces the recording.

This is the ``sensor_dynamics`` "different filter class" of issue 7: a simulation filtered at
CFC 60 compared with a test channel filtered at CFC 180 has lower, later, broader peaks than
the test for no physical reason. The fix is to compare both at the recording's class
(re-filter the simulation's raw channel), which the diagnosis does before anything else.

Notes
-----
Whittle likelihood of a periodogram: Whittle (1953); Percival & Walden, *Spectral Analysis for
Physical Applications* (1993), section 6.6: the periodogram ordinates of a Gaussian process
are asymptotically independent ``S(f) chi^2_2 / 2``. With a Hann taper neighbouring ordinates
are correlated, so every second ordinate is used. J211 response: ``_dsp._j211_ba``.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal as sps
from scipy.optimize import minimize

from crashdem.diagnosis import _dsp
from crashdem.signal import Signal

__all__ = ["filter_class_check", "CLASSES", "MIN_SAMPLES", "class_response"]

#: filter classes tried [Hz] (SAE J211-1 / ISO 6487; CFC 20 is used for some vehicle channels);
#: ``None`` = unfiltered
CLASSES: tuple[float | None, ...] = (20.0, 60.0, 180.0, 600.0, 1000.0, None)
#: minimum quiet samples (at 12.5 kHz, 20 ms: a 50 Hz resolution resolves the CFC 60 corner)
MIN_SAMPLES = 256
#: lowest periodogram ordinates skipped (the linear detrend removes power there)
SKIP_LOW = 2
#: highest frequency used, as a fraction of Nyquist (anti-alias / integrating-acquisition roll-off)
F_MAX_NYQUIST = 0.9


def class_response(f: np.ndarray, fs: float, cfc: float | None) -> np.ndarray:
    """Power response ``|H|^2`` of the forward-backward J211 filter of class ``cfc`` at
    frequencies ``f`` [Hz] (1 for ``None``)."""
    if cfc is None:
        return np.ones_like(f, dtype=float)
    if 2.0775 * cfc >= 0.5 * fs:  # the class is not realisable at this rate
        return np.full_like(f, np.nan, dtype=float)
    b, a = _dsp._j211_ba(cfc, fs)
    _, h = sps.freqz(b, a, worN=f, fs=fs)
    return np.abs(h) ** 4


def _whittle(p: np.ndarray, g: np.ndarray) -> tuple[float, float, float]:
    """Minimum Whittle negative log-likelihood of ``S = s0 g + s1`` (``s1`` only for a filtered
    class) for periodogram ordinates ``p``; returns (nll, s0, s1)."""
    flat = bool(np.all(g == 1.0))
    if flat:
        s0 = float(np.mean(p))
        return float(np.sum(np.log(s0) + p / s0)), s0, 0.0

    def nll(x):
        s = math.exp(x[0]) * g + math.exp(x[1])
        return float(np.sum(np.log(s) + p / s))

    lo = float(np.mean(p[g < 1e-3])) if np.any(g < 1e-3) else 1e-6 * float(np.mean(p))
    hi = float(np.sum(p * g) / max(np.sum(g * g), 1e-300))
    best = None
    for x0 in ([math.log(max(hi, 1e-300)), math.log(max(lo, 1e-300))],
               [math.log(max(np.mean(p), 1e-300)), math.log(max(1e-3 * np.mean(p), 1e-300))]):
        r = minimize(nll, x0, method="Nelder-Mead",
                     options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 2000})
        if best is None or r.fun < best.fun:
            best = r
    return float(best.fun), math.exp(best.x[0]), math.exp(best.x[1])


def filter_class_check(sig: Signal, quiet: tuple[float, float] | None, *,
                       declared: float | None = None, accept_margin: float = 10.0
                       ) -> dict[str, Any]:
    """Which CFC class was this channel filtered with? Read from its pre-event noise spectrum.

    Parameters
    ----------
    sig : the recorded channel (uniform sampling)
    quiet : its quiet pre-event segment [t0, t1] [s] (``mismatch.estimate_noise``'s window)
    declared : the class the file declares (``Signal.cfc``), None when unknown
    accept_margin : Delta BIC by which the measured class must beat the declared one

    Returns
    -------
    dict: ``applicable`` (and ``reason`` when not), ``measured`` (best class [Hz], None = raw),
    ``bic`` per class (str keys, "raw"), ``delta_bic_next`` (best vs the runner-up),
    ``declared``, ``delta_bic_declared`` (declared vs best; 0 when they agree),
    ``contradicts_declared`` (measured beats the declared class by ``accept_margin``),
    ``decisive`` (the best beats every other class by ``accept_margin``), ``samples``.
    """
    out: dict[str, Any] = {"applicable": False, "declared": declared}
    if quiet is None:
        out["reason"] = "no quiet pre-event segment"
        return out
    m = (sig.t >= quiet[0]) & (sig.t <= quiet[1])
    x = np.asarray(sig.data[m], dtype=float)
    out["samples"] = int(x.size)
    if x.size < MIN_SAMPLES:
        out["reason"] = f"quiet segment has {x.size} samples (< {MIN_SAMPLES})"
        return out
    fs = float(sig.fs)
    f, p = sps.periodogram(x, fs=fs, window="hann", detrend="linear", scaling="density")
    keep = (np.arange(f.size) >= SKIP_LOW) & (f <= F_MAX_NYQUIST * 0.5 * fs)
    f, p = f[keep][::2], p[keep][::2]
    if f.size < 8 or not np.all(np.isfinite(p)) or float(np.max(p)) <= 0.0:
        out["reason"] = "the quiet segment holds no noise (a noise-free record)"
        return out
    p = p / float(np.mean(p))  # scale-free likelihood
    bics: dict[str, float] = {}
    levels: dict[str, tuple[float, float]] = {}
    for c in CLASSES:
        g = class_response(f, fs, c)
        if not np.all(np.isfinite(g)):
            continue
        nll, s0, s1 = _whittle(p, g)
        k = 1 if c is None else 2
        key = "raw" if c is None else f"{c:g}"
        bics[key] = 2.0 * nll + k * math.log(f.size)
        levels[key] = (s0, s1)
    order = sorted(bics, key=bics.get)
    best = order[0]
    measured = None if best == "raw" else float(best)
    dkey = None if declared is None else f"{float(declared):g}"
    d_decl = (bics[dkey] - bics[best]) if dkey in bics else None
    out.update(applicable=True, measured=measured, bic=bics,
               delta_bic_next=(bics[order[1]] - bics[best]) if len(order) > 1 else math.inf,
               delta_bic_declared=d_decl,
               contradicts_declared=bool(d_decl is not None and d_decl > accept_margin),
               decisive=bool(len(order) < 2 or bics[order[1]] - bics[best] > accept_margin),
               floor_ratio=levels[best][1] / levels[best][0] if levels[best][0] > 0 else None,
               ordinates=int(f.size))
    return out
