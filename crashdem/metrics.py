"""Objective comparison of a simulated channel with a test channel: ISO/TS 18571 + simple errors.

``iso18571(reference, candidate)`` returns the ISO/TS 18571 rating (corridor, phase, magnitude,
slope sub-scores and their weighted sum in [0, 1]); ``compare`` adds peak, peak-time, RMS and
duration errors. The *reference* is the test (T), the *candidate* the model (C).

Procedure
---------
1. Both channels are converted to SI and must share the SI unit.
2. Evaluation interval: ``t_window`` or the intersection of both time ranges.
3. Both are resampled by linear interpolation onto one uniform grid ``t0 + k*dt``
   (``dt = 1e-4 s``, the 10 kHz the standard's implementations require), N samples.
4. Corridor score Z: inner/outer half-widths ``a0*max|T|`` and ``b0*max|T|``; each sample scores 1
   inside the inner corridor, 0 outside the outer one and ``((delta_o - |C-T|)/(delta_o -
   delta_i))**k_z`` in between; Z is the mean.
5. Phase score E_P: the shift n (0 <= n <= floor(eps_p N)) of C against T, to the left (C
   earlier) or right, that maximises the Pearson correlation of the overlapping parts (left
   checked before right, the smaller shift kept on ties); E_P = 1 for n = 0, 0 for
   n >= eps_p N, else ((eps_p N - n)/(eps_p N))**k_p.
6. Magnitude score E_M: the phase-shifted overlapping curves are aligned by dynamic time warping
   (squared-difference local cost, steps (1,0), (0,1), (1,1) of weight 1, Sakoe-Chiba band
   |i - j| < ceil(0.1 n)); e_M = ||C_w - T_w||_1 / ||T_w||_1; E_M = ((eps_m - e_M)/eps_m)**k_m,
   0 if e_M > eps_m ("EEARTH" magnitude error).
7. Slope score E_S: derivatives of the phase-shifted curves by central differences, smoothed by
   a 9-point moving average (1-, 3-, 5-, 7-point averages at the ends); e_S = ||C' - T'||_1 /
   ||T'||_1; E_S = ((eps_s - e_S)/eps_s)**k_s, 0 if e_S >= eps_s.
8. Overall R = w_z Z + w_p E_P + w_m E_M + w_s E_S.

Notes
-----
Method: ISO/TS 18571:2014/2024 (anchors.md section 7 [V] for the four sub-scores and DTW/EEARTH).
Parameter values (a0 = 0.05, b0 = 0.5, k_z = 2, eps_p = 0.2, k_p = 1, eps_m = 0.5, k_m = 1,
eps_s = 2.0, k_s = 1, weights 0.4/0.2/0.2/0.2, 10 kHz, DTW band 10 %, 9-point derivative smoothing,
L1 norms) were compared against two open implementations, not against the standard's text:
VSI Graz ``objective_rating_metrics`` (class ``ISO18571``, PyPI 1.3 and its later local-DTW
version) and a class ``ISORating`` citing ISO/TS 18571:2024. Both agree on all values above
except the norm of the magnitude and slope errors (``ISORating`` uses L2, VSI uses L1; L1 is
used here). Unverified against the standard: the L1/L2 question, the DTW step pattern and band,
the end treatment of the slope smoothing, and the grade limits in ``GRADES``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from crashdem.signal import Signal

#: rating grades (lower limits, exclusive): ISO/TS 18571 sliding scale as commonly quoted --
#: [M] not verified against the standard's text
GRADES = ((0.94, "excellent"), (0.80, "good"), (0.58, "fair"), (-math.inf, "poor"))

__all__ = ["GRADES", "ISO18571Params", "ISO18571Result", "compare", "corridor_score", "duration",
           "dtw_align", "grade", "iso18571", "magnitude_score", "peak_error", "peak_time_error",
           "phase_shift", "rms_error", "slope_score"]


@dataclass(frozen=True)
class ISO18571Params:
    """ISO/TS 18571 parameters (defaults: the published values, see module Notes).

    Parameters
    ----------
    a0 : inner corridor half-width / max|T| [-], in (0, b0)
    b0 : outer corridor half-width / max|T| [-], > a0
    k_z : corridor exponent [-], > 0
    eps_p : maximum allowable time shift as a fraction of the interval [-], in (0, 1)
    k_p : phase exponent [-], > 0
    eps_m : maximum allowable magnitude error [-], > 0
    k_m : magnitude exponent [-], > 0
    eps_s : maximum allowable slope error [-], > 0
    k_s : slope exponent [-], > 0
    dtw_band : Sakoe-Chiba band as a fraction of the shifted length [-], in (0, 1]
    w_z, w_p, w_m, w_s : weights [-], >= 0, summing to 1
    dt : resampling interval [s], > 0 (1e-4 s = 10 kHz)
    """

    a0: float = 0.05
    b0: float = 0.50
    k_z: float = 2.0
    eps_p: float = 0.20
    k_p: float = 1.0
    eps_m: float = 0.50
    k_m: float = 1.0
    eps_s: float = 2.0
    k_s: float = 1.0
    dtw_band: float = 0.10
    w_z: float = 0.4
    w_p: float = 0.2
    w_m: float = 0.2
    w_s: float = 0.2
    dt: float = 1e-4

    def __post_init__(self) -> None:
        def need(name: str, ok: bool, rng: str) -> None:
            if not ok:
                raise ValueError(f"ISO18571Params.{name}={getattr(self, name)!r}: must be {rng}")

        for name in ("k_z", "k_p", "eps_m", "k_m", "eps_s", "k_s", "dt"):
            v = getattr(self, name)
            need(name, math.isfinite(v) and v > 0, "> 0")
        need("b0", math.isfinite(self.b0) and self.b0 > 0, "> 0")
        need("a0", math.isfinite(self.a0) and 0 < self.a0 < self.b0, f"in (0, b0={self.b0})")
        need("eps_p", 0 < self.eps_p < 1, "in (0, 1)")
        need("dtw_band", 0 < self.dtw_band <= 1, "in (0, 1]")
        for name in ("w_z", "w_p", "w_m", "w_s"):
            need(name, math.isfinite(getattr(self, name)) and getattr(self, name) >= 0, ">= 0")
        s = self.w_z + self.w_p + self.w_m + self.w_s
        if abs(s - 1.0) > 1e-12:
            raise ValueError(f"ISO18571Params weights sum to {s!r}: must be 1 "
                             "(w_z + w_p + w_m + w_s)")


@dataclass(frozen=True)
class ISO18571Result:
    """Sub-scores, overall rating and the intermediate quantities of one comparison."""

    overall: float
    corridor: float
    phase: float
    magnitude: float
    slope: float
    grade: str
    shift_samples: int        # n_eps [-]
    time_shift: float         # [s], > 0: candidate late (shifted left to match)
    correlation: float        # Pearson correlation at the chosen shift [-]
    magnitude_error: float    # e_M [-]
    slope_error: float        # e_S [-]
    t_start: float            # [s]
    t_end: float              # [s]
    n_samples: int
    params: ISO18571Params = field(repr=False)

    def as_dict(self) -> dict[str, Any]:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "params"}
        return d


# --------------------------------------------------------------------------- sub-scores

def corridor_score(T: np.ndarray, C: np.ndarray, p: ISO18571Params = ISO18571Params()) -> float:
    """Corridor score Z in [0, 1] (see module docstring, step 4).

    Notes
    -----
    ISO/TS 18571 corridor method; a0, b0, k_z per module Notes.
    """
    T, C = _pair(T, C)
    t_norm = float(np.max(np.abs(T)))
    if t_norm == 0.0:
        raise ValueError("corridor score: the reference is identically zero (corridor width 0)")
    d_i, d_o = p.a0 * t_norm, p.b0 * t_norm
    diff = np.abs(C - T)
    s = np.clip((d_o - diff) / (d_o - d_i), 0.0, 1.0) ** p.k_z
    s[diff <= d_i] = 1.0
    return float(np.mean(s))


def _pearson_by_lag(T: np.ndarray, C: np.ndarray, m_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Pearson correlation for shifts 0..m_max: left (C[m:] vs T[:N-m]) and right
    (C[:N-m] vs T[m:]), from running sums and the direct cross products."""
    n = T.size
    m = np.arange(m_max + 1)
    L = (n - m).astype(float)
    full = np.correlate(C, T, mode="full")  # full[n-1+k] = sum_i C[i+k] T[i]
    pT = np.concatenate([[0.0], np.cumsum(T)])
    pC = np.concatenate([[0.0], np.cumsum(C)])
    qT = np.concatenate([[0.0], np.cumsum(T * T)])
    qC = np.concatenate([[0.0], np.cumsum(C * C)])

    def corr(sxy, sx, sy, sxx, syy):
        cov = sxy - sx * sy / L
        vx = sxx - sx * sx / L
        vy = syy - sy * sy / L
        tol_x = 64 * np.finfo(float).eps * np.maximum(1.0, sxx)
        tol_y = 64 * np.finfo(float).eps * np.maximum(1.0, syy)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = cov / np.sqrt(vx * vy)
        r = np.where((vx <= tol_x) | (vy <= tol_y), -np.inf, r)
        return np.clip(r, -1.0, 1.0)

    # left: pairs (C[i+m], T[i]), i < n-m
    left = corr(full[n - 1 + m], pT[n - m], pC[n] - pC[m], qT[n - m], qC[n] - qC[m])
    # right: pairs (C[i], T[i+m]), i < n-m
    right = corr(full[n - 1 - m], pT[n] - pT[m], pC[n - m], qT[n] - qT[m], qC[n - m])
    return left, right


def phase_shift(T: np.ndarray, C: np.ndarray, p: ISO18571Params = ISO18571Params()
                ) -> tuple[int, int, float]:
    """Shift of C against T maximising the Pearson correlation.

    Returns
    -------
    n : shift [samples], 0 <= n <= floor(eps_p N)
    direction : +1 if C is shifted left (C late: compare C[n:] with T[:N-n]), -1 right, 0 none
    rho : the correlation at that shift

    Notes
    -----
    ISO/TS 18571 phase method; tie rule (left before right, smaller shift kept) as in the VSI
    implementation (module Notes).
    """
    T, C = _pair(T, C)
    n = T.size
    m_max = min(int(math.floor(p.eps_p * n)), n - 2)
    left, right = _pearson_by_lag(T, C, m_max)
    best, n_best, direction = left[0], 0, 0
    for m in range(1, m_max + 1):
        if left[m] > best:
            best, n_best, direction = left[m], m, 1
        if right[m] > best:
            best, n_best, direction = right[m], m, -1
    return n_best, direction, float(best)


def _phase_score(n_shift: int, n: int, p: ISO18571Params) -> float:
    limit = p.eps_p * n
    if n_shift == 0:
        return 1.0
    if n_shift >= limit:
        return 0.0
    return ((limit - n_shift) / limit) ** p.k_p


def _shifted(T: np.ndarray, C: np.ndarray, n_shift: int, direction: int
             ) -> tuple[np.ndarray, np.ndarray]:
    if n_shift == 0:
        return T, C
    if direction > 0:
        return T[:-n_shift], C[n_shift:]
    return T[n_shift:], C[:-n_shift]


@numba.njit(cache=True)
def _dtw_path(x, y, r):  # pragma: no cover - compiled
    """DTW path of two equal-length series: cost (x_i - y_j)^2, steps (1,0), (0,1), (1,1) with
    weight 1, band |i - j| < r. Banded storage; the predecessor is chosen in the order
    (i-1, j), (i, j-1), (i-1, j-1), first minimum kept."""
    n = x.shape[0]
    w = 2 * r - 1
    inf = np.inf
    prev = np.full(w, inf)
    cur = np.full(w, inf)
    move = np.zeros((n, w), dtype=np.int8)  # 0 start, 1 up (i-1,j), 2 left (i,j-1), 3 diag
    for i in range(n):
        for k in range(w):
            cur[k] = inf
        j0 = max(0, i - r + 1)
        j1 = min(n, i + r)
        for j in range(j0, j1):
            k = j - i + r - 1
            c = (x[i] - y[j]) ** 2
            if i == 0 and j == 0:
                cur[k] = c
                move[i, k] = 0
                continue
            best = inf
            mv = 0
            if i > 0 and k + 1 < w:           # (i-1, j): same j, previous row -> index k+1
                if prev[k + 1] < best:
                    best = prev[k + 1]
                    mv = 1
            if j > 0 and k > 0:               # (i, j-1): this row, index k-1
                if cur[k - 1] < best:
                    best = cur[k - 1]
                    mv = 2
            if i > 0 and j > 0:               # (i-1, j-1): previous row, index k
                if prev[k] < best:
                    best = prev[k]
                    mv = 3
            cur[k] = c + best
            move[i, k] = mv
        for k in range(w):
            prev[k] = cur[k]
    # backtrack
    path_i = np.empty(2 * n, dtype=np.int64)
    path_j = np.empty(2 * n, dtype=np.int64)
    i = n - 1
    j = n - 1
    cnt = 0
    while True:
        path_i[cnt] = i
        path_j[cnt] = j
        cnt += 1
        k = j - i + r - 1
        mv = move[i, k]
        if mv == 0:
            break
        elif mv == 1:
            i -= 1
        elif mv == 2:
            j -= 1
        else:
            i -= 1
            j -= 1
    return path_i[:cnt][::-1].copy(), path_j[:cnt][::-1].copy()


def dtw_align(x: np.ndarray, y: np.ndarray, band: float = 0.10) -> tuple[np.ndarray, np.ndarray]:
    """Warp two equal-length series onto each other by DTW (module docstring, step 6).

    Returns
    -------
    x[path_i], y[path_j] : the warped series (equal length)

    Notes
    -----
    Dynamic time warping with a Sakoe-Chiba band (Sakoe & Chiba 1978); band radius
    ceil(band * n) as in the VSI ISO/TS 18571 implementation.
    """
    x = np.ascontiguousarray(x, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size == 0:
        raise ValueError(f"dtw_align: x {x.shape} and y {y.shape} must be 1-D, non-empty and of "
                         "equal length")
    r = max(1, int(math.ceil(band * x.size)))
    pi, pj = _dtw_path(x, y, r)
    return x[pi], y[pj]


def magnitude_score(T_s: np.ndarray, C_s: np.ndarray, p: ISO18571Params = ISO18571Params()
                    ) -> tuple[float, float]:
    """Magnitude score E_M and error e_M of phase-shifted curves (module docstring, step 6).

    Notes
    -----
    ISO/TS 18571 magnitude (EEARTH) method with DTW; eps_m, k_m and L1 norm per module Notes.
    """
    T_s, C_s = _pair(T_s, C_s)
    c_w, t_w = dtw_align(C_s, T_s, p.dtw_band)
    den = float(np.sum(np.abs(t_w)))
    if den == 0.0:
        raise ValueError("magnitude score: the warped reference is identically zero")
    e = float(np.sum(np.abs(c_w - t_w))) / den
    if e == 0.0:
        return 1.0, 0.0
    if e > p.eps_m:
        return 0.0, e
    return ((p.eps_m - e) / p.eps_m) ** p.k_m, e


def _smoothed_derivative(x: np.ndarray, dt: float) -> np.ndarray:
    d0 = np.gradient(x, dt)
    out = np.empty_like(d0)
    n = d0.size
    if n < 9:
        return d0
    out[4:-4] = np.convolve(d0, np.ones(9) / 9.0, mode="valid")
    for k, w in enumerate((1, 3, 5, 7)):
        out[k] = np.mean(d0[:w])
        out[n - 1 - k] = np.mean(d0[n - w:])
    return out


def slope_score(T_s: np.ndarray, C_s: np.ndarray, dt: float,
                p: ISO18571Params = ISO18571Params()) -> tuple[float, float]:
    """Slope score E_S and error e_S of phase-shifted curves (module docstring, step 7).

    Notes
    -----
    ISO/TS 18571 slope method; central differences + 9-point moving average, eps_s, k_s, L1
    norm per module Notes.
    """
    T_s, C_s = _pair(T_s, C_s)
    dT = _smoothed_derivative(T_s, dt)
    dC = _smoothed_derivative(C_s, dt)
    den = float(np.sum(np.abs(dT)))
    if den == 0.0:
        raise ValueError("slope score: the reference derivative is identically zero")
    e = float(np.sum(np.abs(dC - dT))) / den
    if e <= 0.0:
        return 1.0, 0.0
    if e >= p.eps_s:
        return 0.0, e
    return ((p.eps_s - e) / p.eps_s) ** p.k_s, e


def grade(rating: float) -> str:
    """Verbal grade of an overall rating (``GRADES``, [M] unverified)."""
    for lim, name in GRADES:
        if rating > lim:
            return name
    return "poor"  # pragma: no cover


# --------------------------------------------------------------------------- front

def _pair(T: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    T = np.asarray(T, dtype=float)
    C = np.asarray(C, dtype=float)
    if T.shape != C.shape or T.ndim != 1 or T.size < 3:
        raise ValueError(f"reference {T.shape} and candidate {C.shape} must be 1-D arrays of "
                         "equal length >= 3")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(C))):
        raise ValueError("reference/candidate contain NaN or inf")
    return T, C


def _common_grid(reference: Signal, candidate: Signal, t_window: tuple[float, float] | None,
                 dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Both signals in SI on the grid t0 + k dt over the evaluation interval."""
    r, c = reference.to_si(), candidate.to_si()
    if r.unit != c.unit:
        raise ValueError(f"reference {reference.name!r} [{reference.unit}] and candidate "
                         f"{candidate.name!r} [{candidate.unit}] have different SI units "
                         f"({r.unit} vs {c.unit})")
    lo = max(r.t[0], c.t[0])
    hi = min(r.t[-1], c.t[-1])
    if t_window is not None:
        w0, w1 = float(t_window[0]), float(t_window[1])
        if not w1 > w0:
            raise ValueError(f"t_window={t_window!r}: end must be after start [s]")
        if w0 < lo - 1e-12 or w1 > hi + 1e-12:
            raise ValueError(f"t_window={t_window!r} s is outside the common time range "
                             f"[{lo:.6g}, {hi:.6g}] s of {reference.name!r} and "
                             f"{candidate.name!r}")
        lo, hi = max(w0, lo), min(w1, hi)
    if not hi > lo:
        raise ValueError(f"{reference.name!r} and {candidate.name!r} do not overlap in time")
    n = int(math.floor((hi - lo) / dt * (1 + 1e-12))) + 1
    t = lo + dt * np.arange(n)
    t[-1] = min(t[-1], hi)
    return t, r.resample(t).data, c.resample(t).data, r.unit


def iso18571(reference: Signal, candidate: Signal, t_window: tuple[float, float] | None = None,
             params: ISO18571Params = ISO18571Params()) -> ISO18571Result:
    """ISO/TS 18571 objective rating of ``candidate`` (model) against ``reference`` (test).

    Parameters
    ----------
    reference : test channel T
    candidate : model channel C (same physical quantity; units converted to SI)
    t_window : evaluation interval (t_start, t_end) [s]; default: the common time range
    params : ISO18571Params (published values by default)

    Returns
    -------
    ISO18571Result with overall rating in [0, 1] and the four sub-scores.

    Notes
    -----
    ISO/TS 18571 (anchors.md section 7); procedure and parameter sources in the module docstring.
    """
    t, T, C, _ = _common_grid(reference, candidate, t_window, params.dt)
    n = T.size
    if n < 10:
        raise ValueError(f"evaluation interval has {n} samples at dt={params.dt} s; need >= 10")
    Z = corridor_score(T, C, params)
    n_shift, direction, rho = phase_shift(T, C, params)
    E_P = _phase_score(n_shift, n, params)
    T_s, C_s = _shifted(T, C, n_shift, direction)
    E_M, e_M = magnitude_score(T_s, C_s, params)
    E_S, e_S = slope_score(T_s, C_s, params.dt, params)
    R = params.w_z * Z + params.w_p * E_P + params.w_m * E_M + params.w_s * E_S
    R = float(min(1.0, max(0.0, R)))
    return ISO18571Result(R, Z, E_P, E_M, E_S, grade(R), n_shift,
                          direction * n_shift * params.dt, rho, e_M, e_S, float(t[0]),
                          float(t[-1]), n, params)


def _peak(x: np.ndarray) -> int:
    return int(np.argmax(np.abs(x)))


def peak_error(reference: Signal, candidate: Signal, t_window: tuple[float, float] | None = None
               ) -> float:
    """Relative error of the peak value [-]: (C_peak - T_peak) / |T_peak|.

    The peak is the sample of largest magnitude (signed value), in SI, over the evaluation
    interval on each signal's own samples (no resampling, so the peak is not smoothed).
    """
    r, c = _windowed(reference, candidate, t_window)
    tp, cp = r.data[_peak(r.data)], c.data[_peak(c.data)]
    if tp == 0.0:
        raise ValueError(f"reference {reference.name!r} is identically zero in the window")
    return float((cp - tp) / abs(tp))


def peak_time_error(reference: Signal, candidate: Signal,
                    t_window: tuple[float, float] | None = None) -> float:
    """Time of the candidate's peak minus the reference's [s] (peaks as in ``peak_error``)."""
    r, c = _windowed(reference, candidate, t_window)
    return float(c.t[_peak(c.data)] - r.t[_peak(r.data)])


def rms_error(reference: Signal, candidate: Signal, t_window: tuple[float, float] | None = None,
              dt: float = 1e-4, relative: bool = False) -> float:
    """Root-mean-square difference on the common grid [SI unit], or relative to rms(T) [-]."""
    _, T, C, _ = _common_grid(reference, candidate, t_window, dt)
    e = float(np.sqrt(np.mean((C - T) ** 2)))
    if relative:
        den = float(np.sqrt(np.mean(T ** 2)))
        if den == 0.0:
            raise ValueError(f"reference {reference.name!r} has zero rms in the window")
        return e / den
    return e


def duration(signal: Signal, threshold: float = 0.05,
             t_window: tuple[float, float] | None = None) -> float:
    """Pulse duration [s]: from the first to the last sample with |x| >= threshold * max|x|.

    Parameters
    ----------
    signal : the channel
    threshold : fraction of the peak magnitude, in (0, 1)
    t_window : restrict to (t0, t1) [s]
    """
    if not 0 < threshold < 1:
        raise ValueError(f"threshold={threshold!r}: must be in (0, 1)")
    s = signal.window(*t_window) if t_window is not None else signal
    a = np.abs(s.data)
    if a.size == 0 or a.max() == 0.0:
        raise ValueError(f"signal {signal.name!r}: no pulse (empty or identically zero)")
    idx = np.flatnonzero(a >= threshold * a.max())
    return float(s.t[idx[-1]] - s.t[idx[0]])


def _windowed(reference: Signal, candidate: Signal, t_window: tuple[float, float] | None
              ) -> tuple[Signal, Signal]:
    r, c = reference.to_si(), candidate.to_si()
    if r.unit != c.unit:
        raise ValueError(f"reference [{reference.unit}] and candidate [{candidate.unit}] have "
                         "different SI units")
    if t_window is not None:
        r, c = r.window(*t_window), c.window(*t_window)
    if r.t.size == 0 or c.t.size == 0:
        raise ValueError(f"t_window={t_window!r}: no samples of {reference.name!r} or "
                         f"{candidate.name!r} inside")
    return r, c


def compare(reference: Signal, candidate: Signal, t_window: tuple[float, float] | None = None,
            params: ISO18571Params = ISO18571Params()) -> dict[str, Any]:
    """All comparison numbers of a model channel against a test channel.

    Returns
    -------
    dict with: ``iso18571`` (overall), ``corridor``, ``phase``, ``magnitude``, ``slope``,
    ``grade``, ``time_shift`` [s], ``peak_reference``, ``peak_candidate`` [SI], ``peak_error``
    [-], ``peak_time_error`` [s], ``rms_error`` [SI], ``rms_error_relative`` [-],
    ``duration_reference``, ``duration_candidate`` [s], ``duration_error`` [-], ``unit`` (SI),
    ``t_start``, ``t_end`` [s].

    Notes
    -----
    ISO/TS 18571 as in ``iso18571``; the other errors are plain definitions (docstrings).
    """
    res = iso18571(reference, candidate, t_window, params)
    r, c = _windowed(reference, candidate, t_window)
    d_r = duration(r)
    d_c = duration(c)
    return {
        "iso18571": res.overall, "corridor": res.corridor, "phase": res.phase,
        "magnitude": res.magnitude, "slope": res.slope, "grade": res.grade,
        "time_shift": res.time_shift,
        "peak_reference": float(r.data[_peak(r.data)]),
        "peak_candidate": float(c.data[_peak(c.data)]),
        "peak_error": peak_error(reference, candidate, t_window),
        "peak_time_error": peak_time_error(reference, candidate, t_window),
        "rms_error": rms_error(reference, candidate, t_window, params.dt),
        "rms_error_relative": rms_error(reference, candidate, t_window, params.dt, True),
        "duration_reference": d_r, "duration_candidate": d_c,
        "duration_error": (d_c - d_r) / d_r if d_r > 0 else math.nan,
        "unit": r.unit, "t_start": res.t_start, "t_end": res.t_end,
    }
