"""Write a diagnosis :class:`crashdem.diagnosis.Report` to ``report.json``, ``report.md`` and
overlay plots (recording, baseline, refitted simulation; mismatch windows shaded).

Plots use matplotlib's Agg backend (no display); accelerations are shown in g (``G0``).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from crashdem.diagnosis.catalogue import HERTZ_FLOOR_FORM
from crashdem.diagnosis.confirm import OWN_LAW
from crashdem.signal import G0

__all__ = ["write_report", "to_json", "to_markdown", "plot_overlays"]


def _clean(x: Any) -> Any:
    """JSON-safe copy: numpy scalars to Python, non-finite floats to None, tuples to lists."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    return x


def without_wall_times(x: Any) -> Any:
    """Report JSON (or a part of it) without its wall times (keys ``wall_time_s``,
    ``*_wall_time_s`` and ``*_wall_s``): what two diagnoses of the same inputs must agree on."""
    if isinstance(x, dict):
        return {k: without_wall_times(v) for k, v in x.items()
                if not (k.endswith("wall_time_s") or k.endswith("_wall_s"))}
    if isinstance(x, list):
        return [without_wall_times(v) for v in x]
    return x


def to_json(report, d: dict[str, Any] | None = None) -> str:
    """The report as JSON text (what ``report.json`` holds); ``d``: ``report.to_dict()`` when
    the caller has it already (it rates the fit again at every alignment it tries)."""
    return json.dumps(_clean(report.to_dict() if d is None else d), indent=2, sort_keys=False)


def _fmt(v: float | None, nd: int = 3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{v:.{nd}g}"


def _not_told_apart(report, d: dict[str, Any]) -> str:
    """The headline of a report whose confirmation found two effects it could not tell apart
    (``fit["confirmation_ambiguous"]``): each with its located value (the full model's search
    level, when it has one), Delta BIC over the reference, score and what its run changes of
    the baseline's mismatch features (``full_model_evidence["changes"]``)."""
    ev = {h["name"]: h.get("full_model_evidence") or {} for h in d["hypotheses"]}
    parts = []
    for name, c in d["fit"]["confirmation_ambiguous"].items():
        # a value comes only from a search level, so the effect is a searched one
        value = c.get("value", ev.get(name, {}).get("value"))
        fs = report.catalogue.full_search.get(name)
        where = f"{fs.parameter} = {_fmt(value)} {fs.unit}; " if value is not None else ""
        what = ev.get(name, {}).get("changes")
        parts.append(f"{name} ({where}Delta BIC {c['delta_bic_vs_reference']:.1f} over the "
                     f"reference, score {_fmt(c['score'])}" + (f"; {what}" if what else "") + ")")
    return (" and ".join(parts) + ": each fits the recording decisively better than the "
            "reference, neither decisively better than the other, so neither is named -- the "
            "recording alone cannot choose between them at this resolution")


def _unit(unit: str | None) -> str:
    """A unit as shown after a value: none for a dimensionless one ("1")."""
    return "" if unit in (None, "", "1") else unit


def to_markdown(report, plots: list[str] | None = None,
                d: dict[str, Any] | None = None) -> str:
    """A readable summary of the report; ``d`` as in :func:`to_json`."""
    from crashdem.diagnosis import CONFIRM_MIN_GAIN, REPLICATE

    d = report.to_dict() if d is None else d
    fit = d["fit"]
    lines = ["# crashdem diagnosis report", ""]
    mp = d["missing_physics"]
    lines += [f"**Missing physics:** {mp if mp else 'none claimed'}  ",
              f"**Best explanation:** {d['best'] or 'baseline (within noise)'}  "]
    named = next((h for h in d["hypotheses"] if h["name"] == mp), None) if mp else None
    if named is not None:
        units = named.get("units", {})
        if named["parameters"]:
            lines.append("**Value:** " + "; ".join(
                f"{k} = {_fmt(v)} ± {_fmt(named['uncertainty'].get(k))} {_unit(units.get(k))}"
                .rstrip() for k, v in named["parameters"].items()) + "  ")
        lines.append(f"**Why:** {named['evidence']}  ")
    if not mp and fit.get("confirmation_ambiguous"):
        lines.append(f"**Not told apart:** {_not_told_apart(report, d)}  ")
    lines += [f"**Decision:** {d['decision']}", ""]
    conv = fit.get("recorded_channels")
    if conv:
        lines += ["## Recorded channels", "", "| model channel | recorded as | conversion |",
                  "|---|---|---|"]
        lines += [f"| {ch} | {c['recorded']} | {c['converted'] or 'none'} |"
                  for ch, c in conv.items()]
        lines.append("")
    for name, why in (fit.get("recorded_channels_skipped") or {}).items():
        lines.append(f"Not used, unusable: `{name}` ({why})  ")
    if fit.get("recorded_channels_skipped"):
        lines.append("")
    lines += ["## Noise of the recording", "", "| channel | sigma | unit | method |", "|---|---|---|---|"]
    for ch, n in d["noise"].items():
        lines.append(f"| {ch} | {_fmt(n['sigma'])} | {n['unit']} | {n['method']} |")
    lines += ["", "## Mismatch windows (baseline vs recording)", ""]
    if d["mismatch"]:
        lines += ["| channel | from [ms] | to [ms] | feature | size | max residual [sigma] | what |",
                  "|---|---|---|---|---|---|---|"]
        for w in d["mismatch"]:
            lines.append(f"| {w['channel']} | {w['t_start_s'] * 1e3:.1f} | {w['t_end_s'] * 1e3:.1f} | "
                         f"{w['feature']} | {_fmt(w['size'])} {w['unit']} | "
                         f"{w['max_residual_sigma']:.1f} | {w['description']} |")
    else:
        lines.append("No window exceeds the noise threshold.")
    reranked = "ranking" in fit
    lines += ["", "## Hypotheses (" + (fit["ranking"] if reranked else "ranked by BIC") + ")", ""]
    if reranked:
        lines += ["| rank | name | parameters (± 1 sigma) | score before | score after | Delta BIC "
                  "vs recal. | penalty | evidence | screening rank | full model: Delta BIC over "
                  "the realisation floor |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
    else:
        lines += ["| rank | name | parameters (± 1 sigma) | score before | score after | Delta BIC "
                  "vs recal. | penalty | evidence |",
                  "|---|---|---|---|---|---|---|---|"]
    for i, h in enumerate(d["hypotheses"], 1):
        pars = h["parameters"] if h["parameters"] else h["recalibration"]
        unc = h["uncertainty"] if h["parameters"] else h["recalibration_uncertainty"]
        units = h.get("units", {})
        ptxt = "; ".join(f"{k} = {_fmt(v)} ± {_fmt(unc.get(k))} {_unit(units.get(k))}".strip()
                         for k, v in pars.items())
        row = (f"| {i} | {h['name']} | {ptxt} | {_fmt(h['score_before'])} | "
               f"{_fmt(h['score_after'])} | {h['delta_bic_vs_recalibration']:.1f} | "
               f"{h['complexity_penalty']:.1f} | {h['evidence']} |")
        if reranked:
            ev = h.get("full_model_evidence")
            row += (f" {h.get('screening_rank', '')} | "
                    + (f"{ev['delta_bic_vs_floor']:.1f} ({ev['tier']})"
                       + (f"; its run {ev['changes']}" if ev.get("changes") else "") if ev else
                       "0 (the baseline physics: its best realisation)"
                       if h["name"] == "recalibration" else "not run")
                    + " |")
        lines.append(row)
    sc = fit.get("sensor_check") or {}
    lines += ["", "## Accelerometer vs measured velocity (model-free sensor check)", ""]
    if not sc.get("applicable"):
        lines.append(f"Not applicable: {sc.get('reason', 'not run')}.")
    else:
        verdict = (f"**sensor dynamics found**: {sc['form']} sensor, fn = "
                   f"{_fmt(sc['mount_frequency'])} ± {_fmt(sc['uncertainty']['mount_frequency'])} Hz, "
                   f"zeta = {_fmt(sc['mount_damping'])} ± {_fmt(sc['uncertainty']['mount_damping'])}"
                   if sc.get("detected") else "consistent with an ideal accelerometer")
        lines.append(f"The acceleration differs from the derivative of the recorded velocity by "
                     f"{_fmt(sc['rms_sigma_ideal'])} sigma RMS (ideal sensor, gain "
                     f"{_fmt(sc['gain_ideal'])}); best sensor model: {_fmt(sc['rms_sigma_fitted'])} "
                     f"sigma, Delta BIC = {sc['delta_bic']:.1f}: {verdict}.")
    lines += ["", f"## Fit ({fit['metric']})", "",
              "| channel | score before | score after | peak error before | peak error after | "
              "timing error before [ms] | timing error after [ms] | RMS before | RMS after |",
              "|---|---|---|---|---|---|---|---|---|"]
    for ch in d["channels"]:
        b = fit["before"]["per_channel"][ch]
        a = fit["after"]["per_channel"][ch]
        lines.append(f"| {ch} | {_fmt(b['score'])} | {_fmt(a['score'])} | {_fmt(b['peak_error'])} | "
                     f"{_fmt(a['peak_error'])} | {b['timing_error_s'] * 1e3:.1f} | "
                     f"{a['timing_error_s'] * 1e3:.1f} | {_fmt(b['rms_error'])} | {_fmt(a['rms_error'])} |")
    lines.append(f"| **overall** | {_fmt(fit['before']['overall'])} | {_fmt(fit['after']['overall'])} "
                 "| | | | | | |")
    best = fit.get("rating_best_alignment")
    if best:
        def _at(k):
            b = best[k]
            each = ", ".join(f"{ch} {_fmt(v)}" for ch, v in b["per_channel"].items())
            return f"{_fmt(b['overall'])} ({each}; shifted {b['shift_s'] * 1e3:+.2f} ms)"
        lines += ["", f"The ratings above are taken at the least-squares alignment. At the best "
                  f"common alignment within {best['tolerance_s'] * 1e3:g} ms of it: before "
                  f"{_at('before')}, after {_at('after')}. The standard's phase search is "
                  f"bistable on a monotone channel such as a velocity (its correlation is ~0.99 "
                  f"at every lag), so half a millisecond of alignment can move that channel's "
                  f"rating by 0.4: a large difference between the two is that alignment, not "
                  f"the fit."]
    scr = fit.get("after_screening_refit")
    if scr:
        each = ", ".join(f"{ch} {_fmt(v['score'])}" for ch, v in scr["per_channel"].items())
        lines += ["", f"After: the full simulation with {fit['after_hypothesis']} (the refitted "
                  f"curve of the plots). The screening refit ({scr['hypothesis']} with the "
                  f"recalibration, on the reduced-order model anchored on the baseline "
                  f"simulation) scores {_fmt(scr['overall'])} ({each})."]
    conf = fit.get("confirmation")
    if conf:
        lines += ["", "## Full-simulation confirmation", "",
                  f"Reference score (the better of the baseline and the recalibrated full run): "
                  f"{_fmt(fit.get('confirmation_reference_score'))}; confirmed: "
                  f"{fit.get('confirmed_missing_physics') or 'none'}.", "",
                  "| run | scenario overrides | score | Delta BIC vs reference |", "|---|---|---|---|"]
        for r in conf:
            if "search_value" in r or r["hypothesis"] == REPLICATE:  # their own tables below
                continue
            ov = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in (r.get("overrides") or {}).items())
            db = r.get("delta_bic_vs_reference")
            lines.append(f"| {r['hypothesis']} | {ov or '-'} | {_fmt(r.get('score'))} | "
                         f"{'-' if db is None else f'{db:.1f}'} |")
    verdicts = fit.get("confirmation_verdicts")
    if verdicts:
        lines += ["", "Why each effect run in the full model was or was not named:", "",
                  "| effect | verdict |", "|---|---|"]
        lines += [f"| {name} | {why} |" for name, why in verdicts.items()]
    search = fit.get("full_search")
    if search and search.get("levels"):
        deposited = sorted({lv["hypothesis"] for lv in search["levels"] if lv.get("beds")})
        beds = (f" Each level of {', '.join(deposited)} deposits its own bed, so it ran on "
                f"{search.get('level_beds')} beds (the baseline's packing and the replicates') "
                "and stands for the mean of its changes against the baseline of each bed."
                if deposited else "")
        lines += ["", f"Full-model search ({search.get('tier')}, {search.get('runs')} runs): best "
                  "level of each effect (a level at the end where the effect fades names "
                  f"nothing).{beds}", "", "| effect | best level | score | Delta BIC vs reference |",
                  "|---|---|---|---|"]
        for name, b in (search.get("best") or {}).items():
            lines.append(f"| {name} | {_fmt(b['value'], 4)} | {_fmt(b['score'])} | "
                         f"{b['delta_bic_vs_reference']:.1f} |")
        for name, fc in (search.get("forms") or {}).items():
            each = "; ".join(
                f"{f}: {'no level ran' if b is None else 'best level ' + _fmt(b['value'], 4)}"
                + ("" if b is None else f", Delta BIC {b['delta_bic_vs_reference']:.1f}")
                for f, b in fc["forms"].items())
            lines += ["", (f"{name} ran in each of its forms ({each}); the {fc['chosen']} "
                          f"form fits best (by its best {fc.get('by', 'level')}) and is the one "
                          "searched further.")]
        named = search.get("named")
        if named and named.get("interval"):
            par = named["parameter"]
            iv = named["interval"]
            u = named.get("unit", "")
            u = "" if u in ("", "1", "-") else f" {u}"
            ends = [n for n, o in zip(("lower", "upper"), iv["open"]) if o]
            open_txt = (f"; the {' and '.join(ends)} end{'s are' if len(ends) > 1 else ' is'} "
                        f"the searched span's, so not bounded there" if ends else "")
            lines += ["", f"Named: {named['hypothesis']}, {par} = {_fmt(named[par], 4)}{u}. "
                      f"The runs within Delta BIC {iv['margin']:.3g} of the best (the larger of "
                      f"the replicates' and the levels' own scatter: within it two runs are not "
                      f"told apart) span {_fmt(iv['low'], 4)} to {_fmt(iv['high'], 4)}{u}"
                      f"{open_txt}: reported as ± {_fmt(named['uncertainty'], 3)}{u} (the noise "
                      f"alone: ± {_fmt(named['noise_uncertainty'], 3)}{u}; the larger of these "
                      f"and the numerics check below)."]
            der = named.get("derived")
            if der:
                du = "" if der["unit"] in ("", "1", "-") else f" {der['unit']}"
                span = (f" (interval {_fmt(der['interval'][0], 3)} to "
                        f"{_fmt(der['interval'][1], 3)}{du})" if der.get("interval") else "")
                lines += ["", f"Derived: {der['name']} = {_fmt(der['value'], 3)}{du}{span}: "
                          f"{der['meaning']}."]
            num = named.get("numerics")
            if num:
                vals = "; ".join(f"x{p['radius_scale']:g}: {_fmt(p['value'], 4)}{u}"
                                 if p.get("value") is not None else
                                 f"x{p['radius_scale']:g}: no run scored"
                                 for p in num["values"])
                lines += ["", f"Numerics check ({num['runs']} runs): the {named['hypothesis']} "
                          f"levels with the grain radius scaled locate {par} at {vals}, against "
                          f"{_fmt(num.get('own_value'), 4)}{u} with the simulation's own grains"
                          + (f" (± {_fmt(num['uncertainty'], 3)}{u})"
                             if num.get("uncertainty") is not None else "") + "."]
        if search.get("verdicts"):
            lines += ["", "| effect (search tier) | promotion to a full run |", "|---|---|"]
            lines += [f"| {n} | {v} |" for n, v in search["verdicts"].items()]
    gfit = fit.get("grain_fit")
    if gfit and gfit.get("sizes"):
        at = gfit.get("at_model_grains")
        lines += ["", f"Grain fit ({gfit['runs']} runs): the baseline's realisations with the "
                  f"grain radius scaled, each size rated by the mean BIC of its realisations "
                  f"against the recording; another size is taken when it beats the model's "
                  f"grains by {gfit['margin_bic']:g}"
                  + (f" and by {gfit['se_factor']:g} standard errors of the difference (the "
                     f"realisations' scatter)" if gfit.get("se_factor") else "")
                  + " (of those within the margin of the best, the nearest). "
                  + (f"Run on: {gfit['simulator']}. " if gfit.get("simulator") else "")
                  + (f"Taken: x{gfit['chosen']:g}; the confirmation above is made with every run "
                     f"at it (the grain radius is part of the recalibration). At the model's "
                     f"grains it named "
                     + (at['named'] if at and at.get('named') else "nothing") + "."
                     if gfit["chosen"] != 1.0 else "The model's grains stand."),
                  "", ("| grain radius | mean BIC | sd | Delta BIC vs the model's grains (its "
                       "standard error) | mean score | realisations |"),
                  "|---|---|---|---|---|---|"]
        for g in gfit["sizes"]:
            lines.append(f"| x{g['radius_scale']:g} | "
                         + _rated_cells(g, g["radius_scale"] == 1.0))
    lfit = fit.get("law_fit")
    if lfit and lfit.get("laws"):
        lines += _law_fit_lines(lfit)
    real = fit.get("realisation")
    if real and real.get("runs"):
        lines += ["", f"Realisation floor ({len(real['runs'])} replicate packings of the baseline "
                  f"on the {real.get('tier')}): an effect is named only when its run fits the "
                  f"recording better than every replicate (Delta BIC above "
                  f"{real['floor_delta_bic']:.1f}, score {CONFIRM_MIN_GAIN:g} above "
                  f"{_fmt(real['floor_score'])})"
                  + (f"; their Delta BIC scatters by {real['scatter_delta_bic']:.1f} (sample "
                     f"standard deviation): two effects closer than that are not told apart"
                     if real.get("scatter_delta_bic") is not None else "") + ".",
                  "", "| replicate | score | Delta BIC vs reference |", "|---|---|---|"]
        for r in real["runs"]:
            ov = ", ".join(f"{k}={v}" for k, v in (r.get("overrides") or {}).items())
            db = r.get("delta_bic_vs_reference")
            lines.append(f"| {ov or '-'} | {_fmt(r.get('score'))} | "
                         f"{'-' if db is None else f'{db:.1f}'} |")
        if real.get("stiffer_soil"):
            below = any(str(r.get("form", "")).startswith("below")
                        for r in real["stiffer_soil"])
            lines += ["", ("A stiffer soil is a recalibration, not missing physics: the floor "
                           "also holds the baseline's beds with the grains' modulus multiplied, "
                           + ("in the whole bed and below its top grain row (a layer that "
                              "shallow is not told apart from how stiff the surface grains are "
                              "against the confined ones; the change averaged over the beds)"
                              if below else
                              "in the whole bed (both layers of the scenario's own layering, "
                              "through the grains' impact modulus; the change averaged over "
                              "the beds)")
                           + ("; and, as another code's realisation, the whole bed with the "
                              "Hertz-Mindlin contact law" if any(
                                  r.get("form") == HERTZ_FLOOR_FORM
                                  for r in real["stiffer_soil"]) else "") + "."), "",
                      "| grains | E factor | score | Delta BIC vs reference |",
                      "|---|---|---|---|"]
            for r in real["stiffer_soil"]:
                db = r.get("delta_bic_vs_reference")
                lines.append(f"| {r.get('form', 'whole bed')} | x{r['young_factor']:g} | "
                             f"{_fmt(r.get('score'))} | {'-' if db is None else f'{db:.1f}'} |")
    det = fit.get("detectability")
    if det and det.get("effects"):
        lines += ["", f"Detectability: how far each search level moves the baseline simulation "
                  f"({det['measure']}); the replicate packings move it by "
                  f"{', '.join(f'{x:.2g}' for x in det['replicates'])}. A level below the least "
                  f"of these ({det['threshold']:.2g}) differs from the model no more than another "
                  f"packing of the same bed does: this resolution cannot show it.", "",
                  "| effect | levels (separation) | visible from |", "|---|---|---|"]
        for name, e in det["effects"].items():
            lv = ", ".join(f"{v:.4g}: {x:.2g}" for v, x in e["levels"])
            vf = e.get("visible_from")
            lines.append(f"| {name} ({e['parameter']}, {e['unit']}) | {lv} | "
                         f"{'none' if vf is None else f'{vf:.4g}'} |")
    sims = d["simulations"]
    lines += ["", "## Cost", "",
              f"Screening runs ({sims['screening_model']}): {sims['screening_runs']}; full simulations: "
              f"{sims['full_simulations']}"
              + (f"; search simulations: {sims['search_simulations']}"
                 if sims.get("search_simulations") else "")
              + f"; wall time {sims['wall_time_s']:.1f} s.", ""]
    if sims.get("full_search"):
        lines += [f"Full-model search: {sims['full_search']}.", ""]
    ib = sims.get("imported_bed")
    if isinstance(ib, dict):
        lines += [f"Imported bed {ib['packing_file']} ({ib['grains']:,} grains): {ib['why']}.", ""]
    pc = sims.get("packing_cache")
    if isinstance(pc, dict):
        lines += [f"Deposited beds: {pc['beds_deposited']} new"
                  + (f" in the packing cache {pc['directory']} (shared with later diagnoses of "
                     f"this scenario)" if pc["directory"] != "off" else " (packing cache off)")
                  + ".", ""]
    rc = sims.get("run_cache")
    if isinstance(rc, dict):
        lines += [(f"Full runs: {rc['runs']} made, {rc['hits']} taken from the run cache "
                   f"{rc['directory']} (runs of the same scenario and code made before, bit for "
                   f"bit).") if rc["directory"] != "off" else "Full runs: run cache off.", ""]
    if plots:
        lines += ["## Plots", ""] + [f"![{Path(p).stem}]({Path(p).name})" for p in plots] + [""]
    return "\n".join(lines)


def plot_overlays(report, out_dir: Path) -> list[str]:
    """One PNG per channel: recording, baseline, refitted simulation, shaded mismatch windows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for ch in report.channels:
        rec = report.recording[ch]
        scale, unit = (1.0 / G0, "g") if rec.unit == "m/s^2" else (1.0, rec.unit)
        fig, ax = plt.subplots(figsize=(8, 4.5))
        # each window shaded (adjacent ones told apart by the shade) and labelled with its
        # feature at its start
        wins = [w for w in report.mismatch if w.channel == ch]
        for i, w in enumerate(wins):
            ax.axvspan(w.t_start_s * 1e3, w.t_end_s * 1e3, color="tab:red",
                       alpha=0.10 if i % 2 == 0 else 0.22, lw=0)
            ax.text(w.t_start_s * 1e3, 0.98, f" {w.feature.replace('_', ' ')}",
                    transform=ax.get_xaxis_transform(), rotation=90, ha="left", va="top",
                    fontsize=7, color="tab:red")
        ax.plot(rec.t * 1e3, rec.data * scale, color="k", lw=1.2, label="recording")
        if ch in report.baseline:
            b = report.baseline[ch]
            ax.plot(b.t * 1e3, b.data * scale, color="tab:blue", lw=1.0, ls="--", label="baseline")
        if ch in report.refitted:
            r = report.refitted[ch]
            lab = (f"full simulation with {report.best}"
                   if report.fit.get("after_source") == "full simulation"
                   else f"refitted ({report.best})" if report.best else "refitted")
            ax.plot(r.t * 1e3, r.data * scale, color="tab:orange", lw=1.0, label=lab)
        ax.set_xlabel("time [ms]")
        ax.set_ylabel(f"{ch} [{unit}]")
        title = f"{ch}: missing physics = {report.missing_physics or 'none'}"
        ax.set_title(title)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        p = out_dir / f"overlay_{ch}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(str(p))
    return paths


def write_report(report, out_dir, plots: bool = True) -> dict[str, str | list[str]]:
    """Write ``report.json``, ``report.md`` and (optionally) overlay PNGs into ``out_dir``.

    Returns
    -------
    dict with the written paths (``json``, ``md``, ``plots``).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    pngs = plot_overlays(report, out) if plots else []
    d = report.to_dict()  # once: the rating at the best alignment is not free (~0.3 s)
    jp = out / "report.json"
    jp.write_text(to_json(report, d), encoding="utf-8")
    mp = out / "report.md"
    mp.write_text(to_markdown(report, pngs, d), encoding="utf-8")
    return {"json": str(jp), "md": str(mp), "plots": pngs}


def _law_fit_lines(lfit: dict[str, Any]) -> list[str]:
    """report.md's paragraph and table of the law fit (``fit.law_fit``)."""
    at, ch = lfit.get("at_model_law"), lfit.get("chosen")
    law = lfit["law"]
    stiff = any(g["contact_law"] == OWN_LAW and g["impact_young_factor"] is not None
                for g in lfit["laws"])
    named = at["named"] if at and at.get("named") else "nothing"
    if ch is None:
        taken = "The scenario's law stands at its modulus."
    elif ch["contact_law"] == OWN_LAW:
        taken = (f"Taken: the scenario's law at x{ch['impact_young_factor']:g} the modulus, a "
                 f"recalibration of the soil's stiffness; the confirmation above is made with "
                 f"every run at it. At the scenario's modulus it named {named}.")
    else:
        taken = (f"Taken: {ch['contact_law']} at x{ch['impact_young_factor']:g} the modulus; "
                 f"the confirmation above is made with every run in it (the law and its modulus "
                 f"are part of the recalibration). In the scenario's law it named {named}.")
    lines = ["", f"Law fit ({lfit['runs']} runs): the baseline's realisations on their own beds "
             f"with the {law} contact law "
             + ("and with the scenario's law " if stiff else "")
             + "at each factor on the grains' modulus in the impact "
             f"(soil.impact_young_factor), each rated by the mean BIC of its realisations "
             f"against the recording; another law or modulus is taken when it beats the "
             f"scenario's own by {lfit['margin_bic']:g} and by {lfit['se_factor']:g} standard "
             f"errors of the difference (of those within the margin of the best BIC, the best "
             f"mean score)"
             + (f", the {law} law only when it also beats the scenario's law at its best "
                f"modulus so (Delta BIC vs the scenario's law's best in brackets)" if stiff
                else "") + ". "
             + (f"Run on: {lfit['simulator']}. " if lfit.get("simulator") else "")
             + taken + _undecided_sentence(lfit.get("law_undecided")),
             "", ("| contact law | modulus factor | mean BIC | sd | Delta BIC vs the scenario's "
                  "law (its standard error) | mean score | realisations |"),
             "|---|---|---|---|---|---|---|"]
    for g in lfit["laws"]:
        k = g["impact_young_factor"]
        own = k is None
        name = "the scenario's" if g["contact_law"] == OWN_LAW else g["contact_law"]
        vs = g.get("delta_bic_vs_own_law")
        lines.append(f"| {name} | {'-' if own else f'x{k:g}'} | "
                     + _rated_cells(g, own, "" if vs is None else f" [{vs:.1f}]"))
    return lines


def _undecided_sentence(u: dict[str, Any] | None) -> str:
    """report.md's sentence on a law the law fit did not take though it fit better
    (``fit.law_fit.law_undecided``); "" when there is none."""
    if not u:
        return ""
    return (f" The {u['contact_law']} law at x{u['impact_young_factor']:g} the modulus fits the "
            f"recording better than the scenario's law at its best modulus by "
            f"{u['delta_bic_vs_own_law']:.1f} in BIC ({u['se_vs_own_law']:.1f} standard error), "
            f"not decisively: the recording does not tell the two contact laws apart.")


def _rated_cells(g: dict[str, Any], own: bool, note: str = "") -> str:
    """The cells of one rated variant of a realisation fit (``fit.grain_fit.sizes``,
    ``fit.law_fit.laws``) from its mean BIC on: mean BIC, sd, Delta BIC vs the model's own
    variant with its standard error ("-" for the model's own) and ``note``, mean score,
    realisations."""
    sd, db, se = g.get("bic_sd"), g.get("delta_bic_vs_model"), g.get("se_vs_model")
    return (f"{g['bic_mean']:.1f} | {'-' if sd is None else f'{sd:.1f}'} | "
            + ("-" if db is None or own else
               f"{db:.1f}" + (f" ({se:.1f})" if se is not None else "") + note)
            + f" | {_fmt(g['score_mean'])} | {g['realisations']} |")

