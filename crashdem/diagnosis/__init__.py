"""Diagnosis of simulation-vs-test mismatch: locate it, name the missing physics, refit, report.

Three lines::

    from crashdem.diagnosis import diagnose, write_report
    rep = diagnose(baseline_signals, recording_signals)      # dict[str, Signal] each
    write_report(rep, "out/")                                 # report.json, report.md, PNGs

Flow of :func:`diagnose`
------------------------
1. noise of every recorded channel (pre-event MAD, ``mismatch.estimate_noise``);
2. mismatch windows between the baseline simulation and the recording (``mismatch``);
3. the screening model (default: the ROM, ``rom.RomSimulator``) is first calibrated to the
   *baseline simulation* (so the screening starts from what the simulation did, however it
   was produced), then the recalibration and every catalogue hypothesis are fitted to the
   recording (``fit``), ranked by BIC and accepted or not (``fit.ACCEPT_MARGIN``);
4. a :class:`Report` with the windows, ranked hypotheses, the accepted missing physics (or
   None) and the before/after fit.

:func:`screen_then_confirm` adds step 5: the top-k hypotheses are re-run with the expensive
simulator (the full DEM through a scenario), counting full simulations.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from crashdem.diagnosis import catalogue
from crashdem.diagnosis.catalogue import CATALOGUE, RECALIBRATION, Hypothesis, ParameterSpec
from crashdem.diagnosis.fit import (ACCEPT_MARGIN, MIN_SCORE_GAIN, PRE_ONSET, WITHIN_NOISE_RATIO,
                                    FitProblem, FitResult, event_window, fit_hypothesis,
                                    fit_variants, metric_name, rank, score_signals)
from crashdem.diagnosis.mismatch import (MismatchWindow, NoiseEstimate, align, estimate_noise,
                                         locate_mismatch, onset_time)
from crashdem.diagnosis.rom import ACCEL, PENETRATION, VELOCITY, RomParams, RomSettings, RomSimulator
from crashdem.diagnosis.rom_planar import PLANAR_CHANNELS, PlanarParams, PlanarSimulator
from crashdem.diagnosis import _dsp
from crashdem.diagnosis.filter_check import CLASSES as FILTER_CLASSES, filter_class_check
from crashdem.diagnosis.sensor_check import accel_velocity_check
from crashdem.signal import Signal

__all__ = ["Report", "confirm", "diagnose", "screen_then_confirm", "write_report", "catalogue",
           "CATALOGUE", "RECALIBRATION", "working_rate", "MAX_SAMPLE_RATE", "replicate_overrides"]

Simulator = Callable[[dict[str, Any]], Mapping[str, Signal]]

#: channels the default ROM can produce
ROM_CHANNELS = ("accel_z", "velocity_z")
#: a full simulation must raise the overall score over the baseline by this much to confirm
CONFIRM_MIN_GAIN = 0.02
#: two decisive full runs of different effects within this Delta BIC of each other are not
#: told apart (Kass & Raftery 1995: 0-2 is "not worth more than a bare mention"); neither is
#: named unless the screening claimed one of them
AMBIGUITY_MARGIN = 2.0
#: full-model search on a separate (cheaper) simulator: this many leading effects that beat
#: its baseline decisively are run with the full simulator
SEARCH_PROMOTE = 2
#: name of the replicate-realisation runs (the baseline with another packing seed) in the
#: confirmation table: they stand for no physics, only for the scatter of the realisation
REPLICATE = "replicate"
#: a decisive full run must beat the best replicate by this much in BIC (besides the reference
#: by ACCEPT_MARGIN): with R replicates, a run that fits better than every one of them is an
#: outlier of the realisation scatter at about 1 / (R + 1) (exchangeability); measured on the
#: 28 searched DEM / Yade / raw-Yade cases with 4 replicates: a floor of Delta BIC 0-57
#: (median 12); 10 on top of it would drop 2 of the 16 named effects (a damping and a floor
#: beating it by 2.0 / 2.4) and prevent no wrong claim, see docs/diagnosis.md
REALISATION_MARGIN = 0.0


def replicate_overrides(seed: int, n: int) -> list[dict[str, Any]]:
    """Overrides of ``n`` replicate realisations of a baseline whose packing seed is ``seed``:
    ``scenario.seed`` = seed + 1 ... seed + n (``screen_then_confirm``'s ``replicates``)."""
    return [{"scenario.seed": int(seed) + i} for i in range(1, int(n) + 1)]

#: a measured impact-speed offset of at least this many standard deviations is model-free
#: evidence for ``initial_conditions`` (like the sensor check): the claim stands whatever the
#: soil model's realisation scatter
SPEED_CHECK_SIGMAS = 5.0
#: weighted residual RMS [sigma] left by the accepted effect above which combinations of two
#: effects are tried (single-effect fits of the validation end below 3 sigma: model error)
SECOND_STAGE_RMS = 4.0
#: a second effect must leave at most this fraction of the first effect's residual RMS
#: (measured: a true second effect (drop ROM truth, layering + floor) 0.09; nuisance pairs on
#: glider truth with another nose radius and accelerometer position 0.66-0.96)
SECOND_EFFECT_RMS_RATIO = 0.5
#: how the baseline anchor indexes the discrepancy (baseline - calibrated screening model):
#: "time" transfers it to a hypothesis at the same time; "depth" at the same tip depth of the
#: screening model (``_depth_index``: the discrepancy of a granular bed belongs to its layers,
#: and an effect that stops the impactor earlier does not inherit the baseline's late tail).
#: Measured on the 14 DEM-truth cases (docs/diagnosis.md): "depth" names no additional effect
#: (floor proximity and cohesion still unclaimed, Delta BIC < 0) and moves the speed-offset
#: recovery from +1.6/+14.7 % to -11.5/+13.1 %, so "time" stays the default
ANCHOR_INDEX = "time"
#: timing uncertainty of the acceleration onset used to extrapolate the free-fall velocity to
#: the contact [s] (measured: the extrapolated impact speed of 7 DEM and Yade recordings within
#: 0.06 m/s of the truth, i.e. ~6 ms x g)
IMPACT_ONSET_TIMING = 0.006
#: residual RMS [sigma] after the final fit above which the report warns of model-form error
MODEL_ERROR_RMS = 3.0


@dataclass
class Report:
    """Result of a diagnosis (``to_dict`` is what ``report.json`` holds)."""

    channels: list[str]
    noise: dict[str, NoiseEstimate]
    mismatch: list[MismatchWindow]
    hypotheses: list[dict[str, Any]]
    missing_physics: str | None
    best: str | None
    fit: dict[str, Any]
    simulations: dict[str, Any]
    decision: str
    recording: dict[str, Signal] = field(repr=False, default_factory=dict)
    baseline: dict[str, Signal] = field(repr=False, default_factory=dict)
    refitted: dict[str, Signal] = field(repr=False, default_factory=dict)
    fits: dict[str, FitResult] = field(repr=False, default_factory=dict)
    after_mismatch: list[MismatchWindow] = field(default_factory=list)
    #: the hypothesis set of the screening model (drop or planar)
    catalogue: catalogue.Catalogue = field(repr=False, default=catalogue.DROP)

    def to_dict(self) -> dict[str, Any]:
        """Everything ``report.json`` holds (signals excluded)."""
        return {
            "channels": self.channels,
            "noise": {ch: {"sigma": n.sigma, "unit": n.unit, "method": n.method,
                           "window_s": list(n.window) if n.window else None}
                      for ch, n in self.noise.items()},
            "mismatch": [w.to_dict() for w in self.mismatch],
            "hypotheses": self.hypotheses,
            "missing_physics": self.missing_physics,
            "best": self.best,
            "decision": self.decision,
            "fit": self.fit,
            "remaining_mismatch": [w.to_dict() for w in self.after_mismatch],
            "simulations": self.simulations,
            "catalogue": self.catalogue.describe(),
            "catalogue_model": self.catalogue.model,
            "catalogue_not_represented": self.catalogue.excluded,
        }


def _si(signals: Mapping[str, Signal]) -> dict[str, Signal]:
    return {k: s.to_si() for k, s in signals.items()}


#: relative deviation of a sample interval from the median above which a channel counts as
#: non-uniformly sampled (float rounding of printed times stays far below)
UNIFORM_TOLERANCE = 1.0e-3


def _uniform(signals: Mapping[str, Signal]) -> tuple[dict[str, Signal], dict[str, Any]]:
    """Channels on uniform time grids: a non-uniformly sampled channel (another code's output
    at variable steps) is linearly interpolated at its median rate, since the filters, spectra
    and noise estimates of the diagnosis assume uniform sampling. Returns the channels and
    ``{name: {"from_samples", "to_samples", "rate_hz", "max_interval_deviation"}}``."""
    out, info = {}, {}
    for k, s in signals.items():
        dt = np.diff(s.t)
        if dt.size < 2:
            out[k] = s
            continue
        med = float(np.median(dt))
        dev = float(np.max(np.abs(dt - med))) / med
        if dev <= UNIFORM_TOLERANCE:
            out[k] = s
            continue
        n = int(math.floor((s.t[-1] - s.t[0]) / med)) + 1
        t = s.t[0] + med * np.arange(n)
        out[k] = Signal(s.name, t, np.interp(t, s.t, s.data), s.unit, s.cfc,
                        {**s.meta, "resampled": f"non-uniform -> {1.0 / med:.6g} Hz"})
        info[k] = {"from_samples": int(s.t.size), "to_samples": int(n), "rate_hz": 1.0 / med,
                   "max_interval_deviation": dev}
    return out, info


#: highest sample rate the diagnosis works at [Hz]: the screening models integrate at
#: ``RomSettings.dt`` = 20 us and sample at most every second step (25 kHz; 20 kHz keeps a
#: margin). A recording sampled faster (a DEM code's output every few steps, a 100 kHz+
#: acquisition) is decimated to ``fs / ceil(fs / MAX_SAMPLE_RATE)``; J211 asks for 10 x CFC,
#: i.e. 10 kHz for CFC 1000
MAX_SAMPLE_RATE = 20_000.0


def working_rate(signals: Mapping[str, Signal]) -> tuple[dict[str, Signal], dict[str, Any]]:
    """Channels sampled above ``MAX_SAMPLE_RATE`` decimated by the smallest integer factor q
    that brings them to or below it (``scipy.signal.resample_poly``: zero-phase Kaiser FIR
    anti-aliasing; the record's ends are padded along their line, so a free-fall ramp keeps no
    edge transient). Others are returned unchanged. Returns the channels and
    ``{name: {"from_rate_hz", "to_rate_hz", "factor"}}``."""
    from scipy.signal import resample_poly

    out, info = {}, {}
    for k, s in signals.items():
        if s.t.size < 3 or s.fs <= MAX_SAMPLE_RATE * (1.0 + UNIFORM_TOLERANCE):
            out[k] = s
            continue
        q = int(math.ceil(s.fs / MAX_SAMPLE_RATE - UNIFORM_TOLERANCE))
        y = resample_poly(s.data, 1, q, padtype="line")
        t = s.t[::q][: y.size]
        out[k] = Signal(s.name, t, y[: t.size], s.unit, s.cfc,
                        {**s.meta, "decimated": f"{s.fs:.6g} Hz / {q}"})
        info[k] = {"from_rate_hz": float(s.fs), "to_rate_hz": float(s.fs) / q, "factor": q}
    return out, info


def _noise_in_window(sig: Signal, quiet: tuple[float, float] | None) -> NoiseEstimate:
    """Noise of a channel over the primary channel's quiet window (its own when there is none
    or the window does not fit the channel)."""
    if quiet:
        try:
            return estimate_noise(sig, quiet=quiet)
        except ValueError:
            pass
    return estimate_noise(sig)


def _evidence(h: Hypothesis, res: FitResult, before: list[MismatchWindow],
              after: list[MismatchWindow], base_rms: float) -> str:
    """One sentence saying what the fitted hypothesis changes."""
    fixed = [w for w in before if not any(
        a.channel == w.channel and a.t_end_s >= w.t_start_s and a.t_start_s <= w.t_end_s
        for a in after)]
    own = ", ".join(f"{p.name} = {res.parameters[p.name]:.3g} {p.unit}" for p in h.parameters) \
        if res.variant != FILTER_CLASS_VARIANT else \
        f"the baseline re-filtered at CFC {res.parameters['filter_class']:g}"
    if fixed:
        f = max(fixed, key=lambda w: w.max_residual_sigma)
        what = f.feature.replace("_", " ")
        tf = f.feature_time_s if f.feature_time_s is not None else 0.5 * (f.t_start_s + f.t_end_s)
        verb = {"missing_peak": "adds the missing peak", "extra_peak": "removes the extra peak"}.get(
            f.feature, f"removes the '{what}' mismatch")
        txt = f"{verb} at {tf * 1e3:.1f} ms on {f.channel}"
    else:
        txt = "removes no mismatch window"
    return (f"{txt}; residual {base_rms:.2g} -> {res.rms_sigma:.2g} sigma RMS"
            + (f" with {own}" if own else "") + ".")


def _residual_correlation(res: np.ndarray) -> float:
    """Integral correlation length of a residual in samples, ``1 + 2 sum rho_k`` (sum to the
    first non-positive autocorrelation; Bendat & Piersol, *Random Data*, section 8.2)."""
    r = res - np.mean(res)
    var = float(np.dot(r, r))
    if var <= 0.0:
        return 1.0
    tau = 1.0
    for k in range(1, r.size // 2):
        rho = float(np.dot(r[:-k], r[k:])) / var
        if rho <= 0.0:
            break
        tau += 2.0 * rho
    return tau


#: the screening model's calibration to the baseline simulation: the recalibration scales with
#: ranges wide enough for a simulator of another resolution or code (a coarse DEM bed behaves
#: like a nearly strength-less, drag-dominated medium: strength x0.05, drag x1.6 for the
#: small-resolution drop bed); what remains is counted as model error (``_model_error``)
BASELINE_CALIBRATION = Hypothesis(
    "baseline_calibration", "screening-model calibration to the baseline simulation",
    tuple(replace(p, lo=0.05, hi=20.0) for p in RECALIBRATION.parameters),
    None, (), RECALIBRATION.to_scenario)


def _fit_fixed(problem: FitProblem, h: Hypothesis, fixed: Mapping[str, float],
               uncertainty: Mapping[str, float], recal: FitResult,
               variant: str | None = None) -> FitResult:
    """Hypothesis ``h`` with its own parameters *measured* outside the soil-model fit (``fixed``
    ROM values, ``uncertainty`` of the reported ones): the recalibration is refitted with them;
    the measured parameters still count in ``k``."""
    base = dict(problem.base_values)
    problem.base_values = {**base, **fixed}
    try:
        r = fit_hypothesis(problem, RECALIBRATION, start=recal.parameters, grid_points=1,
                           n_starts=1)
    finally:
        problem.base_values = base
    r.hypothesis = h.name
    r.variant = variant
    for p in h.parameters:
        r.parameters[p.name] = float(fixed[p.name])
        r.uncertainty[p.name] = float(uncertainty[p.name])
        r.units[p.name] = p.unit
    r.k += len(h.parameters)
    r.form_penalty = math.log(len(h.variants)) if (variant is not None and h.variants) else 0.0
    r.complexity_penalty = r.k * math.log(r.n_eff) + r.form_penalty
    r.bic = r.n_eff * math.log(max(r.rss, 1e-300) / r.n) + r.complexity_penalty
    return r


def _fit_checked_sensor(problem: FitProblem, h: Hypothesis, check: Mapping[str, Any],
                        recal: FitResult) -> FitResult:
    """The ``sensor_dynamics`` fit when the model-free sensor check found the sensor: the form,
    frequency and damping are the check's (fixed), the recalibration is refitted with them."""
    fixed = {"mount_frequency": float(check["mount_frequency"]),
             "mount_damping": float(check["mount_damping"]),
             "mount_form": float(check["form"] == "mount")}
    return _fit_fixed(problem, h, fixed, check["uncertainty"], recal, str(check["form"]))


#: label of the ``sensor_dynamics`` form "the recording was filtered with another CFC class"
FILTER_CLASS_VARIANT = "filter_class"


#: a channel filtered at CFC c has at most this fraction of its event power above
#: ``BAND_TEST_FACTOR`` x c (measured, noise-free: CFC 60 ROM and DEM channels 1.4e-9-1.3e-8;
#: CFC 180 4e-6-4e-5, unfiltered ROM / DEM / Yade output 7e-5-4e-4 above 400 Hz)
BAND_TEST_FRACTION = 1.0e-6
#: the band test's lower frequency as a multiple of the class (6.67 x CFC = 4 x its -3 dB
#: frequency of ~1.67 x CFC, where the 4-pole J211 response is below 1e-4 in power)
BAND_TEST_FACTOR = 6.67


def _power_above(sig: Signal, f0: float, t_from: float) -> float | None:
    """Fraction of a channel's power above ``f0`` [Hz] from ``t_from`` on (Hann periodogram);
    None when ``f0`` is beyond 0.9 x Nyquist or the segment is too short."""
    from scipy import signal as sps

    m = sig.t >= t_from
    if m.sum() < 64 or f0 >= 0.45 * sig.fs:
        return None
    f, p = sps.periodogram(sig.data[m], fs=sig.fs, window="hann", detrend="constant")
    tot = float(np.sum(p))
    return float(np.sum(p[f > f0]) / tot) if tot > 0.0 else None


def _filter_class_stage(rec: dict[str, Signal], base: dict[str, Signal],
                        base_raw: Mapping[str, Signal] | None, channels: list[str],
                        noise: Mapping[str, NoiseEstimate], accept_margin: float,
                        shift: float = 0.0, t_quiet_end: float | None = None
                        ) -> tuple[dict[str, Signal], dict[str, Signal], dict[str, Any]]:
    """Filter class of each recorded channel (declared, or read from its pre-event noise
    spectrum: ``filter_check``) against the baseline's; where they differ the baseline is
    re-filtered at the recording's class (from its raw channel when given, else -- only to a
    lower class -- from its filtered one), so that everything after compares like with like.

    A recording that declares no class and holds no noise to read one from (noise at the
    acquisition floor: a simulation's output) is tested on its event instead: more than
    ``BAND_TEST_FRACTION`` of its power above ``BAND_TEST_FACTOR`` x the baseline's class means
    it was not filtered at that class (raw output, or a wider class); it is then filtered at
    the baseline's class for the comparison (processing, not a finding), else taken to be at it.

    Returns the recording (``cfc`` set to the class used), the baseline to diagnose on, and
    ``{"channels": {ch: check + class_used, source, baseline_class, refilter}, "mismatch",
    "class", "delta_bic", "recording_filtered"}``."""
    rec2, base2 = dict(rec), dict(base)
    quiet = noise[channels[0]].window
    if quiet is not None and t_quiet_end is not None:  # never past the event onset
        quiet = (quiet[0], min(quiet[1], t_quiet_end))
        if quiet[1] <= quiet[0]:
            quiet = None
    per: dict[str, Any] = {}
    mism, classes, evidence, rec_filtered = False, [], 0.0, []
    for ch in channels:
        r = rec[ch]
        if "below the floor" in noise[ch].method:
            chk = {"applicable": False, "declared": r.cfc,
                   "reason": "noise at the acquisition floor (a noise-free record)"}
        else:
            chk = filter_class_check(r, quiet, declared=r.cfc, accept_margin=accept_margin)
        used, how = r.cfc, "declared by the recording"
        b = base[ch].cfc
        if r.cfc is None and not chk.get("applicable") and b is not None:
            t_on = float(base[ch].t[0]) + shift
            frac = _power_above(r, BAND_TEST_FACTOR * float(b), t_on)
            chk["event_power_above"] = {"f_hz": BAND_TEST_FACTOR * float(b), "fraction": frac}
            if frac is not None and frac > BAND_TEST_FRACTION:
                rec2[ch] = Signal(r.name, r.t, _dsp.cfc(r.data, r.fs, float(b)), r.unit, float(b),
                                  {**r.meta, "filtered_by_diagnosis": f"CFC {float(b):g}"})
                rec_filtered.append(ch)
                per[ch] = {**chk, "class_used": float(b), "baseline_class": b, "refilter": None,
                           "source": (f"no class declared, no noise to read one from, event "
                                      f"power above {BAND_TEST_FACTOR * float(b):.0f} Hz "
                                      f"{frac:.1e} > {BAND_TEST_FRACTION:g}: unfiltered or a "
                                      f"wider class; filtered at the baseline's CFC {float(b):g} "
                                      "for the comparison")}
                continue
            if frac is not None:
                used, how = float(b), (f"no class declared, no noise to read one from; event "
                                       f"power above {BAND_TEST_FACTOR * float(b):.0f} Hz "
                                       f"{frac:.1e} <= {BAND_TEST_FRACTION:g}: taken as the "
                                       f"baseline's CFC {float(b):g}")
        if chk.get("applicable") and chk["decisive"]:
            if r.cfc is None:
                used, how = chk["measured"], "measured (the recording declares none)"
            elif chk["contradicts_declared"]:
                used, how = chk["measured"], (f"measured (the recording declares CFC "
                                              f"{r.cfc:g}, its noise spectrum says otherwise)")
        if used != r.cfc:
            rec2[ch] = replace(r, cfc=used)
        entry = {**chk, "class_used": used, "source": how, "baseline_class": b,
                 "refilter": None}
        if used is not None and b is None:
            # an unfiltered baseline (raw simulation output) is compared at the recording's
            # class: processing, not a mismatch of the simulation
            bs = base[ch]
            base2[ch] = Signal(bs.name, bs.t.copy(), _dsp.cfc(bs.data, bs.fs, float(used)),
                               bs.unit, float(used),
                               {**bs.meta, "refiltered": f"raw -> CFC {float(used):g}"})
            entry["refilter"] = "unfiltered baseline filtered at the recording's class"
        elif used is not None and b is not None and not math.isclose(float(used), float(b)):
            raw = (base_raw or {}).get(ch)
            bs = base[ch]
            if raw is not None:
                rs = raw.to_si()
                data, how_f, t = _dsp.cfc(rs.data, rs.fs, float(used)), "from the raw channel", rs.t
            elif float(used) < float(b):
                data, how_f, t = _dsp.cfc(bs.data, bs.fs, float(used)), \
                    "from the filtered channel (lower class)", bs.t
            else:
                data, how_f, t = None, None, None
            if data is not None:
                base2[ch] = Signal(bs.name, t.copy(), data, bs.unit, float(used),
                                   {**bs.meta, "refiltered": f"CFC {b:g} -> {used:g} {how_f}"})
            entry["refilter"] = how_f or (f"not possible: a CFC {b:g} channel cannot be turned "
                                          f"into CFC {used:g} without its raw data")
            mism = True
            classes.append(float(used))
            if chk.get("applicable") and chk.get("measured") == used:
                evidence += chk["bic"].get(f"{float(b):g}", 0.0) - chk["bic"][f"{float(used):g}"]
        per[ch] = entry
    return rec2, base2, {"channels": per, "mismatch": mism,
                         "class": classes[0] if classes else None,
                         "delta_bic": evidence if evidence > 0 else None,
                         "recording_filtered": rec_filtered}


#: cosine similarity (recording vs baseline over the event) below which a channel is read as
#: recorded with the opposite sign convention (z down, deceleration negative, ...) -- flipped
#: only when the flipped channel then agrees as well (cosine above minus this)
SIGN_FLIP_COSINE = -0.5


def _sign_convention(rec: dict[str, Signal], base: dict[str, Signal], channels: list[str],
                     shift: float, t_on: float) -> tuple[dict[str, Signal], dict[str, Any]]:
    """Channels recorded with the opposite sign convention, turned to the simulation's.

    Over the event (from the onset ``t_on`` to the end of the baseline), the cosine similarity
    ``sum(r b) / sqrt(sum r^2 sum b^2)`` of the recording ``r`` and the aligned baseline ``b``
    is close to +1 for the same convention (deceleration and velocity alike: not
    mean-removed, so the free-fall velocity counts) and close to -1 for the opposite one; a
    channel is flipped when it is below ``SIGN_FLIP_COSINE``. Returns the recording and
    ``{ch: {"cosine", "flipped"}}``."""
    out, info = dict(rec), {}
    for ch in channels:
        r, b = rec[ch], base[ch]
        m = (r.t >= t_on) & (r.t <= float(b.t[-1]) + shift)
        if m.sum() < 8:
            continue
        x = r.data[m]
        y = np.interp(r.t[m], b.t + shift, b.data)
        den = math.sqrt(float(np.dot(x, x)) * float(np.dot(y, y)))
        cos = float(np.dot(x, y)) / den if den > 0.0 else 0.0
        flip = cos < SIGN_FLIP_COSINE
        info[ch] = {"cosine": cos, "flipped": bool(flip)}
        if flip:
            out[ch] = Signal(r.name, r.t, -r.data, r.unit, r.cfc,
                             {**r.meta, "sign": "flipped to the simulation's convention"})
    return out, info


def measured_impact_speed(acc: Signal | None, vel: Signal, noise_vel: NoiseEstimate,
                          sigma_acc: float, gravity: float = 9.81) -> dict[str, Any] | None:
    """Impact speed read from the recording's free-fall velocity before the onset.

    Before contact ``v_z(t) = -v_imp - g (t - t_on)``: the mean of ``v_z + g (t - t_on)`` over
    the quiet pre-event segment (ending ``PRE_ONSET`` before the acceleration onset ``t_on``;
    without an acceleration channel, the onset of the velocity's derivative) is ``-v_imp``.
    Uncertainty: the velocity noise over the segment's independent samples and the onset timing
    (``IMPACT_ONSET_TIMING`` x g). None without a quiet segment of 8 samples.
    """
    v_s = vel.to_si()
    a_s = acc.to_si() if acc is not None else v_s
    t_on = onset_time(a_s, sigma_acc if acc is not None else noise_vel.sigma)
    w = v_s.t <= t_on - PRE_ONSET
    if noise_vel.window:
        w &= v_s.t >= noise_vel.window[0]
    how = "pre-event segment"
    if w.sum() < 8 and a_s.cfc is None and v_s.cfc is None:
        # unfiltered channels (a simulation's output starting just before contact): nothing
        # smears the contact backwards, every sample before the onset is free fall
        w = v_s.t < t_on
        how = "unfiltered samples before the onset"
    if w.sum() < 1 or (how == "pre-event segment" and w.sum() < 8):
        return None
    c = float(np.mean(v_s.data[w] + gravity * (v_s.t[w] - t_on)))
    n_eff = _dsp.effective_samples(int(w.sum()), v_s.fs, v_s.cfc)
    sig = math.hypot(noise_vel.sigma / math.sqrt(max(n_eff, 1.0)), gravity * IMPACT_ONSET_TIMING)
    return {"impact_speed": -c, "sigma": sig, "onset_s": t_on, "samples": int(w.sum()),
            "segment": how}


def _residual_n_eff(problem: FitProblem, res: FitResult) -> float:
    """Independent samples of a fit's weighted residual over the event window: per channel
    ``N / tau`` with ``tau`` the integral correlation length in samples
    (``_residual_correlation``), summed over the channels."""
    n = 0.0
    for ch in problem.channels:
        rec = problem.recording[ch]
        idx = np.flatnonzero(rec.t >= problem.t0)
        r = (res.aligned[ch].data[idx] - rec.data[idx]) * problem.weights[ch]
        n += max(1.0, idx.size / _residual_correlation(r))
    return float(n)


def _requalify(results: list[FitResult], n_eff: float) -> None:
    """Recompute BIC, complexity penalty and uncertainties of fitted hypotheses for a smaller
    number of independent samples ``n_eff`` (same RSS)."""
    for r in results:
        f = math.sqrt(r.n_eff / n_eff) if n_eff < r.n_eff else 1.0
        r.uncertainty = {k: v * f for k, v in r.uncertainty.items()}
        r.n_eff = n_eff
        r.complexity_penalty = r.k * math.log(n_eff) + r.form_penalty
        r.bic = n_eff * math.log(max(r.rss, 1e-300) / r.n) + r.complexity_penalty


def _calibrate_rom(baseline: dict[str, Signal], noise: dict[str, NoiseEstimate],
                   channels: list[str], rom: RomSimulator) -> tuple[dict[str, float], float]:
    """Recalibration scales making the ROM reproduce the baseline simulation."""
    t0 = onset_time(baseline[channels[0]], noise[channels[0]].sigma) - PRE_ONSET
    problem = FitProblem(baseline, noise, channels, rom, {}, 0.0, t0)
    res = fit_hypothesis(problem, BASELINE_CALIBRATION, with_recal=False, grid_points=1, n_starts=1)
    return res.parameters, res.shift_s


def _discrepancy(baseline: dict[str, Signal], rom_cal: Mapping[str, Signal], shift: float,
                 channels: list[str]) -> dict[str, Signal]:
    """Baseline simulation minus the calibrated screening model, on the screening model's time
    axis (zero before the baseline's first sample: both are in free fall there; held after its
    last one)."""
    out = {}
    for ch in channels:
        r, b = rom_cal[ch], baseline[ch]
        tb = r.t + shift
        d = np.interp(tb, b.t, b.data) - r.data
        d[tb < b.t[0]] = 0.0
        out[ch] = Signal(ch, r.t.copy(), d, r.unit, r.cfc, {"source": "baseline - calibrated ROM"})
    return out


def _depth_index(t: np.ndarray, z_h: np.ndarray, z_c: np.ndarray) -> np.ndarray:
    """Times of the calibrated screening run at which it had the state of the hypothesis run.

    While the hypothesis run penetrates (up to its deepest point) the index is the time at
    which the calibrated run reached the same tip depth ``z_h(t)`` (the calibrated run's
    loading branch, made monotone); deeper than the calibrated run ever went, and after the
    hypothesis run's deepest point, the index advances with time from the last matched point.
    Before contact (depth 0) it is the time itself. Both runs share the time axis ``t``
    (0 = first contact)."""
    tau = np.array(t, dtype=float)
    i_c = int(np.argmax(z_c))
    i_h = int(np.argmax(z_h))
    if i_c < 1 or i_h < 1 or z_c[i_c] <= 0.0:
        return tau
    zc = np.maximum.accumulate(z_c[:i_c + 1])
    keep = np.concatenate(([True], np.diff(zc) > 0.0))  # strictly increasing abscissa
    zc, tc = zc[keep], t[:i_c + 1][keep]
    load = (np.arange(t.size) <= i_h) & (z_h > 0.0)
    tau[load] = np.interp(z_h[load], zc, tc)
    deeper = np.flatnonzero(load & (z_h > zc[-1]))
    if deeper.size:
        tau[deeper] = tc[-1] + (t[deeper] - t[deeper[0]])
    after = np.arange(t.size) > i_h
    tau[after] = tau[i_h] + (t[after] - t[i_h])
    return tau


def _model_error(disc: Mapping[str, Signal], shift: float, t0: float, t1: float,
                 noise: Mapping[str, NoiseEstimate]) -> dict[str, tuple[float, float]]:
    """Model-error floor per channel from the discrepancy between the baseline simulation and
    the calibrated screening model over the event window [t0, t1] (baseline time): its RMS
    [channel unit] and its integral correlation length [s].

    Rationale: what the screening model cannot reproduce of the baseline simulation (granular
    force fluctuations of a DEM, shape details) is model-form error of the same kind and size
    that separates the baseline from a recording made by other numerics or another code; it is
    counted as correlated error, not as evidence (cf. Kennedy & O'Hagan 2001, model discrepancy).
    """
    out = {}
    for ch, d in disc.items():
        tb = d.t + shift
        m = (tb >= t0) & (tb <= t1)
        if m.sum() < 8:
            continue
        x = d.data[m] - float(np.mean(d.data[m]))
        rms = float(np.sqrt(np.mean(x**2)))
        if rms <= noise[ch].sigma:  # the screening model reproduces the baseline within noise
            continue
        tau = _residual_correlation(x) / d.fs
        out[ch] = (rms, tau)
    return out


def diagnose(baseline_signals: Mapping[str, Signal], recording_signals: Mapping[str, Signal], *,
             channels: Sequence[str] | None = None, simulator: Simulator | None = None,
             rom_base: RomParams | None = None, hypotheses: Sequence[str] | None = None,
             noise: Mapping[str, NoiseEstimate] | None = None,
             calibrate_to_baseline: bool = True, anchor_to_baseline: bool = True,
             accept_margin: float = ACCEPT_MARGIN, anchor_index: str = ANCHOR_INDEX,
             impact_speed: float | None = None,
             baseline_raw: Mapping[str, Signal] | None = None,
             catalog: catalogue.Catalogue | None = None) -> Report:
    """Locate the mismatch, fit every hypothesis, decide the missing physics.

    Parameters
    ----------
    baseline_signals : the simulation being questioned (any producer: ROM, full DEM, other code)
    recording_signals : the test channels (SI or convertible units; CFC in ``Signal.cfc``)
    channels : channels to diagnose (default: those present in both, among what the screening
        simulator produces)
    simulator : screening simulator ``f(params: dict) -> dict[str, Signal]`` taking the ROM
        parameter names of ``catalogue`` (default: ``rom.RomSimulator`` on ``rom_base`` with the
        recording's sample rate, CFC and span)
    rom_base : baseline ROM parameters (default ``RomParams()``: the 850 kg sphere drop); a
        ``rom_planar.PlanarParams`` screens with the planar (glider) model and its catalogue
        (``catalogue.planar_catalogue``; channels ``accel_x``, ``accel_z``, ``pitch_rate``)
    hypotheses : catalogue names to try (default: all)
    noise : noise estimates per channel (default: estimated from the recording)
    calibrate_to_baseline : first refit the screening model's calibration to the baseline
        simulation (disable when ``simulator`` already *is* the baseline model)
    anchor_to_baseline : with ``calibrate_to_baseline``, predict every hypothesis as the baseline
        simulation plus the screening model's change (``baseline + ROM(h) - ROM(calibrated)``)
        and count what the screening model cannot reproduce of the baseline as a correlated
        model-error floor (``fit.FitProblem.model_error``)
    accept_margin : Delta BIC needed over the recalibration to claim missing physics
    impact_speed : the baseline simulation's impact speed [m/s] (the CLI passes the
        scenario's); with it and a recorded ``velocity_z`` holding a free-fall segment, the
        ``initial_conditions`` speed offset is *measured* (``measured_impact_speed``: recorded
        minus this) instead of fitted. Default: ``rom_base.v0`` when ``rom_base`` is given, else
        not measured
    anchor_index : ``"time"`` (default ``ANCHOR_INDEX``): the discrepancy is transferred to a
        hypothesis at the same time; ``"depth"``: at the same tip depth of the screening model
        (``_depth_index``; an effect that stops the impactor earlier or lets it go deeper takes
        the baseline's discrepancy of that depth, not of that time). ``"depth"`` needs a
        ``penetration`` channel from the screening model (the ROM has one), else falls back
        to time
    baseline_raw : the baseline's unfiltered channels (same names), used to re-filter the
        baseline when the recording was filtered with another CFC class (``filter_check``);
        without them only a lower class can be matched
    catalog : the hypothesis set (default: the ``simulator``'s ``catalogue`` attribute, else
        the drop catalogue, or ``catalogue.planar_catalogue(rom_base)`` for a planar
        ``rom_base``)

    Returns
    -------
    Report
    """
    t_start = time.perf_counter()
    if anchor_index not in ("time", "depth"):
        raise ValueError(f"anchor_index={anchor_index!r}: must be 'time' or 'depth'")
    rec, resampled = _uniform(_si(recording_signals))
    rec, decimated = working_rate(rec)
    base = _si(baseline_signals)
    planar = simulator is None and isinstance(rom_base, PlanarParams)
    if catalog is not None:
        cat = catalog
    elif simulator is not None:
        cat = getattr(simulator, "catalogue", None) or catalogue.DROP
    else:
        cat = catalogue.planar_catalogue(rom_base) if planar else catalogue.DROP
    if channels is None:
        model_channels = PLANAR_CHANNELS if planar else ROM_CHANNELS
        channels = [c for c in model_channels if c in rec and c in base] if simulator is None \
            else [c for c in rec if c in base]
    channels = list(channels)
    for ch in channels:
        if ch not in rec or ch not in base:
            raise ValueError(f"channel {ch!r}: must be in both the recording ({sorted(rec)}) and "
                             f"the baseline ({sorted(base)})")
    if not channels:
        raise ValueError("diagnose: no channel common to the recording and the baseline")
    primary = channels[0]
    if noise is None:
        # the primary (first) channel locates the quiet pre-event window; the other channels use
        # the same window (a slowly varying channel such as a velocity shows its onset late)
        noise = {primary: estimate_noise(rec[primary])}
        for ch in channels[1:]:
            noise[ch] = _noise_in_window(rec[ch], noise[primary].window)
    noise = dict(noise)
    sigma_p = noise[primary].sigma
    shift0 = onset_time(rec[primary], sigma_p) - onset_time(base[primary], 0.0)
    t0 = onset_time(rec[primary], sigma_p) - PRE_ONSET
    rec, signs = _sign_convention(rec, base, channels, shift0, t0)
    # the filter class of the recording against the baseline's: from here on both are compared
    # at the recording's class; "before" (mismatch windows, score) is the baseline as the user
    # has it against the recording as processed here
    base_user = base
    rec_given, noise_given = dict(rec), dict(noise)  # before any filtering by the diagnosis
    rec, base, fclass = _filter_class_stage(
        rec, base, _si(baseline_raw) if baseline_raw else None, channels, noise, accept_margin,
        shift0, t0)
    for ch in fclass["recording_filtered"]:  # noise of a channel filtered here
        noise[ch] = _noise_in_window(rec[ch], noise[primary].window)
    windows: list[MismatchWindow] = []
    for ch in channels:
        windows += locate_mismatch(rec[ch], base_user[ch], noise[ch], shift=shift0)
    base_aligned = {ch: align(rec[ch], base_user[ch], shift0) for ch in channels}
    filter_found = bool(fclass["mismatch"]) and "sensor_dynamics" in (
        list(hypotheses) if hypotheses is not None else list(cat.names))

    rom_calls0 = 0
    if simulator is None:
        fs = rec[primary].fs
        settings = RomSettings(t_pre=max(0.0, -float(rec[primary].t[0] - shift0)) + 0.005,
                               t_end=float(rec[primary].t[-1] - shift0) + 0.01,
                               sample_rate=fs, cfc=rec[primary].cfc)
        simulator = PlanarSimulator(rom_base, settings, cat) if planar else \
            RomSimulator(rom_base or RomParams(), settings)
    base_values: dict[str, float] = {}
    disc: dict[str, Signal] = {}
    depth_cal: Signal | None = None
    model_err: dict[str, tuple[float, float]] = {}
    if calibrate_to_baseline:
        base_values, cal_shift = _calibrate_rom(base, noise, channels,
                                                simulator)  # type: ignore[arg-type]
        if anchor_to_baseline:
            # screening predictions are anchored on the baseline simulation: hypothesis h
            # predicts baseline + (ROM(h) - ROM(calibrated)), so the screening model only has
            # to get the *change* an effect makes right, not the baseline's own shape
            cal = simulator(dict(base_values))
            disc = _discrepancy(base, cal, cal_shift, channels)
            if anchor_index == "depth" and PENETRATION in cal:
                depth_cal = cal[PENETRATION]
            tb0 = onset_time(base[primary], noise[primary].sigma) - PRE_ONSET
            tb1 = event_window(base[primary], tb0)[1]
            model_err = _model_error(disc, cal_shift, tb0, tb1, noise)
        rom_calls0 = getattr(simulator, "calls", 0)

    class _Scaled:
        """Compose the calibration scales with the fitted recalibration scales; add the
        baseline anchor (discrepancy) when there is one."""

        def __init__(self, inner, scales, disc, depth_cal=None):
            self.inner, self.scales, self.disc, self.calls = inner, scales, disc, 0
            self.depth_cal = depth_cal  # calibrated run's tip depth (depth-indexed anchor)

        def __call__(self, values):
            self.calls += 1
            v = dict(values)
            for k, s in self.scales.items():
                v[k] = v.get(k, 1.0) * s
            out = self.inner(v)
            if not self.disc:
                return out
            out = dict(out)
            tau = None
            zc = self.depth_cal
            if zc is not None and PENETRATION in out and out[PENETRATION].t.shape == zc.t.shape \
                    and np.array_equal(out[PENETRATION].t, zc.t):
                tau = _depth_index(zc.t, out[PENETRATION].data, zc.data)
            for ch, d in self.disc.items():
                o = out[ch]
                if tau is not None and o.t.shape == zc.t.shape and np.array_equal(o.t, zc.t):
                    add = np.interp(tau, d.t, d.data)
                else:
                    add = d.data if (o.t.shape == d.t.shape and np.array_equal(o.t, d.t)) else \
                        np.interp(o.t, d.t, d.data)
                out[ch] = Signal(o.name, o.t, o.data + add, o.unit, o.cfc, o.meta)
            return out

    sim = _Scaled(simulator, base_values, disc, depth_cal)
    problem = FitProblem(rec, noise, channels, sim, {}, shift0, t0, model_error=model_err)
    base_scores = problem.scores(base_aligned)
    base_res = np.concatenate([((base_aligned[ch].data - rec[ch].data) / noise[ch].sigma)[problem.masks[ch]]
                               for ch in channels])
    base_rms = float(np.sqrt(np.mean(base_res**2)))

    names = list(hypotheses) if hypotheses is not None else list(cat.names)
    # model-free sensor check: the accelerometer against the measured velocity's derivative
    check: dict[str, Any] = {"applicable": False, "reason": "needs accel_z and velocity_z"}
    if ACCEL in channels and VELOCITY in channels:
        check = accel_velocity_check(rec[ACCEL], rec[VELOCITY],
                                     quiet=noise[ACCEL].window if noise[ACCEL].window else None,
                                     accept_margin=accept_margin)
    sensor_found = bool(check.get("detected")) and "sensor_dynamics" in names
    v_nom = impact_speed if impact_speed is not None else (rom_base.v0 if rom_base else None)
    speed: dict[str, Any] | None = None
    if v_nom is not None and VELOCITY in channels:
        # on the channels as recorded (a channel filtered here would smear the contact into
        # the free fall)
        has_acc = ACCEL in rec_given and ACCEL in noise_given
        speed = measured_impact_speed(rec_given[ACCEL] if has_acc else None,
                                      rec_given[VELOCITY], noise_given[VELOCITY],
                                      noise_given[ACCEL].sigma if has_acc else 0.0)
        if speed is not None:
            speed.update(nominal=float(v_nom), offset=speed["impact_speed"] - float(v_nom))
            if not abs(speed["offset"]) < 0.5 * float(v_nom):
                # another sign convention or unit, or another test: not an offset of this one
                speed = {**speed, "used": False,
                         "reason": f"recorded impact speed {speed['impact_speed']:.3g} m/s is not "
                                   f"within 50 % of the baseline's {float(v_nom):.3g} m/s"}
            else:
                speed["used"] = True
    fits: dict[str, FitResult] = {}
    recal = fit_hypothesis(problem, RECALIBRATION, grid_points=1, n_starts=1)
    fits[RECALIBRATION.name] = recal
    for name in names:
        h = cat.get(name)
        if name == "sensor_dynamics" and sensor_found:
            fits[name] = _fit_checked_sensor(problem, h, check, recal)
        elif name == "initial_conditions" and speed is not None and speed["used"]:
            fits[name] = _fit_fixed(problem, h, {"speed_offset": speed["offset"]},
                                    {"speed_offset": speed["sigma"]}, recal)
        else:
            fits[name] = fit_variants(problem, h, start=recal.parameters)
    # error model from the residual of the most complete explanation (lowest RSS): correlated
    # model-form error left by it (granular force fluctuations, another code's numerics, a
    # screening model coarser than the recording) leaves fewer independent samples than the
    # sensor bandwidth suggests, for every hypothesis alike
    n_eff_res = _residual_n_eff(problem, min(fits.values(), key=lambda r: r.rss))
    n_eff_band = problem.n_eff
    if n_eff_res < problem.n_eff:
        _requalify(list(fits.values()), n_eff_res)
        problem.n_eff = n_eff_res
    if sensor_found:
        # the evidence for the sensor is the model-free check's, not the soil-model fit's
        fits["sensor_dynamics"].bic = recal.bic - float(check["delta_bic"])
    if filter_found:
        # sensor_dynamics as "another filter class": the recalibration on the baseline
        # re-filtered at the recording's class; its evidence is the noise spectrum's (none
        # when the class is only declared by the file: a fact, not an inference)
        fr = replace(recal, hypothesis="sensor_dynamics", variant=FILTER_CLASS_VARIANT,
                     parameters=dict(recal.parameters), uncertainty=dict(recal.uncertainty),
                     units=dict(recal.units))
        fr.parameters["filter_class"] = float(fclass["class"])
        fr.uncertainty["filter_class"] = 0.0
        fr.units["filter_class"] = "Hz"
        fr.form_penalty = math.log(len(FILTER_CLASSES))  # the class is chosen among these
        fr.complexity_penalty = recal.complexity_penalty + fr.form_penalty
        fr.bic = recal.bic + fr.form_penalty - float(fclass["delta_bic"] or 0.0)
        fits["sensor_dynamics"] = fr
    ranked = rank(list(fits.values()))

    # decision
    best_phys = next((r for r in ranked if r.hypothesis != RECALIBRATION.name), None)
    if base_rms <= WITHIN_NOISE_RATIO:
        decision = (f"baseline explains the recording within noise (residual {base_rms:.2f} sigma "
                    f"RMS <= {WITHIN_NOISE_RATIO})")
        missing, best_name, chosen = None, None, None
    elif filter_found:
        f = fclass["channels"][primary]
        ev = (f"Delta BIC = {fclass['delta_bic']:.1f} from the pre-event noise spectrum"
              if fclass["delta_bic"] else "declared by the recording")
        decision = (f"sensor_dynamics (filter class): the recording is filtered at CFC "
                    f"{fclass['class']:g} ({f['source']}; {ev}), the baseline at CFC "
                    f"{f['baseline_class']:g}; the baseline is compared re-filtered "
                    f"{f['refilter']}")
        missing, best_name, chosen = "sensor_dynamics", "sensor_dynamics", fits["sensor_dynamics"]
        other = next((r for r in ranked if r.hypothesis not in (RECALIBRATION.name,
                                                                 "sensor_dynamics")), None)
        if other is not None and (recal.bic - other.bic) > accept_margin and (
                other.scores["overall"] - recal.scores["overall"]) >= MIN_SCORE_GAIN:
            decision += (f"; at that class {other.hypothesis} also beats the recalibration "
                         f"(Delta BIC = {recal.bic - other.bic:.1f})")
    elif sensor_found and best_phys is not None and best_phys.hypothesis == "sensor_dynamics":
        decision = (f"sensor_dynamics: the accelerometer disagrees with the measured velocity's "
                    f"derivative by {check['rms_sigma_ideal']:.1f} sigma RMS, explained by a "
                    f"{check['form']} sensor at {check['mount_frequency']:.1f} Hz, zeta "
                    f"{check['mount_damping']:.3f} ({check['rms_sigma_fitted']:.2f} sigma RMS; "
                    f"Delta BIC = {check['delta_bic']:.1f} > {accept_margin:g}, no soil model "
                    "involved)")
        missing, best_name, chosen = best_phys.hypothesis, best_phys.hypothesis, best_phys
    elif best_phys is not None and (recal.bic - best_phys.bic) > accept_margin and (
            best_phys.scores["overall"] - recal.scores["overall"]) >= MIN_SCORE_GAIN:
        decision = (f"{best_phys.hypothesis} beats recalibration by Delta BIC = "
                    f"{recal.bic - best_phys.bic:.1f} > {accept_margin:g} and raises the score "
                    f"{recal.scores['overall']:.3f} -> {best_phys.scores['overall']:.3f}")
        missing, best_name, chosen = best_phys.hypothesis, best_phys.hypothesis, best_phys
    else:
        gain = (recal.bic - best_phys.bic) if best_phys else float("nan")
        decision = (f"no hypothesis beats recalibration by the margin (best Delta BIC = {gain:.1f}, "
                    f"needed {accept_margin:g}): reported as recalibration")
        missing, best_name, chosen = None, RECALIBRATION.name, recal

    # second stage: a large unexplained residual after the accepted effect -> try it combined
    # with each other effect (greedy forward selection, same nested-BIC rule). A pair is a
    # candidate only when its added effect is switched on (not at its "off" values: that is the
    # single effect with a nuisance tweak, e.g. a wall 1 cm nearer for a 1 cm larger nose) and
    # explains most of what the first effect leaves (residual RMS at most SECOND_EFFECT_RMS_RATIO
    # of it): a model-form difference buys smaller gains from any flexible extra term
    second_stage: list[dict[str, Any]] = []
    if missing is not None and chosen is not None and chosen.rms_sigma > SECOND_STAGE_RMS and \
            hypotheses is None:
        combos = []
        for name in cat.names:
            if name == missing:
                continue
            h2 = cat.combine(missing, name)
            r2 = fit_variants(problem, h2, start=chosen.parameters,
                              grid_over=[p.name for p in cat.get(name).parameters],
                              n_starts=3, n_full=3)
            ratio = r2.rms_sigma / chosen.rms_sigma if chosen.rms_sigma > 0 else 1.0
            row = {"name": h2.name, "delta_bic": chosen.bic - r2.bic, "rms_ratio": ratio}
            if _left_off(cat.get(name), r2.parameters):
                row["rejected"] = f"{name} stays at its off values"
            elif ratio > SECOND_EFFECT_RMS_RATIO:
                row["rejected"] = (f"explains too little of the residual (RMS ratio {ratio:.2f} > "
                                   f"{SECOND_EFFECT_RMS_RATIO:g})")
            second_stage.append(row)
            if "rejected" in row:
                continue
            fits[h2.name] = r2
            combos.append(r2)
        best2 = min(combos, key=lambda r: r.bic) if combos else None
        if best2 is not None and chosen.bic - best2.bic > accept_margin:
            decision += (f"; the residual left ({chosen.rms_sigma:.1f} sigma RMS) is explained "
                         f"further by {best2.hypothesis} (Delta BIC = {chosen.bic - best2.bic:.1f})")
            missing, best_name, chosen = best2.hypothesis, best2.hypothesis, best2
        ranked = rank(list(fits.values()))

    after = []
    if chosen is not None:
        for ch in channels:
            after += locate_mismatch(rec[ch], chosen.aligned[ch], noise[ch], shift=0.0)
    hyp_out = []
    for r in ranked:
        h = cat.get(r.hypothesis)
        after_r = []
        for ch in channels:
            after_r += locate_mismatch(rec[ch], r.aligned[ch], noise[ch], shift=0.0)
        own = [p.name for p in h.parameters]
        if r.variant == FILTER_CLASS_VARIANT:
            own = ["filter_class"]
        hyp_out.append({
            "name": r.hypothesis,
            "parameters": {k: r.parameters[k] for k in own} if own else {},
            "uncertainty": {k: r.uncertainty[k] for k in own} if own else {},
            "units": {k: r.units[k] for k in own},
            "recalibration": {p.name: r.parameters[p.name] for p in RECALIBRATION.parameters},
            "recalibration_uncertainty": {p.name: r.uncertainty[p.name]
                                          for p in RECALIBRATION.parameters},
            "variant": r.variant,
            "scenario_overrides": ({"instrumentation.cfc": r.parameters["filter_class"]}
                                   if r.variant == FILTER_CLASS_VARIANT else
                                   h.scenario_overrides(r.parameters, r.variant)),
            "effects": r.hypothesis.split("+") if r.hypothesis != RECALIBRATION.name else [],
            "score_before": base_scores["overall"],
            "score_after": r.scores["overall"],
            "residual_rms_sigma": r.rms_sigma,
            "bic": r.bic,
            "delta_bic_vs_recalibration": recal.bic - r.bic,
            "complexity_penalty": r.complexity_penalty,
            "n_parameters": r.k,
            "parameters_at_bounds": r.at_bounds,
            "evidence": _evidence(h, r, windows, after_r, base_rms) + (
                f" The accelerometer disagrees with the recorded velocity's derivative by "
                f"{check['rms_sigma_ideal']:.1f} sigma RMS; a {check['form']} sensor explains it "
                f"to {check['rms_sigma_fitted']:.2f} sigma (model-free check)."
                if (sensor_found and r.hypothesis == "sensor_dynamics") else ""),
            "time_shift_s": r.shift_s,
            "n_evaluations": r.n_evals,
        })
    fit_out = {
        "metric": metric_name(),
        "before": base_scores,
        "after": chosen.scores if chosen is not None else base_scores,
        "after_hypothesis": chosen.hypothesis if chosen is not None else None,
        "residual_rms_sigma_before": base_rms,
        "residual_rms_sigma_after": chosen.rms_sigma if chosen is not None else base_rms,
        "n_samples": problem.n,
        "n_effective": problem.n_eff,
        "n_effective_bandwidth": n_eff_band,
        "accept_margin_bic": accept_margin,
        "model_error": {ch: {"sigma": m[0], "correlation_s": m[1]} for ch, m in model_err.items()},
        "recalibration_rms_total": recal.rms_sigma,
        "recalibration_unexplained": bool(recal.rms_sigma > WITHIN_NOISE_RATIO and
                                          base_rms > WITHIN_NOISE_RATIO),
        "score_window_s": list(problem.score_window),
        "sensor_check": check,
        "impact_speed_check": speed,
        "filter_class": fclass,
        "sign_convention": signs,
        "resampled": resampled,
        "decimated": decimated,
        "second_stage": second_stage,
    }
    # residual diagnostics of the final explanation: a residual much more correlated than the
    # filtered noise, or far above it, is model-form error the catalogue does not cover
    final = chosen.aligned if chosen is not None else base_aligned
    res_f = np.concatenate([((final[ch].data - rec[ch].data) / noise[ch].sigma)[problem.masks[ch]]
                            for ch in channels])
    tau = _residual_correlation(res_f)
    fit_out["residual_n_effective"] = float(res_f.size / tau)
    rms_f = float(np.sqrt(np.mean(res_f**2)))
    if rms_f > MODEL_ERROR_RMS:
        fit_out["warning"] = (f"residual after the fit is {rms_f:.1f} sigma RMS (> {MODEL_ERROR_RMS:g}): "
                              "model-form error the catalogue does not explain; treat the result as "
                              "a screening result and confirm with the full simulation")
    flipped = [ch for ch, v in signs.items() if v["flipped"]]
    if flipped:
        decision += (f" (channels {flipped} were recorded with the opposite sign convention and "
                     "are compared sign-flipped)")
    refitted = dict(chosen.aligned) if chosen is not None else {}
    sims = {"screening_model": type(simulator).__name__,
            "screening_runs": rom_calls0 + sim.calls,
            "full_simulations": 0,
            "wall_time_s": time.perf_counter() - t_start}
    return Report(channels, noise, windows, hyp_out, missing, best_name, fit_out, sims, decision,
                  rec, base_aligned, refitted, fits, after, cat)


def screen_then_confirm(baseline_signals: Mapping[str, Signal],
                        recording_signals: Mapping[str, Signal],
                        full_simulator: Simulator, *, top_k: int = 2,
                        full_search: bool | Mapping[str, catalogue.FullSearch] = True,
                        search_simulator: Simulator | None = None,
                        replicates: Sequence[Mapping[str, Any]] = (),
                        **diagnose_kw) -> Report:
    """ROM screening, then confirmation of the top-k hypotheses with the expensive simulator.

    Parameters
    ----------
    baseline_signals, recording_signals : as for :func:`diagnose`
    full_simulator : ``f(overrides: dict) -> dict[str, Signal]`` taking *scenario* keys
        (``physics.<name>.*``, ``calibration.*_scale``), e.g. a wrapper around ``crashdem.run``;
        when it has a ``map(list_of_overrides) -> list_of_signals`` method (e.g.
        ``distributed.DaskFullSimulator``) the runs are requested as one batch
    top_k : number of missing-physics hypotheses confirmed (each costs one full simulation)
    full_search : also run, unless a model-free sensor answer stands, every effect of the
        catalogue's ``full_search`` (or of the mapping given) at its levels in the full model's
        own terms (``catalogue.FullSearch``; drop: 22 runs) plus one refinement run of the
        leading effect; each effect is then judged by its best run
    search_simulator : run the search on this cheaper simulator instead (e.g. the scenario at
        a coarser resolution), each run anchored on the baseline simulation (baseline + its
        change against the search simulator's own baseline run, ``{}``); the best level of each
        of the ``SEARCH_PROMOTE`` leading effects that beat the baseline decisively is then run
        with ``full_simulator`` and judged like any candidate, in the place of the screened
        candidates other than the screening's claim (the full runs stay 1 + ``top_k``)
    replicates : overrides of other realisations of the baseline itself (e.g.
        ``[{"scenario.seed": 2}, {"scenario.seed": 3}]``: another packing), run with the
        simulator the search runs on (the full one without ``search_simulator``). They change
        no physics, so how well the best of them fits the recording is the **realisation
        floor**: an effect is decisive only when it also beats the best replicate by
        ``REALISATION_MARGIN`` in BIC and ``CONFIRM_MIN_GAIN`` in score, and the screening's
        claim stands only when it is not decisively worse than it (``fit.realisation``); a
        model-free answer (sensor check, a measured impact-speed offset of at least
        ``SPEED_CHECK_SIGMAS``) stands without it. On the
        search simulator the floor applies to the promotion of its levels (the full model's
        resolution has its own scatter)
    diagnose_kw : passed to :func:`diagnose`

    Returns
    -------
    Report, with ``simulations["full_simulations"]`` and a ``confirmation`` table in ``fit``.
    Candidates are confirmed when the screening claims missing physics *or* when the
    recalibration leaves a residual above the total (sensor + model) error
    (``fit["recalibration_unexplained"]``: the screening model may be too coarse to claim what
    the full simulation can show). Each candidate is run as its effect alone on the baseline
    scenario and compared with the reference, the better of the baseline and the full
    recalibrated run (BIC of the weighted residual with the diagnosis's sensor and model-error
    weights and n_eff; ISO/TS 18571 score). The screening's claim stands unless its full run is
    worse than the reference by more than ``ACCEPT_MARGIN`` in BIC; another candidate replaces
    it (or is named when the screening claimed nothing) when its full run beats the reference by
    ``ACCEPT_MARGIN`` in BIC and ``CONFIRM_MIN_GAIN`` in score, and beats the claim's full run
    by ``CONFIRM_MIN_GAIN`` in score; among several such rivals the highest Delta BIC wins.
    With ``full_search`` each effect's best run (screened value, search levels, refinement)
    stands for it, and a named searched effect reports the full model's value of its main
    parameter (``hypotheses[*].full_model``; it replaces the screening's value when both mean
    the same, e.g. a floor or interface depth).
    """
    rep = diagnose(baseline_signals, recording_signals, **diagnose_kw)
    rec = rep.recording
    chans = rep.channels
    primary = chans[0]

    def rated(al: Mapping[str, Signal]) -> dict[str, Any]:
        """Per-channel and overall scores of channels aligned on the recording."""
        per = {ch: score_signals(rec[ch], al[ch], tuple(rep.fit["score_window_s"])) for ch in chans}
        return {"score": float(np.mean([v["score"] for v in per.values()])),
                "per_channel": per, "aligned": dict(al)}

    def score(h_name: str, overrides: dict[str, Any], out: Mapping[str, Signal]) -> dict[str, Any]:
        out = _si(out)
        shift = onset_time(rec[primary], rep.noise[primary].sigma) - onset_time(out[primary], 0.0)
        return {"hypothesis": h_name, "overrides": overrides,
                **rated({ch: align(rec[ch], out[ch], shift) for ch in chans})}

    by_name = {h["name"]: h for h in rep.hypotheses}
    recal = by_name[RECALIBRATION.name]
    fclass = rep.fit.get("filter_class") or {}
    # every full run is filtered at the recording's class (instrumentation.cfc), as the
    # screening compared it
    cfc_key = ({"instrumentation.cfc": float(fclass["class"])}
               if fclass.get("mismatch") and fclass.get("class") is not None else {})
    # a sensor found by the model-free accelerometer/velocity check (or the noise spectrum)
    # needs no soil model: its full run only adds granular noise to the same conclusion
    checked = (rep.missing_physics == "sensor_dynamics"
               and (bool(rep.fit.get("sensor_check", {}).get("detected"))
                    or bool(fclass.get("mismatch"))))
    spd = rep.fit.get("impact_speed_check") or {}
    speed_measured = bool(rep.missing_physics == "initial_conditions" and spd.get("used")
                          and abs(spd["offset"]) >= SPEED_CHECK_SIGMAS * spd["sigma"])
    unexplained = bool(rep.fit.get("recalibration_unexplained", False))
    lacks = rep.catalogue.full_unsupported
    skipped: dict[str, str] = {}
    candidates: list[dict[str, Any]] = []
    if rep.missing_physics is not None or unexplained:
        for h in rep.hypotheses:
            missing = [e for e in h["name"].split("+") if e in lacks]
            if h["name"] == RECALIBRATION.name or len(candidates) == top_k:
                continue
            if missing:  # the full model cannot run it: the next candidate takes its place
                skipped[h["name"]] = lacks[missing[0]]
                continue
            candidates.append(h)
    # the search runs even when the recalibration explains the recording within the total
    # error: the screening model's error floor can hide what the full model resolves
    if checked or not full_search:
        searched: dict[str, catalogue.FullSearch] = {}
    elif isinstance(full_search, Mapping):
        searched = dict(full_search)
    else:
        searched = dict(rep.catalogue.full_search)
    allowed = diagnose_kw.get("hypotheses")
    if allowed is not None:
        searched = {k: v for k, v in searched.items() if k in allowed}
    # the replicates only run when there is something for their floor to judge
    replicates = [dict(rv) for rv in replicates] if not checked and (searched or candidates) \
        else []
    n_eff = float(rep.fit["n_effective"])
    n_res = float(rep.fit["n_samples"])

    def bic(rss: float, k: int) -> float:
        return n_eff * math.log(max(rss, 1e-300) / n_res) + k * math.log(n_eff)

    def row(name: str, ov: dict[str, Any], x: float | None, out: Any) -> dict[str, Any]:
        r = (score(name, ov, out) if not isinstance(out, Exception) else
             {"hypothesis": name, "overrides": ov, "score": -math.inf, "error": str(out)})
        if x is not None:
            r["search_value"] = x
        if "aligned" in r:
            r["rss"] = _full_rss(rep, r["aligned"])
        return r

    def levels(names: Sequence[str]) -> list[tuple[str, dict[str, Any], float]]:
        return [(n, {**searched[n].overrides(x), **cfc_key}, float(x))
                for n in names for x in searched[n].values]

    def located(r: dict[str, Any]) -> bool:
        """A scored run that can stand for its effect: not a search run at the end of the span
        where the effect fades (``FullSearch.located``)."""
        return "rss" in r and not ("search_value" in r and r["hypothesis"] in searched
                                   and not searched[r["hypothesis"]].located(r["search_value"]))

    def anchored(r: dict[str, Any], ref: dict[str, Any]) -> dict[str, Any]:
        """Run ``r`` of another simulator as the baseline simulation plus its change against
        that simulator's baseline run ``ref`` (both aligned on the recording)."""
        if "aligned" not in r or "aligned" not in ref:
            return r
        al = {ch: Signal(ch, rep.baseline[ch].t, rep.baseline[ch].data + r["aligned"][ch].data
                         - ref["aligned"][ch].data, rep.baseline[ch].unit, rep.baseline[ch].cfc)
              for ch in chans}
        return {**r, **rated(al), "anchored": True, "rss": _full_rss(rep, al)}

    def refined(sim: Simulator, rws: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """One run of the leading searched effect at the vertex of the parabola through its
        best level and the two neighbours (in the search coordinate), when interior; the
        caller gives it its Delta BIC."""
        lead = _best_rows(r for r in rws if "search_value" in r and r["hypothesis"] in searched
                          and located(r))
        if not lead:
            return []
        top = max(lead.values(), key=lambda r: r["delta_bic_vs_reference"])
        v = _search_vertex(top, rws, searched[top["hypothesis"]])
        if v is None:
            return []
        name = top["hypothesis"]
        ov = {**searched[name].overrides(v["value"]), **cfc_key}
        extra = row(name, ov, v["value"], _run_full(sim, [(name, ov)])[0])
        extra["refined"] = True
        return [extra]

    t_full = time.perf_counter()
    search_rows: list[dict[str, Any]] = []
    promoted: list[tuple[str, dict[str, Any], float | None]] = []
    if searched and search_simulator is not None:
        # tier 1: every level on the cheaper search simulator, judged against that
        # simulator's own baseline run; the leading effects' best levels go to the full model
        s_req = ([("baseline", dict(cfc_key), None)] + levels(list(searched))
                 + [(REPLICATE, {**rv, **cfc_key}, None) for rv in replicates])
        s_out = _run_full(search_simulator, [(n, ov) for n, ov, _ in s_req])
        if isinstance(s_out[0], Exception):
            raise s_out[0]
        raw_rows = [row(n, ov, x, o) for (n, ov, x), o in zip(s_req, s_out)]
        s_ref = raw_rows[0]
        # anchored like the screening: each search run predicts the baseline simulation plus
        # the change its effect makes in the search simulator (its run minus that simulator's
        # baseline run), so the search simulator's own misfit is not read as an effect
        search_rows = [s_ref] + [anchored(r, s_ref) for r in raw_rows[1:]]
        s_bic = bic(_full_rss(rep, rep.baseline), 0)

        def s_qualify(r: dict[str, Any]) -> None:
            if "rss" in r:
                k = int(r["hypothesis"] != REPLICATE)  # a level carries one parameter
                r["delta_bic_vs_reference"] = s_bic - bic(r["rss"], k)

        for r in search_rows[1:]:
            s_qualify(r)
        extra = [anchored(r, s_ref) for r in refined(search_simulator, search_rows)]
        for r in extra:
            s_qualify(r)
        search_rows += extra
        s_floor = _realisation_floor(search_rows, float(rep.fit["before"]["overall"]))
        best_s = _best_rows(r for r in search_rows[1:]
                            if located(r) and r["hypothesis"] != REPLICATE)
        promote = sorted((r for r in best_s.values() if _decisive(r, s_floor)),
                         key=lambda r: -r["delta_bic_vs_reference"])[:SEARCH_PROMOTE]
        # the full runs stay 1 + top_k: the screening's claim, then the promoted levels, then
        # the other screened candidates
        claim = [h for h in candidates if h["name"] == rep.missing_physics]
        promote = promote[:max(0, top_k - len(claim))]
        candidates = claim + [h for h in candidates if h["name"] != rep.missing_physics][
            :max(0, top_k - len(claim) - len(promote))]
        promoted = [(r["hypothesis"], dict(r["overrides"]), r["search_value"]) for r in promote]
        s_verdicts = {n: ("promoted to a full run" if any(p is r for p in promote) else
                          "not promoted: " + _verdict(r, s_floor, False, None, None))
                      for n, r in best_s.items()}
    requests: list[tuple[str, dict[str, Any], float | None]] = [
        (RECALIBRATION.name, {**RECALIBRATION.scenario_overrides(recal["recalibration"]),
                              **cfc_key}, None)]
    for h in candidates:
        # the effect alone on the baseline scenario: the screening model's recalibration
        # factors do not carry over to the full model's material parameters (measured on the
        # DEM: every full run with the mapped factors scored below the baseline), while the
        # effect parameters (depths, speeds, frequencies) have the same meaning in both
        requests.append((h["name"], {**_confirmation_overrides(h, rep.catalogue), **cfc_key},
                         None))
    requests += promoted
    if searched and search_simulator is None:
        requests += levels(list(searched))
    if search_simulator is None:
        requests += [(REPLICATE, {**rv, **cfc_key}, None) for rv in replicates]
    outs = _run_full(full_simulator, [(n, ov) for n, ov, _ in requests])
    rows = [row(n, ov, x, out) for (n, ov, x), out in zip(requests, outs)]
    recal_row = rows[0]
    # reference: the better of the baseline simulation and the recalibrated full run
    base_row = {"hypothesis": "baseline", "score": float(rep.fit["before"]["overall"]),
                "aligned": rep.baseline}
    base_row["rss"] = _full_rss(rep, rep.baseline)
    ref_row = max([base_row, recal_row], key=lambda r: r["score"])
    reference = ref_row["score"]
    ref_k = 0 if ref_row is base_row else len(RECALIBRATION.parameters)
    ref_bic = bic(ref_row["rss"], ref_k)

    def qualify(r: dict[str, Any]) -> None:
        if "rss" in r:
            # a screened candidate's run carries the effect's parameters, a search level one
            # (the level), the reference its recalibration when it is the recalibrated run
            k = (1 if "search_value" in r else 0 if r["hypothesis"] == REPLICATE
                 else len(rep.catalogue.get(r["hypothesis"]).parameters))
            r["delta_bic_vs_reference"] = ref_bic - bic(r["rss"], k)

    for r in rows[1:]:
        qualify(r)
    if searched and search_simulator is None:
        extra = refined(full_simulator, rows)
        for r in extra:
            qualify(r)
        rows += extra
    t_full = time.perf_counter() - t_full
    # the realisation floor: the best replicate of the baseline among the full runs (none
    # there, e.g. when they ran on the search simulator: the reference)
    floor = _realisation_floor(rows, reference)

    best_h = _best_rows(r for r in rows[1:] if located(r) and r["hypothesis"] != REPLICATE)
    cands = list(best_h.values())
    confirmed, best = None, recal_row
    screened = best_h.get(rep.missing_physics) if rep.missing_physics else None
    if screened is not None and (checked or speed_measured or (
            screened["delta_bic_vs_reference"] - floor["delta_bic"] >= -ACCEPT_MARGIN
            and screened["score"] >= floor["score"] - CONFIRM_MIN_GAIN)):
        # the screening's claim stands unless its full run is decisively worse than the
        # reference or the best replicate (in likelihood, or by CONFIRM_MIN_GAIN in score: a
        # full run that fits the recording worse by the field's objective rating does not
        # confirm anything) or another candidate's full run is decisively better than it; a
        # model-free answer (sensor check, measured impact speed) stands as it is
        confirmed, best = screened["hypothesis"], screened
    claim_stood = confirmed is not None
    rivals = [] if checked or speed_measured else sorted(
        (r for r in cands if r is not screened and _decisive(r, floor)),
        key=lambda r: -r["delta_bic_vs_reference"])
    ambiguous = None
    if rivals:
        # among decisive rivals the likelihood ranks (the score is the field's rating, its
        # differences between two good fits are not evidence); two within AMBIGUITY_MARGIN
        # of each other are not told apart
        top = rivals[0]
        if len(rivals) > 1 and (top["delta_bic_vs_reference"] - rivals[1]["delta_bic_vs_reference"]
                                <= AMBIGUITY_MARGIN):
            ambiguous = [r["hypothesis"] for r in rivals[:2]]
        elif screened is None or top["score"] - screened["score"] >= CONFIRM_MIN_GAIN:
            confirmed, best = top["hypothesis"], top
    if ambiguous:
        rep.fit["confirmation_ambiguous"] = {
            r["hypothesis"]: {"delta_bic_vs_reference": r["delta_bic_vs_reference"],
                              "score": r["score"]} for r in rivals[:2]}
    # why each effect run in the full model was or was not named, in one line each
    model_free = ("the sensor check" if checked else
                  "the measured impact speed" if speed_measured else None)
    every = _best_rows(r for r in rows[1:] if "rss" in r and r["hypothesis"] != REPLICATE)
    verdicts: dict[str, str] = {}
    for name in dict.fromkeys(r["hypothesis"] for r in rows[1:]):
        if name in (REPLICATE, RECALIBRATION.name):
            continue
        r = best_h.get(name)
        if name == confirmed:
            why = "named"
        elif r is not None and r is screened and claim_stood:
            why = (f"the screening's claim stood (Delta BIC {r['delta_bic_vs_reference']:.1f}, "
                   f"score {r['score']:.3f}), but {confirmed}'s full run beats it by "
                   f"{CONFIRM_MIN_GAIN:g} in score and the reference decisively")
        elif r is None:
            err = next((x.get("error") for x in rows if x["hypothesis"] == name and "error" in x),
                       None)
            why = (f"the full model could not run it ({err})" if err and name not in every else
                   "its best run is at the end of the span where the effect fades "
                   f"({searched[name].parameter} = {every[name]['search_value']:.4g} "
                   f"{searched[name].unit}, Delta BIC "
                   f"{every[name]['delta_bic_vs_reference']:.1f}): names nothing")
        else:
            why = _verdict(r, floor, r is screened, model_free, ambiguous)
        verdicts[name] = why
    rep.fit["confirmation_verdicts"] = verdicts
    if confirmed is not None and "search_value" in best:
        _adopt_full_parameters(rep, best, searched[confirmed], search_rows or rows)
    if skipped:
        rep.fit["confirmation_skipped"] = skipped
    if replicates:
        on_search = search_simulator is not None
        f = s_floor if on_search else floor
        rep.fit["realisation"] = {
            "tier": "search simulator" if on_search else "full simulator",
            "runs": [{"overrides": r["overrides"],
                      "score": None if not math.isfinite(r["score"]) else r["score"],
                      "delta_bic_vs_reference": r.get("delta_bic_vs_reference"),
                      **({"error": r["error"]} if "error" in r else {})}
                     for r in (search_rows if on_search else rows)
                     if r["hypothesis"] == REPLICATE],
            "floor_delta_bic": f["delta_bic"], "floor_score": f["score"]}
    if searched:
        lv = [r for r in (search_rows[1:] if search_simulator is not None else rows)
              if "search_value" in r]
        rep.fit.setdefault("full_search", {}).update(
            tier="search simulator" if search_simulator is not None else "full simulator",
            runs=len(lv) + (1 if search_simulator is not None else 0),
            levels=[{"hypothesis": r["hypothesis"], "value": r["search_value"],
                     "score": None if not math.isfinite(r["score"]) else r["score"],
                     "delta_bic_vs_reference": r.get("delta_bic_vs_reference"),
                     "refined": bool(r.get("refined")), "located": located(r)}
                    for r in lv],
            best={n: {"value": r["search_value"], "score": r["score"],
                      "delta_bic_vs_reference": r["delta_bic_vs_reference"]}
                  for n, r in _best_rows(r for r in lv if "rss" in r).items()})
        if search_simulator is not None:
            rep.fit["full_search"]["search_baseline_score"] = search_rows[0]["score"]
            rep.fit["full_search"]["verdicts"] = s_verdicts
            rep.simulations["search_simulations"] = len(search_rows)
    rep.fit["confirmation"] = [{k: (None if k == "score" and not math.isfinite(v) else v)
                                for k, v in r.items() if k != "aligned"} for r in rows]
    rep.fit["confirmation_reference_score"] = reference
    rep.fit["confirmed_missing_physics"] = confirmed
    if confirmed is not None:
        rep.fit["after_full"] = {"hypothesis": confirmed, "overall": best["score"],
                                 "per_channel": best["per_channel"]}
        rep.refitted = dict(best["aligned"])
    rep.simulations["full_simulations"] = len(rows)
    rep.simulations["full_wall_time_s"] = t_full
    rep.missing_physics = confirmed
    n_lv = sum('search_value' in r for r in rows)
    if searched and search_simulator is not None:
        how = (f"{len(rows)} runs, {n_lv} of them the best levels of a {len(search_rows)}-run "
               f"search over {len(searched)} effects on the search simulator")
    elif searched:
        how = f"{len(rows)} runs, {n_lv} of them a full-model search over {len(searched)} effects"
    else:
        how = f"{len(rows)} runs"
    at = (f" at {searched[confirmed].parameter} = {best['search_value']:.4g} "
          f"{searched[confirmed].unit}" if confirmed and "search_value" in best else "")
    if replicates:
        rf = rep.fit["realisation"]
        how += (f"; realisation floor of {len(replicates)} replicate packings on the "
                f"{rf['tier']}: Delta BIC {rf['floor_delta_bic']:.1f}, score "
                f"{rf['floor_score']:.3f}")
    rep.decision += (f"; full-simulation confirmation ({how}, reference score "
                     f"{reference:.3f}): "
                     + (f"{' and '.join(ambiguous)} both beat the reference within Delta BIC "
                        f"{AMBIGUITY_MARGIN:g} of each other, neither named; " if ambiguous else "")
                     + (f"{confirmed} confirmed{at} (score {best['score']:.3f}, Delta BIC "
                        f"{best.get('delta_bic_vs_reference', 0.0):.1f})"
                        if confirmed and best is not recal_row else
                        f"{confirmed} confirmed (score {best['score']:.3f})" if confirmed
                        else "no missing physics confirmed"))
    return rep


def _run_full(full_simulator: Simulator, requests: list[tuple[str, dict[str, Any]]]) -> list[Any]:
    """Run the full simulator on every request (one batch when it has ``map``); a run the full
    model cannot do (``ValueError`` / ``RuntimeError``) is returned as the exception, except the
    recalibration's, which is raised."""
    if hasattr(full_simulator, "map"):
        try:
            return list(full_simulator.map([ov for _, ov in requests]))  # type: ignore[attr-defined]
        except (RuntimeError, ValueError):
            # a run of the batch failed (e.g. a hypothesis the full model cannot represent):
            # run them one by one so that the others can still be scored
            pass
    outs: list[Any] = []
    for name, ov in requests:
        try:
            outs.append(full_simulator(ov))
        except (ValueError, RuntimeError) as e:  # the full model cannot run this hypothesis
            if name == RECALIBRATION.name:
                raise
            outs.append(e)
    return outs


def _verdict(r: dict[str, Any], floor: dict[str, float], is_claim: bool,
             model_free: str | None, ambiguous: list[str] | None) -> str:
    """One line on why the effect whose best full run is ``r`` was not named (the rules of
    ``screen_then_confirm``, first failed first); ``is_claim``: ``r`` is the screening's claim
    and did not stand (a claim that stood and was replaced is worded by the caller);
    ``model_free`` names a model-free answer that stands (then nothing else is named)."""
    db, sc = float(r["delta_bic_vs_reference"]), float(r["score"])
    if model_free:
        return f"a model-free answer ({model_free}) names another effect"
    if ambiguous and r["hypothesis"] in ambiguous:
        return (f"decisive (Delta BIC {db:.1f}) but within Delta BIC {AMBIGUITY_MARGIN:g} of "
                f"{next(a for a in ambiguous if a != r['hypothesis'])}: not told apart")
    if is_claim:
        return (f"the screening's claim, but its full run is decisively worse than the reference "
                f"or the best replicate (Delta BIC {db:.1f}, score {sc:.3f})")
    if db <= ACCEPT_MARGIN:
        return f"Delta BIC {db:.1f} over the reference, not above {ACCEPT_MARGIN:g}"
    if db - floor["delta_bic"] <= REALISATION_MARGIN:
        return (f"fits no better than a replicate packing of the baseline (Delta BIC {db:.1f} "
                f"against the best replicate's {floor['delta_bic']:.1f})")
    if sc - floor["score"] < CONFIRM_MIN_GAIN:
        return (f"Delta BIC {db:.1f}, but its score {sc:.3f} is not {CONFIRM_MIN_GAIN:g} above "
                f"{floor['score']:.3f} (reference and replicates)")
    return (f"decisive (Delta BIC {db:.1f}, score {sc:.3f}) but another effect ranks higher or "
            f"the screening's claim stands")


def _decisive(r: dict[str, Any], floor: dict[str, float]) -> bool:
    """A scored run beats the reference (Delta BIC > ``ACCEPT_MARGIN``) and the realisation
    ``floor`` (Delta BIC above the best replicate's by ``REALISATION_MARGIN``, score by
    ``CONFIRM_MIN_GAIN`` above the best of reference and replicates): the rule for naming a
    full run and for promoting a search-tier level to one."""
    db = r["delta_bic_vs_reference"]
    return (db > ACCEPT_MARGIN and db - floor["delta_bic"] > REALISATION_MARGIN
            and r["score"] - floor["score"] >= CONFIRM_MIN_GAIN)


def _realisation_floor(rows: Iterable[dict[str, Any]], reference_score: float) -> dict[str, float]:
    """The best Delta BIC (at least 0: the reference) and the best score (at least the
    reference's) of the scored replicate runs among ``rows``."""
    reps = [r for r in rows if r["hypothesis"] == REPLICATE and "delta_bic_vs_reference" in r
            and math.isfinite(r["score"])]
    return {"delta_bic": max([0.0] + [float(r["delta_bic_vs_reference"]) for r in reps]),
            "score": max([float(reference_score)] + [float(r["score"]) for r in reps])}


def _best_rows(rows: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The run with the highest Delta BIC of each hypothesis among scored ``rows``."""
    best: dict[str, dict[str, Any]] = {}
    for r in rows:
        if "delta_bic_vs_reference" in r and (
                r["hypothesis"] not in best
                or r["delta_bic_vs_reference"] > best[r["hypothesis"]]["delta_bic_vs_reference"]):
            best[r["hypothesis"]] = r
    return best


def _level_rows(rows: list[dict[str, Any]], name: str) -> list[dict[str, Any]]:
    """The scored search-level runs of hypothesis ``name``, by ascending value."""
    return sorted((r for r in rows if r["hypothesis"] == name and "search_value" in r
                   and "delta_bic_vs_reference" in r), key=lambda r: r["search_value"])


def _parabola(lv: list[dict[str, Any]], i: int, fs: catalogue.FullSearch
              ) -> tuple[np.ndarray, float, float] | None:
    """The parabola ``a2 u^2 + a1 u + a0`` of Delta BIC through level ``lv[i]`` and its two
    neighbours in the search coordinate u: ``(u of the three, a2, a1)``; None at an edge."""
    if i <= 0 or i >= len(lv) - 1:
        return None
    u = np.array([fs.coord(lv[j]["search_value"]) for j in (i - 1, i, i + 1)])
    a2, a1, _ = np.polyfit(u, [lv[j]["delta_bic_vs_reference"] for j in (i - 1, i, i + 1)], 2)
    return u, float(a2), float(a1)


def _search_vertex(best: dict[str, Any], rows: list[dict[str, Any]],
                   fs: catalogue.FullSearch) -> dict[str, float] | None:
    """The vertex of the parabola through the best search level and its two neighbours
    (Delta BIC against the search coordinate), when the best level is interior and the
    parabola opens downwards: ``{"value"}``, else None."""
    lv = _level_rows(rows, best["hypothesis"])
    i = next((j for j, r in enumerate(lv) if r is best), None)
    par = _parabola(lv, i, fs) if i is not None else None
    if par is None or not par[1] < 0.0:
        return None
    u, a2, a1 = par
    return {"value": fs.value(float(np.clip(-a1 / (2.0 * a2), u[0], u[2])))}


def _adopt_full_parameters(rep: Report, best: dict[str, Any], fs: catalogue.FullSearch,
                           rows: list[dict[str, Any]]) -> None:
    """Record the full model's value of a named searched effect in its hypothesis entry
    (``full_model``) and, where the screening parameter means the same, in ``parameters``
    (the screening's kept in ``screening_parameters``). Uncertainty: from the curvature of
    Delta BIC over the levels around the best run (1 / sqrt(information) in the search
    coordinate), else half the distance to the nearest level."""
    name, x = best["hypothesis"], float(best["search_value"])
    lv = _level_rows(rows, name)
    levels = [r for r in lv if not r.get("refined")]
    i = min(range(len(levels)), key=lambda j: abs(fs.coord(levels[j]["search_value"]) - fs.coord(x)))
    par = _parabola(levels, i, fs)
    sd = None
    if par is not None and par[1] < 0.0:
        su = 1.0 / math.sqrt(-par[1] / 2.0)
        sd = su * x if fs.scale == "log" else su
    if sd is None:
        gaps = [abs(fs.coord(r["search_value"]) - fs.coord(x)) for r in levels
                if r["search_value"] != x]
        su = 0.5 * min(gaps) if gaps else float("nan")
        sd = su * x if fs.scale == "log" else su
    h = next((h for h in rep.hypotheses if h["name"] == name), None)
    if h is None:
        return
    h["full_model"] = {"parameters": {fs.parameter: x}, "uncertainty": {fs.parameter: sd},
                       "unit": {fs.parameter: fs.unit}, "overrides": best["overrides"],
                       "score": best["score"],
                       "delta_bic_vs_reference": best["delta_bic_vs_reference"],
                       "runs": len(lv)}
    # the scenario fix is the full model's own (the screening's values were mapped across)
    h["scenario_overrides"] = dict(best["overrides"])
    if fs.parameter in h.get("parameters", {}):
        h["screening_parameters"] = dict(h["parameters"])
        h["parameters"] = {**h["parameters"], fs.parameter: x}
        if isinstance(h.get("uncertainty"), dict):
            h["uncertainty"] = {**h["uncertainty"], fs.parameter: sd}
    rep.fit.setdefault("full_search", {})["named"] = {"hypothesis": name, fs.parameter: x,
                                                      "uncertainty": sd, "unit": fs.unit}


#: a parameter within this fraction of its search range of its "off" value leaves the effect off
OFF_TOLERANCE = 0.02


def _at_off(p: ParameterSpec, value: float) -> bool:
    """True when ``value`` of a parameter that has an ``off`` value is within
    ``OFF_TOLERANCE`` of it in the unit-box search coordinate (the effect is left off)."""
    return p.off is not None and abs(p.to_unit(value) - p.to_unit(p.off)) < OFF_TOLERANCE


def _left_off(h: Hypothesis, values: Mapping[str, float]) -> bool:
    """True when every parameter of ``h`` that has an ``off`` value is at it (``_at_off``) and
    at least one has one."""
    specs = [p for p in h.parameters if p.off is not None and p.name in values]
    return bool(specs) and all(_at_off(p, values[p.name]) for p in specs)


def _confirmation_overrides(h: dict[str, Any],
                            cat: catalogue.Catalogue = catalogue.DROP) -> dict[str, Any]:
    """Scenario overrides of a candidate's full run: its screened parameters, except where
    the screening left the effect switched off (a parameter at its ``off`` value, i.e. the
    screening model could not see the effect): there the catalogue's nominal value is used."""
    if h.get("variant") == FILTER_CLASS_VARIANT:
        return {"instrumentation.cfc": float(h["parameters"]["filter_class"])}
    hyp = cat.get(h["name"])
    vals = dict(h["parameters"])
    for p in hyp.parameters:
        if p.name in vals and _at_off(p, vals[p.name]):
            vals[p.name] = p.nominal
    return dict(hyp.scenario_overrides({**h["recalibration"], **vals}, h.get("variant")))


def _full_rss(rep: Report, aligned: Mapping[str, Signal]) -> float:
    """Weighted residual sum of squares of aligned channels against the report's recording,
    on the residual samples of the diagnosis (weights: sensor noise and model-error floor)."""
    rss = 0.0
    t0 = float(rep.fit["score_window_s"][0])
    me = rep.fit.get("model_error", {})
    for ch in rep.channels:
        rec = rep.recording[ch]
        sm = me.get(ch, {}).get("sigma", 0.0)
        w = 1.0 / math.sqrt(rep.noise[ch].sigma ** 2 + sm * sm)
        idx = np.flatnonzero(rec.t >= t0)
        stride = max(1, int(round(idx.size / max(1, rep.fit["n_samples"] // len(rep.channels)))))
        idx = idx[::stride]
        rss += float(np.sum(((aligned[ch].data[idx] - rec.data[idx]) * w) ** 2))
    return rss


def write_report(report: Report, out_dir, plots: bool = True):
    """Write ``report.json``, ``report.md`` and overlay PNGs into ``out_dir`` (see ``report``)."""
    from crashdem.diagnosis.report import write_report as _w

    return _w(report, out_dir, plots=plots)

