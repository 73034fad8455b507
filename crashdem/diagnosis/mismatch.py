"""Locate where a simulated channel disagrees with a recording, judged against the recording's
own noise, and say what the disagreement looks like (missing peak, peak too high, late, ...).

All feature names describe the *simulation* relative to the recording: ``missing_peak`` = the
recording has a peak the simulation lacks; ``peak_too_high`` = the simulated peak is higher;
``peak_late`` = the simulated peak comes later; ``rebound_too_strong`` = the simulated body leaves
faster; ``duration_too_long`` = the simulated pulse lasts longer.

Notes
-----
Robust scale: sigma = 1.4826 MAD (Hampel 1974; Rousseeuw & Croux 1993). Peak detection by
topographic prominence (``scipy.signal.find_peaks``) with a prominence floor of k sigma.
Exceedance of |residual| > k sigma over a minimum duration of one noise correlation time
1 / (2 B_eq) (band-limited noise, Bendat & Piersol, *Random Data*, section 8.2).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy import signal as sps

from crashdem.diagnosis import _dsp
from crashdem.signal import Signal

__all__ = ["NoiseEstimate", "Feature", "MismatchWindow", "FeatureChange", "estimate_noise",
           "onset_time", "align", "find_features", "locate_mismatch", "feature_changes",
           "describe_changes", "MAD_TO_SIGMA", "K_SIGMA", "SIMULATED_SPAN"]

#: Gaussian consistency factor of the median absolute deviation
MAD_TO_SIGMA = 1.4826
#: residual significance threshold [sigma]: P(|N(0,1)| > 4) = 6e-5 per independent sample, i.e.
#: < 1 % chance of a false window over ~100 independent samples of a 0.15 s CFC 60 record
K_SIGMA = 4.0
#: prominence threshold of a peak [sigma]
K_PEAK = 6.0
#: peaks closer than this in time are the same peak when matching recording and simulation [s]
PEAK_MATCH_TOL = 0.006
#: minimum number of quiet samples for a pre-event noise estimate
MIN_QUIET_SAMPLES = 32
#: onset threshold [sigma] and as a fraction of the signal range
K_ONSET = 8.0
ONSET_FRACTION = 0.02
#: gap kept between the quiet (noise) window and the event onset [s] (raw data); filtered data
#: keep three noise correlation times 3 / (2 B_eq) (CFC 60: ~14 ms)
QUIET_GUARD = 0.002
#: noise floor as a fraction of the channel range: 1e-4 is ~ the LSB of a 14-bit acquisition
#: over the used range; only bites on noise-free (simulated) records
NOISE_FLOOR_FRACTION = 1e-4
#: duration of a pulse: between first and last crossing of this fraction of the recorded peak
DURATION_FRACTION = 0.1
#: a lobe of the residual whose peak |residual| is below this fraction of a neighbouring
#: lobe's, as near to it as it is long, is merged into it: an overshoot where the residual
#: crosses zero (``_merge_minor_lobes``)
LOBE_MIN_RATIO = 0.1
#: ``Signal.meta`` key of an aligned simulation: the time span [s] (on the recording's time
#: base) it was simulated over; ``align`` holds the nearest simulated value outside it, where
#: ``locate_mismatch`` compares nothing
SIMULATED_SPAN = "simulated_span_s"
#: a mismatch feature counts as removed or corrected by a fit when its size shrinks by at least
#: this fraction (``describe_changes``)
CHANGE_FRACTION = 0.5


@dataclass(frozen=True)
class NoiseEstimate:
    """Noise level of a channel: ``sigma`` [unit], how it was obtained, and the quiet window [s]."""

    sigma: float
    method: str
    window: tuple[float, float] | None
    unit: str = ""


@dataclass(frozen=True)
class Feature:
    """One characterised difference between simulation and recording."""

    feature: str
    time_s: float
    size: float
    unit: str
    significance: float  # size / its noise-induced uncertainty [-]
    description: str


@dataclass
class MismatchWindow:
    """A time window where |recording - simulation| exceeds k sigma for long enough."""

    channel: str
    t_start_s: float
    t_end_s: float
    feature: str
    size: float
    unit: str
    max_residual_sigma: float
    description: str
    feature_time_s: float | None = None  # when the feature occurs in the recording [s]
    other_features: list[dict[str, Any]] = field(default_factory=list)
    significance: float | None = None  # the main feature's size over its noise uncertainty

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the window."""
        return asdict(self)


def _mad_sigma(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    return MAD_TO_SIGMA * float(np.median(np.abs(x - np.median(x))))


def _detrended(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    if t.size < 3:
        return x - np.median(x)
    c = np.polyfit(t - t[0], x, 1)
    return x - np.polyval(c, t - t[0])


def estimate_noise(sig: Signal, quiet: tuple[float, float] | None = None,
                   floor_fraction: float = NOISE_FLOOR_FRACTION) -> NoiseEstimate:
    """Noise standard deviation of a recorded channel, at least ``floor_fraction`` x range.

    See ``_estimate_noise`` for the method. The floor keeps noise-free (simulated) "recordings"
    from making every difference significant: sigma >= floor_fraction * (max - min).
    """
    est = _estimate_noise(sig, quiet)
    floor = floor_fraction * float(np.ptp(sig.data)) if sig.data.size else 0.0
    if est.sigma < floor:
        return NoiseEstimate(floor, est.method + f"; below the floor, set to {floor_fraction:g} x range",
                             est.window, est.unit)
    return est


def _estimate_noise(sig: Signal, quiet: tuple[float, float] | None = None) -> NoiseEstimate:
    """Noise standard deviation of a recorded channel.

    Parameters
    ----------
    sig : the recorded channel
    quiet : optional (t0, t1) [s] known to hold no event (pre-impact); if omitted, the leading
        segment before the event onset is found automatically (pre-trigger data), else the
        high-frequency residual is used.

    Returns
    -------
    NoiseEstimate with sigma in the channel unit.

    Notes
    -----
    Pre-event: sigma = 1.4826 MAD of the linearly detrended quiet segment (a free-fall velocity
    is a ramp). Fallback: 1.4826 MAD of the second difference divided by sqrt(6) (white noise;
    underestimates band-limited noise, flagged in ``method``).
    """
    t, x = sig.t, sig.data
    if quiet is not None:
        m = (t >= quiet[0]) & (t <= quiet[1])
        if m.sum() < MIN_QUIET_SAMPLES:
            raise ValueError(f"estimate_noise: quiet window {quiet} s of {sig.name!r} holds "
                             f"{int(m.sum())} samples, need >= {MIN_QUIET_SAMPLES}")
        s = _mad_sigma(_detrended(t[m], x[m]))
        return NoiseEstimate(s, "quiet window (given), MAD", (float(t[m][0]), float(t[m][-1])), sig.unit)
    # leading segment: start with the first 5 % (or pre-zero data) and extend until the onset
    guard = QUIET_GUARD if sig.cfc is None else filter_startup(sig)
    n_g = int(guard * sig.fs)
    est = _leading_segment(sig, 0, guard)
    if sig.cfc is not None and est is not None and est[1] <= n_g \
            and t.size - n_g >= 2 * MIN_QUIET_SAMPLES:
        # the segment ended inside the filter's start-up: its transient, not the event, when
        # the same search from the end of the start-up finds a quiet segment longer than the
        # guard (a record that begins near the contact has none)
        late = _leading_segment(sig, n_g, guard)
        if late is not None and late[1] - n_g >= n_g + MIN_QUIET_SAMPLES:
            est = late
    if est is not None:
        n_a, n1 = est[0], est[2]
        seg = _detrended(t[n_a:n1], x[n_a:n1])
        return NoiseEstimate(_mad_sigma(seg), "pre-event segment, MAD",
                             (float(t[n_a]), float(t[n1 - 1])), sig.unit)
    d2 = np.diff(x, 2)
    return NoiseEstimate(_mad_sigma(d2) / math.sqrt(6.0),
                         "second-difference MAD (no quiet segment; underestimates filtered noise)",
                         None, sig.unit)


def filter_startup(sig: Signal) -> float:
    """Duration [s] at the start of a CFC-filtered record that the filter's start-up leaves
    unreliable when the record was filtered as cut (a zero-phase filter padded at the edge turns
    the first samples' noise into a decaying transient of the raw noise's size): three noise
    correlation times 3 / (2 B_eq), at least ``QUIET_GUARD``; 0 for an unfiltered channel."""
    if sig.cfc is None:
        return 0.0
    return max(QUIET_GUARD, 3.0 / (2.0 * _dsp.noise_bandwidth(sig.fs, sig.cfc)))


def _leading_segment(sig: Signal, start: int, guard: float) -> tuple[int, int, int] | None:
    """The quiet leading segment of ``sig`` from sample ``start``: a linear fit to the first 5 %
    (or the pre-zero data), extended until the channel leaves it by K_ONSET sigma or
    ONSET_FRACTION of its range, minus ``guard`` [s] (a zero-phase filter spreads the event
    backwards in time); the filter's start-up (``guard``) is also skipped at the beginning when
    there is room. Returns (first sample, sample where the channel left the fit, end sample)
    or None when the start holds no quiet segment."""
    t, x = sig.t[start:], sig.data[start:]
    n0 = max(MIN_QUIET_SAMPLES, int(0.05 * t.size))
    if np.any(t < 0.0):
        n0 = max(n0, int(np.searchsorted(t, 0.0)) - 2)
    n0 = min(n0, t.size)
    seg = _detrended(t[:n0], x[:n0])
    s0 = _mad_sigma(seg)
    rng = float(np.ptp(sig.data)) if sig.data.size else 0.0
    if not (n0 >= MIN_QUIET_SAMPLES and s0 > 0 and s0 < 0.05 * rng):
        return None
    c = np.polyfit(t[:n0] - t[0], x[:n0], 1)
    dev = np.abs(x - np.polyval(c, t - t[0]))
    thr = max(K_ONSET * s0, ONSET_FRACTION * rng)
    above = np.flatnonzero(dev > thr)
    n_left = int(above[0]) if above.size else t.size
    n1 = max(MIN_QUIET_SAMPLES, n_left - max(3, int(guard * sig.fs)))
    n_a = int(guard * sig.fs) if (start == 0 and n1 - int(guard * sig.fs) >= MIN_QUIET_SAMPLES) \
        else 0
    return start + n_a, start + n_left, start + n1


def onset_time(sig: Signal, sigma: float, _restart: bool = True) -> float:
    """First time [s] the channel leaves its initial level by more than the onset threshold.

    A CFC-filtered record that was filtered as cut begins with the filter's start-up transient
    (``filter_startup``); a crossing inside it is not taken as the onset when the record after
    the start-up is quiet for at least another start-up duration (measured: on a Yade 5 m drop
    filtered at CFC 60, the first sample read -4.9 m/s^2, the 0.5 g raw noise of the first
    sample spread by the filter's edge padding; against a 168 m/s^2 peak it crossed the onset
    threshold, so the onset was placed 80 ms early, the impact speed was not read and the
    score fell to 0.36).

    A velocity channel (unit ``m/s``) is a ramp before the event (free fall), so its onset is
    that of its time derivative (constant -g, or +g, before the event), with the derivative's
    own noise from the pre-event segment when ``sigma`` > 0 (a recorded channel) and 0 else (a
    simulated one)."""
    if sig.unit == "m/s" and sig.t.size >= 3:
        d = Signal(sig.name, sig.t, np.gradient(sig.data, sig.t), "m/s^2", sig.cfc, sig.meta)
        return onset_time(d, estimate_noise(d).sigma if sigma > 0.0 else 0.0, _restart)
    x = sig.data
    n0 = max(3, min(MIN_QUIET_SAMPLES, x.size // 10))
    base = float(np.median(x[:n0]))
    thr = max(K_ONSET * sigma, ONSET_FRACTION * float(np.ptp(x)))
    idx = np.flatnonzero(np.abs(x - base) > thr)
    if not idx.size:
        return float(sig.t[0])
    i = int(idx[0])
    g = filter_startup(sig)
    if _restart and g > 0.0 and sig.t[i] < sig.t[0] + g:
        # a crossing inside the filter's start-up: when the record after it holds a quiet
        # segment of another start-up duration before its own onset, the crossing was the
        # start-up transient, not the event (a record that begins near the contact is kept)
        late = sig.t >= sig.t[0] + g
        if late.sum() >= 2 * n0:
            cut = Signal(sig.name, sig.t[late], x[late], sig.unit, sig.cfc, sig.meta)
            t_cut = onset_time(cut, sigma, _restart=False)
            if t_cut >= float(cut.t[0]) + g:
                return t_cut
    if i == 0:
        return float(sig.t[0])
    # linear interpolation of the crossing
    x0, x1 = abs(x[i - 1] - base), abs(x[i] - base)
    frac = (thr - x0) / (x1 - x0) if x1 != x0 else 0.0
    return float(sig.t[i - 1] + frac * (sig.t[i] - sig.t[i - 1]))


def align(recording: Signal, simulation: Signal, shift: float = 0.0) -> Signal:
    """The simulation, time-shifted by ``shift`` [s] and resampled on the recording's time base;
    samples outside the simulated range hold the nearest simulated value. The range simulated,
    shifted, is kept in ``meta[SIMULATED_SPAN]`` (a simulation aligned before keeps its own)."""
    ts = simulation.t + shift
    data = np.interp(recording.t, ts, simulation.data)
    lo, hi = _span(simulation)
    meta = {**simulation.meta, SIMULATED_SPAN: (lo + shift, hi + shift)}
    return Signal(simulation.name, recording.t.copy(), data, simulation.unit, simulation.cfc,
                  meta)


def _span(simulation: Signal) -> tuple[float, float]:
    """The time span [s] a simulation holds simulated samples over (``SIMULATED_SPAN``, else
    its own time base)."""
    span = simulation.meta.get(SIMULATED_SPAN)
    if span is not None:
        return float(span[0]), float(span[1])
    return float(simulation.t[0]), float(simulation.t[-1])


def _peaks(t: np.ndarray, x: np.ndarray, sigma: float, distance: int) -> list[tuple[float, float, float]]:
    """(time, height, prominence) of the positive peaks above K_PEAK sigma prominence."""
    prom = max(K_PEAK * sigma, 0.03 * float(np.ptp(x)))
    idx, props = sps.find_peaks(x, prominence=prom, distance=max(1, distance))
    return [(float(t[i]), float(x[i]), float(p)) for i, p in zip(idx, props["prominences"])]


def _duration(t: np.ndarray, x: np.ndarray, level: float) -> tuple[float, float] | None:
    idx = np.flatnonzero(x > level)
    if idx.size == 0:
        return None
    return float(t[idx[0]]), float(t[idx[-1]])


def _peak_match_tol(t: float) -> float:
    """How far apart in time [s] two peaks near ``t`` [s] may be and still be one peak:
    ``PEAK_MATCH_TOL``, or 15 % of the time after contact when longer."""
    return max(PEAK_MATCH_TOL, 0.15 * max(t, 1e-3))


def find_features(recording: Signal, simulation: Signal, sigma: float,
                  kind: str | None = None, t_initial: float | None = None) -> list[Feature]:
    """Characterise the differences between an aligned simulation and the recording.

    Parameters
    ----------
    recording, simulation : same time base (see ``align``)
    sigma : recording noise [unit]
    kind : "acceleration" (pulse-like: peaks and duration), "velocity" (rebound) or None
        (from the unit)
    t_initial : time [s] at which initial values are compared (default: first sample)
    """
    t, xr, xs = recording.t, recording.data, simulation.data
    fs = recording.fs
    unit = recording.unit
    if kind is None:
        kind = "velocity" if unit in ("m/s",) else "acceleration"
    out: list[Feature] = []
    if kind == "acceleration":
        dist = int(0.004 * fs)
        pr = _peaks(t, xr, sigma, dist)
        ps = _peaks(t, xs, sigma, dist)
        used: set[int] = set()
        for tr, hr, prr in pr:
            j_best, d_best = -1, math.inf
            for j, (ts_, _, _) in enumerate(ps):
                if j not in used and abs(ts_ - tr) < d_best:
                    j_best, d_best = j, abs(ts_ - tr)
            if j_best >= 0 and d_best <= _peak_match_tol(tr):
                used.add(j_best)
                ts_, hs, _ = ps[j_best]
                dh = hs - hr
                if abs(dh) > K_SIGMA * sigma:
                    name = "peak_too_high" if dh > 0 else "peak_too_low"
                    out.append(Feature(name, tr, dh, unit, abs(dh) / sigma,
                                       f"simulated peak {'higher' if dh > 0 else 'lower'} by "
                                       f"{abs(dh):.3g} {unit} at {tr * 1e3:.1f} ms"))
                dt = ts_ - tr
                # timing noise: sigma / curvature-limited slope; use 2 samples as the floor
                if abs(dt) > max(2.0 / fs, 0.002):
                    name = "peak_late" if dt > 0 else "peak_early"
                    out.append(Feature(name, tr, dt, "s", abs(dt) * fs / 2.0,
                                       f"simulated peak {abs(dt) * 1e3:.1f} ms "
                                       f"{'late' if dt > 0 else 'early'} (recorded at {tr * 1e3:.1f} ms)"))
            else:
                nth = ["first", "second", "third", "fourth"][min(3, sum(1 for p in pr if p[0] < tr))]
                out.append(Feature("missing_peak", tr, prr, unit, prr / sigma,
                                   f"recording has a {nth} peak of {prr:.3g} {unit} prominence at "
                                   f"{tr * 1e3:.1f} ms that the simulation lacks"))
        for j, (ts_, hs, prs) in enumerate(ps):
            if j not in used:
                out.append(Feature("extra_peak", ts_, prs, unit, prs / sigma,
                                   f"simulation has a peak at {ts_ * 1e3:.1f} ms "
                                   f"({prs:.3g} {unit} prominence) absent from the recording"))
        level = DURATION_FRACTION * float(np.max(xr))
        dr, ds = _duration(t, xr, level), _duration(t, xs, level)
        if dr is not None and ds is not None:
            lr, ls = dr[1] - dr[0], ds[1] - ds[0]
            d = ls - lr
            if abs(d) > max(0.002, 3.0 / fs):
                name = "duration_too_long" if d > 0 else "duration_too_short"
                out.append(Feature(name, dr[1], d, "s", abs(d) * fs / 3.0,
                                   f"simulated pulse {abs(d) * 1e3:.1f} ms "
                                   f"{'longer' if d > 0 else 'shorter'} (recorded {lr * 1e3:.1f} ms)"))
        # ringing: many sign changes of the residual above the noise within the event
        res = xs - xr
        big = np.abs(res) > K_SIGMA * sigma
        if big.sum() > 0:
            sgn = np.sign(res[big])
            changes = int(np.sum(sgn[1:] != sgn[:-1]))
            if changes >= 6:
                tb = t[big]
                out.append(Feature("oscillation", float(np.median(tb)), float(np.max(np.abs(res))),
                                   unit, changes / 2.0,
                                   f"residual oscillates ({changes} sign changes above "
                                   f"{K_SIGMA:g} sigma) between {tb[0] * 1e3:.1f} and "
                                   f"{tb[-1] * 1e3:.1f} ms: unmodelled resonance or filter"))
    else:
        # velocity along +z: rebound = largest upward velocity after the velocity crosses zero
        def rebound(x: np.ndarray) -> tuple[float, float] | None:
            up = np.flatnonzero(x > 0.0)
            if not up.size:
                return None
            i0 = int(up[0])
            i = i0 + int(np.argmax(x[i0:]))
            return float(t[i]), float(x[i])

        rr, rs = rebound(xr), rebound(xs)
        if rr is not None or rs is not None:
            vr = rr[1] if rr else 0.0
            vs = rs[1] if rs else 0.0
            tt = (rr or rs)[0]
            d = vs - vr
            if abs(d) > K_SIGMA * sigma:
                name = "rebound_too_strong" if d > 0 else "rebound_too_weak"
                out.append(Feature(name, tt, d, unit, abs(d) / sigma,
                                   f"simulated rebound speed {vs:.3g} {unit} vs recorded {vr:.3g} {unit}"))
        i0 = int(np.searchsorted(t, t_initial)) if t_initial is not None else 0
        i0 = min(i0, t.size - 1)
        d0 = xs[i0] - xr[i0]
        if abs(d0) > K_SIGMA * sigma:
            out.append(Feature("initial_offset", float(t[i0]), d0, unit, abs(d0) / sigma,
                               f"simulated initial value differs by {d0:.3g} {unit}: impact "
                               "conditions differ"))
    return out


def _merge_minor_lobes(runs: list[list[int]], res: np.ndarray, gap: int) -> list[list[int]]:
    """Runs of samples ``[i0, i1]`` (in order) of the residual ``res`` with each minor lobe
    merged into a neighbour: the residual overshooting the other side for a moment where it
    crosses zero (noise, a slightly shifted flank) is part of the lobe beside it, not a window
    of its own. A lobe is minor beside a neighbour when its peak |residual| is below
    ``LOBE_MIN_RATIO`` of the neighbour's and the two are no further apart than the lobe is
    long (or ``gap``); it joins the larger such neighbour. A lone lobe stays one."""
    runs = [list(r) for r in runs]

    def peak(r: list[int]) -> float:
        return float(np.max(np.abs(res[r[0]:r[1] + 1])))

    def minor(k: int, j: int) -> bool:
        if not 0 <= j < len(runs):
            return False
        a, b = runs[k], runs[j]
        d = a[0] - b[1] if j < k else b[0] - a[1]
        return peak(a) < LOBE_MIN_RATIO * peak(b) and d <= max(gap, a[1] - a[0])

    while True:
        k = next((k for k in range(len(runs)) if minor(k, k - 1) or minor(k, k + 1)), None)
        if k is None:
            return runs
        j = max((j for j in (k - 1, k + 1) if minor(k, j)), key=lambda j: peak(runs[j]))
        lo, hi = min(j, k), max(j, k)
        runs[lo:hi + 1] = [[runs[lo][0], runs[hi][1]]]


def locate_mismatch(recording: Signal, simulation: Signal, noise: NoiseEstimate | None = None,
                    k_sigma: float = K_SIGMA, min_duration: float | None = None,
                    shift: float | None = None) -> list[MismatchWindow]:
    """Windows where the simulation leaves the recording's noise band, each with a feature.

    Parameters
    ----------
    recording : recorded channel (the reference)
    simulation : simulated channel (any time base; resampled onto the recording)
    noise : recording noise (default ``estimate_noise(recording)``)
    k_sigma : significance threshold [sigma]
    min_duration : shortest window kept [s]; default one noise correlation time 1/(2 B_eq) of
        the recording's CFC (or 2 samples for raw data)
    shift : time shift applied to the simulation [s]; default: align the onsets

    Returns
    -------
    list of MismatchWindow, in time order.
    """
    rec = recording.to_si()
    sim = simulation.to_si()
    if noise is None:
        noise = estimate_noise(rec)
    sigma = max(noise.sigma, 1e-12 * max(1.0, float(np.max(np.abs(rec.data)))))
    if shift is None:
        shift = onset_time(rec, sigma) - onset_time(sim, 0.0)
        if abs(shift) > 0.05 * float(np.ptp(rec.t)):
            shift = 0.0
    sim_a = align(rec, sim, shift)
    fs = rec.fs
    if min_duration is None:
        min_duration = (1.0 / (2.0 * _dsp.noise_bandwidth(fs, rec.cfc)) if rec.cfc else 2.0 / fs)
    res = sim_a.data - rec.data
    # only where the simulation exists (no extrapolated samples, also of one aligned before)
    lo, hi = _span(simulation)
    valid = (rec.t >= lo + shift) & (rec.t <= hi + shift)
    mask = (np.abs(res) > k_sigma * sigma) & valid
    # close gaps shorter than the minimum duration between exceedances of the same sign (the
    # simulation on the same side of the recording), then drop short runs: a window is one
    # lobe of the residual, so that a long event is located part by part
    gap = max(1, int(round(min_duration * fs)))
    idx = np.flatnonzero(mask)
    runs: list[list[int]] = []
    for i in idx:
        if runs and i - runs[-1][1] <= gap and (res[i] > 0.0) == (res[runs[-1][1]] > 0.0):
            runs[-1][1] = i
        else:
            runs.append([i, i])
    runs = _merge_minor_lobes(runs, res, gap)
    runs = [r for r in runs if float(rec.t[r[1]] - rec.t[r[0]]) >= min_duration]
    kind = "velocity" if rec.unit == "m/s" else "acceleration"
    t_init = float(rec.t[valid][0]) if valid.any() else None
    feats = find_features(rec, sim_a, sigma, kind, t_initial=t_init)
    # each feature to the one window nearest its time, within a pad of a quarter of the
    # window's length plus the minimum duration (an initial offset, a value at one instant:
    # the minimum duration only)
    owner: dict[int, list[Feature]] = {}
    for f in feats:
        best, d_best = None, math.inf
        for k, (i0, i1) in enumerate(runs):
            t0, t1 = float(rec.t[i0]), float(rec.t[i1])
            d = max(t0 - f.time_s, f.time_s - t1, 0.0)
            pad = min_duration + (0.0 if f.feature == "initial_offset" else 0.25 * (t1 - t0))
            if d <= pad and d < d_best:
                best, d_best = k, d
        if best is not None:
            owner.setdefault(best, []).append(f)
    windows: list[MismatchWindow] = []
    for k, (i0, i1) in enumerate(runs):
        t0, t1 = float(rec.t[i0]), float(rec.t[i1])
        inside = sorted(owner.get(k, []), key=lambda f: -f.significance)
        seg = res[i0:i1 + 1]
        peak_res = float(np.max(np.abs(seg)) / sigma)
        # a feature in the channel's unit under LOBE_MIN_RATIO of the window's largest
        # difference does not describe it (a 0.04 m/s initial offset heading a 100 ms lobe
        # reaching 2.2 m/s): the window is then described by its mean, the feature kept beside
        f = next((g for g in inside if g.unit != rec.unit
                  or abs(g.size) >= LOBE_MIN_RATIO * peak_res * sigma), None)
        if f is not None:
            windows.append(MismatchWindow(rec.name, t0, t1, f.feature, f.size, f.unit, peak_res,
                                          f.description, f.time_s,
                                          [asdict(g) for g in inside if g is not f],
                                          significance=f.significance))
        else:
            mean = float(np.mean(seg))
            name = ("force_too_high" if mean > 0 else "force_too_low") if kind == "acceleration" \
                else ("value_too_high" if mean > 0 else "value_too_low")
            windows.append(MismatchWindow(rec.name, t0, t1, name, mean, rec.unit, peak_res,
                                          f"simulation {'above' if mean > 0 else 'below'} the "
                                          f"recording by {abs(mean):.3g} {rec.unit} on average "
                                          f"between {t0 * 1e3:.1f} and {t1 * 1e3:.1f} ms",
                                          0.5 * (t0 + t1), [asdict(g) for g in inside],
                                          significance=abs(mean) / sigma))
    return windows



#: what property of a pulse each feature describes: a fit changes a feature's size within its
#: family (a peak's height or timing, the pulse duration, the rebound, the initial value, the
#: mean level), or removes a peak one of the two lacks
_FAMILY = {name: family for family, names in (
    ("peak_height", ("peak_too_high", "peak_too_low")),
    ("peak_timing", ("peak_late", "peak_early")),
    ("missing_peak", ("missing_peak",)), ("extra_peak", ("extra_peak",)),
    ("duration", ("duration_too_long", "duration_too_short")),
    ("rebound", ("rebound_too_strong", "rebound_too_weak")),
    ("initial_offset", ("initial_offset",)), ("oscillation", ("oscillation",)),
    ("level", ("force_too_high", "force_too_low", "value_too_high", "value_too_low")))
    for name in names}
#: families ``find_features`` reports at most once per channel (matched whatever their time)
_ONCE_PER_CHANNEL = ("duration", "rebound", "initial_offset", "oscillation")


@dataclass(frozen=True)
class FeatureChange:
    """One mismatch feature of a baseline and the same feature against a fitted simulation:
    its signed ``before`` and ``after`` size (``after`` 0: the feature is gone) on ``channel``
    at ``time_s`` in the recording; ``significance``: the feature's before (size / noise)."""

    channel: str
    feature: str
    time_s: float
    before: float
    after: float
    unit: str
    significance: float

    @property
    def reduction(self) -> float:
        """The fraction of the feature's size the fit removed (1: gone; < 0: grown)."""
        return 1.0 - abs(self.after) / abs(self.before) if self.before else 0.0


def _window_features(windows: list[MismatchWindow]) -> list[tuple[str, dict[str, Any]]]:
    """``(channel, feature)`` of every feature of ``windows``: the main one of each window and
    the others it holds (``feature``, ``time_s``, ``size``, ``unit``, ``significance``)."""
    out: list[tuple[str, dict[str, Any]]] = []
    for w in windows:
        t = w.feature_time_s if w.feature_time_s is not None else 0.5 * (w.t_start_s + w.t_end_s)
        sig = w.significance if w.significance is not None else w.max_residual_sigma
        out.append((w.channel, {"feature": w.feature, "time_s": t, "size": w.size,
                                "unit": w.unit, "significance": sig}))
        out += [(w.channel, dict(f)) for f in w.other_features]
    return out


def feature_changes(before: list[MismatchWindow], after: list[MismatchWindow]
                    ) -> list[FeatureChange]:
    """How each feature of the ``before`` mismatch windows (a baseline against the recording)
    fares against a fitted simulation's windows ``after`` (``locate_mismatch`` of the same
    recording): matched on the channel, the feature's family (``_FAMILY``) and, for a peak,
    the time (``_peak_match_tol``, as ``find_features`` matches peaks).
    A feature with no match is gone (``after`` 0). A peak's height or timing counts as not
    changed when the fitted simulation lacks that peak altogether (``missing_peak`` there).
    In the order of ``before``."""
    later = _window_features(after)
    out: list[FeatureChange] = []
    for ch, f in _window_features(before):
        fam = _FAMILY.get(f["feature"])
        t = float(f["time_s"])
        tol = _peak_match_tol(t)

        def near(g: dict[str, Any], family: str) -> bool:
            return (_FAMILY.get(g["feature"]) == family
                    and (family in _ONCE_PER_CHANNEL or abs(float(g["time_s"]) - t) <= tol))

        same = [g for c, g in later if c == ch and near(g, fam)]
        size = float(f["size"])
        if same:
            g = min(same, key=lambda g: abs(float(g["time_s"]) - t))
            after_size = float(g["size"])
        elif fam in ("peak_height", "peak_timing") and any(
                c == ch and near(g, "missing_peak") for c, g in later):
            after_size = size
        else:
            after_size = 0.0
        out.append(FeatureChange(ch, f["feature"], t, size, after_size, f["unit"],
                                 float(f["significance"])))
    return out


#: the phrase of a signed feature's change: the verb when the simulation was above (later,
#: longer) the recording and when below, what it acts on, and the size's format (scale to the
#: shown unit, its format, the unit: None for the feature's own)
_SIGNED_PHRASE = {
    "peak_height": ("lowers", "raises", "the peak at {ms:.1f} ms", "error ", 1.0, "+.3g", None),
    "peak_timing": ("advances", "delays", "the peak at {ms:.1f} ms", "", 1e3, "+.1f", "ms"),
    "duration": ("shortens", "lengthens", "the pulse", "error ", 1e3, "+.1f", "ms"),
    "rebound": ("weakens", "strengthens", "the rebound", "error ", 1.0, "+.3g", None),
    "initial_offset": ("removes", "removes", "the initial offset", "", 1.0, "+.3g", None),
    "level": ("closes", "closes", "the mean gap around {ms:.1f} ms", "", 1.0, "+.3g", None)}


def _change_phrase(c: FeatureChange) -> str:
    """What the fit did to one feature, in words with the numbers."""
    fam, ms, ch = _FAMILY.get(c.feature), c.time_s * 1e3, c.channel
    if fam == "missing_peak":
        return f"adds the missing peak of {c.before:.3g} {c.unit} at {ms:.1f} ms on {ch}"
    if fam == "extra_peak":
        return f"removes the extra peak at {ms:.1f} ms on {ch}"
    if fam == "oscillation":
        return f"removes the residual oscillation on {ch}"
    above, below, what, label, scale, fmt, unit = _SIGNED_PHRASE[fam or "level"]
    return (f"{above if c.before > 0 else below} {what.format(ms=ms)} on {ch} ({label}"
            f"{c.before * scale:{fmt}} -> {c.after * scale:{fmt}} {unit or c.unit})")


def describe_changes(changes: list[FeatureChange], n: int = 2) -> str | None:
    """The ``n`` features a fit changed most (by their before significance times the fraction
    removed, each removed or shrunk by at least ``CHANGE_FRACTION``), joined in one clause
    (e.g. "adds the missing peak of 194 m/s^2 at 28.8 ms on accel_z; strengthens the rebound
    on velocity_z (error -2.05 -> -0.1 m/s)"); None when none qualifies."""
    good = sorted((c for c in changes if c.reduction >= CHANGE_FRACTION),
                  key=lambda c: -c.significance * c.reduction)
    return "; ".join(_change_phrase(c) for c in good[:n]) or None
