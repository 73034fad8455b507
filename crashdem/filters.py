"""SAE J211-1 channel-frequency-class (CFC) filter: 4-pole zero-phase Butterworth.

The filter is the recursive 2-pole Butterworth of SAE J211-1 Appendix C run forward and then
backward over the record, which gives a 4-pole, zero-phase low-pass. ``cfc_filter`` is the one
entry point; it accepts a :class:`crashdem.signal.Signal` or a plain array.

Sample-rate rules (see ``docs/filtering.md``):

* hard error (``ValueError``) when ``fs <= 2 * K * CFC`` (``K = 2.0775``, or 2.0833 for ISO 6487):
  the pre-warped design frequency ``wd*T/2`` reaches pi/2, ``tan`` diverges and the poles reach
  ``z = -1`` -- the recursion is undefined;
* ``SampleRateWarning`` when ``fs < 10 * CFC``: J211-1 recommends sampling at least ten times
  ``F_H`` (numerically equal to the CFC) when the reconstruction is simple; the filter itself is
  still inside the J211 corridor up to the Nyquist frequency, but the data may be aliased.

End handling (default ``padding="odd"``): each end is extended by ``max(10 ms, 3/F_N)``
(``F_N = 5/3 * CFC``) with an odd reflection about the end sample, ``2*x[0] - x[k]``; each pass
starts from the steady state of its first sample (all delayed ``X`` and ``Y`` equal to it); the
padding is cropped after the backward pass. The method is stored in ``Signal.meta["filter"]``.

Notes
-----
Coefficients and recursion: SAE J211-1 (2014) Appendix C, Eq. C1 (anchors.md section 2 [V],
checked against E. J. Whitney's ``J211_2pole`` and the WSI/FlexPro CFC documentation).
ISO 6487 design factor 2.0833 = 1.25 * 5/3 (anchors.md section 2).
"""
from __future__ import annotations

import math
import warnings
from typing import Any, overload

import numba
import numpy as np

from crashdem.signal import Signal

#: SAE J211-1 Appendix C design factor: wd = 2*pi*CFC*J211_FACTOR [rad/s]
J211_FACTOR = 2.0775
#: ISO 6487 design factor (1.25 * 5/3)
ISO6487_FACTOR = 2.0833
#: the standard channel frequency classes and their F_N [Hz]
#: (J211-1 Fig. 1, anchors.md section 2 [M])
CFC_F_N: dict[int, float] = {1000: 1650.0, 600: 1000.0, 180: 300.0, 60: 100.0}
#: J211-1 sampling recommendation: fs >= 10 * F_H for simple reconstruction
#: (anchors.md section 2 [V])
RECOMMENDED_FS_PER_CFC = 10.0
#: minimum padding duration [s] (10 ms rule, anchors.md section 2 / Whitney)
MIN_PAD_TIME = 0.010
#: padding as a number of F_N periods (anchors.md section 2 recommendation)
PAD_PERIODS_F_N = 3.0
#: relative tolerance on uniform sampling of a Signal (max |dt - mean dt| / mean dt); a timing
#: jitter of 1e-3 dt shifts the phase at F_N by < 2 pi F_N 1e-3 dt < 1e-3 rad for fs > 10 F_N,
#: and tolerates time columns written with 7-8 significant digits
UNIFORM_DT_RTOL = 1e-3

PADDING_MODES = ("odd", "even", "constant", "none")

__all__ = [
    "CFC_F_N",
    "ISO6487_FACTOR",
    "J211_FACTOR",
    "PADDING_MODES",
    "SampleRateWarning",
    "cfc_filter",
    "check_sample_rate",
    "f_n",
    "j211_coefficients",
    "j211_response",
    "minimum_fs",
    "pad_length",
]


class SampleRateWarning(UserWarning):
    """The sample rate is below J211-1's 10 x F_H recommendation (filter still defined)."""


def f_n(cfc: float) -> float:
    """Frequency F_N [Hz] of the J211 corridor for a channel class.

    Parameters
    ----------
    cfc : channel frequency class [Hz], > 0

    Returns
    -------
    F_N [Hz]: the tabulated value for CFC 1000/600/180/60, else 5/3 * CFC.

    Notes
    -----
    Table values: SAE J211-1 Fig. 1 (anchors.md section 2 [M]); 5/3 * CFC is the -3 dB frequency
    of the 4-pole cascade (anchors.md section 2 [D]) and reproduces 1000/300/100 Hz exactly.
    """
    _check_cfc(cfc)
    key = int(round(cfc))
    if abs(cfc - key) < 1e-12 and key in CFC_F_N:
        return CFC_F_N[key]
    return 5.0 / 3.0 * float(cfc)


def minimum_fs(cfc: float, iso6487: bool = False) -> float:
    """Sample rate [Hz] at and below which the J211 recursion is undefined: 2 * K * CFC.

    Notes
    -----
    SAE J211-1 Appendix C: wa = tan(wd T / 2) requires wd T / 2 < pi / 2.
    """
    _check_cfc(cfc)
    return 2.0 * (ISO6487_FACTOR if iso6487 else J211_FACTOR) * float(cfc)


def check_sample_rate(fs: float, cfc: float, name: str = "<array>", *, strict: bool = False,
                      iso6487: bool = False) -> None:
    """Check that a channel sampled at ``fs`` can be filtered at ``cfc``.

    Parameters
    ----------
    fs : sample rate [Hz]
    cfc : channel frequency class [Hz]
    name : channel name used in messages
    strict : if True, a rate below 10 * CFC is an error instead of a ``SampleRateWarning``
    iso6487 : use the ISO 6487 design factor for the hard limit

    Raises
    ------
    ValueError
        ``fs <= 2 * K * CFC`` (filter undefined), or ``fs < 10 * CFC`` with ``strict``.

    Notes
    -----
    Hard limit: J211-1 Appendix C (wd T/2 < pi/2); recommendation: J211-1 section on sampling,
    fs >= 10 F_H (anchors.md section 2 [V]).
    """
    _check_cfc(cfc)
    if not (np.isfinite(fs) and fs > 0):
        raise ValueError(f"channel {name!r}: fs={fs!r}: sample rate must be finite and > 0 [Hz]")
    f_min = minimum_fs(cfc, iso6487)
    if fs <= f_min:
        raise ValueError(
            f"channel {name!r}: fs={fs:g} Hz is too low for CFC {cfc:g}: the J211 filter needs "
            f"fs > 2*{ISO6487_FACTOR if iso6487 else J211_FACTOR}*CFC = {f_min:g} Hz "
            f"(wd*T/2 < pi/2); J211-1 recommends fs >= {RECOMMENDED_FS_PER_CFC:g}*CFC = "
            f"{RECOMMENDED_FS_PER_CFC * cfc:g} Hz"
        )
    f_rec = RECOMMENDED_FS_PER_CFC * cfc
    if fs < f_rec * (1.0 - 1e-9):
        msg = (f"channel {name!r}: fs={fs:g} Hz is below the J211-1 recommendation "
               f"fs >= {RECOMMENDED_FS_PER_CFC:g}*CFC = {f_rec:g} Hz for CFC {cfc:g}")
        if strict:
            raise ValueError(msg)
        warnings.warn(msg, SampleRateWarning, stacklevel=3)


def j211_coefficients(cfc: float, fs: float, iso6487: bool = False
                      ) -> tuple[float, float, float, float, float]:
    """Coefficients (a0, a1, a2, b1, b2) of the J211-1 2-pole recursion.

    Parameters
    ----------
    cfc : channel frequency class [Hz], > 0
    fs : sample rate [Hz], > 2 * K * CFC
    iso6487 : use K = 2.0833 (ISO 6487) instead of 2.0775 (SAE J211-1)

    Returns
    -------
    a0, a1, a2, b1, b2 [-] for ``Y[t] = a0 X[t] + a1 X[t-1] + a2 X[t-2] + b1 Y[t-1] + b2 Y[t-2]``.

    Notes
    -----
    SAE J211-1 Appendix C: wd = 2 pi CFC K, wa = sin(wd T/2)/cos(wd T/2), D = 1 + sqrt(2) wa + wa^2,
    a0 = wa^2/D, a1 = 2 a0, a2 = a0, b1 = -2 (wa^2 - 1)/D, b2 = (-1 + sqrt(2) wa - wa^2)/D.
    """
    _check_cfc(cfc)
    if not (np.isfinite(fs) and fs > minimum_fs(cfc, iso6487)):
        raise ValueError(
            f"fs={fs!r}: must be > 2*K*CFC = {minimum_fs(cfc, iso6487):g} Hz for CFC {cfc:g}"
        )
    T = 1.0 / fs
    wd = 2.0 * math.pi * cfc * (ISO6487_FACTOR if iso6487 else J211_FACTOR)
    wa = math.sin(wd * T / 2.0) / math.cos(wd * T / 2.0)
    D = 1.0 + math.sqrt(2.0) * wa + wa * wa
    a0 = wa * wa / D
    a1 = 2.0 * a0
    a2 = a0
    b1 = -2.0 * (wa * wa - 1.0) / D
    b2 = (-1.0 + math.sqrt(2.0) * wa - wa * wa) / D
    return a0, a1, a2, b1, b2


def j211_response(f: np.ndarray | float, cfc: float, fs: float, iso6487: bool = False,
                  passes: int = 2) -> np.ndarray:
    """Magnitude response |H| [-] of the J211 filter at frequencies ``f`` [Hz].

    Parameters
    ----------
    f : frequencies [Hz], 0 <= f <= fs/2
    cfc, fs, iso6487 : as in ``j211_coefficients``
    passes : 1 for the 2-pole recursion, 2 for the forward-backward cascade (zero phase)

    Notes
    -----
    H(z) = (a0 + a1 z^-1 + a2 z^-2) / (1 - b1 z^-1 - b2 z^-2) from J211-1 Eq. C1; the
    forward-backward cascade has |H|^2 (zero phase).
    """
    a0, a1, a2, b1, b2 = j211_coefficients(cfc, fs, iso6487)
    z1 = np.exp(-2j * np.pi * np.asarray(f, dtype=float) / fs)
    h = (a0 + a1 * z1 + a2 * z1 * z1) / (1.0 - b1 * z1 - b2 * z1 * z1)
    return np.abs(h) ** passes


def pad_length(fs: float, cfc: float, pad_time: float | None = None) -> int:
    """Number of samples added at each end: ``ceil(max(10 ms, 3/F_N) * fs)`` by default.

    Parameters
    ----------
    fs : sample rate [Hz]
    cfc : channel frequency class [Hz]
    pad_time : explicit padding duration [s] (>= 0), overrides the rule

    Notes
    -----
    Rule from anchors.md section 2 (10 ms, Whitney's recommendation; 3/F_N periods); justification
    in docs/filtering.md (the 2-pole impulse response decays as exp(-wd t/sqrt(2)), i.e. to below
    1e-6 of its peak within 3/F_N for every class).
    """
    if pad_time is None:
        pad_time = max(MIN_PAD_TIME, PAD_PERIODS_F_N / f_n(cfc))
    elif not (np.isfinite(pad_time) and pad_time >= 0):
        raise ValueError(f"pad_time={pad_time!r}: must be finite and >= 0 [s]")
    return int(math.ceil(pad_time * fs - 1e-9))


@numba.njit(cache=True)
def _j211_pass(x, a0, a1, a2, b1, b2):  # pragma: no cover - compiled
    """One pass of J211-1 Eq. C1, started from the steady state of x[0] (DC gain is 1)."""
    n = x.shape[0]
    y = np.empty(n)
    x1 = x[0]
    x2 = x[0]
    y1 = x[0]
    y2 = x[0]
    for i in range(n):
        xi = x[i]
        yi = a0 * xi + a1 * x1 + a2 * x2 + b1 * y1 + b2 * y2
        y[i] = yi
        x2 = x1
        x1 = xi
        y2 = y1
        y1 = yi
    return y


def _pad(x: np.ndarray, n_pad: int, mode: str) -> np.ndarray:
    """Extend ``x`` by ``n_pad`` samples at each end (see ``cfc_filter``)."""
    if n_pad == 0 or mode == "none":
        return x
    n = x.size
    k = min(n_pad, n - 1)
    if mode == "constant" or k == 0:
        left = np.full(n_pad, x[0])
        right = np.full(n_pad, x[-1])
    else:
        head = x[k:0:-1]          # x[k], ..., x[1]
        tail = x[-2:-k - 2:-1]    # x[n-2], ..., x[n-1-k]
        if mode == "odd":
            head = 2.0 * x[0] - head
            tail = 2.0 * x[-1] - tail
        # if the record is shorter than the padding, continue with the last reflected value
        left = np.concatenate([np.full(n_pad - k, head[0]), head])
        right = np.concatenate([tail, np.full(n_pad - k, tail[-1])])
    return np.concatenate([left, x, right])


def _filter_1d(x: np.ndarray, coeffs: tuple[float, ...], n_pad: int, mode: str) -> np.ndarray:
    xp = _pad(np.ascontiguousarray(x, dtype=float), n_pad, mode)
    y = _j211_pass(xp, *coeffs)
    y = _j211_pass(y[::-1].copy(), *coeffs)[::-1]
    if mode != "none" and n_pad:
        y = y[n_pad:-n_pad]
    return np.ascontiguousarray(y)


@overload
def cfc_filter(signal_or_array: Signal, fs: float | None = None, cfc: float = ...,
               padding: str = "odd", *, pad_time: float | None = None, iso6487: bool = False,
               name: str | None = None, axis: int = -1) -> Signal: ...
@overload
def cfc_filter(signal_or_array: np.ndarray, fs: float | None = None, cfc: float = ...,
               padding: str = "odd", *, pad_time: float | None = None, iso6487: bool = False,
               name: str | None = None, axis: int = -1) -> np.ndarray: ...


def cfc_filter(signal_or_array, fs=None, cfc=None, padding="odd", *, pad_time=None,
               iso6487=False, name=None, axis=-1):
    """Filter a channel with the SAE J211-1 CFC filter (4-pole, zero phase).

    Parameters
    ----------
    signal_or_array : Signal (uniformly sampled) or array (filtered along ``axis``)
    fs : sample rate [Hz]; required for arrays; for a Signal it is derived from ``t`` and, if
        given, must agree with it to ``UNIFORM_DT_RTOL``
    cfc : channel frequency class [Hz] (> 0; 60, 180, 600, 1000 or any other value)
    padding : "odd" (default; reflection 2*x0 - x[k]), "even" (mirror x[k]), "constant"
        (hold the end value) or "none" (no padding; each pass seeded with the steady state of
        its first sample, as J211-1 allows when enough pre/post-event data exist)
    pad_time : padding duration per end [s]; default ``max(10 ms, 3/F_N)``
    iso6487 : use the ISO 6487 design factor 2.0833 instead of J211's 2.0775
    name : channel name for messages (default: the Signal's name)
    axis : axis of an array along which time runs

    Returns
    -------
    Signal with ``cfc`` set and ``meta["filter"]`` describing the method, or a filtered array.

    Raises
    ------
    ValueError
        bad CFC, bad padding mode, non-uniform sampling, NaN/inf data, fewer than 3 samples, or
        ``fs <= 2*K*CFC``. A ``SampleRateWarning`` is issued when ``fs < 10*CFC``.

    Notes
    -----
    SAE J211-1 Appendix C Eq. C1, forward then backward (zero phase); padding and seeding rule
    from anchors.md section 2 (J211 leaves the start-up algorithm to the user).
    """
    if cfc is None:
        raise ValueError("cfc=None: a channel frequency class must be given (> 0 [Hz])")
    _check_cfc(cfc)
    if padding not in PADDING_MODES:
        raise ValueError(f"padding={padding!r}: must be one of {PADDING_MODES}")
    is_signal = isinstance(signal_or_array, Signal)
    if is_signal:
        sig = signal_or_array
        label = name if name is not None else sig.name
        fs_sig = _uniform_fs(sig.t, label)
        if fs is not None and abs(fs - fs_sig) > UNIFORM_DT_RTOL * fs_sig:
            raise ValueError(
                f"channel {label!r}: fs={fs:g} Hz disagrees with the time vector "
                f"(1/dt = {fs_sig:g} Hz)")
        fs = fs_sig
        x = sig.data
        ax = -1
    else:
        label = name if name is not None else "<array>"
        if fs is None:
            raise ValueError(f"channel {label!r}: fs=None: give the sample rate for an array [Hz]")
        x = np.asarray(signal_or_array, dtype=float)
        ax = axis
    fs = float(fs)
    check_sample_rate(fs, cfc, label, iso6487=iso6487)
    if x.ndim == 0 or x.shape[ax] < 3:
        raise ValueError(f"channel {label!r}: needs at least 3 samples to filter, got "
                         f"{0 if x.ndim == 0 else x.shape[ax]}")
    if not np.all(np.isfinite(x)):
        bad = int(np.flatnonzero(~np.isfinite(x.ravel()))[0])
        raise ValueError(f"channel {label!r}: data contain NaN/inf (first at flat index {bad}); "
                         "cannot filter")
    coeffs = j211_coefficients(cfc, fs, iso6487)
    n_pad = 0 if padding == "none" else pad_length(fs, cfc, pad_time)
    xm = np.moveaxis(x, ax, -1)
    flat = xm.reshape(-1, xm.shape[-1])
    out = np.empty_like(flat)
    for r in range(flat.shape[0]):
        out[r] = _filter_1d(flat[r], coeffs, n_pad, padding)
    y = np.moveaxis(out.reshape(xm.shape), -1, ax)
    if not is_signal:
        return y
    info: dict[str, Any] = {
        "standard": "ISO 6487" if iso6487 else "SAE J211-1 Appendix C",
        "cfc": float(cfc),
        "design_factor": ISO6487_FACTOR if iso6487 else J211_FACTOR,
        "fs": fs,
        "passes": "forward-backward (4-pole, zero phase)",
        "padding": padding,
        "pad_samples": int(n_pad),
        "pad_time": n_pad / fs,
        "initial_conditions": "steady state of the first sample of each pass",
        "coefficients": [float(c) for c in coeffs],
    }
    if sig.cfc is not None:
        info["previous_cfc"] = float(sig.cfc)
    meta = dict(sig.meta)
    meta["filter"] = info
    return Signal(sig.name, sig.t.copy(), y, sig.unit, float(cfc), meta)


def _uniform_fs(t: np.ndarray, name: str) -> float:
    """Sample rate of a uniformly sampled time vector, or a ValueError naming the channel."""
    if t.size < 3:
        raise ValueError(f"channel {name!r}: needs at least 3 samples to filter, got {t.size}")
    dt = np.diff(t)
    if not np.all(np.isfinite(dt)) or np.any(dt <= 0):
        i = int(np.flatnonzero(~(dt > 0))[0])
        raise ValueError(f"channel {name!r}: time is not strictly increasing at sample {i + 1} "
                         f"(t={t[i]!r} -> {t[i + 1]!r} s)")
    dt_mean = (t[-1] - t[0]) / (t.size - 1)
    spread = float(np.max(np.abs(dt - dt_mean)))
    if spread > UNIFORM_DT_RTOL * dt_mean + 1e-15:
        raise ValueError(f"channel {name!r}: sampling is not uniform (dt varies by {spread:g} s "
                         f"around {dt_mean:g} s); resample before CFC filtering")
    return 1.0 / dt_mean


def _check_cfc(cfc: float) -> None:
    if isinstance(cfc, bool) or not isinstance(cfc, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(cfc) and cfc > 0):
        raise ValueError(f"cfc={cfc!r}: must be a finite number > 0 [Hz]")
