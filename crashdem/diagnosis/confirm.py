"""Step 5 of the diagnosis: confirm the screening with the full simulator.

:func:`screen_then_confirm` runs :func:`crashdem.diagnosis.diagnose` (the screening) and then
the expensive simulator, in three stages that each have their own function here:

1. **search tier** (:meth:`_Confirmation.search_tier`, only with a ``search_simulator``): every
   level of the catalogue's full-model search on a cheaper simulator, anchored on the baseline
   simulation, judged against that simulator's replicate floor; its decisive leaders are
   promoted to full runs;
2. **full tier** (:meth:`_Confirmation.full_tier`): the recalibrated run, the screened
   candidates, the promoted levels or (without a search simulator) every search level and the
   replicates, scored against the recording with the diagnosis's weights (Delta BIC against
   the reference, ISO/TS 18571 score);
3. **decision** (:meth:`_Confirmation.decide`): the screening's claim stands, a decisive rival
   replaces it, or nothing is named; every searched effect gets a one-line verdict
   (:meth:`_Confirmation.verdicts`), and :meth:`_Confirmation.record` writes it all into the
   report.

A run is a *row*: ``{"hypothesis", "overrides", "score", "per_channel", "aligned", "rss",
"delta_bic_vs_reference"[, "search_value", "refined", "anchored", "beds", "error"]}``. A
level of an effect whose levels deposit their own bed (``FullSearch.deposits``) is one row
pooled over its ``level_beds`` runs (``beds``: each bed's overrides and score).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from crashdem.diagnosis import (FILTER_CLASS_VARIANT, SPEED_OFFSET_SIGMAS, Report, Simulator,
                                _at_off, _remaining_mismatch, _si, _speed_found,
                                catalogue, diagnose)
from crashdem.diagnosis.catalogue import RECALIBRATION, impact_young_range
from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY
from crashdem.diagnosis.fit import ACCEPT_MARGIN, score_signals
from crashdem.diagnosis.mismatch import (SIMULATED_SPAN, align, describe_changes, feature_changes,
                                         onset_time)
from crashdem.signal import Signal
from soil.contact_laws import CONTACT_LAWS, rebound_restitution

__all__ = ["screen_then_confirm", "CONFIRM_MIN_GAIN", "AMBIGUITY_MARGIN", "SEARCH_PROMOTE",
           "REPLICATE", "STIFFER", "REALISATION_MARGIN", "SPEED_CHECK_SIGMAS",
           "replicate_overrides", "NUMERICS_RADIUS_SCALES", "LEVEL_BEDS", "SEARCH_TIER_LEVEL_BEDS"]

#: a full simulation must raise the overall score over the baseline by this much to confirm
CONFIRM_MIN_GAIN = 0.02
#: two decisive full runs of different effects within this Delta BIC of each other are not
#: told apart (Kass & Raftery 1995: 0-2 is "not worth more than a bare mention"); neither is
#: named unless the screening claimed one of them. With replicates the margin is at least their
#: scatter (``_realisation_floor``: the sample standard deviation of their Delta BIC), the
#: scatter one realisation puts on each run's Delta BIC: measured 3.7-15.7 on the 28 searched
#: DEM / Yade / raw-Yade recordings; the three recordings with two decisive effects there had
#: gaps of 8.3-29.7 against scatters of 5.6-8.9 (all named as before), a Yade 5 m floor
#: recording 2.8 against 7.6 (a wrong name, layering, without it)
AMBIGUITY_MARGIN = 2.0
#: full-model search on a separate (cheaper) simulator: this many leading effects that beat
#: its baseline decisively are run with the full simulator
SEARCH_PROMOTE = 2
#: name of the whole-bed stiffness runs (``catalogue.stiffer_soil_overrides``): like the
#: replicates they stand for no new physics, and an effect has to fit better than they do
STIFFER = "stiffer_soil"
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
#: a measured impact-speed offset of at least this many standard deviations (and
#: ``SPEED_OFFSET_MIN_FRACTION`` of the speed: ``diagnosis._speed_found``) is model-free evidence
#: for ``initial_conditions`` (like the sensor check): the claim stands whatever the soil
#: model's realisation scatter (the screening names it by the same rule)
SPEED_CHECK_SIGMAS = SPEED_OFFSET_SIGMAS

#: the numerics check of a named searched value: its search levels run again with the grain
#: radius times each of these factors (on the simulator the search ran on), and the value
#: each profile locates is compared with the one at the simulation's own grains. A recording
#: comes from a soil whose grains the model's coarse-grained ones stand for only to about
#: ten per cent, and from another code; the realisation interval samples packings only.
NUMERICS_RADIUS_SCALES = (0.9, 1.1)

#: the grain check of a named soil effect (``screen_then_confirm(..., grain_check=...)``, CLI
#: ``--grain-check``): the whole confirmation made again with every run's grain radius times
#: each of these factors (its own baseline, replicates, search levels and candidates), and the
#: soil effect named only when they name it too (``GRAIN_CHECK_AGREE``). Off by default (``()``):
#: measured, it keeps 7 of 9 right names and 1 of 5 wrong ones with "any", and breaks the
#: 15-minute budget at the default resolution (docs/diagnosis.md, "The grain check")
GRAIN_CHECK_SCALES: tuple[float, ...] = ()
#: how many of the grain check's factors must name the effect: "all", or "any" (at least one:
#: with the model's own grains, two of three grain sizes)
GRAIN_CHECK_AGREE = "all"

#: the grain fit (``screen_then_confirm(..., grain_fit=...)``, CLI ``--grain-fit``): the
#: baseline and its replicate packings run again with the grain radius times each factor, and
#: when one grain size fits the recording decisively better than the model's own
#: (``GRAIN_FIT_MARGIN``), the whole confirmation is made at that grain size. The grain size
#: of a coarse-grained DEM soil is a numerics choice that the recording's soil does not fix,
#: and another code's recording answers differently at different grain sizes (measured on
#: Yade at 13.7 m, docs/diagnosis.md "The grain fit"). Off by default (``()``)
GRAIN_FIT_SCALES: tuple[float, ...] = ()
#: how much lower (BIC, mean over the baseline's realisations) another grain size must fit the
#: recording than the model's own grains for the grain fit to move to it
GRAIN_FIT_MARGIN = 6.0
#: ... and by this many standard errors of the difference of the two means (their realisations'
#: sample standard deviations): a grain size is not taken on a difference the packing scatter
#: makes. With both standard deviations at most 4, two standard errors stay below
#: ``GRAIN_FIT_MARGIN``; on the Yade sets' small bed null 24 moves to 1.25 x by 5.4 standard
#: errors (sd 4-10), as without the rule. At the default resolution (sd 10-22) a full-model
#: grain fit took 0.8 x on a recording of 1.25 x grains by 1.9 standard errors and then named
#: a floor on it (docs/diagnosis.md "The grain fit")
GRAIN_FIT_SE = 2.0

#: the law fit (``screen_then_confirm(..., law_fit=...)``, CLI ``--law-fit``): the baseline
#: and its replicate packings run again on their own beds with the other contact law
#: (``law_fit_law``; the command line takes Hertz-Mindlin for a linear scenario and the
#: reverse) at each factor on the grains' modulus in the impact (``soil.impact_young_factor``),
#: and when one fits the recording decisively better than the scenario's law (the grain fit's
#: rule: ``GRAIN_FIT_MARGIN`` and ``GRAIN_FIT_SE``), the whole confirmation is made with every
#: run in that law at that modulus. The contact law of a coarse-grained DEM soil is a model form
#: that the recording's soil does not fix, and most DEM codes use Hertz-Mindlin where this one
#: (after the thesis) uses linear springs; measured on Yade's Hertz-Mindlin recordings with the
#: recording's law in the model: no wrong name and no null claim on 30, against one of each with
#: the linear law (docs/diagnosis.md "The law fit"). The scenario's own law is rated at the same
#: moduli too (``law_fit_stiffness``), and the other law is taken only when it also beats that
#: law's best modulus (session 53). Off by default (``()``)
LAW_FIT_FACTORS: tuple[float, ...] = ()
#: the scenario keys the law fit sets on every run of the other law
LAW_KEY = "soil.contact_law"
IMPACT_YOUNG_KEY = "soil.impact_young_factor"
#: the name of the scenario's own contact law in the law fit's entries (``fit.law_fit.laws``)
OWN_LAW = "scenario"

#: beds per search level of an effect whose levels deposit their own bed
#: (``FullSearch.deposits``: a floor or interface depth): the level's runs with the baseline's
#: packing seed and the first ``LEVEL_BEDS - 1`` replicate seeds, each taken as its change
#: against the baseline run of the same seed (the replicate), and the changes averaged. One bed
#: per level left the level-to-level packing scatter (measured +-10-15 Delta BIC on the small
#: bed, docs/diagnosis.md) above the replicates' ambiguity margin
LEVEL_BEDS = 5
#: the same on a separate (coarser) search simulator, where the default stays one bed per level.
#: Measured on the default CLI path (13.7 m Yade recordings, 0.075 m grains in a 2 m tank, the
#: search at 0.10 m): with 5 beds the coarse floor levels at 0.6-0.7 m rose above the coarse
#: replicates (Delta BIC 38-41 against 26-36) on both the floor recording 12 (0.764 m: named at
#: 0.6 m, -21 %) and the layering recording 11 (0.325 m, E x7.3: named a floor at 0.6 m, wrong),
#: and the full-resolution run that confirms a promoted level has no replicate floor of its own;
#: with one bed both name nothing, as before
SEARCH_TIER_LEVEL_BEDS = 1

Row = dict[str, Any]
Request = tuple[str, dict[str, Any], "float | None"]


def replicate_overrides(seed: int, n: int) -> list[dict[str, Any]]:
    """Overrides of ``n`` replicate realisations of a baseline whose packing seed is ``seed``:
    ``scenario.seed`` = seed + 1 ... seed + n (``screen_then_confirm``'s ``replicates``)."""
    return [{"scenario.seed": int(seed) + i} for i in range(1, int(n) + 1)]


def screen_then_confirm(baseline_signals: Mapping[str, Signal],
                        recording_signals: Mapping[str, Signal],
                        full_simulator: Simulator, *, top_k: int = 2,
                        full_search: bool | Mapping[str, catalogue.FullSearch] = True,
                        search_simulator: Simulator | None = None,
                        replicates: Sequence[Mapping[str, Any]] = (),
                        numerics: Sequence[float] = NUMERICS_RADIUS_SCALES,
                        level_beds: int | None = None,
                        grain_check: Sequence[float] = GRAIN_CHECK_SCALES,
                        grain_agree: str = GRAIN_CHECK_AGREE,
                        grain_fit: Sequence[float] = GRAIN_FIT_SCALES,
                        grain_fit_simulator: Simulator | None = None,
                        law_fit: Sequence[float] = LAW_FIT_FACTORS,
                        law_fit_law: str = "hertz_mindlin",
                        law_fit_stiffness: Sequence[float] | None = None,
                        bed_floor: catalogue.BedFloor | None = None,
                        **diagnose_kw) -> Report:
    """ROM screening, then confirmation of the top-k hypotheses with the expensive simulator.

    Parameters
    ----------
    baseline_signals, recording_signals : as for :func:`crashdem.diagnosis.diagnose`
    full_simulator : ``f(overrides: dict) -> dict[str, Signal]`` taking *scenario* keys
        (``physics.<name>.*``, ``calibration.*_scale``), e.g. a wrapper around ``crashdem.run``;
        when it has a ``map(list_of_overrides) -> list_of_signals`` method (e.g.
        ``distributed.DaskFullSimulator``) the runs are requested as one batch
    top_k : number of missing-physics hypotheses confirmed (each costs one full simulation)
    full_search : also run, unless a model-free sensor answer stands, every effect of the
        catalogue's ``full_search`` (or of the mapping given) at its levels in the full model's
        own terms (``catalogue.FullSearch``; drop: 24 levels, 34 runs with the two forms of
        the layering and of the contact damping) plus one refinement run of the leading
        effect; each effect is then judged by its best run
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
    numerics : grain-radius factors of the numerics check of a named searched value
        (``NUMERICS_RADIUS_SCALES``; ``()`` skips it): the named effect's search levels run
        again at each (on the simulator the search ran on), and the reported uncertainty is at
        least how far the value each profile locates lies from the one at the simulation's own
        grains (``hypotheses[*].full_model.numerics``, ``fit.full_search.named.numerics``)
    level_beds : beds per search level of an effect whose levels deposit their own bed
        (``FullSearch.deposits``; at most 1 + the number of replicates; default
        ``LEVEL_BEDS``, or ``SEARCH_TIER_LEVEL_BEDS`` with a ``search_simulator``): bed
        0 is the level with the baseline's packing seed, bed j the level with replicate j's
        overrides. The level's prediction is the baseline plus the mean over its beds of the
        run's change against the baseline run of the same bed (the baseline, replicate j), so
        the packing scatter between the levels of a deposited effect falls with the number of
        beds while each level still carries one realisation's scatter against the recording,
        as every other run does. 1: one bed per level
    grain_check : grain-radius factors of the grain check of a named soil effect
        (``GRAIN_CHECK_SCALES``; ``()`` skips it): when a soil effect is named (not a
        model-free answer, nor with a filter-class mismatch), the whole confirmation is made
        again at each factor -- the baseline run, the screening on it, the replicates, the
        search levels, the candidates and the numerics check, every run with the grain radius
        times the factor -- and the effect stays named only when each of these names it too
        (``grain_agree="all"``) or at least one does (``"any"``); otherwise it is withdrawn
        and the decision taken again without it (a rival it leaves named meets the same rule).
        The factors run in turn, and only while the answer is open. ``fit.grain_check``
        records each factor's answer and runs
    grain_agree : "all" or "any", see ``grain_check``
    grain_fit : grain-radius factors of the grain fit (``GRAIN_FIT_SCALES``; ``()`` skips
        it): unless the answer is model-free or the recording is at another filter class, the
        baseline and its replicates (the realisations of the realisation floor, on the
        simulator the search ran on, anchored as its runs are) run again at each factor, and
        each grain size is rated by the mean BIC of its realisations against the recording.
        When another size beats the model's own grains decisively (``grain_choice``: by
        ``GRAIN_FIT_MARGIN`` and by ``GRAIN_FIT_SE`` standard errors), the confirmation
        is made again with every run at that grain size (as one factor of the grain check)
        and its answer is the report's; the grain radius is then part of the recalibration
        (``fit.grain_fit``: each size's BIC, the size chosen, the answer at the model's
        grains and the baseline's score there; ``fit.before`` stays the scenario's own
        baseline). The grain check then scales from the chosen grain size
    grain_fit_simulator : run the grain fit's realisations on this simulator instead of the
        one the search ran on (e.g. the scenario's own grains in the coarse tier's smaller
        container, when the search runs on a coarse tier whose grain radius is not the
        scenario's): every realisation at every size, the model's grains too, each anchored on
        the baseline simulation through this simulator's own baseline run at the model's
        grains (``fit.grain_fit.simulator``)
    law_fit : the grains' impact modulus factors (``soil.impact_young_factor``, absolute) of
        the law fit (``LAW_FIT_FACTORS``; ``()`` skips it): after the grain fit, and under the
        same conditions, the baseline's realisations run again on the simulator the search ran
        on with the contact law ``law_fit_law`` at each factor (and in the scenario's own law
        at each factor of ``law_fit_stiffness``), each rated like a grain size; when one beats
        the scenario's law decisively (``law_choice``), the confirmation is made again with
        every run in that law at that modulus (in the other law, the realisation floor's own
        run of that law, ``FullSearch.hertz_floor``, is left out) and its answer is the
        report's; the law and modulus are then part of the recalibration (``fit.law_fit``:
        each law's BIC, the one chosen, the answer at the scenario's law; ``fit.before`` stays
        the scenario's own baseline). The grain check then runs in the law taken
    law_fit_law : the other contact law of the law fit (``CONTACT_LAWS``)
    law_fit_stiffness : the impact modulus factors (absolute) at which the law fit also rates
        the scenario's own law (None: those of ``law_fit`` other than 1; ``()``: none). The
        other law is then taken only when it also beats the scenario's law at its best-rated
        modulus decisively; when the scenario's law at another modulus is what beats it, the
        law stands and that modulus is taken: a recalibration of the soil's stiffness, made as
        the law's is (``law_choice``). A law fit without them cannot tell a contact law from
        a stiffness (measured on Yade's linear recordings: 9 of 12 moved to Hertz-Mindlin)
    bed_floor : the realisation floor's stiffer soil when the layering is not searched
        (``catalogue.BedFloor``; the command line gives it for a scenario with its own
        layering): the whole bed made stiffer through the grains' impact modulus, and in the
        Hertz-Mindlin law, on each bed of a deposited level, run beside the replicates as the
        layering's stiffness form runs them otherwise (``_Confirmation.stiffer_requests``).
        None: no stiffer soil in the floor when the layering is not searched. After a law fit
        that takes the other law its Hertz-Mindlin run is left out, as ``FullSearch.hertz_floor``
    diagnose_kw : passed to :func:`crashdem.diagnosis.diagnose`

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
    if grain_agree not in ("all", "any"):
        raise ValueError(f"grain_agree={grain_agree!r}: must be 'all' or 'any' (how many of the "
                         "grain check's factors must name the effect)")
    if law_fit_law not in CONTACT_LAWS:
        raise ValueError(f"law_fit_law={law_fit_law!r}: must be one of {', '.join(CONTACT_LAWS)}"
                         " (the other contact law of the law fit)")
    if law_fit_stiffness is None:
        law_fit_stiffness = tuple(float(k) for k in law_fit if float(k) != 1.0)
    lo, hi = impact_young_range()
    for name, factors in (("law_fit", law_fit), ("law_fit_stiffness", law_fit_stiffness)):
        bad = [k for k in factors if not lo <= float(k) <= hi]
        if bad:
            raise ValueError(f"{name}={tuple(factors)!r}: factor {bad[0]!r} is outside "
                             f"[{lo:g}, {hi:g}] (the grains' impact modulus factor, "
                             f"{IMPACT_YOUNG_KEY})")
    if level_beds is None:
        level_beds = SEARCH_TIER_LEVEL_BEDS if search_simulator is not None else LEVEL_BEDS
    if isinstance(level_beds, bool) or not isinstance(level_beds, int) or level_beds < 1:
        raise ValueError(f"level_beds={level_beds!r}: must be an integer >= 1 (beds per search "
                         "level of an effect that deposits its own bed)")
    p = _confirm_pass(baseline_signals, recording_signals, full_simulator, search_simulator,
                      top_k=top_k, full_search=full_search, replicates=replicates,
                      level_beds=level_beds, numerics=numerics, bed_floor=bed_floor,
                      **diagnose_kw)
    fitted = None
    if grain_fit and not p.c.model_free and not p.c.cfc_key:
        fitted = _grain_fit(p, grain_fit, replicates, grain_fit_simulator)
        if fitted["chosen"] != 1.0:
            f = fitted["chosen"]
            at_model = p
            # the grain check below scales from the grain size taken
            p, full_simulator, search_simulator = _scaled_pass(
                f, recording_signals, full_simulator, search_simulator, top_k=top_k,
                full_search=full_search, replicates=replicates, level_beds=level_beds,
                numerics=numerics, bed_floor=bed_floor, **diagnose_kw)
            _moved(fitted, "at_model_grains", "grain_fit", at_model, p,
                   _runs_made(full_simulator, search_simulator))
    lawed = None
    if law_fit and not p.c.model_free and not p.c.cfc_key:
        lawed = _law_fit(p, law_fit, law_fit_law, replicates, law_fit_stiffness)
        if lawed["chosen"] is not None:
            k = lawed["chosen"]["impact_young_factor"]
            taken = law_fit_law if lawed["chosen"]["contact_law"] != OWN_LAW else None
            at_model = p
            if taken is not None:
                full_search = _without_hertz_floor(full_search)
                if bed_floor is not None:
                    bed_floor = replace(bed_floor, hertz=None)
            p, full_simulator, search_simulator = _varied_pass(
                lambda sim: _LawSwitched(sim, taken, k), recording_signals,
                full_simulator, search_simulator, top_k=top_k, full_search=full_search,
                replicates=replicates, level_beds=level_beds, numerics=numerics,
                bed_floor=bed_floor, **diagnose_kw)
            _moved(lawed, "at_model_law", "law_fit", at_model, p,
                   _runs_made(full_simulator, search_simulator))
    rep, c, full, tier, d, checks = p.rep, p.c, p.full, p.tier, p.d, p.checks
    answers: dict[float, dict[str, Any]] = {}

    def answer(f: float) -> dict[str, Any]:
        """The confirmation at grain factor ``f`` (made once, when first asked)."""
        if f not in answers:
            answers[f] = _grain_decision(
                f, recording_signals, full_simulator, search_simulator, top_k=top_k,
                full_search=full_search, replicates=replicates, numerics=numerics,
                level_beds=level_beds, bed_floor=bed_floor, **diagnose_kw)
        return answers[f]

    def holds(name: str) -> bool:
        agree = all if grain_agree == "all" else any
        return agree(answer(float(f))["named"] == name for f in grain_check)

    while grain_check and c.grain_checked(d) and not holds(d.confirmed):
        c.withdrawn = {**c.withdrawn,
                       d.confirmed: _grain_verdict(list(answers.values()), grain_agree)}
        d = c.decide(full, tier)
        if c.grain_checked(d) and d.confirmed not in {ch["hypothesis"] for ch in checks}:
            d, more = _numerics_decision(c, d, full, tier, p.search_sim, numerics)
            checks += more
    c.record(full, tier, d, p.t_full)
    for check in checks:
        c.numerics_record(check, d)
    if answers:
        rep.fit["grain_check"] = {"agree": grain_agree, "factors": list(answers.values())}
        rep.simulations["grain_check_simulations"] = sum(g["runs"] for g in answers.values())
    if fitted is not None:
        rep.fit["grain_fit"] = fitted
        rep.simulations["grain_fit_simulations"] = fitted["runs"]
        if fitted["chosen"] != 1.0:  # the grain size taken is a recalibration of the model's
            for h in rep.hypotheses:
                if h["name"] == RECALIBRATION.name:
                    h["grain_radius_scale"] = fitted["chosen"]
    if lawed is not None:
        rep.fit["law_fit"] = lawed
        rep.simulations["law_fit_simulations"] = lawed["runs"]
        if lawed["chosen"] is not None:  # so is the law taken (or kept), at its modulus
            for h in rep.hypotheses:
                if h["name"] == RECALIBRATION.name:
                    if lawed["chosen"]["contact_law"] != OWN_LAW:
                        h["contact_law"] = law_fit_law
                    h["impact_young_factor"] = lawed["chosen"]["impact_young_factor"]
    return rep


def _moved(fitted: dict[str, Any], at: str, name: str, at_model: _Pass, p: _Pass,
           runs: int) -> None:
    """Record in a realisation fit's entry ``fitted`` (the grain fit's, the law fit's) that the
    confirmation ``p`` was made again in the variant it took: the answer of the confirmation
    ``at_model`` before it under ``at``, the ``runs`` of ``p`` added, and ``p``'s report given
    the scenario's own baseline as ``fit.before`` (its own kept as ``before_at_<name>``)."""
    fitted[at] = {"named": at_model.d.confirmed,
                  "ambiguous": list(at_model.d.ambiguous) if at_model.d.ambiguous else None,
                  "before": at_model.rep.fit["before"],
                  "full_simulations": at_model.rep.simulations.get("full_simulations")}
    fitted["runs"] += runs
    for key in ("before", "residual_rms_sigma_before"):
        p.rep.fit[f"{key}_at_{name}"] = p.rep.fit[key]
        p.rep.fit[key] = at_model.rep.fit[key]


def _grain_fit(p: _Pass, factors: Sequence[float], replicates: Sequence[Mapping[str, Any]],
               tier_sim: Simulator | None = None) -> dict[str, Any]:
    """The grain fit of ``screen_then_confirm``: the baseline's realisations (its own packing
    and the replicates) at each grain-radius factor, rated by ``_realisation_fit`` on the
    simulator the search ran on or on ``tier_sim``; the factor taken is ``grain_choice``'s."""
    variants: list[tuple[dict[str, Any], Callable[[Simulator], _Varied]]] = [
        ({"radius_scale": 1.0}, _Varied)]
    variants += [({"radius_scale": f}, lambda sim, f=f: _GrainScaled(sim, f))
                 for f in (float(x) for x in factors) if f != 1.0]
    sizes, runs, where = _realisation_fit(p, variants, replicates, tier_sim)
    return {"sizes": sizes, "margin_bic": GRAIN_FIT_MARGIN, "se_factor": GRAIN_FIT_SE,
            "chosen": grain_choice(sizes), "runs": runs, "simulator": where}


def _law_fit(p: _Pass, factors: Sequence[float], law: str,
             replicates: Sequence[Mapping[str, Any]], own_factors: Sequence[float] = ()
             ) -> dict[str, Any]:
    """The law fit of ``screen_then_confirm``: the baseline's realisations in the scenario's
    own law (``OWN_LAW``), in that law at each impact modulus factor of ``own_factors``, then
    in contact law ``law`` at each factor of ``factors``, rated by ``_realisation_fit`` on the
    simulator the search ran on; the one taken is ``law_choice``'s (None: the scenario's law
    stands at its modulus)."""
    variants: list[tuple[dict[str, Any], Callable[[Simulator], _Varied]]] = [
        ({"contact_law": OWN_LAW, "impact_young_factor": None}, _Varied)]
    variants += [({"contact_law": OWN_LAW, "impact_young_factor": float(k)},
                  lambda sim, k=float(k): _LawSwitched(sim, None, k)) for k in own_factors]
    variants += [({"contact_law": law, "impact_young_factor": float(k)},
                  lambda sim, k=float(k): _LawSwitched(sim, law, k)) for k in factors]
    laws, runs, where = _realisation_fit(p, variants, replicates, None)
    chosen = law_choice(laws)
    return {"law": law, "laws": laws, "margin_bic": GRAIN_FIT_MARGIN, "se_factor": GRAIN_FIT_SE,
            "chosen": chosen, "law_undecided": _law_undecided(laws, chosen), "runs": runs,
            "simulator": where}


def _law_undecided(laws: list[dict[str, Any]], chosen: dict[str, Any] | None
                   ) -> dict[str, Any] | None:
    """When the law fit kept the scenario's law (``chosen`` None or ``OWN_LAW``) although the
    other law at some modulus fits better than the scenario's law at its best modulus (after
    ``law_choice``: ``delta_bic_vs_own_law`` > 0), that best entry of the other law (its
    modulus, Delta BIC and standard error): the recording does not tell the two laws apart.
    None otherwise."""
    if chosen is not None and chosen["contact_law"] != OWN_LAW:
        return None
    better = [s for s in laws if (s.get("delta_bic_vs_own_law") or 0.0) > 0.0]
    if not better:
        return None
    b = max(better, key=lambda s: s["delta_bic_vs_own_law"])
    return {"contact_law": b["contact_law"], "impact_young_factor": b["impact_young_factor"],
            "delta_bic_vs_own_law": b["delta_bic_vs_own_law"], "se_vs_own_law": b["se_vs_own_law"]}


def _realisation_fit(p: _Pass, variants: Sequence[tuple[dict[str, Any],
                                                        Callable[[Simulator], _Varied]]],
                     replicates: Sequence[Mapping[str, Any]], tier_sim: Simulator | None
                     ) -> tuple[list[dict[str, Any]], int, str]:
    """The baseline's realisations (its own packing and the replicates) run as each model
    variant of ``variants`` (``(entry, wrap)``: the entry's keys name it in the report, ``wrap``
    makes its simulator; the first is the model's own), each variant rated by the mean BIC of
    its realisations against the recording (``_Confirmation.bic`` of its weighted residual, no
    parameter). The runs are made on the simulator the search ran on (anchored on the baseline
    simulation through that simulator's own baseline run when it is a separate tier), or on
    ``tier_sim`` when given (every realisation of every variant, anchored through its own
    baseline run of the model's variant). Without ``tier_sim`` the model's variant's first
    realisation is the baseline simulation itself, and its runs are those the confirmation
    made already (``_reused_realisations``): only the other variants run. Returns each rated
    variant's entry (with ``bic_mean``, ``bic_sd``, ``score_mean``, ``realisations``,
    ``bics``), the runs made and where they ran."""
    c = p.c
    own_tier = tier_sim is not None
    sim = tier_sim if own_tier else p.search_sim
    anchor = p.tier.rows[0] if p.tier is not None and not own_tier else None
    reals: list[dict[str, Any]] = [{}, *[dict(r) for r in replicates]]
    rated: list[dict[str, Any]] = []
    runs = 0
    for i, (entry, wrap) in enumerate(variants):
        own = i == 0
        todo = reals if (not own or anchor is not None or own_tier) else reals[1:]
        rows = _reused_realisations(c, len(todo)) if own and not own_tier else None
        if rows is None:
            varied = wrap(sim)
            outs = _run_full(varied, [(REPLICATE, ov) for ov in todo])
            runs += varied.n
            rows = [c.row(REPLICATE, ov, None, o) for ov, o in zip(todo, outs)]
        if own_tier and own:
            if "aligned" not in rows[0]:
                raise RuntimeError("the grain fit's tier: its baseline run at the model's grains "
                                   f"failed ({rows[0].get('error', 'no signals')}), so no run "
                                   "can be anchored on it")
            anchor = rows[0]
        if anchor is not None:
            rows = [c.anchored(r, anchor) for r in rows]
        bics = [c.bic(r["rss"], 0) for r in rows if "rss" in r]
        scores = [r["score"] for r in rows if "rss" in r]
        if own and anchor is None:
            bics.insert(0, c.bic(_full_rss(c.rep, c.rep.baseline), 0))
            scores.insert(0, float(c.rep.fit["before"]["overall"]))
        if not bics:
            continue
        rated.append({**entry, "bic_mean": float(np.mean(bics)),
                      "bic_sd": float(np.std(bics, ddof=1)) if len(bics) > 1 else None,
                      "score_mean": float(np.mean(scores)), "realisations": len(bics),
                      "bics": [float(b) for b in bics]})
    where = ("grain-fit tier (anchored)" if own_tier else
             "search tier (anchored)" if anchor is not None else "full")
    return rated, runs, where


def grain_choice(sizes: list[dict[str, Any]]) -> float:
    """The grain-radius factor the grain fit takes from its sizes (``radius_scale``,
    ``bic_mean``, ``bic_sd`` or None, ``realisations``): another size than the model's (1)
    only when it beats the model's mean BIC decisively (``_beating_model``); of those, the one
    nearest the model's grains (the realisation means scatter by a few Delta BIC between
    neighbouring grain sizes; moving further is not supported). Each size gets its
    ``delta_bic_vs_model`` and ``se_vs_model``. 1 when the model's grains were not rated."""
    own = next((s for s in sizes if s["radius_scale"] == 1.0), None)
    if own is None:
        return 1.0
    near = _beating_model(sizes, own)
    if not near:
        return 1.0
    return float(min(near, key=lambda s: abs(math.log(s["radius_scale"])))["radius_scale"])


def law_choice(laws: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The contact law and modulus the law fit takes from its entries (``_law_fit``: the
    scenario's law (``OWN_LAW``) first, ``impact_young_factor`` None; then that law at other
    moduli, and the other law at its moduli). Another entry only when it beats the scenario's
    own decisively (``_beating_model``); of those (all within the margin of the best BIC,
    which does not tell them apart), the one the recording rates best (mean ISO/TS 18571 score
    of its realisations). The other law is taken only when it also beats the scenario's law at
    its best modulus decisively (the same rule, ``delta_bic_vs_own_law`` and
    ``se_vs_own_law`` on each of its entries). Otherwise the law stands, and of its moduli
    that beat the scenario's own decisively and lie within the margin of its best, the best
    rated is taken (its stiffness is recalibrated), or none: a better fit in the other law that
    the scenario's law at another modulus matches within the packings' scatter does not tell a
    law from a stiffness, and the stiffness is the parameter the model has. Measured on a Yade
    Hertz-Mindlin null (13.7 m, seed 30), the other law alone: 4 and 8 x the modulus within 5.6
    in BIC, rated 0.755 and 0.701 (the truth: 4 x); on the 24 rated Yade recordings at 13.7 m
    the other law was taken on 4 of 12 Hertz-Mindlin and 1 of 12 linear recordings, 12 and 9
    without the scenario's law at the same moduli (docs/diagnosis.md). Each entry gets its
    ``delta_bic_vs_model`` and ``se_vs_model``. None: the scenario's law stands at its own
    modulus (also when it was not rated)."""
    own = next((s for s in laws if s["impact_young_factor"] is None), None)
    if own is None:
        return None
    near = _beating_model(laws, own)
    same = [s for s in laws if s["contact_law"] == own["contact_law"]]
    best_own = min(same, key=lambda s: s["bic_mean"])
    other = [s for s in laws if s["contact_law"] != own["contact_law"]]
    if len(same) > 1:
        for s in other:
            s["delta_bic_vs_own_law"] = best_own["bic_mean"] - s["bic_mean"]
            s["se_vs_own_law"] = _se_of_difference(best_own, s)
    pick = [s for s in near if s in other and _decisive_over(s, best_own)]
    if not pick:  # the law stands; a modulus of it that beats its own, near its best
        pick = [s for s in same if _decisive_over(s, own)
                and s["bic_mean"] - best_own["bic_mean"] <= GRAIN_FIT_MARGIN]
    if not pick:
        return None
    best = max(pick, key=lambda s: s["score_mean"])
    return {"contact_law": best["contact_law"],
            "impact_young_factor": best["impact_young_factor"]}


def _beating_model(entries: list[dict[str, Any]], own: dict[str, Any]) -> list[dict[str, Any]]:
    """The entries of a realisation fit (``_realisation_fit``) that beat the model's own
    ``own`` decisively (``_decisive_over``) and lie within the margin of the best; every entry
    gets its ``delta_bic_vs_model`` and ``se_vs_model``."""
    for s in entries:
        s["delta_bic_vs_model"] = own["bic_mean"] - s["bic_mean"]
        s["se_vs_model"] = _se_of_difference(own, s)
    best = min(s["bic_mean"] for s in entries)
    return [s for s in entries if _decisive_over(s, own)
            and s["bic_mean"] - best <= GRAIN_FIT_MARGIN]


def _decisive_over(s: Mapping[str, Any], ref: Mapping[str, Any]) -> bool:
    """Whether realisation-fit entry ``s`` beats ``ref`` by ``GRAIN_FIT_MARGIN`` in mean BIC
    and by ``GRAIN_FIT_SE`` standard errors of the difference (``_se_of_difference``)."""
    d = ref["bic_mean"] - s["bic_mean"]
    return d > GRAIN_FIT_MARGIN and d > GRAIN_FIT_SE * _se_of_difference(ref, s)


def _se_of_difference(a: Mapping[str, Any], b: Mapping[str, Any]) -> float:
    """Standard error of the difference of two grain sizes' mean BICs (``_grain_fit``'s
    entries: each realisation's sample standard deviation over the square root of their
    number; 0 for a size with one realisation, whose scatter is not known)."""
    if a is b:
        return 0.0
    var = sum((x["bic_sd"] or 0.0) ** 2 / x["realisations"] for x in (a, b))
    return math.sqrt(var)


def _reused_realisations(c: _Confirmation, n: int) -> list[Row] | None:
    """The grain fit's ``n`` realisations at the model's grains as the confirmation ran them
    (``_Confirmation.realisation_rows``: the search simulator's baseline run when it is a
    separate tier, then the replicates), or None when it did not run them all (the grain fit
    then runs them)."""
    got = c.realisation_rows
    return list(got) if got is not None and len(got) == n else None


@dataclass
class _Pass:
    """One confirmation made up to its decision: the screened report, its confirmation, the
    tiers, the decision after the numerics check, the checks made, the simulator the search
    ran on and the wall time of the tiers."""

    rep: Report
    c: _Confirmation
    full: _FullTier
    tier: _SearchTier | None
    d: _Decision
    checks: list[dict[str, Any]]
    search_sim: Simulator
    t_full: float


def _confirm_pass(baseline_signals: Mapping[str, Signal],
                  recording_signals: Mapping[str, Signal], full_simulator: Simulator,
                  search_simulator: Simulator | None, *, top_k: int,
                  full_search: bool | Mapping[str, catalogue.FullSearch],
                  replicates: Sequence[Mapping[str, Any]], level_beds: int,
                  numerics: Sequence[float], bed_floor: catalogue.BedFloor | None = None,
                  **diagnose_kw) -> _Pass:
    """The screening of ``recording_signals`` against ``baseline_signals``, the search and
    full tiers, the decision and the numerics check (``screen_then_confirm``'s steps before
    the grain check and the report; the grain check makes one per factor)."""
    rep = diagnose(baseline_signals, recording_signals, **diagnose_kw)
    c = _Confirmation(rep, top_k, full_search, diagnose_kw.get("hypotheses"), replicates,
                      level_beds, baseline_signals, bed_floor)
    t_full = time.perf_counter()
    tier = (c.search_tier(search_simulator) if c.searched and search_simulator is not None
            else None)
    full = c.full_tier(full_simulator, tier)
    t_full = time.perf_counter() - t_full
    d = c.decide(full, tier)
    search_sim = search_simulator if tier is not None else full_simulator
    d, checks = _numerics_decision(c, d, full, tier, search_sim, numerics)
    return _Pass(rep, c, full, tier, d, checks, search_sim, t_full)


def _numerics_decision(c: _Confirmation, d: _Decision, full: _FullTier,
                       tier: _SearchTier | None, sim: Simulator, numerics: Sequence[float]
                       ) -> tuple[_Decision, list[dict[str, Any]]]:
    """The decision after the numerics check: a named value the numerics cannot resolve is
    withdrawn and the decision taken again without it (each effect at most once); the checks
    made."""
    checks: list[dict[str, Any]] = []
    if not numerics:
        return d, checks
    for _ in range(len(c.searched)):
        check = c.numerics_runs(sim, tier, full, d, numerics)
        if check is None:
            break
        checks.append(check)
        why = c.unresolved(d, check)
        if why is None:
            break
        c.withdrawn = {**c.withdrawn, check["hypothesis"]: why}
        d = c.decide(full, tier)
    return d, checks


class _Varied:
    """A simulator whose every run has its overrides changed by ``scaled`` (here: unchanged,
    the model's own variant); ``n`` counts the runs made: each single run, and a ``map`` batch
    once it returns (a batch that raises is run again one by one by ``_run_full``, and those
    runs are the ones counted)."""

    def __init__(self, sim: Simulator):
        self.sim, self.n = sim, 0

    def scaled(self, overrides: Mapping[str, Any]) -> dict[str, Any]:
        return dict(overrides)

    def __call__(self, overrides: Mapping[str, Any]) -> Any:
        self.n += 1
        return self.sim(self.scaled(overrides))

    def map(self, batch: list[Mapping[str, Any]]) -> list[Any]:
        scaled = [self.scaled(ov) for ov in batch]
        if hasattr(self.sim, "map"):
            out = list(self.sim.map(scaled))  # type: ignore[attr-defined]
        else:
            out = [self.sim(ov) for ov in scaled]
        self.n += len(batch)
        return out


class _GrainScaled(_Varied):
    """A simulator whose every run has its grain radius times ``factor``
    (``RADIUS_SCALE_KEY``, multiplied into a factor the request already has)."""

    def __init__(self, sim: Simulator, factor: float):
        super().__init__(sim)
        self.factor = float(factor)

    def scaled(self, overrides: Mapping[str, Any]) -> dict[str, Any]:
        if self.factor == 1.0:  # the model's own grains: the very runs (and run-cache keys)
            return dict(overrides)
        return {**overrides,
                RADIUS_SCALE_KEY: self.factor * float(overrides.get(RADIUS_SCALE_KEY, 1.0))}


class _LawSwitched(_Varied):
    """A simulator whose every run is in contact law ``law`` (``LAW_KEY``; None: the law the
    request has, the scenario's) with the grains' impact modulus factor ``young_factor``
    (``IMPACT_YOUNG_KEY``, multiplied into a factor the request already has): the bed each run
    deposits, and its packing cache entry, stay the scenario's."""

    def __init__(self, sim: Simulator, law: str | None, young_factor: float):
        super().__init__(sim)
        self.law, self.young_factor = law, float(young_factor)

    def scaled(self, overrides: Mapping[str, Any]) -> dict[str, Any]:
        out = {**overrides, IMPACT_YOUNG_KEY:
               self.young_factor * float(overrides.get(IMPACT_YOUNG_KEY, 1.0))}
        if self.law is not None:
            out[LAW_KEY] = self.law
        return out


def _without_hertz_floor(full_search: bool | Mapping[str, catalogue.FullSearch]
                         ) -> bool | Mapping[str, catalogue.FullSearch]:
    """``full_search`` without the realisation floor's run of the other contact law
    (``FullSearch.hertz_floor``): in a confirmation made in the law the law fit took, that run
    is neither the other law nor at its calibrated modulus."""
    if not isinstance(full_search, Mapping):
        return full_search
    return {k: replace(fs, hertz_floor=None) if fs.hertz_floor is not None else fs
            for k, fs in full_search.items()}


def _grain_decision(factor: float, recording_signals: Mapping[str, Signal],
                    full_simulator: Simulator, search_simulator: Simulator | None,
                    **confirm_kw) -> dict[str, Any]:
    """One factor of the grain check: the confirmation made again (``_confirm_pass``), every
    run (the baseline first) with the grain radius times ``factor``; what it names and how
    many runs it made. The baseline's raw channels are not passed on (the check is not made
    with the recording at another filter class, ``_Confirmation.grain_checked``)."""
    t0 = time.perf_counter()
    p, full, search = _scaled_pass(factor, recording_signals, full_simulator,
                                   search_simulator, **confirm_kw)
    d = p.d
    return {"radius_scale": factor, "named": d.confirmed,
            "ambiguous": list(d.ambiguous) if d.ambiguous else None,
            "value": d.best.get("search_value") if d.confirmed else None,
            "score": d.best.get("score") if d.confirmed else None,
            "runs": _runs_made(full, search), "wall_time_s": time.perf_counter() - t0}


def _scaled_pass(factor: float, recording_signals: Mapping[str, Signal],
                 full_simulator: Simulator, search_simulator: Simulator | None,
                 **confirm_kw) -> tuple[_Pass, _Varied, _Varied | None]:
    """The confirmation made again with every run's grain radius times ``factor``, its
    baseline run first (the grain check's factor, the grain fit's size): the pass and its
    scaled full and search simulators. The baseline's raw channels are not passed on
    (neither is made with the recording at another filter class)."""
    kw = dict(confirm_kw)
    if isinstance(kw.get("full_search"), Mapping):
        # the top grain row of the levels' bed (the floor's bed stiffer below it) is one grain
        # diameter: it scales with the grains
        kw["full_search"] = {k: replace(fs, top_row_depth=fs.top_row_depth * float(factor))
                             if fs.top_row_depth is not None else fs
                             for k, fs in kw["full_search"].items()}
    return _varied_pass(lambda sim: _GrainScaled(sim, factor), recording_signals,
                        full_simulator, search_simulator, **kw)


def _varied_pass(wrap: Callable[[Simulator], _Varied], recording_signals: Mapping[str, Signal],
                 full_simulator: Simulator, search_simulator: Simulator | None,
                 **confirm_kw) -> tuple[_Pass, _Varied, _Varied | None]:
    """The confirmation made again with every run varied by ``wrap`` (a grain size, a contact
    law), its baseline run first: the pass and its varied full and search simulators. The
    baseline's raw channels are not passed on (no variant is made with the recording at
    another filter class)."""
    full = wrap(full_simulator)
    search = wrap(search_simulator) if search_simulator is not None else None
    kw = {k: v for k, v in confirm_kw.items() if k != "baseline_raw"}
    return _confirm_pass(full({}), recording_signals, full, search, **kw), full, search


def _runs_made(full: _Varied, search: _Varied | None) -> int:
    """The runs the varied simulators of ``_varied_pass`` have made."""
    return full.n + (search.n if search is not None else 0)


def _grain_verdict(grain: Sequence[Mapping[str, Any]], agree: str) -> str:
    """Why a soil effect named at the model's grains is withdrawn by the grain check."""
    each = "; ".join(f"{g['radius_scale']:g}x grains: "
                     + (g["named"] if g["named"] else
                        "nothing (" + " / ".join(g["ambiguous"]) + " not told apart)"
                        if g.get("ambiguous") else "nothing")
                     for g in grain)
    where = "at every grain size" if agree == "all" else "at any other grain size"
    return (f"the confirmation made again with the grain radius scaled does not name it "
            f"{where} ({each}): the answer is not resolved by the model's numerics")


@dataclass
class _SearchTier:
    """Outcome of the search tier: its rows (the search simulator's baseline run first), its
    realisation floor, the promoted levels as full-run requests, the candidates kept and the
    per-effect promotion verdicts."""

    rows: list[Row]
    floor: dict[str, float]
    promoted: list[Request]
    candidates: list[dict[str, Any]]
    verdicts: dict[str, str]
    #: the run that stands for each effect on the search tier (``standing``)
    standing: dict[str, Row] = field(default_factory=dict)
    #: the floor a screened claim is held to there (``_search_support``): the replicates, the
    #: stiffer-soil runs at the layer levels' own modulus factor only and the bed with the
    #: Hertz-Mindlin law (another code's realisation, no stiffness of its own); None: ``floor``
    claim_floor: dict[str, float] | None = None
    #: the verdict's words for the runs that raised ``claim_floor`` above the replicates'
    #: ("" when none did)
    claim_floor_stiffer: str = ""


@dataclass
class _FullTier:
    """Outcome of the full tier: every full run (the recalibrated run first), the reference
    score (the better of baseline simulation and recalibrated run) and the realisation floor."""

    rows: list[Row]
    reference: float
    floor: dict[str, float]


@dataclass
class _Decision:
    """What the confirmation names: ``confirmed`` (or None) and the run standing for the final
    answer (``best``: the recalibrated run when nothing is named), the screened claim's best
    run, whether it stood, the ambiguous pair and the best run of each effect."""

    confirmed: str | None
    best: Row
    screened: Row | None
    claim_stood: bool
    ambiguous: list[str] | None
    best_by_effect: dict[str, Row] = field(default_factory=dict)
    #: why the screening's claim did not stand on the search tier (None: it did, or not asked)
    unsupported: str | None = None
    #: a rival that out-ranks the effect about to be named in likelihood without being
    #: decisive (``_Confirmation._likelihood_rival``): then nothing is named
    contested: dict[str, Any] | None = None
    #: screened candidates whose full run was decisive but which do not hold on the search
    #: tier (``_Confirmation._search_support``), with why: not named
    unheld: dict[str, str] = field(default_factory=dict)
    #: the screening's claim stood by its score alone against a decisive rival that fits the
    #: recording with a higher likelihood, or by the lenient rule of a claim against a rival
    #: that beats it (and the realisation floor) in likelihood and score (``decide``): then
    #: neither is named
    outranked: bool = False


class _Confirmation:
    """One confirmation of a screened report: what is run, how a run is scored, what is named."""

    #: effects named, then withdrawn by the numerics check (``unresolved``), with the reason
    withdrawn: Mapping[str, str] = MappingProxyType({})

    def __init__(self, rep: Report, top_k: int,
                 full_search: bool | Mapping[str, catalogue.FullSearch],
                 allowed: Sequence[str] | None, replicates: Sequence[Mapping[str, Any]],
                 level_beds: int = 1, baseline_signals: Mapping[str, Signal] | None = None,
                 bed_floor: catalogue.BedFloor | None = None):
        self.rep = rep
        self.bed_floor = bed_floor
        self.chans = rep.channels
        self.primary = self.chans[0]
        by_name = {h["name"]: h for h in rep.hypotheses}
        self.recal = by_name[RECALIBRATION.name]
        fclass = rep.fit.get("filter_class") or {}
        # every full run is filtered at the recording's class (instrumentation.cfc), as the
        # screening compared it
        self.cfc_key = ({"instrumentation.cfc": float(fclass["class"])}
                        if fclass.get("mismatch") and fclass.get("class") is not None else {})
        # a sensor found by the model-free accelerometer/velocity check (or the noise
        # spectrum) needs no soil model: its full run only adds granular noise to the same
        # conclusion
        self.checked = (rep.missing_physics == "sensor_dynamics"
                        and (bool(rep.fit.get("sensor_check", {}).get("detected"))
                             or bool(fclass.get("mismatch"))))
        spd = rep.fit.get("impact_speed_check") or {}
        self.speed_measured = rep.missing_physics == "initial_conditions" and _speed_found(spd)
        self.model_free = ("the sensor check" if self.checked else
                           "the measured impact speed" if self.speed_measured else None)
        self.top_k = top_k
        self.skipped: dict[str, str] = {}
        self.candidates = self._candidates()
        # the search runs even when the recalibration explains the recording within the total
        # error: the screening model's error floor can hide what the full model resolves
        if self.checked or not full_search:
            searched: dict[str, catalogue.FullSearch] = {}
        elif isinstance(full_search, Mapping):
            searched = dict(full_search)
        else:
            searched = dict(rep.catalogue.full_search)
        if allowed is not None:
            searched = {k: v for k, v in searched.items() if k in allowed}
        self.searched = searched
        # the replicates only run when there is something for their floor to judge
        self.replicates = ([dict(rv) for rv in replicates]
                           if not self.checked and (searched or self.candidates) else [])
        self.n_eff = float(rep.fit["n_effective"])
        self.n_res = float(rep.fit["n_samples"])
        # the beds of a deposited level: the baseline's packing, then the replicates'
        self.beds: list[dict[str, Any]] = [{}] + self.replicates[:max(0, int(level_beds) - 1)]
        self.baseline_signals = baseline_signals
        # the runs each bed's change is taken against (set by the tier that runs the levels)
        self.bed_bases: list[Row] = []
        self.bed_anchor: Mapping[str, Signal] = rep.baseline
        # the level runs of the forms not kept (``choose_forms``) and each effect's choice
        self.form_rows: list[Row] = []
        self.forms_chosen: dict[str, dict[str, Any]] = {}
        # the whole-bed stiffness runs of the full tier (``stiffer_requests``), pooled per factor
        self.stiff_rows: list[Row] = []
        # the baseline's realisations run on the simulator the levels ran on, unanchored: that
        # simulator's baseline run when it is a separate tier (the full model's is the baseline
        # simulation itself, not a run), then the replicates' runs in their order (set by the
        # tier that ran them; the grain fit reads them at the model's grains,
        # ``_reused_realisations``)
        self.realisation_rows: list[Row] | None = None
        # what each simulator returned, by the overrides it ran (``outputs``): a run asked for
        # twice in one confirmation (the search's 0.15 m x5 stiffness level is the floor's bed
        # stiffer below its top grain row) is made once
        self._made: list[tuple[Simulator, dict[str, Any]]] = []

    def _candidates(self) -> list[dict[str, Any]]:
        """The screened hypotheses confirmed with a full run (at most ``top_k``), when the
        screening claims missing physics or the recalibration leaves an unexplained residual;
        one the full model cannot run is skipped (``skipped``) and the next takes its place.
        One whose full run would be the baseline simulation itself (every mapped parameter at
        its ``off`` value, the nominal put in its place included: a speed offset of 0) is not
        run either, unless it is the screening's claim, and keeps its place: the run would cost
        a full simulation and could only repeat the baseline (measured at the default
        resolution: the damping recording's second candidate, a 0 m/s offset, took a worker
        48 s to give the reference's own score, 0.832, and Delta BIC -3.1)."""
        rep = self.rep
        lacks = rep.catalogue.full_unsupported
        out: list[dict[str, Any]] = []
        if rep.missing_physics is None and not rep.fit.get("recalibration_unexplained", False):
            return out
        taken = 0
        for h in rep.hypotheses:
            missing = [e for e in h["name"].split("+") if e in lacks]
            if h["name"] == RECALIBRATION.name or taken == self.top_k:
                continue
            if missing:
                self.skipped[h["name"]] = lacks[missing[0]]
                continue
            taken += 1
            if h["name"] != rep.missing_physics and _runs_the_baseline(h, rep.catalogue):
                self.skipped[h["name"]] = ("its full run would be the baseline simulation (every "
                                           "mapped parameter at its off value)")
                continue
            out.append(h)
        return out

    # -- scoring a run -------------------------------------------------------------------

    def rated(self, al: Mapping[str, Signal]) -> Row:
        """Per-channel and overall scores of channels aligned on the recording."""
        rec = self.rep.recording
        win = tuple(self.rep.fit["score_window_s"])
        per = {ch: score_signals(rec[ch], al[ch], win) for ch in self.chans}
        return {"score": float(np.mean([v["score"] for v in per.values()])),
                "per_channel": per, "aligned": dict(al)}

    def bic(self, rss: float, k: int) -> float:
        """BIC of a weighted residual sum of squares with ``k`` fitted parameters."""
        return self.n_eff * math.log(max(rss, 1e-300) / self.n_res) + k * math.log(self.n_eff)

    def row(self, name: str, ov: dict[str, Any], x: float | None, out: Any) -> Row:
        """The scored row of a run (``out``: its signals, or the exception it raised)."""
        if isinstance(out, Exception):
            r: Row = {"hypothesis": name, "overrides": ov, "score": -math.inf, "error": str(out)}
        else:
            out = _si(out)
            rec = self.rep.recording
            shift = (onset_time(rec[self.primary], self.rep.noise[self.primary].sigma)
                     - onset_time(out[self.primary], 0.0))
            r = {"hypothesis": name, "overrides": ov,
                 **self.rated({ch: align(rec[ch], out[ch], shift) for ch in self.chans})}
        if x is not None:
            r["search_value"] = x
            form = (_stiffer_form(ov) if name == STIFFER else self.form_of(name, ov))
            if form is not None:
                r["form"] = form
        if "aligned" in r:
            r["rss"] = _full_rss(self.rep, r["aligned"])
        return r

    def form_of(self, name: str, ov: Mapping[str, Any]) -> str | None:
        """The form of a level run of effect ``name`` with the overrides ``ov``
        (``FullSearch.form_of``); None for an effect that is not searched."""
        fs = self.searched.get(name)
        return None if fs is None else fs.form_of(ov)

    def choose_forms(self, rows: list[Row]) -> list[Row]:
        """``rows`` with the level runs of every form but the best of each effect with
        ``forms`` left out (kept in ``form_rows``, counted as runs): the best form is the one
        whose best located level (``FullSearch.located``: short of the end where the effect
        fades; Delta BIC against the reference; the first form on a tie) fits the recording
        best -- by its best level of all when no form has a located one -- and ``searched``
        becomes that form alone (``FullSearch.with_form``), so the extension, refinement,
        numerics check and the decision see one profile per effect. ``forms_chosen`` records
        each form's best level. A level at the fading end is "a little of the effect", the
        shape a code or packing difference also takes: measured on a Yade layering at 13.7 m
        (stiffness-only, 0.26 m realised), the compacted form's 0.5 m level (Delta BIC 28.2)
        out-fitted the stiffness form's 0.25 m (20.6), and choosing by it left the layer
        unnamed where the stiffness form alone named it within 5 %."""
        keep = list(rows)
        for name in [n for n, fs in self.searched.items() if fs.forms]:
            fs = self.searched[name]
            best: dict[str, Row | None] = {}
            best_located: dict[str, Row | None] = {}
            for form, _ in fs.forms:
                lv = [r for r in keep if r["hypothesis"] == name and r.get("form") == form
                      and "delta_bic_vs_reference" in r]
                best[form] = max(lv, key=lambda r: r["delta_bic_vs_reference"], default=None)
                best_located[form] = max((r for r in lv if fs.located(r["search_value"])),
                                         key=lambda r: r["delta_bic_vs_reference"], default=None)
            by = best_located if any(b is not None for b in best_located.values()) else best
            ranked = [f for f, _ in fs.forms if by[f] is not None]
            if not ranked:
                continue
            chosen = max(ranked, key=lambda f: by[f]["delta_bic_vs_reference"])
            self.forms_chosen[name] = {
                "chosen": chosen,
                "by": "located level" if by is best_located else "level",
                "forms": {f: (None if b is None else
                              {"value": b["search_value"],
                               "delta_bic_vs_reference": b["delta_bic_vs_reference"],
                               "score": b["score"] if math.isfinite(b["score"]) else None,
                               "located_value": (None if best_located[f] is None else
                                                 best_located[f]["search_value"]),
                               "located_delta_bic": (
                                   None if best_located[f] is None else
                                   best_located[f]["delta_bic_vs_reference"])})
                          for f, b in best.items()}}
            self.form_rows += [r for r in keep if r["hypothesis"] == name and "form" in r
                               and r["form"] != chosen]
            keep = [r for r in keep if not (r["hypothesis"] == name and "form" in r
                                            and r["form"] != chosen)]
            self.searched[name] = fs.with_form(chosen)
        return keep

    def stiffer_requests(self) -> list[Request]:
        """Requests of the bed made stiffer by each of ``catalogue.STIFFER_SOIL_FACTORS``, whole
        and below its top grain row (``catalogue.stiffer_soil_depths``), on each bed of a
        deposited level (``catalogue.stiffer_soil_overrides``), when the layering is searched
        with its stiffness form; when the layering is not searched and a ``bed_floor`` is
        given (a scenario with its own layering), the whole bed made stiffer through the
        grains' impact modulus (``catalogue.BedFloor``) on each bed; else none."""
        lay = self.searched.get("soil_layering")
        out: list[Request] = []
        if lay is None and self.bed_floor is not None and self.searched:
            return [(STIFFER, {**ov, **rv, **self.cfc_key}, f)
                    for f, ov in self.bed_floor.overrides() for rv in self.beds]
        for below in catalogue.stiffer_soil_depths(lay):
            for f in catalogue.STIFFER_SOIL_FACTORS:
                ov = catalogue.stiffer_soil_overrides(lay, f, below)
                if ov is not None:
                    out += [(STIFFER, {**ov, **rv, **self.cfc_key}, float(f))
                            for rv in self.beds]
        ov = catalogue.hertz_floor_overrides(lay)
        if ov is not None:
            out += [(STIFFER, {**ov, **rv, **self.cfc_key}, float(lay.hertz_floor))
                    for rv in self.beds]
        return out

    def outputs(self, sim: Simulator, requests: list[Request]) -> list[Any]:
        """What ``sim`` returns for each request (``_run_full``: one batch when it has
        ``map``), each distinct set of overrides run once in this confirmation: a request
        whose overrides ``sim`` already ran here, or that comes twice in ``requests``, takes
        that run's output (a simulation is a function of its overrides: same inputs, same
        result). ``_n_distinct`` counts the runs behind rows the same way."""
        made = next((m for s, m in self._made if s is sim), None)
        if made is None:
            made = {}
            self._made.append((sim, made))
        keys = [_overrides_key(ov) for _, ov, _ in requests]
        todo: dict[str, tuple[str, dict[str, Any]]] = {}
        for (n, ov, _), k in zip(requests, keys):
            if k not in made and k not in todo:
                todo[k] = (n, ov)
        made.update(zip(todo, _run_full(sim, list(todo.values()))))
        return [made[k] for k in keys]

    def run(self, sim: Simulator, requests: list[Request]) -> list[Row]:
        """Scored rows of ``requests`` run on ``sim`` (``outputs``)."""
        outs = self.outputs(sim, requests)
        return [self.row(n, ov, x, o) for (n, ov, x), o in zip(requests, outs)]

    def level_requests(self, name: str, x: float) -> list[Request]:
        """Requests of the search level ``x`` of effect ``name``: one per bed when its levels
        deposit their own bed (``FullSearch.deposits``), else one."""
        fs = self.searched[name]
        beds = self.beds if fs.deposits else [{}]
        return [(name, {**v.overrides(x), **rv, **self.cfc_key}, float(x))
                for v in fs.variants() for rv in beds]

    def levels(self, names: Sequence[str]) -> list[Request]:
        """Requests of every search level of the effects ``names``."""
        return [q for n in names for x in self.searched[n].values
                for q in self.level_requests(n, x)]

    def pooled(self, rows: list[Row]) -> list[Row]:
        """``rows`` with the bed runs of each deposited level (and of each whole-bed stiffness
        factor, ``stiffer_requests``) replaced by one row (at the place of its first bed): the
        anchor (``bed_anchor``) plus the mean over the beds of the run's change against the run
        of the same bed in ``bed_bases`` (the baseline's, the replicates'). Beds whose run or
        base failed are left out of the mean; a level with no bed left is an error row. Nothing
        changes with one bed per level."""
        if len(self.beds) < 2:
            return rows
        order: list[Any] = []
        groups: dict[tuple[str, float, bool, str | None], list[Row]] = {}
        for r in rows:
            n = r["hypothesis"]
            if "search_value" in r and (n == STIFFER or n in self.searched
                                        and self.searched[n].deposits):
                key = (n, float(r["search_value"]), bool(r.get("refined")), r.get("form"))
                if key not in groups:
                    groups[key] = []
                    order.append(key)
                groups[key].append(r)
            else:
                order.append(r)
        return [self._pool(groups[o]) if isinstance(o, tuple) else o for o in order]

    def _pool(self, group: list[Row]) -> Row:
        """One deposited level's row from its bed runs (``pooled``)."""
        first = group[0]
        out: Row = {"hypothesis": first["hypothesis"], "overrides": first["overrides"],
                    "search_value": first["search_value"],
                    "beds": [{"overrides": r["overrides"],
                              "score": r["score"] if math.isfinite(r["score"]) else None,
                              **({"error": r["error"]} if "error" in r else {})}
                             for r in group]}
        if first.get("refined"):
            out["refined"] = True
        if "form" in first:
            out["form"] = first["form"]
        pairs = [(r, b) for r, b in zip(group, self.bed_bases)
                 if "aligned" in r and "aligned" in b]
        if not pairs:
            errs = [r["error"] for r in group if "error" in r]
            return {**out, "score": -math.inf,
                    "error": errs[0] if errs else "no bed of this level and its base ran"}
        base = self.bed_anchor
        return {**out, **self.rated_on(base, {ch: base[ch].data + np.mean(
                    [r["aligned"][ch].data - b["aligned"][ch].data for r, b in pairs], axis=0)
                    for ch in self.chans}), "beds_pooled": len(pairs)}

    def set_beds(self, base0: Row, rows: Iterable[Row], anchor: Mapping[str, Signal]) -> None:
        """The bases of the beds: ``base0`` (the baseline run of the simulator the levels run
        on), then the replicate runs among ``rows`` in the order of ``replicates``; ``anchor``
        is what a pooled level's mean change is added to."""
        reps = [r for r in rows if r["hypothesis"] == REPLICATE]
        self.bed_bases = [base0] + reps[:len(self.beds) - 1]
        self.bed_anchor = anchor

    def replicate_requests(self) -> list[Request]:
        """Requests of the replicate realisations of the baseline."""
        return [(REPLICATE, {**rv, **self.cfc_key}, None) for rv in self.replicates]

    def standing(self, rows: Iterable[Row], floor: dict[str, float]) -> dict[str, Row]:
        """The run that stands for each effect among ``rows`` (located, not a replicate): its
        best decisive run (``_decisive`` against ``floor``), else its best run, by Delta BIC.
        An effect with a run that passes every naming rule is a candidate explanation even when
        another of its levels fits with a higher likelihood but a lower score. Measured on a
        Yade 18.45 m drop with the floor at 0.83 m: the floor's best-likelihood level (0.9 m,
        Delta BIC 24.3) failed the score margin, so cohesion (24.7) was named while the floor
        at 1.05 m (21.7, score 0.862) passed every rule within the realisation scatter (9.1)
        of it; now the two are not told apart."""
        rows = list(rows)
        out = self.faded_out(rows)
        # an effect whose optimum lies clearly beyond its span, or whose named value the
        # numerics check could not resolve, stands for nothing (the screening's claim aside)
        gone = (set(self.beyond_span(rows, floor, out)) - {self.rep.missing_physics}
                | set(self.withdrawn))
        rows = [r for r in rows if self.located(r) and r["hypothesis"] != REPLICATE
                and r["hypothesis"] not in gone]
        if out and any(_decisive(r, floor) for r in rows if r["hypothesis"] not in out):
            # a rival with a located optimum explains the recording decisively
            rows = [r for r in rows if r["hypothesis"] not in out]
        best = _best_rows(rows)
        best.update(_best_rows(r for r in rows if _decisive(r, floor)))
        return best

    def faded_out(self, rows: Iterable[Row]) -> set[str]:
        """The searched effects among ``rows`` whose best search level (Delta BIC, refinements
        aside) is strictly the level at the end of their span where they fade: the recording
        asks for less of the effect than any level short of that end gives, so the optimum lies
        beyond the span and no run of it locates the effect. ``standing`` then leaves such an
        effect out when another effect has a decisive located run (that rival explains the
        recording with its optimum inside its span); without a rival it stands by its located
        levels as before. Measured at the default resolution with the search on the scenario
        itself (0.075 m grains, 2 m tank), Yade floor recording 12 (bed 0.76 m): layering's best
        level was its deepest, 0.5 m (Delta BIC 74.8), and layering was named at 0.4 m (38.7)
        over the floor at 0.6 m (21.5, decisive); now the floor. Without the rival condition
        the Yade free-rotation recording 12 lost its right answer on the default two-tier path
        (its coarse levels peak at rolling resistance 0.2, Delta BIC 42.5, with no rival). On the
        46 reports of the identity check no decision changes."""
        lv = [r for r in _scored_levels(rows) if r["hypothesis"] in self.searched]
        best = _best_rows(lv)
        inner = _best_rows(r for r in lv
                           if self.searched[r["hypothesis"]].located(r["search_value"]))
        # strictly better than every level short of the end (a tie locates nothing either way)
        return {n for n, r in best.items()
                if not self.searched[n].located(r["search_value"])
                and (n not in inner or inner[n]["delta_bic_vs_reference"]
                     < r["delta_bic_vs_reference"])}

    def beyond_span(self, rows: Iterable[Row], floor: dict[str, float],
                    out: set[str] | None = None) -> dict[str, tuple[Row, Row | None]]:
        """The faded-out effects among ``rows`` (``faded_out``, or ``out``) whose located runs
        all fit the recording worse than their fading-end level by more than the realisation
        margin (``_ambiguity_margin`` of ``floor``): the profile still rises towards the end
        where the effect vanishes, so the recording asks for less of it than the span holds
        and its located levels are only the flank of that -- what a packing or code-to-code
        difference that pulls the same way also gives. Mapped to (the fading-end level, the
        best located run or None). ``standing`` lets no run of such an effect stand for it,
        unless the screening claimed it. Measured on Yade recordings (library path, 0.1 m
        truth grains): at 10 m the floor recording 12 was named ``soil_layering`` at 0.4 m
        (its end level 0.5 m led by more than the scatter); now nothing. Within the margin the
        effect stands by its located levels as before (Yade free rotation 12 stays named)."""
        rows = list(rows)
        if out is None:
            out = self.faded_out(rows)
        if not out:
            return {}
        margin = _ambiguity_margin(floor)
        lv = _best_rows(r for r in _scored_levels(rows) if r["hypothesis"] in out)
        inner = _best_rows(r for r in rows if r["hypothesis"] in out and self.located(r)
                           and "rss" in r and "delta_bic_vs_reference" in r)
        res: dict[str, tuple[Row, Row | None]] = {}
        for n in out:
            if n not in lv:
                continue
            own = inner.get(n)
            if own is None or (lv[n]["delta_bic_vs_reference"] - own["delta_bic_vs_reference"]
                               > margin):
                res[n] = (lv[n], own)
        return res

    def _beyond_verdict(self, name: str, end: Row, own: Row | None,
                        floor: dict[str, float]) -> str:
        """Why an effect whose optimum lies beyond its span (``beyond_span``) names nothing."""
        fs = self.searched[name]
        head = (f"its best level is at the end of the span where the effect fades "
                f"({fs.parameter} = {end['search_value']:.4g} {fs.unit}, Delta BIC "
                f"{end['delta_bic_vs_reference']:.1f})")
        if own is None:
            return head + " and no run short of that end was scored: names nothing"
        at = (f"{own['search_value']:.4g} {fs.unit}, " if "search_value" in own else "")
        return (head + f"; its best run short of that end ({at}Delta BIC "
                f"{own['delta_bic_vs_reference']:.1f}) is more than "
                f"{_ambiguity_margin(floor):.3g} below it: the optimum lies beyond the span: "
                f"names nothing")

    def located(self, r: Row) -> bool:
        """A scored run that can stand for its effect: not a search run at the end of the span
        where the effect fades (``FullSearch.located``)."""
        return "rss" in r and not ("search_value" in r and r["hypothesis"] in self.searched
                                   and not self.searched[r["hypothesis"]].located(
                                       r["search_value"]))

    def anchored(self, r: Row, ref: Row) -> Row:
        """Run ``r`` of another simulator as the baseline simulation plus its change against
        that simulator's baseline run ``ref`` (both aligned on the recording)."""
        if "aligned" not in r or "aligned" not in ref:
            return r
        base = self.rep.baseline
        return {**r, **self.rated_on(base, {ch: base[ch].data + r["aligned"][ch].data
                                            - ref["aligned"][ch].data for ch in self.chans}),
                "anchored": True}

    def rated_on(self, base: Mapping[str, Signal], data: Mapping[str, np.ndarray]) -> Row:
        """``rated`` and ``rss`` of a prediction ``data`` per channel on the time axes (units,
        classes) of ``base``: an anchored run or a pooled level. The span ``base`` was simulated
        over (``mismatch.SIMULATED_SPAN``) is the prediction's."""
        al = {ch: Signal(ch, base[ch].t, data[ch], base[ch].unit, base[ch].cfc,
                         {k: v for k, v in base[ch].meta.items() if k == SIMULATED_SPAN})
              for ch in self.chans}
        return {**self.rated(al), "rss": _full_rss(self.rep, al)}

    def extended(self, sim: Simulator, rows: list[Row],
                 finish: Callable[[Row], Row]) -> list[Row]:
        """Further levels beyond the strong end of each searched effect with an ``extension``
        (``FullSearch.extended``): while the effect's best level (Delta BIC, refinements aside)
        is the strong end of its span run so far, the next extension value is run (on its
        beds, pooled; ``finish`` anchors and scores a new row) and becomes part of the span
        (``searched`` is updated, so the refinement, the numerics check and the reported value
        see it). Nothing runs when the strong end does not fit best. Measured on a Yade bed
        0.6 m deep at 13.7 m through the command line: the floor's best level was its
        shallowest (0.6 m) and the recording was named ``soil_layering``; with the levels
        0.5 and 0.4 m it is named ``boundary_proximity`` at 0.4 m (-16 % from the realised
        depth)."""
        extra: list[Row] = []
        for name in list(self.searched):
            while self.searched[name].extension:
                fs = self.searched[name]
                top = _best_rows(r for r in _scored_levels([*rows, *extra])
                                 if r["hypothesis"] == name).get(name)
                if top is None or abs(float(top["search_value"]) - fs.strong_end) > fs.tolerance:
                    break
                self.searched[name] = fs = fs.extended()
                new = self.pooled(self.run(sim, self.level_requests(name, fs.strong_end)))
                for r in new:
                    r["extension"] = True
                extra += [finish(r) for r in new]
        return extra

    def refined(self, sim: Simulator, rows: list[Row]) -> list[Row]:
        """One run of the leading searched effect at the vertex of the parabola through its
        best level and the two neighbours (in the search coordinate), when interior; the
        caller gives it its Delta BIC."""
        lead = _best_rows(r for r in rows if "search_value" in r and r["hypothesis"] in self.searched
                          and self.located(r))
        if not lead:
            return []
        top = max(lead.values(), key=lambda r: r["delta_bic_vs_reference"])
        v = _search_vertex(top, rows, self.searched[top["hypothesis"]])
        if v is None:
            return []
        name = top["hypothesis"]
        runs = self.run(sim, self.level_requests(name, v["value"]))
        for r in runs:
            r["refined"] = True
        return self.pooled(runs)

    # -- the stages ----------------------------------------------------------------------

    def search_tier(self, sim: Simulator) -> _SearchTier:
        """Every level on the cheaper search simulator, judged against that simulator's own
        baseline run; the leading effects' best levels go to the full model."""
        rep = self.rep
        req = ([("baseline", dict(self.cfc_key), None)] + self.levels(list(self.searched))
               + self.replicate_requests())
        # the realisation floor holds the bed made stiffer here, as on a single tier
        # (``full_tier``): the search tier's floor is the one the levels are promoted against
        stiff = self.stiffer_requests() if self.replicates else []
        own_factor = catalogue.layer_level_factor(self.searched.get("soil_layering"))
        outs = self.outputs(sim, req + stiff)
        if isinstance(outs[0], Exception):
            raise outs[0]
        raw = [self.row(n, ov, x, o) for (n, ov, x), o in zip(req + stiff, outs)]
        stiff_raw, raw = raw[len(req):], raw[:len(req)]
        ref = raw[0]
        self.realisation_rows = [ref] + [r for r in raw[1:] if r["hypothesis"] == REPLICATE]
        # anchored like the screening: each search run predicts the baseline simulation plus
        # the change its effect makes in the search simulator (its run minus that simulator's
        # baseline run), so the search simulator's own misfit is not read as an effect
        self.set_beds(ref, raw[1:], rep.baseline)
        rows = [ref] + [r if "beds" in r else self.anchored(r, ref)
                        for r in self.pooled(raw[1:])]
        stiff_rows = [r if "beds" in r else self.anchored(r, ref)
                      for r in self.pooled(stiff_raw)]
        base_bic = self.bic(_full_rss(rep, rep.baseline), 0)

        def qualify(r: Row) -> Row:
            if "rss" in r:
                k = int(r["hypothesis"] != REPLICATE)  # a level carries one parameter
                r["delta_bic_vs_reference"] = base_bic - self.bic(r["rss"], k)
            return r

        for r in rows[1:]:
            qualify(r)
        rows = self.choose_forms(rows)
        rows += self.extended(sim, rows,
                              lambda r: qualify(r if "beds" in r else self.anchored(r, ref)))
        extra = [r if "beds" in r else self.anchored(r, ref) for r in self.refined(sim, rows)]
        for r in extra:
            qualify(r)
        rows += extra
        for r in stiff_rows:
            qualify(r)
        self.stiff_rows = stiff_rows
        before = float(rep.fit["before"]["overall"])
        floor = _realisation_floor(rows, before, stiff_rows)
        hertz = [r for r in stiff_rows if r.get("form") == catalogue.HERTZ_FLOOR_FORM]
        as_levels = [r for r in stiff_rows if r["search_value"] == own_factor
                     and r.get("form") != catalogue.HERTZ_FLOOR_FORM]
        claim_floor = _realisation_floor(rows, before, as_levels + hertz)
        raised = ""
        if claim_floor != _realisation_floor(rows, before):
            raised = " or the bed made as stiff as its levels" + (
                " or with the Hertz-Mindlin law" if hertz else "")
        best = self.standing(rows[1:], floor)
        promote = sorted((r for r in best.values() if _decisive(r, floor)),
                         key=lambda r: -r["delta_bic_vs_reference"])[:SEARCH_PROMOTE]
        # the full runs stay 1 + top_k: the screening's claim, then the promoted levels, then
        # the other screened candidates
        claim = [h for h in self.candidates if h["name"] == rep.missing_physics]
        promote = promote[:max(0, self.top_k - len(claim))]
        others = [h for h in self.candidates if h["name"] != rep.missing_physics]
        candidates = claim + others[:max(0, self.top_k - len(claim) - len(promote))]
        verdicts = {n: ("promoted to a full run" if any(p is r for p in promote) else
                        "not promoted: " + _verdict(r, floor, False, None, None))
                    for n, r in best.items()}
        for n, (end, own) in self.beyond_span(rows[1:], floor).items():
            if n not in verdicts:
                verdicts[n] = "not promoted: " + self._beyond_verdict(n, end, own, floor)
        return _SearchTier(rows, floor,
                           [(r["hypothesis"], dict(r["overrides"]), r["search_value"])
                            for r in promote], candidates, verdicts, best, claim_floor, raised)

    def full_tier(self, sim: Simulator, tier: _SearchTier | None) -> _FullTier:
        """The full runs: recalibration, candidates, promoted levels, or (without a search
        tier) every search level, its refinement and the replicates."""
        rep = self.rep
        candidates = tier.candidates if tier is not None else self.candidates
        requests: list[Request] = [
            (RECALIBRATION.name, {**RECALIBRATION.scenario_overrides(self.recal["recalibration"]),
                                  **self.cfc_key}, None)]
        for h in candidates:
            # the effect alone on the baseline scenario: the screening model's recalibration
            # factors do not carry over to the full model's material parameters (measured on
            # the DEM: every full run with the mapped factors scored below the baseline), while
            # the effect parameters (depths, speeds, frequencies) have the same meaning in both
            level = self.level_for_candidate(h, tier)
            ov = (dict(level["overrides"]) if level is not None
                  else _confirmation_overrides(h, rep.catalogue))
            requests.append((h["name"], {**ov, **self.cfc_key}, None))
        if tier is not None:
            requests += tier.promoted
        else:
            requests += self.levels(list(self.searched)) + self.replicate_requests()
        # a stiffer soil is a recalibration: on the full tier the whole bed made stiffer runs
        # beside the replicates, and an effect has to beat it too (the realisation floor)
        stiff = self.stiffer_requests() if tier is None and self.replicates else []
        rows = self.run(sim, requests + stiff)
        stiff_rows, rows = rows[len(requests):], rows[:len(requests)]
        if tier is None:
            self.realisation_rows = [r for r in rows if r["hypothesis"] == REPLICATE]
        if tier is None and len(self.beds) > 1:
            # bed 0's base: the baseline simulation aligned as every run is (as the screening
            # aligned it when its raw channels are not at hand)
            b0 = (self.row("baseline", {}, None, dict(self.baseline_signals))
                  if self.baseline_signals is not None else
                  {"hypothesis": "baseline", "aligned": rep.baseline})
            self.set_beds(b0, rows, b0["aligned"])
            rows = [rows[0]] + self.pooled(rows[1:])
            stiff_rows = self.pooled(stiff_rows)
        recal_row = rows[0]
        # reference: the better of the baseline simulation and the recalibrated full run
        base_row: Row = {"hypothesis": "baseline", "score": float(rep.fit["before"]["overall"]),
                         "aligned": rep.baseline, "rss": _full_rss(rep, rep.baseline)}
        ref_row = max([base_row, recal_row], key=lambda r: r["score"])
        ref_k = 0 if ref_row is base_row else len(RECALIBRATION.parameters)
        ref_bic = self.bic(ref_row["rss"], ref_k)

        def qualify(r: Row) -> Row:
            if "rss" in r:
                # a screened candidate's run carries the effect's parameters, a search level
                # one (the level), the reference its recalibration when it is the recalibrated
                # run
                k = (1 if "search_value" in r else 0 if r["hypothesis"] == REPLICATE
                     else len(rep.catalogue.get(r["hypothesis"]).parameters))
                r["delta_bic_vs_reference"] = ref_bic - self.bic(r["rss"], k)
            return r

        for r in rows[1:]:
            qualify(r)
        if self.searched and tier is None:
            rows = self.choose_forms(rows)
            rows += self.extended(sim, rows, qualify)
            extra = self.refined(sim, rows)
            for r in extra:
                qualify(r)
            rows += extra
        # the realisation floor: the best replicate of the baseline among the full runs (none
        # there, e.g. when they ran on the search simulator: the reference), raised to the best
        # whole-bed stiffness run
        for r in stiff_rows:
            qualify(r)
        if tier is None:
            self.stiff_rows = stiff_rows
        return _FullTier(rows, ref_row["score"],
                         _realisation_floor(rows, ref_row["score"], stiff_rows))

    def decide(self, full: _FullTier, tier: _SearchTier | None = None) -> _Decision:
        """The screening's claim stands unless its full run is decisively worse than the
        reference or the best replicate (in likelihood, or by ``CONFIRM_MIN_GAIN`` in score:
        a full run that fits the recording worse by the field's objective rating does not
        confirm anything) or another candidate's full run is decisively better than it; a
        model-free answer (sensor check, measured impact speed) stands as it is. Among decisive
        rivals the likelihood ranks (the score is the field's rating, its differences between
        two good fits are not evidence); two within ``AMBIGUITY_MARGIN`` or the replicates'
        scatter of each other are not told apart. A claim that stands only by that lenient
        rule is not named beside a rival that beats it in both likelihood and score and the
        realisation floor in both (``_contends``) but misses the ``CONFIRM_MIN_GAIN`` margin
        over the floor: the rival is held to a margin the claim was not, so the two are not
        told apart. Measured through the command line on the Yade 5 m floor recording 11
        (bed 0.82 m deep): the layer claimed by the screening stood at Delta BIC 15.4, score
        0.842 (floor 10.5, 0.837) beside the floor's 0.9 m level at 20.5, 0.847, and was named
        wrongly. With a search ``tier`` the replicates ran there, not among the full runs: a
        claim of a searched effect then also has to hold there, its best search run against
        that tier's realisation floor by the same rule (``_search_support``)."""
        rep, floor = self.rep, full.floor
        best_h = self.standing(full.rows[1:], floor)
        confirmed, best = None, full.rows[0]
        screened = best_h.get(rep.missing_physics) if rep.missing_physics else None
        unsupported = (self._search_support(screened["hypothesis"], tier)
                       if screened is not None and tier is not None and not self.model_free
                       else None)
        if screened is not None and unsupported is None and (
                self.model_free or _not_decisively_worse(screened, floor)):
            confirmed, best = screened["hypothesis"], screened
        claim_stood = confirmed is not None
        # a screened candidate of a searched effect (neither the claim nor a promoted level,
        # which was decisive there) meets the claim's rule on the search tier too
        unheld = {} if tier is None or self.model_free else {
            r["hypothesis"]: why for r in best_h.values()
            if r is not screened and "search_value" not in r and _decisive(r, floor)
            and (why := self._search_support(r["hypothesis"], tier,
                                             "a screened candidate")) is not None}
        rivals = [] if self.model_free else sorted(
            (r for r in best_h.values() if r is not screened and _decisive(r, floor)
             and r["hypothesis"] not in unheld),
            key=lambda r: -r["delta_bic_vs_reference"])
        ambiguous, outranked_by = None, None
        if rivals:
            top = rivals[0]
            if len(rivals) > 1 and (top["delta_bic_vs_reference"]
                                    - rivals[1]["delta_bic_vs_reference"]
                                    <= _ambiguity_margin(floor)):
                ambiguous = [r["hypothesis"] for r in rivals[:2]]
                rep.fit["confirmation_ambiguous"] = _pair_record(rivals[:2])
            elif screened is None or top["score"] - screened["score"] >= CONFIRM_MIN_GAIN:
                confirmed, best = top["hypothesis"], top
            elif claim_stood and (top["delta_bic_vs_reference"]
                                  > screened["delta_bic_vs_reference"]):
                # the claim would stand by its score alone: a decisive rival fits the
                # recording with a higher likelihood, which ranks effects everywhere else
                outranked_by = top
        if (outranked_by is None and claim_stood and best is screened and ambiguous is None
                and not self.model_free):
            # the claim stands by the lenient rule (not decisively worse than the floor); a
            # rival that beats it in likelihood *and* score, and the floor in both, is held
            # to the score margin over the floor that the claim was not held to
            outranked_by = max((r for r in best_h.values() if r is not screened
                                and r["hypothesis"] not in unheld and _contends(r, floor)
                                and r["delta_bic_vs_reference"]
                                > screened["delta_bic_vs_reference"]
                                and r["score"] > screened["score"]),
                               key=lambda r: r["delta_bic_vs_reference"], default=None)
        if outranked_by is not None:
            ambiguous = [screened["hypothesis"], outranked_by["hypothesis"]]
            rep.fit["confirmation_ambiguous"] = _pair_record((screened, outranked_by))
            confirmed, best = None, full.rows[0]
        contested = None
        if confirmed is not None and not self.model_free:
            contested = self._likelihood_rival(confirmed, best, tier)
            if contested is not None:
                ambiguous = [confirmed, contested["rival"]]
                rep.fit["confirmation_ambiguous"] = {
                    confirmed: {"delta_bic_vs_reference": contested["own_delta_bic"],
                                "score": contested["own_score"], "tier": contested["tier"]},
                    contested["rival"]: {"delta_bic_vs_reference": contested["delta_bic"],
                                         "score": contested["score"], "tier": contested["tier"],
                                         "value": contested.get("value")}}
                confirmed, best = None, full.rows[0]
        return _Decision(confirmed, best, screened, claim_stood, ambiguous, best_h, unsupported,
                         contested, unheld, outranked_by is not None)

    def _likelihood_rival(self, name: str, run: Row,
                          tier: _SearchTier | None) -> dict[str, Any] | None:
        """On a two-tier confirmation, another effect that leaves ``name`` (about to be named
        by its promoted search level's full run ``run``) not told apart from it, or None: a
        located search-tier run of another effect that fits the recording with a *higher*
        likelihood than ``name``'s best located level there, beats that tier's reference and
        best replicate in Delta BIC (``ACCEPT_MARGIN``, ``REALISATION_MARGIN``) and scores no
        worse than the best of reference and replicates -- a ``contender`` that failed only
        the ``CONFIRM_MIN_GAIN`` score margin of promotion. Such a rival never reaches the full
        tier, and the full tier carries no replicates: ``name``'s full run is judged against
        the reference alone, so without this the likelihood (which ranks effects) is
        overruled by a score margin the rival missed on the coarse bed. Measured on a Yade
        13.7 m drop with the floor at 0.6 m (default CLI path, 2 m tank): the floor's best
        coarse level (0.68 m, Delta BIC 47.6, score 0.646 against the replicates' 0.645)
        out-ranked layering's (0.3 m, 42.0, score 0.72), and layering was named wrongly. On a
        single tier every effect's runs meet the same rules in the same decision, and the rule
        is not applied there: on DEM truth damping 11 the floor's 0.8 m run (21.7, score 0.811
        against the replicates' 0.797) would contest the named damping (20.3, 0.853) and cost
        a right answer."""
        if tier is None or name not in self.searched or "search_value" not in run:
            return None
        own = _best_rows(r for r in tier.rows[1:] if r["hypothesis"] == name
                         and "search_value" in r and self.located(r)).get(name)
        if own is None:
            return None
        rows, floor = tier.rows[1:], tier.floor
        out = self.faded_out(rows)
        found = [r for r in rows
                 if r["hypothesis"] not in (name, REPLICATE, RECALIBRATION.name, *out,
                                            *self.withdrawn)
                 and self.located(r) and math.isfinite(r["score"]) and _contends(r, floor)
                 and r["delta_bic_vs_reference"] > own["delta_bic_vs_reference"]]
        if not found:
            return None
        r = max(found, key=lambda x: x["delta_bic_vs_reference"])
        return {"rival": r["hypothesis"], "tier": "search simulator",
                "delta_bic": float(r["delta_bic_vs_reference"]), "score": float(r["score"]),
                "own_delta_bic": float(own["delta_bic_vs_reference"]),
                "own_score": float(own["score"]),
                **({"value": float(r["search_value"])} if "search_value" in r else {})}

    def level_for_candidate(self, h: dict[str, Any], tier: _SearchTier | None) -> Row | None:
        """The search-tier run a screened candidate's full run takes its value from, else None.

        On a two-tier confirmation, a candidate of a searched effect that the screening left
        switched off (a mapped parameter at its ``off`` value: the screening model could not
        place the effect) runs at the level that stands for the effect on the search tier
        (``standing``: located, not beyond the span) instead of the catalogue's nominal value,
        and is reported with that value (``record``). Measured at the default resolution
        (``validation/diagnose_cost.py --effect boundary_proximity --value 0.8``): the floor
        candidate, left at the modelled 2 m, ran at the nominal 1.2 m and was named there
        (+50 %) while the search tier stood at 0.9 m."""
        if (tier is None or h["name"] not in self.searched
                or h.get("variant") == FILTER_CLASS_VARIANT):
            return None
        hyp = self.rep.catalogue.get(h["name"])
        vals = h["parameters"]
        if not any(p.scenario_key is not None and p.name in vals and _at_off(p, vals[p.name])
                   for p in hyp.parameters):
            return None
        run = tier.standing.get(h["name"])
        return run if run is not None and "search_value" in run else None

    def _search_support(self, name: str, tier: _SearchTier,
                        who: str = "the screening's claim") -> str | None:
        """None when the screening's claim ``name`` holds on the search tier -- its best located
        search run not decisively worse than that tier's best replicate (Delta BIC within
        ``ACCEPT_MARGIN`` of it, score within ``CONFIRM_MIN_GAIN``), or ``name`` not searched or
        no replicates there -- else why not, in one line. The full runs of a two-tier
        confirmation carry no replicates, so without this a claim the screening model makes
        (and the full model at the scenario's resolution fits better than the reference) stood
        although another packing of the coarse bed fits the recording better than any level of
        it. Measured at the default resolution (0.075 m grains) on the Yade floor recording 12:
        layering claimed by the screening, its full run 28.2 over the reference, its best coarse
        level 9.4 against the best coarse replicate's 26.2 -- named wrongly before. ``decide``
        asks the same of a screened candidate that is not the claim (``who`` words the
        line): its full run, too, has only the reference to beat.

        The floor here (``_SearchTier.claim_floor``) is the replicates' raised only to the
        stiffer-soil runs at the modulus factor the layer levels run at (x5): each is such a
        level without its interface, so a claim whose best level fits decisively worse than it
        is a stiffer bed, not that effect (a screening-model recording of the whole bed x5
        stiffer, claimed as a layer: best level Delta BIC 211 against the whole bed x5's 703).
        A bed stiffer by another factor would also out-fit every x5 level of a real layer at
        that other factor: on the screening model's layer at 0.24 m, x1.9
        (``test_replicates_run_on_the_search_simulator``) the bed x2 stiffer below 0.15 m
        reached Delta BIC 101 on the search tier and the layer's best level -1.3, and against
        the whole floor the claim, which was right, was not named."""
        if name not in self.searched or not any(r["hypothesis"] == REPLICATE for r in tier.rows):
            return None
        f = tier.claim_floor if tier.claim_floor is not None else tier.floor
        run = self.standing([r for r in tier.rows[1:] if r["hypothesis"] == name], f).get(name)
        if run is None:
            ran = any(r["hypothesis"] == name and "search_value" in r for r in tier.rows[1:])
            return (f"{who}, but " + ("on the search simulator no level of it short of the end "
                                      "where it fades stands for it" if ran else
                                      "no level of it ran on the search simulator"))
        if _not_decisively_worse(run, f):
            return None
        stiff = tier.claim_floor_stiffer
        return (f"{who}, but on the search simulator its best level "
                f"({run['search_value']:.4g} {self.searched[name].unit}, Delta BIC "
                f"{run['delta_bic_vs_reference']:.1f}, score {run['score']:.3f}) is decisively "
                f"worse than the best replicate packing there{stiff} (Delta BIC "
                f"{f['delta_bic']:.1f}, score {f['score']:.3f})")

    def verdicts(self, full: _FullTier, d: _Decision) -> dict[str, str]:
        """Why each effect run in the full model was or was not named, in one line each."""
        rows = full.rows
        every = _best_rows(r for r in rows[1:] if "rss" in r and r["hypothesis"] != REPLICATE)
        beyond = self.beyond_span(rows[1:], full.floor)
        out: dict[str, str] = {}
        for name in dict.fromkeys(r["hypothesis"] for r in rows[1:]):
            if name in (REPLICATE, RECALIBRATION.name):
                continue
            r = d.best_by_effect.get(name)
            if name == d.confirmed:
                why = "named"
            elif name in self.withdrawn:
                why = "named, then withdrawn: " + self.withdrawn[name]
            elif r is None and name in beyond:
                why = self._beyond_verdict(name, *beyond[name], full.floor)
            elif d.contested is not None and name in d.ambiguous:
                why = _contested_verdict(name, d.ambiguous, d.contested)
            elif d.outranked and name in d.ambiguous:
                why = _outranked_verdict(name, d)
            elif r is not None and r is d.screened and d.unsupported:
                why = d.unsupported
            elif name in d.unheld:
                why = d.unheld[name]
            elif r is not None and r is d.screened and d.claim_stood:
                why = (f"the screening's claim stood (Delta BIC "
                       f"{r['delta_bic_vs_reference']:.1f}, score {r['score']:.3f}), but "
                       f"{d.confirmed}'s full run beats it by {CONFIRM_MIN_GAIN:g} in score and "
                       f"the reference decisively")
            elif r is None:
                err = next((x.get("error") for x in rows
                            if x["hypothesis"] == name and "error" in x), None)
                fs = self.searched.get(name)
                lv = _best_rows(x for x in _scored_levels(rows) if x["hypothesis"] == name)
                why = (f"the full model could not run it ({err})" if err and name not in every
                       else "its best level is at the end of the span where the effect fades "
                       f"({fs.parameter} = {lv[name]['search_value']:.4g} {fs.unit}, Delta "
                       f"BIC {lv[name]['delta_bic_vs_reference']:.1f}): names nothing"
                       if fs is not None and name in lv else "no run of it can stand for it")
            else:
                why = _verdict(r, full.floor, r is d.screened, self.model_free,
                               d.ambiguous)
            out[name] = why
        return out

    def record(self, full: _FullTier, tier: _SearchTier | None, d: _Decision,
               t_full: float) -> None:
        """Write the confirmation into the report: tables, verdicts, floor, search, decision."""
        rep, rows, searched = self.rep, full.rows, self.searched
        rep.fit["confirmation_verdicts"] = self.verdicts(full, d)
        if d.confirmed is not None and "search_value" in d.best:
            _adopt_full_parameters(rep, d.best, searched[d.confirmed],
                                   tier.rows if tier is not None else rows,
                                   tier.floor if tier is not None else full.floor)
        elif d.confirmed is not None and tier is not None:
            # a screened candidate run at its search-tier level: that level is its value, with
            # the search tier's profile and realisation interval as its uncertainty
            h = next((h for h in tier.candidates if h["name"] == d.confirmed), None)
            lv = self.level_for_candidate(h, tier) if h is not None else None
            if lv is not None:
                _adopt_full_parameters(rep, {**d.best, "search_value": lv["search_value"]},
                                       searched[d.confirmed], tier.rows, tier.floor)
        if self.skipped:
            rep.fit["confirmation_skipped"] = self.skipped
        if self.replicates:
            f = tier.floor if tier is not None else full.floor
            rep.fit["realisation"] = {
                "tier": "search simulator" if tier is not None else "full simulator",
                "runs": [{"overrides": r["overrides"],
                          "score": None if not math.isfinite(r["score"]) else r["score"],
                          "delta_bic_vs_reference": r.get("delta_bic_vs_reference"),
                          **({"error": r["error"]} if "error" in r else {})}
                         for r in (tier.rows if tier is not None else rows)
                         if r["hypothesis"] == REPLICATE],
                "floor_delta_bic": f["delta_bic"], "floor_score": f["score"],
                "scatter_delta_bic": f["scatter"]}
            if self.stiff_rows:
                rep.fit["realisation"]["stiffer_soil"] = [
                    {"young_factor": r["search_value"], "form": r.get("form", "whole bed"),
                     "below_m": _stiffer_below(r["overrides"]),
                     "score": r["score"] if math.isfinite(r["score"]) else None,
                     "delta_bic_vs_reference": r.get("delta_bic_vs_reference"),
                     "runs": _n_runs([r]), **({"error": r["error"]} if "error" in r else {})}
                    for r in self.stiff_rows]
        det = _detectability(rep, tier.rows if tier is not None else rows, searched)
        if det is not None:
            rep.fit["detectability"] = det
            for name, why in rep.fit["confirmation_verdicts"].items():
                note = _invisible_note(det, name, searched.get(name))
                if why != "named" and note:
                    rep.fit["confirmation_verdicts"][name] = why + "; " + note
        if searched:
            lv = [r for r in (tier.rows[1:] if tier is not None else rows) if "search_value" in r]
            rep.fit.setdefault("full_search", {}).update(
                tier="search simulator" if tier is not None else "full simulator",
                runs=_n_runs(lv) + _n_runs(self.form_rows) + (1 if tier is not None else 0),
                level_beds=len(self.beds),
                levels=[{"hypothesis": r["hypothesis"], "value": r["search_value"],
                         "score": None if not math.isfinite(r["score"]) else r["score"],
                         "delta_bic_vs_reference": r.get("delta_bic_vs_reference"),
                         "refined": bool(r.get("refined")),
                         "located": self.located(r) if kept else False,
                         "extension": bool(r.get("extension")),
                         **({"beds": len(r["beds"])} if "beds" in r else {}),
                         **({"form": r["form"], "form_kept": kept} if "form" in r else {})}
                        for r, kept in [*((r, True) for r in lv),
                                        *((r, False) for r in self.form_rows)]],
                best={n: {"value": r["search_value"], "score": r["score"],
                          "delta_bic_vs_reference": r["delta_bic_vs_reference"]}
                      for n, r in _best_rows(r for r in lv if "rss" in r).items()})
            if tier is not None:
                rep.fit["full_search"]["search_baseline_score"] = tier.rows[0]["score"]
                rep.fit["full_search"]["verdicts"] = tier.verdicts
                if d.contested is not None and d.ambiguous[1] in tier.verdicts:
                    tier.verdicts[d.ambiguous[1]] += "; " + _contested_verdict(
                        d.ambiguous[1], d.ambiguous, d.contested)
                rep.simulations["search_simulations"] = _n_distinct(tier.rows, self.form_rows,
                                                                    self.stiff_rows)
            if self.forms_chosen:
                rep.fit["full_search"]["forms"] = self.forms_chosen
        rep.fit["confirmation"] = [{k: (None if k == "score" and not math.isfinite(v) else v)
                                    for k, v in r.items() if k != "aligned"} for r in rows]
        rep.fit["confirmation_reference_score"] = full.reference
        rep.fit["confirmed_missing_physics"] = d.confirmed
        if d.confirmed is not None:
            rep.fit["after_full"] = {"hypothesis": d.confirmed, "overall": d.best["score"],
                                     "per_channel": d.best["per_channel"]}
            rep.refitted = dict(d.best["aligned"])
        rep.simulations["full_simulations"] = _n_distinct(
            rows, *([self.stiff_rows, self.form_rows] if tier is None else []))
        rep.simulations["full_wall_time_s"] = t_full
        rep.missing_physics = d.confirmed
        self.settle(d)
        rep.decision += "; " + self.sentence(full, tier, d)
        for name, why in self.withdrawn.items():
            rep.decision += f"; {name} withdrawn: {why}"
        self.rerank(full, tier, d)
        self.full_evidence(d)
        self.full_after(d)

    def run_changes(self, r: Row) -> dict[str, str]:
        """``{"changes": ...}``: what a run changes of the baseline's mismatch features
        against the recording (``mismatch.describe_changes``; on the recording's time base,
        an anchored or pooled run as the baseline plus its change), or {} when it changes none
        by half or has no signals."""
        rep = self.rep
        if "aligned" not in r or not getattr(rep, "mismatch", None):
            return {}
        chans = [ch for ch in self.chans if ch in r["aligned"]]
        after = _remaining_mismatch(rep.recording, r["aligned"], rep.noise, chans)
        txt = describe_changes(feature_changes(rep.mismatch, after))
        return {"changes": txt} if txt else {}

    def full_evidence(self, d: _Decision) -> None:
        """The named effect's ``evidence`` from its full run, the answer the report gives: the
        baseline's mismatch features the run removes or shrinks most
        (``mismatch.describe_changes`` of ``rep.mismatch`` against ``rep.after_mismatch``),
        the full model's value (a named search value, else the run's numeric scenario
        overrides) and the score before and after (a model-free check's sentence,
        when the screening's evidence has one, kept at the end). The screening model's sentence,
        which speaks of its own refit and values, is kept in ``screening_evidence``."""
        rep = self.rep
        h = next((h for h in rep.hypotheses if h["name"] == d.confirmed), None)
        if d.confirmed is None or h is None or not rep.refitted:
            return
        fm = h.get("full_model") or {}
        units = fm.get("unit") or {}
        what = ", ".join(f"{k} = {v:.4g} {units.get(k, '')}".rstrip()
                         for k, v in (fm.get("parameters") or {}).items()) or ", ".join(
            f"{k} = {v:.4g}" for k, v in d.best.get("overrides", {}).items()
            if isinstance(v, (int, float)) and not isinstance(v, bool)
            and not k.startswith("calibration."))
        changes = describe_changes(feature_changes(rep.mismatch, rep.after_mismatch))
        txt = (f"in the full simulation{f' with {what}' if what else ''}: "
               f"{changes or 'halves no mismatch feature of the baseline'}; score "
               f"{rep.fit['before']['overall']:.3f} -> {float(d.best['score']):.3f}.")
        h["screening_evidence"] = h.get("evidence")
        h["evidence"] = txt + (f" {h['model_free_evidence']}" if h.get("model_free_evidence")
                               else "")

    def full_after(self, d: _Decision) -> None:
        """With an effect named, the fit "after" is its full run's (``fit.after_source`` =
        "full simulation"): the simulation with the physics added, the refitted curve of the
        plots and the one the remaining mismatch is measured on. The screening refit's scores
        (the reduced-order model's change on the baseline simulation, with the recalibration
        fitted beside the effect) stay in ``fit.after_screening_refit``, and the named
        hypothesis's own in ``screening_score_after``. Before, ``fit.after`` and the hypothesis's
        ``score_after`` were the screening refit's while the plots showed the full run: a
        Yade contact-damping recording named cohesion read 0.792 -> 0.810 overall, its
        acceleration 0.762 -> 0.730, where the run plotted scores 0.899 (0.827)."""
        rep = self.rep
        full = rep.fit.get("after_full")
        if d.confirmed is None or not full:
            return
        rep.fit["after_screening_refit"] = {
            "hypothesis": rep.fit.get("after_hypothesis"), **rep.fit["after"],
            "residual_rms_sigma": rep.fit.get("residual_rms_sigma_after")}
        rep.fit["after"] = {"per_channel": full["per_channel"], "overall": full["overall"]}
        rep.fit["after_hypothesis"] = d.confirmed
        rep.fit["after_source"] = "full simulation"
        res = np.concatenate(_full_residuals(rep, d.best["aligned"]))
        rep.fit["residual_rms_sigma_after"] = float(np.sqrt(np.mean(res ** 2)))
        h = next((h for h in rep.hypotheses if h["name"] == d.confirmed), None)
        if h is not None:
            h["screening_score_after"] = h["score_after"]
            h["score_after"] = full["overall"]

    def grain_checked(self, d: _Decision) -> bool:
        """Whether the grain check applies to decision ``d``: an effect named on the soil
        model's evidence -- not a model-free answer (sensor check, measured impact speed),
        and not with the recording at another filter class (the check's baselines would need
        their raw channels to be re-filtered)."""
        return d.confirmed is not None and not self.model_free and not self.cfc_key

    def numerics_runs(self, sim: Simulator, tier: _SearchTier | None, full: _FullTier,
                      d: _Decision, scales: Sequence[float]) -> dict[str, Any] | None:
        """How far the value of a named searched effect moves with the grain size: its search
        levels run again on ``sim`` (the simulator the search ran on) with the grain radius
        times each factor of ``scales`` (on a search tier each with its own baseline run, on
        which they are anchored as the search's levels are), and each profile's optimum
        (``_profile_optimum``) is compared with that of the levels at the simulation's own
        grains. The largest distance is the numerics uncertainty (``numerics_record`` makes the
        reported uncertainty at least it); ``unresolved`` reads the same runs. None when nothing
        searched is named."""
        name = d.confirmed
        if name is None or name not in self.searched or "search_value" not in d.best:
            return None
        fs, rep = self.searched[name], self.rep
        t0 = time.perf_counter()
        req: list[Request] = []
        for f in scales:
            num = {RADIUS_SCALE_KEY: float(f)}
            if tier is not None:
                req.append(("baseline", {**self.cfc_key, **num}, None))
            req += [(name, {**fs.overrides(x), **self.cfc_key, **num}, float(x))
                    for x in fs.values]
        rows = self.run(sim, req)
        base_bic = self.bic(_full_rss(rep, rep.baseline), 0)
        per: list[dict[str, Any]] = []
        for f in scales:
            mine = [r for r in rows if r["overrides"].get(RADIUS_SCALE_KEY) == float(f)]
            ref = next((r for r in mine if r["hypothesis"] == "baseline"), None)
            lv = [r for r in mine if "search_value" in r]
            if tier is not None:
                # anchored on this factor's own baseline run; without it nothing is located
                lv = [self.anchored(r, ref) for r in lv] if ref is not None and "rss" in ref \
                    else []
            for r in lv:
                if "rss" in r:
                    r["delta_bic_vs_reference"] = base_bic - self.bic(r["rss"], 1)
            u = _profile_optimum(lv, fs)
            per.append({"radius_scale": float(f), "value": None if u is None else fs.value(u),
                        "runs": len(mine), "failed": sum("rss" not in r for r in mine)})
        own_lv = [r for r in _scored_levels(tier.rows if tier is not None else full.rows)
                  if r["hypothesis"] == name]
        own = _profile_optimum(own_lv, fs)
        own_best = _best_rows(own_lv).get(name)
        # does a level at or beyond the edge of the located span fit strictly better than
        # every level inside it? (a tie, e.g. a flat profile, places nothing at the edge)
        scored = [r for r in own_lv if "delta_bic_vs_reference" in r]
        inside = [r["delta_bic_vs_reference"] for r in scored if fs.inside(r["search_value"])]
        outside = [r["delta_bic_vs_reference"] for r in scored
                   if not fs.inside(r["search_value"])]
        at_edge = bool(outside) and (not inside or max(outside) > max(inside))
        x = float(d.best["search_value"])
        shifts = [abs(p["value"] - fs.value(own)) if fs.scale != "log" else
                  abs(fs.coord(p["value"]) - own) * x
                  for p in per if p["value"] is not None and own is not None]
        sd = max(shifts) if shifts else None
        return {"hypothesis": name, "radius_scales": [float(f) for f in scales], "values": per,
                "own_value": None if own is None else fs.value(own),
                "own_best_level": None if own_best is None else float(own_best["search_value"]),
                "own_at_edge": at_edge,
                "uncertainty": sd,
                "runs": len(rows), "wall_time_s": time.perf_counter() - t0}

    def unresolved(self, d: _Decision, check: Mapping[str, Any] | None) -> str | None:
        """Why the named effect is withdrawn after its numerics check, or None. Withdrawn when
        no grain size places its optimum inside the span: its best level at the simulation's
        own grains is the edge of the located span (the last level short of the end where it
        fades) or that end itself, strictly better than every level inside the edge
        (``own_at_edge``: a flat profile places nothing), and at every other grain-radius
        factor the optimum of its profile lies beyond the edge (``FullSearch.located`` false).
        The value named is then one bed's packing and grain size, not a located value. Never
        withdrawn: the screening's claim (the screening model's own evidence for it, as in ``beyond_span``); a value named
        inside the span whose reruns drift out (that is its numerics uncertainty, already
        reported); a check with a factor whose profile located nothing (failed runs).
        Measured on Yade recordings (library path): at 5 m floor recording 12 was named
        ``soil_layering`` at 0.4 m (reruns 0.413 and 0.5 m) and cohesion recording 11 a floor at
        1.05 m (reruns 1.25 and 1.25 m); at 13.7 m null 30 was named ``contact_damping`` at
        restitution 0.1 while its own best level was 0.5 (reruns 0.5 and 0.5): all three
        wrongly, none claimed by the screening. Kept: the DEM-truth floor 12 (named at 0.80 m,
        reruns 1.056 and 1.25 m), the Yade damping recordings 11 / 12 at 18.45 m (best level
        0.1, reruns 0.5), the Yade free rotation 12 through the command line (best level 0.2,
        reruns 0.2, the screening's claim)."""
        name = d.confirmed
        if check is None or name is None or check.get("hypothesis") != name \
                or name == self.rep.missing_physics:
            return None
        fs = self.searched.get(name)
        vals = [p["value"] for p in check["values"]]
        own = check.get("own_best_level")
        if fs is None or not vals or own is None \
                or any(v is None for v in vals) or any(fs.located(v) for v in vals):
            return None
        if not check.get("own_at_edge"):
            # named inside the span (its reruns' drift is its numerics uncertainty), or a flat
            # profile whose levels tie
            return None
        shown = ", ".join(f"{p['radius_scale']:g}x grains {p['value']:.4g} {fs.unit}"
                          for p in check["values"])
        return (f"its best level at the model's grains ({fs.parameter} = {own:.4g} {fs.unit}) "
                f"is at or beyond the edge of the located span ({fs.edge:.4g} {fs.unit}) and the "
                f"numerics check puts its optimum beyond that edge, towards the end where the "
                f"effect fades, at every other grain size ({shown}): the named value is not "
                f"resolved by the model's numerics")

    def numerics_record(self, check: dict[str, Any], d: _Decision) -> None:
        """Write a numerics check into the report: for the named effect, its uncertainty
        becomes at least the check's (``hypotheses[*].full_model.numerics``,
        ``fit.full_search.named.numerics``); for a withdrawn one, under
        ``fit.full_search.withdrawn``."""
        rep, name = self.rep, check["hypothesis"]
        rep.simulations["numerics_simulations"] = (
            int(rep.simulations.get("numerics_simulations", 0)) + int(check["runs"]))
        if name != d.confirmed:
            wd = rep.fit.setdefault("full_search", {}).setdefault("withdrawn", {})
            wd[name] = {"reason": self.withdrawn.get(name), "numerics": check}
            return
        h = next((h for h in rep.hypotheses if h["name"] == name), None)
        if h is None or "full_model" not in h:
            return
        p = self.searched[name].parameter
        sd = check["uncertainty"]
        fm = h["full_model"]
        fm["numerics"] = {p: check}
        named = rep.fit["full_search"]["named"]
        named["numerics"] = check
        if sd is not None and sd > fm["uncertainty"][p]:
            fm["uncertainty"][p] = sd
            named["uncertainty"] = sd
            if isinstance(h.get("uncertainty"), dict) and p in h["uncertainty"]:
                h["uncertainty"] = {**h["uncertainty"], p: sd}

    def settle(self, d: _Decision) -> None:
        """Make the report's best explanation, "after" fit, refitted signals and remaining
        mismatch those of the confirmation's answer, not of the screening's choice: the named
        effect's full run (its scores in ``fit.after`` by ``full_after``), else the
        recalibration (its screening refit), as ``diagnose`` reports when nothing beats it.
        The screening's own choice stays in ``fit.screening_after``. Before, a claim the full
        model rejected still headed the report ("best explanation", the orange "refitted"
        curve and the score "after")."""
        rep = self.rep
        if d.confirmed is None and rep.best in (None, RECALIBRATION.name):
            return  # the screening's answer already (within noise, or the recalibration)
        answer = d.confirmed or RECALIBRATION.name
        if rep.best == answer:  # the screening's choice confirmed: its full run is the refit
            self.remaining_mismatch()
            return
        rep.fit["screening_after"] = {"hypothesis": rep.fit.get("after_hypothesis"),
                                      "overall": rep.fit["after"]["overall"],
                                      "residual_rms_sigma": rep.fit.get("residual_rms_sigma_after")}
        fr = rep.fits.get(answer)
        if fr is not None:
            rep.fit["after"] = fr.scores
            rep.fit["after_hypothesis"] = answer
            rep.fit["residual_rms_sigma_after"] = fr.rms_sigma
        rep.best = answer
        if d.confirmed is None and fr is not None:
            rep.refitted = dict(fr.aligned)
        self.remaining_mismatch()

    def remaining_mismatch(self) -> None:
        """The report's remaining mismatch windows: the recording against the refitted
        signals (none without them)."""
        rep = self.rep
        if rep.refitted:
            rep.after_mismatch = _remaining_mismatch(
                rep.recording, rep.refitted, rep.noise,
                [ch for ch in self.chans if ch in rep.refitted])

    def rerank(self, full: _FullTier, tier: _SearchTier | None, d: _Decision) -> None:
        """Order ``rep.hypotheses`` by the evidence the confirmation ended with, not the
        screening model's: the answer first (the named effect, else the recalibration: the
        baseline physics explains the recording as well as anything run), then every hypothesis
        the full model ran, by its best located run's Delta BIC above the realisation floor
        (the recalibration at 0), then those it did not run, in the screening's order. Each
        entry keeps its ``screening_rank``; ``full_model_evidence`` gives the run, tier, Delta
        BIC and floor behind its place. Measured on the 26 DEM / Yade / raw-Yade effect cases
        at 13.7 m: the screening's first hypothesis was the concealed effect in 13, the final
        answer in 18 (before, the recalibration or a screened effect stood first on 4 of the
        DEM cases the confirmation named right)."""
        rep = self.rep
        evidence: dict[str, dict[str, Any]] = {}
        tiers = [("full simulator", full.rows[1:], full.floor)]
        if tier is not None:
            tiers.append(("search simulator", tier.rows[1:], tier.floor))
        for label, rows, floor in tiers:
            best = _best_rows(r for r in rows if self.located(r) and r["hypothesis"]
                              not in (REPLICATE, RECALIBRATION.name))
            for name, r in best.items():
                if name in evidence:  # the full simulator's runs come first
                    continue
                evidence[name] = {"tier": label,
                                  "delta_bic_vs_reference": float(r["delta_bic_vs_reference"]),
                                  "floor_delta_bic": float(floor["delta_bic"]),
                                  "delta_bic_vs_floor": float(r["delta_bic_vs_reference"]
                                                              - floor["delta_bic"]),
                                  "score": float(r["score"]),
                                  **({"value": r["search_value"]} if "search_value" in r else {}),
                                  **self.run_changes(r)}
        answer = d.confirmed or RECALIBRATION.name
        hyps = list(rep.hypotheses)
        for i, h in enumerate(hyps, 1):
            h["screening_rank"] = i
            if h["name"] in evidence:
                h["full_model_evidence"] = evidence[h["name"]]

        def key(h: dict[str, Any]) -> tuple[int, float, int]:
            if h["name"] == answer:
                return (0, 0.0, 0)
            if h["name"] == RECALIBRATION.name:
                return (1, -0.0, h["screening_rank"])
            if h["name"] in evidence:
                return (1, -evidence[h["name"]]["delta_bic_vs_floor"], h["screening_rank"])
            return (2, 0.0, h["screening_rank"])

        rep.hypotheses[:] = sorted(hyps, key=key)
        rep.fit["ranking"] = ("the answer first (the named effect, else the recalibration), then "
                              "by the full model's Delta BIC above the realisation floor "
                              "(recalibration 0), then the hypotheses it did not run in the "
                              "screening's order")

    def sentence(self, full: _FullTier, tier: _SearchTier | None, d: _Decision) -> str:
        """The confirmation's part of the report's decision line."""
        rows, searched, best, confirmed = full.rows, self.searched, d.best, d.confirmed
        n_lv = _n_runs(r for r in rows if "search_value" in r)
        if tier is not None:
            how = (f"{len(rows)} runs, {n_lv} of them the best levels of a {_n_runs(tier.rows)}-run "
                   f"search over {len(searched)} effects on the search simulator")
        elif searched:
            how = (f"{_n_runs(rows)} runs, {n_lv} of them a full-model search over "
                   f"{len(searched)} effects")
            if len(self.beds) > 1 and any("beds" in r for r in rows):
                how += f" (deposited levels on {len(self.beds)} beds each)"
        else:
            how = f"{len(rows)} runs"
        at = (f" at {searched[confirmed].parameter} = {best['search_value']:.4g} "
              f"{searched[confirmed].unit}" if confirmed and "search_value" in best else "")
        if self.replicates:
            rf = self.rep.fit["realisation"]
            stiff = _stiffer_text(rf.get("stiffer_soil") or [])
            how += (f"; realisation floor of {len(self.replicates)} replicate packings{stiff} "
                    f"on the {rf['tier']}: Delta BIC {rf['floor_delta_bic']:.1f}, score "
                    f"{rf['floor_score']:.3f}")
        return (f"full-simulation confirmation ({how}, reference score {full.reference:.3f}): "
                + (f"{d.ambiguous[0]} would be named, but {d.ambiguous[1]} fits the recording "
                   f"with a higher likelihood on the {d.contested['tier']} (Delta BIC "
                   f"{d.contested['delta_bic']:.1f} against {d.contested['own_delta_bic']:.1f}) "
                   f"and scores no worse than every replicate ({d.contested['score']:.3f}): not "
                   f"told apart, neither named; " if d.contested is not None else
                   _outranked_sentence(d) if d.outranked else
                   f"{' and '.join(d.ambiguous)} both beat the reference within Delta BIC "
                   f"{_ambiguity_margin(full.floor):.3g} of each other, neither named; "
                   if d.ambiguous else "")
                + (f"{confirmed} confirmed{at} (score {best['score']:.3f}, Delta BIC "
                   f"{best.get('delta_bic_vs_reference', 0.0):.1f})"
                   if confirmed and best is not rows[0] else
                   f"{confirmed} confirmed (score {best['score']:.3f})" if confirmed
                   else "no missing physics confirmed"))


def _n_runs(rows: Iterable[dict[str, Any]]) -> int:
    """Simulations behind ``rows``: a pooled level counts its beds."""
    return sum(len(r["beds"]) if "beds" in r else 1 for r in rows)


def _overrides_key(ov: Mapping[str, Any]) -> str:
    """A run's identity: its overrides, keys sorted, numbers as Python numbers."""
    def plain(v: Any) -> Any:
        return v.tolist() if isinstance(v, (np.generic, np.ndarray)) else repr(v)
    return json.dumps(ov, sort_keys=True, default=plain)


def _n_distinct(*row_lists: Iterable[dict[str, Any]]) -> int:
    """Simulations behind the rows of ``row_lists``, as ``_n_runs`` counts them, but a set of
    overrides that several rows share counted once (``_Confirmation.outputs`` ran it once)."""
    keys: set[str] = set()
    for rows in row_lists:
        for r in rows:
            for b in r.get("beds", [r]):
                keys.add(_overrides_key(b["overrides"]))
    return len(keys)


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
        return (f"decisive (Delta BIC {db:.1f}) but within Delta BIC "
                f"{_ambiguity_margin(floor):.3g} of "
                f"{next(a for a in ambiguous if a != r['hypothesis'])}: not told apart")
    if is_claim:
        return (f"the screening's claim, but its full run is decisively worse than the reference "
                f"or the best replicate (Delta BIC {db:.1f}, score {sc:.3f})")
    if db <= ACCEPT_MARGIN:
        return f"Delta BIC {db:.1f} over the reference, not above {ACCEPT_MARGIN:g}"
    if db - floor["delta_bic"] <= REALISATION_MARGIN:
        return (f"fits no better than a replicate packing of the baseline or the bed made "
                f"stiffer (Delta BIC {db:.1f} against the realisation floor's "
                f"{floor['delta_bic']:.1f})")
    if sc - floor["score"] < CONFIRM_MIN_GAIN:
        return (f"Delta BIC {db:.1f}, but its score {sc:.3f} is not {CONFIRM_MIN_GAIN:g} above "
                f"{floor['score']:.3f} (reference and replicates)")
    return (f"decisive (Delta BIC {db:.1f}, score {sc:.3f}) but another effect ranks higher or "
            f"the screening's claim stands")


def _pair_record(rows: Iterable[Row]) -> dict[str, dict[str, float]]:
    """``fit.confirmation_ambiguous`` of two runs not told apart: each effect's Delta BIC over
    the reference and score."""
    return {r["hypothesis"]: {"delta_bic_vs_reference": r["delta_bic_vs_reference"],
                              "score": r["score"]} for r in rows}


def _outranked_pair(d: _Decision) -> tuple[Row, Row]:
    """The screening's claim and the rival that out-ranks it in likelihood (``outranked``)."""
    return d.best_by_effect[d.ambiguous[0]], d.best_by_effect[d.ambiguous[1]]


def _outranked_sentence(d: _Decision) -> str:
    """The decision line's part for a claim out-ranked in likelihood (``_Decision.outranked``)."""
    claim, rival = _outranked_pair(d)
    if rival["score"] >= claim["score"]:
        return (f"{d.ambiguous[1]} fits the recording with a higher likelihood and a higher "
                f"score than {d.ambiguous[0]}, the screening's claim (Delta BIC "
                f"{rival['delta_bic_vs_reference']:.1f} against "
                f"{claim['delta_bic_vs_reference']:.1f}, score {rival['score']:.3f} against "
                f"{claim['score']:.3f}), but not by the score margin ({CONFIRM_MIN_GAIN:g}) "
                f"that naming asks for: not told apart, neither named; ")
    return (f"{d.ambiguous[0]} (the screening's claim) scores higher ({claim['score']:.3f} "
            f"against {rival['score']:.3f}), but {d.ambiguous[1]} fits the recording with a "
            f"higher likelihood (Delta BIC {rival['delta_bic_vs_reference']:.1f} against "
            f"{claim['delta_bic_vs_reference']:.1f}), both decisively: not told apart, neither "
            f"named; ")


def _outranked_verdict(name: str, d: _Decision) -> str:
    """The verdict line of either effect of an out-ranked claim (``_Decision.outranked``)."""
    claim, rival = _outranked_pair(d)
    if rival["score"] >= claim["score"]:
        if name == d.ambiguous[0]:
            return (f"the screening's claim (Delta BIC {claim['delta_bic_vs_reference']:.1f}, "
                    f"score {claim['score']:.3f}), but {d.ambiguous[1]} fits with a higher "
                    f"likelihood and score ({rival['delta_bic_vs_reference']:.1f}, "
                    f"{rival['score']:.3f}): not told apart")
        return (f"fits with a higher likelihood and score than the screening's claim "
                f"{d.ambiguous[0]} (Delta BIC {rival['delta_bic_vs_reference']:.1f} against "
                f"{claim['delta_bic_vs_reference']:.1f}, score {rival['score']:.3f} against "
                f"{claim['score']:.3f}), short of the score margin ({CONFIRM_MIN_GAIN:g}) that "
                f"naming asks for: not told apart")
    if name == d.ambiguous[0]:
        return (f"the screening's claim (Delta BIC {claim['delta_bic_vs_reference']:.1f}, score "
                f"{claim['score']:.3f}), but {d.ambiguous[1]} fits with a higher likelihood "
                f"({rival['delta_bic_vs_reference']:.1f}, score {rival['score']:.3f}), both "
                f"decisively: not told apart")
    return (f"decisive (Delta BIC {rival['delta_bic_vs_reference']:.1f}, score "
            f"{rival['score']:.3f}) with a higher likelihood than the screening's claim "
            f"{d.ambiguous[0]} ({claim['delta_bic_vs_reference']:.1f}), which scores higher "
            f"({claim['score']:.3f}): not told apart")


def _contested_verdict(name: str, pair: list[str], c: dict[str, Any]) -> str:
    """The verdict line of either effect of a contested pair (``_Decision.contested``)."""
    if name == pair[0]:
        return (f"would be named (Delta BIC {c['own_delta_bic']:.1f}, score "
                f"{c['own_score']:.3f} on the {c['tier']}), but {pair[1]} fits with a higher "
                f"likelihood there ({c['delta_bic']:.1f}, score {c['score']:.3f}, no worse than "
                f"every replicate): not told apart")
    return (f"fits with a higher likelihood than {pair[0]} on the {c['tier']} (Delta BIC "
            f"{c['delta_bic']:.1f} against {c['own_delta_bic']:.1f}) and no worse than every "
            f"replicate (score {c['score']:.3f}), short of the score margin naming asks for: "
            f"the two are not told apart")


def _not_decisively_worse(r: dict[str, Any], floor: dict[str, float]) -> bool:
    """The rule a screening claim's run meets to stand: within ``ACCEPT_MARGIN`` of the
    ``floor``'s Delta BIC and within ``CONFIRM_MIN_GAIN`` of its score (the full tier's floor in
    ``decide``, the search tier's in ``_search_support``)."""
    return (r["delta_bic_vs_reference"] - floor["delta_bic"] >= -ACCEPT_MARGIN
            and r["score"] >= floor["score"] - CONFIRM_MIN_GAIN)


def _contends(r: dict[str, Any], floor: dict[str, float], gain: float = 0.0) -> bool:
    """A scored run that beats the reference (Delta BIC > ``ACCEPT_MARGIN``) and the best
    replicate (by ``REALISATION_MARGIN``) in Delta BIC and scores at least ``gain`` above the
    best of reference and replicates. With ``gain`` 0 (no score margin) it can leave a named
    effect not told apart (``_Confirmation._likelihood_rival``); ``_decisive`` asks for
    ``CONFIRM_MIN_GAIN``."""
    db = r["delta_bic_vs_reference"]
    return (db > ACCEPT_MARGIN and db - floor["delta_bic"] > REALISATION_MARGIN
            and r["score"] - floor["score"] >= gain)


def _decisive(r: dict[str, Any], floor: dict[str, float]) -> bool:
    """A scored run beats the reference (Delta BIC > ``ACCEPT_MARGIN``) and the realisation
    ``floor`` (Delta BIC above the best replicate's by ``REALISATION_MARGIN``, score by
    ``CONFIRM_MIN_GAIN`` above the best of reference and replicates): the rule for naming a
    full run and for promoting a search-tier level to one."""
    return _contends(r, floor, CONFIRM_MIN_GAIN)


def _stiffer_text(stiff: Sequence[Mapping[str, Any]]) -> str:
    """The decision's words for the stiffer-soil runs of the floor, e.g. " and the whole bed
    x2 / x5 stiffer and the bed below 0.15 m x2 / x5 stiffer"."""
    forms: dict[str, list[float]] = {}
    for r in stiff:
        forms.setdefault(r.get("form", "whole bed"), []).append(float(r["young_factor"]))

    def words(form: str, fs: list[float]) -> str:
        x = " / ".join(f"x{f:g}" for f in fs)
        if form == catalogue.HERTZ_FLOOR_FORM:
            return f" and the whole bed with the Hertz-Mindlin law ({x} the modulus)"
        return f" and the {'whole bed' if form == 'whole bed' else 'bed ' + form} {x} stiffer"

    return "".join(words(form, fs) for form, fs in forms.items())


def _stiffer_below(ov: Mapping[str, Any]) -> float:
    """The depth [m] below which a stiffer-soil run (``stiffer_requests``) makes the grains
    stiffer, from its overrides."""
    return float(ov.get("physics.soil_layering.depth", catalogue.WHOLE_BED_DEPTH))


def _stiffer_form(ov: Mapping[str, Any]) -> str:
    """The form of a stiffer-soil run from its overrides: "whole bed", "below D m" (the bed
    stiffer below its top grain row; its runs pool apart), or ``catalogue.HERTZ_FLOOR_FORM``
    (the whole bed with the Hertz-Mindlin law)."""
    if ov.get("soil.contact_law") == "hertz_mindlin":
        return catalogue.HERTZ_FLOOR_FORM
    below = _stiffer_below(ov)
    return "whole bed" if below <= catalogue.WHOLE_BED_DEPTH else f"below {below:g} m"


def _realisation_floor(rows: Iterable[dict[str, Any]], reference_score: float,
                       stiffer: Iterable[dict[str, Any]] = ()) -> dict[str, float]:
    """The best Delta BIC (``delta_bic``, at least 0: the reference) and the best score
    (``score``, at least the reference's) of the scored replicate runs among ``rows`` and the
    scored whole-bed stiffness runs ``stiffer``, and the sample standard deviation of the
    replicates' Delta BIC alone (``scatter``; 0 with fewer than two)."""
    reps = [r for r in rows if r["hypothesis"] == REPLICATE and "delta_bic_vs_reference" in r
            and math.isfinite(r["score"])]
    alt = [r for r in stiffer if "delta_bic_vs_reference" in r and math.isfinite(r["score"])]
    db = [float(r["delta_bic_vs_reference"]) for r in reps]
    return {"delta_bic": max([0.0] + db + [float(r["delta_bic_vs_reference"]) for r in alt]),
            "score": max([float(reference_score)] + [float(r["score"]) for r in reps + alt]),
            "scatter": float(np.std(db, ddof=1)) if len(db) > 1 else 0.0}


def _separation(rep: Report, aligned: Mapping[str, Signal]) -> float:
    """How far a run's aligned channels lie from the baseline simulation's, in the diagnosis's
    own residual weights (sensor noise and model-error floor, ``_full_rss``): the mean squared
    weighted difference on the residual samples, averaged over the channels [-]."""
    t0 = float(rep.fit["score_window_s"][0])
    out = []
    for ch in rep.channels:
        base = rep.baseline[ch]
        w = _residual_weight(rep, ch)
        idx = np.flatnonzero(base.t >= t0)
        out.append(float(np.mean(((aligned[ch].data[idx] - base.data[idx]) * w) ** 2)))
    return float(np.mean(out))


def _detectability(rep: Report, rows: Sequence[dict[str, Any]],
                   searched: Mapping[str, catalogue.FullSearch]) -> dict[str, Any] | None:
    """What this model at this resolution can show at all: how far each search level and each
    replicate packing moves the baseline simulation (``_separation``). A level that moves it
    less than the least different replicate does is below the realisation scatter: a recording
    of that much of the effect differs from the model no more than another packing of the same
    bed would, so no comparison can name it. Per effect: every level's separation and the
    weakest level, counted from the end where the effect fades, from which on every stronger
    level is above that threshold (``visible_from``; None when not even the strongest is).
    None without scored replicates.

    Measured (DEM truth, 13.7 m, small bed): replicates 1.4-6.2, contact cohesion 3e4-2.4e5 Pa
    0.03-0.8 and 4.8e5 Pa 5.1, restitution 0.1-0.5 4.1-6.6, layering 73-161: the concealed
    cohesions of 1.2-1.3e5 Pa lie far below what another packing changes."""
    reps = [_separation(rep, r["aligned"]) for r in rows
            if r["hypothesis"] == REPLICATE and "aligned" in r]
    if not reps:
        return None
    threshold = min(reps)
    effects: dict[str, Any] = {}
    for name, fs in searched.items():
        lv = sorted(((float(r["search_value"]), _separation(rep, r["aligned"])) for r in rows
                     if r["hypothesis"] == name and "search_value" in r and "aligned" in r
                     and not r.get("refined")), reverse=fs.fades == "high")
        if not lv:
            continue
        # from the fading end towards the strong end: the weakest level beyond which every
        # level is visible
        visible_from = None
        for i in range(len(lv)):
            if all(s > threshold for _, s in lv[i:]):
                visible_from = lv[i][0]
                break
        effects[name] = {"parameter": fs.parameter, "unit": fs.unit,
                         "levels": [[v, s] for v, s in sorted(lv)],
                         "visible_from": visible_from}
    return {"measure": "mean squared difference from the baseline simulation in the "
                       "diagnosis's residual weights (noise and model-error floor)",
            "replicates": reps, "threshold": threshold, "effects": effects}


def _invisible_note(det: Mapping[str, Any], name: str, fs: catalogue.FullSearch | None
                    ) -> str | None:
    """The verdict's addendum for an effect the model cannot show in full: the span below its
    detectability limit (``_detectability``), or None."""
    e = det["effects"].get(name)
    if e is None or fs is None:
        return None
    weakest = fs.values[-1] if fs.fades == "high" else fs.values[0]
    v = e["visible_from"]
    if v is not None and v == weakest:
        return None
    if v is None:
        return (f"no level of it moves this model further than another packing of the bed does "
                f"(separation at most {max(s for _, s in e['levels']):.2g} against "
                f"{det['threshold']:.2g}): not visible at this resolution")
    vals = [x for x, _ in e["levels"]]
    hidden = min(x for x in vals if x > v) if fs.fades == "high" else max(x for x in vals if x < v)
    side = "or more" if fs.fades == "high" else "or less"
    return (f"a {fs.parameter} of {hidden:.4g} {fs.unit} {side} moves this model less than "
            f"another packing of the bed does (separation below {det['threshold']:.2g}): not "
            f"visible at this resolution")


def _ambiguity_margin(floor: dict[str, float]) -> float:
    """Delta BIC within which two decisive effects are not told apart: ``AMBIGUITY_MARGIN``,
    or the replicates' scatter when larger."""
    return max(AMBIGUITY_MARGIN, float(floor.get("scatter", 0.0)))


def _best_rows(rows: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The run with the highest Delta BIC of each hypothesis among scored ``rows``."""
    best: dict[str, dict[str, Any]] = {}
    for r in rows:
        if "delta_bic_vs_reference" in r and (
                r["hypothesis"] not in best
                or r["delta_bic_vs_reference"] > best[r["hypothesis"]]["delta_bic_vs_reference"]):
            best[r["hypothesis"]] = r
    return best


def _scored_levels(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The scored search-level runs among ``rows``, refinements aside."""
    return [r for r in rows if "search_value" in r and not r.get("refined") and "rss" in r]


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


def _profile(runs: Iterable[dict[str, Any]], fs: catalogue.FullSearch
             ) -> list[tuple[float, float]]:
    """``(search coordinate, Delta BIC)`` of the search runs with a finite Delta BIC, by
    coordinate."""
    return sorted((fs.coord(float(r["search_value"])), float(r["delta_bic_vs_reference"]))
                  for r in runs if math.isfinite(float(r["delta_bic_vs_reference"])))


def _profile_optimum(levels: Iterable[dict[str, Any]], fs: catalogue.FullSearch
                     ) -> float | None:
    """The search coordinate a profile of search levels (one effect, refinements aside)
    locates: the refinement's vertex (``_search_vertex``) of its best level when there is one,
    else the best level; None without a scored level."""
    lv = [r for r in levels if not r.get("refined") and "delta_bic_vs_reference" in r
          and math.isfinite(float(r["delta_bic_vs_reference"]))]
    if not lv:
        return None
    best = max(lv, key=lambda r: r["delta_bic_vs_reference"])
    v = _search_vertex(best, lv, fs)
    return fs.coord(float(v["value"] if v is not None else best["search_value"]))


def _realisation_interval(lv: list[dict[str, Any]], x: float, margin: float,
                          fs: catalogue.FullSearch) -> dict[str, Any] | None:
    """The values of a searched effect that fit within ``margin`` (Delta BIC) of its best run.
    Every run ``lv`` (levels and refinement) within the margin is not told apart from the best
    (each level is its own realisation of the bed, so the profile is jagged by the realisation
    scatter: the span of all of them counts, not only the runs next to the best); beyond the
    outermost of them the end is interpolated, linearly in the search coordinate, to where the
    profile crosses the best minus ``margin`` towards the next run. A side with no run below
    that is *open*: it ends at the span's end run (the search bounds nothing beyond it). The
    interval always holds ``x``, the adopted value. ``{"low", "high", "open": [low open, high
    open], "margin"}``, or None with fewer than two runs."""
    pts = _profile(lv, fs)
    if len(pts) < 2:
        return None
    thr = max(d for _, d in pts) - margin
    within = [j for j, (_, d) in enumerate(pts) if d >= thr]

    def end(j: int, step: int) -> tuple[float, bool]:
        if not 0 <= j + step < len(pts):
            return pts[j][0], True
        (ua, da), (ub, db) = pts[j], pts[j + step]  # da >= thr > db
        return ua + (da - thr) / (da - db) * (ub - ua), False

    (lo, lo_open), (hi, hi_open) = end(within[0], -1), end(within[-1], +1)
    u = fs.coord(x)
    return {"low": fs.value(min(lo, u)), "high": fs.value(max(hi, u)),
            "open": [lo_open, hi_open], "margin": float(margin)}


def _profile_scatter(levels: list[dict[str, Any]], fs: catalogue.FullSearch) -> float:
    """How far the search levels' Delta BIC scatter about a smooth profile: the residual
    standard deviation of a least-squares parabola in the search coordinate (0 with fewer than
    four levels). Each level is its own packing of the bed, and where runs fit well one packing's
    grains count more than where they all fit badly (the replicates of the baseline): measured
    on DEM truth layering 11 at eight depths of 0.15-0.40 m, the levels scatter by 24 about the
    parabola, the replicates by 3.7; the catalogue levels of the DEM-truth layering and floor
    cases by 4.7-25."""
    pts = _profile(levels, fs)
    if len(pts) < 4:
        return 0.0
    u, d = np.array(pts).T
    res = d - np.polyval(np.polyfit(u, d, 2), u)
    return float(math.sqrt(np.sum(res ** 2) / (len(pts) - 3)))


def _adopt_full_parameters(rep: Report, best: dict[str, Any], fs: catalogue.FullSearch,
                           rows: list[dict[str, Any]], floor: dict[str, float]) -> None:
    """Record the full model's value of a named searched effect in its hypothesis entry
    (``full_model``) and in ``parameters`` (with its uncertainty and unit): in place of the
    screening's where the screening parameter means the same, beside them where it does not
    (the screening's kept in ``screening_parameters``).

    Uncertainty: the larger of two. The noise's: from the curvature of Delta BIC over the
    levels around the best run (1 / sqrt(information) in the search coordinate), else half the
    distance to the nearest level (``noise_uncertainty``). The realisation's: the values whose
    runs fit within a margin of the best (``_realisation_interval``), as the larger distance
    from the value to the interval's ends (``interval``). The margin is the one within which
    two runs are not told apart: the ambiguity margin (the replicates' Delta BIC scatter, at
    least ``AMBIGUITY_MARGIN``), or the levels' own scatter about a smooth profile when larger
    (``_profile_scatter``). The noise's curvature alone treats the levels as one bed; each is
    its own packing."""
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
    noise_sd = sd
    margin = max(_ambiguity_margin(floor), _profile_scatter(levels, fs))
    interval = _realisation_interval(lv, x, margin, fs)
    if interval is not None:
        sd = max(sd, x - interval["low"], interval["high"] - x)
    h = next((h for h in rep.hypotheses if h["name"] == name), None)
    if h is None:
        return
    h["full_model"] = {"parameters": {fs.parameter: x}, "uncertainty": {fs.parameter: sd},
                       "noise_uncertainty": {fs.parameter: noise_sd},
                       "interval": {fs.parameter: interval},
                       "unit": {fs.parameter: fs.unit}, "overrides": best["overrides"],
                       "score": best["score"],
                       "delta_bic_vs_reference": best["delta_bic_vs_reference"],
                       "runs": len(lv), **({"form": fs.form} if fs.form is not None else {})}
    # the scenario fix is the full model's own (the screening's values were mapped across)
    h["scenario_overrides"] = dict(best["overrides"])
    # the full model's value is the one the recording was fitted with: it replaces the
    # screening's where the two mean the same, and joins them where the full model's scenario
    # value is another quantity (the rolling coefficient of a free rotation, where the
    # screening model fits a friction ratio and a mobilisation depth)
    h["screening_parameters"] = dict(h.get("parameters", {}))
    h["parameters"] = {**h.get("parameters", {}), fs.parameter: x}
    if isinstance(h.get("uncertainty"), dict):
        h["uncertainty"] = {**h["uncertainty"], fs.parameter: sd}
    if isinstance(h.get("units"), dict):
        h["units"] = {**h["units"], fs.parameter: fs.unit}
    derived = _derived_values(fs.parameter, x, interval, fs.form)
    if derived:
        h["full_model"]["derived"] = derived
    rep.fit.setdefault("full_search", {})["named"] = {"hypothesis": name, fs.parameter: x,
                                                      "parameter": fs.parameter,
                                                      "uncertainty": sd,
                                                      "noise_uncertainty": noise_sd,
                                                      "interval": interval, "unit": fs.unit,
                                                      **({"form": fs.form}
                                                         if fs.form is not None else {}),
                                                      **({"derived": derived}
                                                         if derived else {})}


#: searched parameter -> (derived name, unit, function, what it is): quantities a user compares
#: with another code or a measurement. The restitution searched is the nominal one of crashdem's
#: dashpot (Yade's betan convention); in its ``no_tension`` form the contact never pulls and a
#: head-on contact of it rebounds faster (``soil.Material.rebound_restitution``), in its
#: ``tension`` form (``catalogue.DAMPING_FORMS``) the dashpot pulls and nominal = rebound.
#: Keyed by parameter and the search's form (None: any form)
DERIVED: dict[tuple[str, str | None], tuple[str, str, Any, str]] = {
    ("restitution", None): (
        "rebound_restitution", "1", rebound_restitution,
        "the rebound ratio of a head-on grain contact at this nominal restitution (crashdem's "
        "contact force never pulls, so it opens early; in a code whose dashpot may pull, "
        "nominal and rebound restitution are the same)"),
    ("restitution", "tension"): (
        "rebound_restitution", "1", float,
        "the rebound ratio of a head-on grain contact at this nominal restitution: the same "
        "value, the dashpot pulls until the contact opens as in Yade's CundallStrackVisco"),
}


def _derived_values(parameter: str, x: float, interval: Mapping[str, Any] | None,
                    form: str | None = None) -> dict[str, Any] | None:
    """The derived quantity of a named searched value (``DERIVED``) in the search's ``form``
    at the value and at the ends of its interval, or None."""
    d = DERIVED.get((parameter, form), DERIVED.get((parameter, None)))
    if d is None:
        return None
    key, unit, f, what = d
    out: dict[str, Any] = {"name": key, "value": f(x), "unit": unit, "meaning": what}
    if interval is not None:
        out["interval"] = [f(interval["low"]), f(interval["high"])]
    return out


def _runs_the_baseline(h: dict[str, Any], cat: catalogue.Catalogue) -> bool:
    """True when a screened candidate's full run (``_confirmation_values``: a parameter at its
    ``off`` value takes the catalogue's nominal) changes nothing in the scenario: it maps at
    least one parameter, and every one it maps is at its ``off`` value, with no model form
    (variant) of its own."""
    if h.get("variant") is not None:
        return False
    hyp = cat.get(h["name"])
    used = _confirmation_values(h, hyp)
    mapped = [p for p in hyp.parameters if p.scenario_key is not None and p.name in used]
    if not mapped or any(p.off is None for p in mapped):
        return False
    return all(_at_off(p, used[p.name]) for p in mapped)


def _confirmation_values(h: dict[str, Any], hyp: catalogue.Hypothesis) -> dict[str, float]:
    """A candidate's parameters for its full run: its screened values, except where the
    screening left the effect switched off (a parameter at its ``off`` value, i.e. the
    screening model could not see the effect): there the catalogue's nominal value."""
    vals = dict(h["parameters"])
    for p in hyp.parameters:
        if p.name in vals and _at_off(p, vals[p.name]):
            vals[p.name] = p.nominal
    return vals


def _confirmation_overrides(h: dict[str, Any],
                            cat: catalogue.Catalogue = catalogue.DROP) -> dict[str, Any]:
    """Scenario overrides of a candidate's full run (``_confirmation_values``)."""
    if h.get("variant") == FILTER_CLASS_VARIANT:
        return {"instrumentation.cfc": float(h["parameters"]["filter_class"])}
    hyp = cat.get(h["name"])
    return dict(hyp.scenario_overrides({**h["recalibration"], **_confirmation_values(h, hyp)},
                                       h.get("variant")))


def _residual_weight(rep: Report, ch: str) -> float:
    """Weight of channel ``ch``'s residuals: 1 / sqrt(sensor noise^2 + model-error floor^2)."""
    sm = rep.fit.get("model_error", {}).get(ch, {}).get("sigma", 0.0)
    return 1.0 / math.sqrt(rep.noise[ch].sigma ** 2 + sm * sm)


def _full_residuals(rep: Report, aligned: Mapping[str, Signal]) -> list[np.ndarray]:
    """Weighted residuals of aligned channels against the report's recording, one array per
    channel, on the residual samples of the diagnosis (weights: sensor noise and model-error
    floor)."""
    t0 = float(rep.fit["score_window_s"][0])
    out = []
    for ch in rep.channels:
        rec = rep.recording[ch]
        w = _residual_weight(rep, ch)
        idx = np.flatnonzero(rec.t >= t0)
        stride = max(1, int(round(idx.size / max(1, rep.fit["n_samples"] // len(rep.channels)))))
        idx = idx[::stride]
        out.append((aligned[ch].data[idx] - rec.data[idx]) * w)
    return out


def _full_rss(rep: Report, aligned: Mapping[str, Signal]) -> float:
    """Weighted residual sum of squares of aligned channels (``_full_residuals``)."""
    rss = 0.0
    for r in _full_residuals(rep, aligned):
        rss += float(np.sum(r ** 2))
    return rss
