"""Fit each hypothesis (its parameters plus the recalibration parameters and a time shift) to a
recording, score it, penalise its complexity and rank the candidates.

Statistical model
-----------------
Residuals are the simulated minus recorded samples of every diagnosed channel divided by that
channel's noise sigma (``mismatch.estimate_noise``), over the event window (onset - 5 ms to the
end of the record). Filtered channels are correlated over about 1/(2 B_eq); the number of
independent samples is ``n_eff = n 2 B_eq / fs`` (``_dsp.effective_samples``; CFC 60 at
12.5 kHz: about 1 independent sample in 50).

* fit: ``scipy.optimize.least_squares`` (trust-region reflective) in unit-box coordinates
  (log or linear per parameter), multi-start from a coarse grid of the hypothesis parameters;
* uncertainty: ``cov = s^2 (J^T J)^-1 n / n_eff`` with ``s^2 = RSS / (n - k)`` (Gauss-Newton
  covariance, inflated for correlated samples);
* complexity: Bayesian information criterion with unknown noise variance,
  ``BIC = n_eff ln(RSS / n) + k ln(n_eff)`` (Schwarz 1978), evaluated with n_eff;
* acceptance: the best missing-physics hypothesis is accepted only if its BIC beats the
  recalibration (which it nests) by ``ACCEPT_MARGIN`` (Kass & Raftery 1995: Delta BIC > 10 is
  "very strong" evidence), its score is not below the recalibration's (``MIN_SCORE_GAIN``), and
  the recalibration does not already explain the recording within noise.

Score: ISO/TS 18571 rating from ``crashdem.metrics`` when importable, otherwise the fallback
``1 - min(1, RMS(sim - rec) / RMS(rec))`` over the event window (named in the report).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares

from crashdem.diagnosis import _dsp
from crashdem.diagnosis.catalogue import RECALIBRATION, Hypothesis, ParameterSpec
from crashdem.diagnosis.mismatch import NoiseEstimate, align
from crashdem.signal import Signal

__all__ = ["FitProblem", "FitResult", "rating_at_best_alignment", "score_signals",
           "fit_hypothesis", "fit_variants", "rank", "metric_name", "ACCEPT_MARGIN",
           "MIN_SCORE_GAIN", "WITHIN_NOISE_RATIO"]

Simulator = Callable[[dict[str, float]], Mapping[str, Signal]]

#: Delta BIC (recalibration - hypothesis) needed to claim missing physics (Kass & Raftery 1995)
ACCEPT_MARGIN = 10.0
#: the claimed physics must not lower the score below the recalibration's by more than this [-]
#: (the BIC decides; the score guards against a likelihood gain the rating does not see)
MIN_SCORE_GAIN = -0.005
#: a fit whose weighted RMS residual is below this many sigma "explains the recording within
#: noise": 1 for a perfect model; 1.5 leaves room for the sigma estimate's own error
#: (MAD of ~100 independent pre-event samples: ~10 % standard error) and model discretisation
WITHIN_NOISE_RATIO = 1.5
#: search range of the time-shift nuisance parameter around its onset estimate [s]
SHIFT_RANGE = 0.004
#: event window starts this long before the recorded onset [s]
PRE_ONSET = 0.005
#: scoring interval: the event lasts until |accel| last exceeds this fraction of its maximum ...
EVENT_FRACTION = 0.05
#: ... plus this tail [s] (the rebound start)
EVENT_TAIL = 0.010
#: least-squares settings: relative finite-difference step in unit coordinates and budget
DIFF_STEP = 2e-3
#: residual samples kept per independent noise sample (2 B_eq per second): 8 keeps the
#: residual an oversampled picture of everything the filtered channel can show
SAMPLES_PER_BAND = 8.0
MAX_NFEV = 150
#: coarse-grid evaluations per recalibration row of the multi-start (cheap: one ROM run each)
GRID_BUDGET = 36
#: function evaluations of the short polish runs started from the best grid points
POLISH_NFEV = 6
#: relative cost / step tolerance of least squares: 1e-6 of the cost is far below the
#: resolution of the BIC (one unit of n_eff ln RSS is a relative change of 1 / n_eff ~ 1e-2)
LS_TOL = 1e-6
#: the report also gives the ISO/TS 18571 rating at the best common time alignment of all
#: channels within this [s] of the least-squares one (``rating_at_best_alignment``): the
#: standard's phase search is bistable on a monotone channel. On a velocity ramp the Pearson
#: correlation is ~0.99 at every lag, and a 0.5 ms change of alignment moved its rating
#: 0.46 -> 0.86 (session 43).
SCORE_SHIFT_S = 2.0e-3
#: ... in steps of [s]
SCORE_SHIFT_STEP_S = 2.5e-4

try:  # ISO/TS 18571 rating (team module, written in parallel)
    from crashdem import metrics as _metrics
except ImportError:  # pragma: no cover - depends on checkout state
    _metrics = None


def metric_name() -> str:
    """Name of the similarity score in use."""
    if _metrics is not None and hasattr(_metrics, "iso18571"):
        return "ISO/TS 18571 overall rating"
    return "1 - NRMSE (fallback: crashdem.metrics not available)"


def _iso_rating(rec: Signal, sim: Signal) -> float | None:
    if _metrics is None or not hasattr(_metrics, "iso18571"):
        return None
    try:
        r = _metrics.iso18571(rec, sim)
    except ValueError:  # interval too short for the metric: fall back
        return None
    return float(r.overall)


def event_window(rec: Signal, t0: float, fraction: float = EVENT_FRACTION,
                 tail: float = EVENT_TAIL) -> tuple[float, float]:
    """Scoring interval [s]: from ``t0`` to the last time |x| exceeds ``fraction`` of its maximum
    plus ``tail`` (ISO/TS 18571 rates the event, not a flat post-event record)."""
    x = np.abs(rec.data)
    above = np.flatnonzero((x > fraction * float(np.max(x))) & (rec.t >= t0))
    t1 = float(rec.t[above[-1]]) + tail if above.size else float(rec.t[-1])
    return t0, min(t1, float(rec.t[-1]))


def _window_mask(t: np.ndarray, window: tuple[float, float] | None) -> np.ndarray:
    """The samples of the time axis ``t`` inside the scoring ``window`` (all without one)."""
    return np.ones(t.shape, bool) if window is None else (t >= window[0]) & (t <= window[1])


def score_signals(rec: Signal, sim: Signal, window: tuple[float, float] | None = None
                  ) -> dict[str, float]:
    """Similarity of an aligned simulated channel (same time base) to the recording.

    Parameters
    ----------
    rec, sim : recorded and simulated channel on the same samples
    window : scoring interval (t0, t1) [s]; default the whole record

    Returns
    -------
    dict with ``score`` [-] (ISO/TS 18571 overall rating, or the fallback), ``nrmse_score``
    (1 - RMS error / RMS recording), ``peak_error`` (simulated minus recorded maximum |value|,
    channel unit), ``timing_error_s`` (time of the simulated maximum minus the recorded one)
    and ``rms_error`` (channel unit).
    """
    m = _window_mask(rec.t, window)
    r = rec.data[m]
    s = sim.data[m]
    t = rec.t[m]
    rms = float(np.sqrt(np.mean((s - r) ** 2)))
    ref = float(np.sqrt(np.mean(r**2)))
    fallback = 1.0 - min(1.0, rms / ref) if ref > 0 else 0.0
    iso = _iso_rating(Signal(rec.name, t, r, rec.unit, rec.cfc), Signal(sim.name, t, s, sim.unit, sim.cfc))
    ir, is_ = int(np.argmax(np.abs(r))), int(np.argmax(np.abs(s)))
    return {
        "score": iso if iso is not None else fallback,
        "nrmse_score": fallback,
        "peak_error": float(abs(s[is_]) - abs(r[ir])),
        "timing_error_s": float(t[is_] - t[ir]),
        "rms_error": rms,
    }


def _shifts() -> list[float]:
    """The alignments [s] tried by ``rating_at_best_alignment``: 0 first, then by growing
    size, the earlier before the later (so that a tie keeps the smaller shift)."""
    n = int(round(SCORE_SHIFT_S / SCORE_SHIFT_STEP_S))
    out = [0.0]
    for k in range(1, n + 1):
        out += [-k * SCORE_SHIFT_STEP_S, k * SCORE_SHIFT_STEP_S]
    return out


def rating_at_best_alignment(recording: Mapping[str, Signal], aligned: Mapping[str, Signal],
                             channels: Sequence[str], window: tuple[float, float] | None
                             ) -> dict[str, Any] | None:
    """The ISO/TS 18571 rating of simulated channels aligned on the recording, taken at the
    common time shift within ``SCORE_SHIFT_S`` of their alignment at which the channels' mean
    rating is highest (shift 0 kept on a tie, then the smaller one).

    Why: the standard's phase sub-score takes the lag of highest Pearson correlation within
    20 % of the interval, and on a monotone channel (a velocity ramp) that correlation is ~0.99
    at every lag, so the lag found jumps between an interior maximum and the limit, where the
    phase and magnitude sub-scores are ~0. The rating at the least-squares alignment (the
    report's ``score``) then depends on that alignment to a fraction of a millisecond
    (measured on a Yade recording's velocity: 0.46 and 0.86 half a millisecond apart), less than
    the alignment's own uncertainty. This one does not.

    Returns ``{"overall", "per_channel": {channel: rating}, "shift_s"}``, or None when the ISO
    rating is not available (``metric_name``) or not defined on the window.
    """
    if metric_name() != "ISO/TS 18571 overall rating":
        return None
    # the windowed recording of each channel, made once for every shift
    refs: dict[str, tuple[np.ndarray, Signal]] = {}
    for ch in channels:
        rec = recording[ch]
        m = _window_mask(rec.t, window)
        refs[ch] = (m, Signal(rec.name, rec.t[m], rec.data[m], rec.unit, rec.cfc))
    best: dict[str, Any] | None = None
    for d in _shifts():
        each = {}
        for ch in channels:
            (m, ref), sim, t = refs[ch], aligned[ch], recording[ch].t
            shifted = np.interp(ref.t, t + d, sim.data) if d else sim.data[m]
            each[ch] = _iso_rating(ref, Signal(sim.name, ref.t, shifted, sim.unit, sim.cfc))
        if any(v is None for v in each.values()):
            return None if d == 0.0 else best
        mean = float(np.mean(list(each.values())))
        if best is None or mean > best["overall"]:
            best = {"overall": mean, "per_channel": each, "shift_s": d}
    return best


@dataclass
class FitProblem:
    """A recording, its noise, the channels to fit and the simulator used to fit them."""

    recording: dict[str, Signal]
    noise: dict[str, NoiseEstimate]
    channels: list[str]
    simulator: Simulator
    base_values: dict[str, float] = field(default_factory=dict)  # fixed inputs to every call
    shift0: float = 0.0
    t0: float = 0.0  # start of the event window [s]
    calls: int = 0
    score_window: tuple[float, float] | None = None  # default: event_window of channel 0
    #: model-error floor per channel: (sigma [channel unit], correlation length [s]); the
    #: residual weight is 1 / sqrt(sigma_noise^2 + sigma_model^2) and the independent samples
    #: are counted with the variance-weighted correlation length (see ``diagnose``)
    model_error: dict[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.masks = {}
        self.weights = {}
        n_eff = 0.0
        for ch in self.channels:
            rec = self.recording[ch]
            full = np.flatnonzero(rec.t >= self.t0)
            n_noise = _dsp.effective_samples(full.size, rec.fs, rec.cfc)
            sn = self.noise[ch].sigma
            sm, tau_m = self.model_error.get(ch, (0.0, 0.0))
            self.weights[ch] = 1.0 / math.sqrt(sn * sn + sm * sm)
            if sm > 0.0 and tau_m > 0.0:
                # independent samples of the total error: correlation lengths weighted by the
                # variances of sensor noise and model error (Bendat & Piersol 8.2)
                tau_n = full.size / max(n_noise, 1e-12) / rec.fs
                tau = (sn * sn * tau_n + sm * sm * tau_m) / (sn * sn + sm * sm)
                n_noise = min(n_noise, full.size / (tau * rec.fs))
            n_eff += max(n_noise, 1.0)
            # residual samples: every stride-th sample, still >= SAMPLES_PER_BAND per noise
            # bandwidth (the dropped samples carry no independent information)
            band = _dsp.noise_bandwidth(rec.fs, rec.cfc)
            stride = max(1, int(rec.fs / (2.0 * SAMPLES_PER_BAND * band)))
            self.masks[ch] = full[::stride]
        self.n = int(sum(m.size for m in self.masks.values()))
        if self.score_window is None:
            self.score_window = event_window(self.recording[self.channels[0]], self.t0)
        self.n_eff = float(min(n_eff, self.n))

    def simulate(self, values: dict[str, float]) -> Mapping[str, Signal]:
        """Run the simulator with ``values`` on top of the fixed ``base_values`` (counted)."""
        self.calls += 1
        return self.simulator({**self.base_values, **values})

    def residual(self, values: dict[str, float], shift: float,
                 sims: Mapping[str, Signal] | None = None) -> np.ndarray:
        """Sigma-normalised residual (sim - rec) / sigma of all channels, simulation shifted by
        ``shift`` [s], on the residual samples (``masks``)."""
        sims = self.simulate(values) if sims is None else sims
        parts = []
        for ch in self.channels:
            rec = self.recording[ch]
            al = align(rec, sims[ch], shift)
            parts.append(((al.data - rec.data) * self.weights[ch])[self.masks[ch]])
        return np.concatenate(parts)

    def aligned(self, sims: Mapping[str, Signal], shift: float) -> dict[str, Signal]:
        """Simulated channels shifted by ``shift`` [s] on the recording's time base."""
        return {ch: align(self.recording[ch], sims[ch], shift) for ch in self.channels}

    def scores(self, aligned: Mapping[str, Signal]) -> dict[str, Any]:
        """Per-channel ``score_signals`` over the score window and their mean (``overall``)."""
        per = {ch: score_signals(self.recording[ch], aligned[ch], self.score_window)
               for ch in self.channels}
        overall = float(np.mean([v["score"] for v in per.values()]))
        return {"per_channel": per, "overall": overall}


@dataclass
class FitResult:
    """A fitted hypothesis."""

    hypothesis: str
    parameters: dict[str, float]
    uncertainty: dict[str, float]
    units: dict[str, str]
    shift_s: float
    rss: float  # sum of squared sigma-normalised residuals
    n: int
    n_eff: float
    k: int  # fitted parameters (recalibration + hypothesis + shift)
    bic: float
    complexity_penalty: float
    scores: dict[str, Any]
    aligned: dict[str, Signal]
    at_bounds: list[str]
    n_evals: int
    variant: str | None = None  # the hypothesis's fitted discrete form (``Hypothesis.variants``)
    form_penalty: float = 0.0  # ln(number of forms) added to the BIC for choosing the form

    @property
    def rms_sigma(self) -> float:
        """RMS of the sigma-normalised residual [-] (1 = within noise)."""
        return math.sqrt(self.rss / self.n)


def _specs(h: Hypothesis, with_recal: bool) -> list[ParameterSpec]:
    specs = list(h.parameters)
    if with_recal and h.name != RECALIBRATION.name:
        specs = list(RECALIBRATION.parameters) + specs
    return specs


def fit_hypothesis(problem: FitProblem, h: Hypothesis, *, with_recal: bool = True,
                   start: dict[str, float] | None = None, grid_points: int | None = None,
                   n_starts: int = 2, grid_over: list[str] | None = None,
                   n_full: int = 1, prior_row: bool = True) -> FitResult:
    """Fit hypothesis ``h`` (plus recalibration and time shift) to the problem's recording.

    Parameters
    ----------
    problem : the recording, noise and simulator
    h : the hypothesis (``catalogue.get(name)``)
    with_recal : also refit the recalibration parameters (default True: nested comparison)
    start : optional starting values (e.g. the recalibration optimum)
    grid_points : coarse-grid points per hypothesis parameter for the multi-start (default:
        ``GRID_BUDGET ** (1 / n)`` for n own parameters, at least 3)
    n_starts : number of least-squares runs started from the best grid points
    grid_over : restrict the coarse grid to these parameter names (default: all of ``h``'s own;
        the others stay at their ``start`` value -- used for combined hypotheses)
    n_full : full least-squares runs, from the best ``n_full`` polished starts
    prior_row : also grid with the recalibration at its prior (not only at ``start``)

    Returns
    -------
    FitResult
    """
    specs = _specs(h, with_recal)
    n_p = len(specs)
    calls0 = problem.calls

    def unpack(u: np.ndarray) -> tuple[dict[str, float], float]:
        vals = {s.name: s.from_unit(x) for s, x in zip(specs, u[:n_p])}
        shift = problem.shift0 + (float(u[n_p]) - 0.5) * 2.0 * SHIFT_RANGE
        return vals, shift

    def fun(u: np.ndarray) -> np.ndarray:
        vals, shift = unpack(u)
        return problem.residual(vals, shift)

    u_nom = np.array([s.to_unit(start.get(s.name, s.nominal) if start else s.nominal) for s in specs]
                     + [0.5])
    own = [i for i, s in enumerate(specs) if s in h.parameters
           and (grid_over is None or s.name in grid_over)]
    # coarse grid over the hypothesis's own parameters (recalibration at its start value)
    level_sets = []
    for i in own:
        g = grid_points or specs[i].grid or max(3, int(round(GRID_BUDGET ** (1.0 / max(1, len(own))))))
        level_sets.append(np.linspace(0.05, 0.95, g) if g > 1 else np.array([0.5]))
    combos = list(itertools.product(*level_sets))
    # recalibration part of the grid: at the given start (usually the recalibration optimum,
    # which may have absorbed part of the effect) and at the prior nominal values
    recal_names = {p.name for p in RECALIBRATION.parameters}
    u_prior = np.array([s.to_unit(s.nominal if (start is None or s.name in recal_names)
                                  else start.get(s.name, s.nominal)) for s in specs] + [0.5])
    recal_rows = [u_nom] if (start is None or not prior_row) else [u_nom, u_prior]
    candidates = [u_nom.copy()]
    for row in recal_rows:
        for combo in combos:
            u = row.copy()
            for i, x in zip(own, combo):
                u[i] = x
            candidates.append(u)
    # the "effect off" start (recalibration optimum, effect switched off): the fit then cannot
    # end worse than the recalibration it nests
    u_off = u_nom.copy()
    for i in own:
        if specs[i].off is not None:
            u_off[i] = specs[i].to_unit(specs[i].off)
    costs = []
    for u in candidates:
        try:
            costs.append(float(np.sum(fun(u) ** 2)))
        except (ValueError, FloatingPointError):
            costs.append(math.inf)
    order = list(np.argsort(costs))
    # short polish of the best grid points (the least-squares basin of a plateau or a step is
    # narrow when the noise is small, so the raw grid cost ranks basins poorly), then a full
    # run from the best polished point and from the "effect off" start
    # distinct starts: equal costs mean the effect is inactive there (same prediction); take
    # the best of each recalibration row first, then the next best distinct points
    row_of = [1] + [1 + (i // len(combos)) for i in range(len(candidates) - 1)]
    chosen: list[int] = []
    seen: set[float] = set()
    for row in sorted(set(row_of)):
        for j in order:
            if row_of[j] == row and round(costs[j], 6) not in seen:
                chosen.append(j)
                seen.add(round(costs[j], 6))
                break
    for j in order:
        if len(chosen) >= max(1, n_starts):
            break
        if j not in chosen and round(costs[j], 6) not in seen:
            chosen.append(j)
            seen.add(round(costs[j], 6))
    polished = []
    for j in chosen[:max(1, n_starts)]:
        sol = least_squares(fun, candidates[j], bounds=(0.0, 1.0), method="trf",
                            diff_step=DIFF_STEP, max_nfev=POLISH_NFEV, x_scale=1.0,
                            ftol=LS_TOL, xtol=LS_TOL)
        polished.append(sol)
    polished.sort(key=lambda r: r.cost)
    best = None
    for pol in polished[:max(1, n_full)]:
        sol = least_squares(fun, pol.x, bounds=(0.0, 1.0), method="trf",
                            diff_step=DIFF_STEP, max_nfev=MAX_NFEV, x_scale=1.0, ftol=LS_TOL,
                            xtol=LS_TOL)
        if best is None or sol.cost < best.cost:
            best = sol
    if h.name != RECALIBRATION.name and any(specs[i].off is not None for i in own):
        # nesting guarantee: never end worse than the effect switched off
        cost_off = 0.5 * float(np.sum(fun(u_off) ** 2))
        if best.cost > cost_off:
            sol = least_squares(fun, u_off, bounds=(0.0, 1.0), method="trf",
                                diff_step=DIFF_STEP, max_nfev=MAX_NFEV, x_scale=1.0,
                                ftol=LS_TOL, xtol=LS_TOL)
            if sol.cost < best.cost:
                best = sol
    assert best is not None
    vals, shift = unpack(best.x)
    sims = problem.simulate(vals)
    res = problem.residual(vals, shift, sims)
    rss = float(np.sum(res**2))
    n, n_eff = problem.n, problem.n_eff
    k = n_p + 1
    # Gauss-Newton covariance in unit coordinates, inflated for correlated samples
    jac = best.jac
    s2 = rss / max(1, n - k)
    cov_u = np.linalg.pinv(jac.T @ jac) * s2 * (n / n_eff)
    unc: dict[str, float] = {}
    for i, s in enumerate(specs):
        dpdu = (s.hi - s.lo) if s.scale == "lin" else vals[s.name] * math.log(s.hi / s.lo)
        unc[s.name] = float(abs(dpdu) * math.sqrt(max(cov_u[i, i], 0.0)))
    at_bounds = [s.name for i, s in enumerate(specs) if best.x[i] < 1e-3 or best.x[i] > 1 - 1e-3]
    penalty = k * math.log(n_eff)
    bic = n_eff * math.log(max(rss, 1e-300) / n) + penalty
    aligned = problem.aligned(sims, shift)
    return FitResult(h.name, vals, unc, {s.name: s.unit for s in specs}, shift, rss, n, n_eff, k,
                     bic, penalty, problem.scores(aligned), aligned, at_bounds,
                     problem.calls - calls0)


def fit_variants(problem: FitProblem, h: Hypothesis, **kw) -> FitResult:
    """``fit_hypothesis`` for each discrete form of ``h`` (``Hypothesis.variants``; the form's
    fixed screening-model values are added to the problem's ``base_values``), the best by BIC
    kept, with ``ln(number of forms)`` added to its BIC and complexity penalty (the choice among
    equally probable forms costs that much evidence). Without variants: ``fit_hypothesis``."""
    if not h.variants:
        return fit_hypothesis(problem, h, **kw)
    base = dict(problem.base_values)
    best: FitResult | None = None
    evals = 0
    try:
        for var in h.variants:
            problem.base_values = {**base, **var.rom_values}
            r = fit_hypothesis(problem, h, **kw)
            evals += r.n_evals
            r.variant = var.label
            if best is None or r.bic < best.bic:
                best = r
    finally:
        problem.base_values = base
    assert best is not None
    best.form_penalty = math.log(len(h.variants))
    best.bic += best.form_penalty
    best.complexity_penalty += best.form_penalty
    best.n_evals = evals
    return best


def rank(results: list[FitResult]) -> list[FitResult]:
    """Order fitted hypotheses by BIC (lowest first)."""
    return sorted(results, key=lambda r: r.bic)
