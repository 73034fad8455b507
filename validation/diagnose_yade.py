"""Out-of-code validation of the diagnosis (issue 7): concealed effects in recordings made by
Yade 2023.02a, diagnosed against crashdem's own DEM baseline.

    python validation/diagnose_yade.py                  # 6 effects x seeds 11, 12 + nulls 21, 22
    python validation/diagnose_yade.py --effects cohesion --seeds 11
    python validation/diagnose_yade.py --scenario validation/scenarios/drop_s2_h5p00.toml
    python validation/diagnose_yade.py --effects cohesion --seeds 31 --fix cohesion=1e6 \
        --nulls --filter-seeds --levels                 # a stronger effect than the drawn span
    python validation/diagnose_yade.py --scenario validation/scenarios/drop_s2_h18p45.toml \
        --cli /tmp/yade_cli                             # through `crashdem diagnose` itself

Each case: ``validation.diagnosis_yade.cases.yade_case`` (Yade deposition, contact laws, time
step and effect implementation; lab acquisition), then ``crashdem.diagnosis.screen_then_confirm``
with crashdem's small-resolution DEM as the baseline and confirmation simulator (the same method
``crashdem diagnose --full-confirm`` runs); with ``--cli DIR``, the recording written as CSV
and diagnosed by ``crashdem diagnose`` in a subprocess, at the scenario's own grain size in the
Yade test's tank (``cli_case``: the command a user types, the path the diagnosis is judged
on). Prints the confusion matrix and a per-case table; the
LAST line is JSON: ``cases`` (truth, claimed, top-ranked, Delta BIC, parameters, scores, full
runs, wall times), ``named_rate``, ``null_claims``, ``wall_s``.

Needs ``yade`` on the PATH (``apt-get install yade``); Yade runs and crashdem DEM runs are cached
under ``~/.cache/crashdem`` (``$CRASHDEM_CACHE``).
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import json
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from crashdem.diagnosis.generator_dem import BASE_OVERRIDES  # noqa: E402
from validation.diagnosis_yade.cases import (CONTACT_LAWS, OWN_LAW_EFFECTS,  # noqa: E402
                                             YADE_EFFECT_DRAWS, check_fixed, yade_available,
                                             yade_case)

TOP_K = 2


#: filter classes of the filter-class cases (drawn per seed; the baseline is filtered at CFC 60)
FILTER_CLASSES = (180.0, 600.0, 1000.0)


def make_case(effect: str | None, seed: int, filter_class: bool = False, raw: bool = False,
              fixed: dict[str, float] | None = None,
              recalibration: dict[str, float] | None = None):
    """The Yade case of ``diagnose_case``: ``(truth, case, compared values)``; a filter-class
    case (``filter_class``) is the null physics of ``seed`` acquired at a class drawn from
    ``FILTER_CLASSES`` and not declared, its truth ``sensor_dynamics``; ``recalibration``:
    the bed's soil values other than the scenario's (``cases.yade_case``)."""
    import dataclasses

    import numpy as np

    if filter_class:
        cfc = float(FILTER_CLASSES[int(np.random.default_rng(20_000 + seed).integers(3))])
        case = yade_case(seed, None, cfc=cfc, declare_cfc=False)
        case = dataclasses.replace(case, drawn={"filter_class": cfc})
        return "sensor_dynamics", case, {"filter_class": cfc}
    case = yade_case(seed, effect, raw=raw, fixed=fixed, recalibration=recalibration)
    return effect, case, case.values


def _errors(fitted: dict, values: dict) -> dict[str, float]:
    """Relative error of each fitted parameter the truth states (``COMPARED`` names)."""
    return {k: (fitted[k] - v) / abs(v) for k, v in values.items() if k in fitted and v != 0}


#: where ``--on-yade-bed`` writes the Yade beds it imports (the library path)
ON_BED_DIR = "yade_beds"


def _check_on_bed(effect: str | None) -> None:
    if effect == "boundary_proximity":
        raise ValueError("on_yade_bed: a floor case's Yade bed is the shallow bed itself, so "
                         "importing it puts the concealed floor into the model; diagnose the "
                         "floor cases on crashdem's own beds")


@contextlib.contextmanager
def _on_bed(meta: dict):
    """crashdem's baseline numerics (``generator_dem.BASELINE_NUMERICS``) on the Yade case's
    own bed (``soil.packing_file``, ``cases.write_yade_bed``) while the block runs."""
    from crashdem.diagnosis import generator_dem
    from validation.diagnosis_yade.cases import write_yade_bed

    digest = Path(meta["packing_npz"]).stem
    path, _, _ = write_yade_bed(meta, generator_dem.cache_dir() / ON_BED_DIR / f"{digest}.npz")
    saved = dict(generator_dem.BASELINE_NUMERICS)
    generator_dem.BASELINE_NUMERICS.update({"soil.radius": float(meta["radius"]),
                                            "soil.packing_file": str(path)})
    try:
        yield path
    finally:
        generator_dem.BASELINE_NUMERICS.clear()
        generator_dem.BASELINE_NUMERICS.update(saved)


def diagnose_case(effect: str | None, seed: int, top_k: int = TOP_K,
                  filter_class: bool = False, raw: bool = False,
                  fixed: dict[str, float] | None = None,
                  recalibration: dict[str, float] | None = None,
                  on_yade_bed: bool = False) -> dict:
    """Make (or load) one Yade case and diagnose it; returns the table row.

    ``filter_class``: the null physics of ``seed`` acquired at a class drawn from
    ``FILTER_CLASSES`` and not declared (truth: ``sensor_dynamics``, filter-class form).
    ``raw``: the recording is Yade's raw output (no acquisition, no noise, no filter, no
    pre-trigger; ``cases.yade_case(..., raw=True)``). ``fixed``: drawn parameters of
    ``effect`` pinned to values (``cases.yade_case(..., fixed=...)``). ``recalibration``: the
    Yade bed's soil values other than the scenario's (``cases.yade_case(...,
    recalibration=...)``; with ``effect=None`` the right answer is no missing physics).
    ``on_yade_bed``: crashdem's baseline and every run on the case's own Yade bed
    (``soil.packing_file``), as ``crashdem diagnose`` searches an imported bed (``cli._one_bed``:
    no replicate packings, one bed per level, no numerics check); not for floor cases."""
    from crashdem.diagnosis import screen_then_confirm
    from crashdem.diagnosis.generator_dem import (DemFullSimulator, dem_baseline,
                                                  dem_baseline_raw, impact_speed, replicates)

    if on_yade_bed:
        _check_on_bed(effect)
    t0 = time.perf_counter()
    effect, case, values = make_case(effect, seed, filter_class, raw, fixed, recalibration)
    t1 = time.perf_counter()
    if on_yade_bed:
        with _on_bed(case.meta):
            rep = screen_then_confirm(dem_baseline(), case.recording, DemFullSimulator(),
                                      top_k=top_k, impact_speed=impact_speed(),
                                      baseline_raw=dem_baseline_raw(), replicates=[],
                                      level_beds=1, numerics=())
    else:
        rep = screen_then_confirm(case.baseline, case.recording, DemFullSimulator(),
                                  top_k=top_k, impact_speed=impact_speed(),
                                  baseline_raw=dem_baseline_raw(), replicates=replicates())
    t2 = time.perf_counter()
    top = rep.hypotheses[0]
    claimed = rep.missing_physics
    fitted = {}
    for h in rep.hypotheses:
        if h["name"] == (claimed or top["name"]):
            fitted = h["parameters"]
    after = rep.fit.get("after_full", {}).get("overall", rep.fit["after"]["overall"])
    return {"truth": effect, "seed": seed, "drawn": case.drawn,
            "recalibration": case.recalibration, "claimed": claimed,
            "top_ranked": top["name"], "top_delta_bic": top["delta_bic_vs_recalibration"],
            "fitted": fitted, "parameter_errors": _errors(fitted, values),
            "named_search": rep.fit.get("full_search", {}).get("named"),
            "score_before": rep.fit["before"]["overall"], "score_after": after,
            "full_simulations": rep.simulations["full_simulations"],
            "realisation_floor_delta_bic": rep.fit.get("realisation", {}).get("floor_delta_bic"),
            "search_best": rep.fit.get("full_search", {}).get("best", {}),
            "grains": case.meta["grains"], "yade_dt_s": case.meta["dt"],
            "case_wall_s": t1 - t0, "diagnosis_wall_s": t2 - t1, "decision": rep.decision}


#: what the Yade truth's test differs from the campaign scenario in: its tank and its bed
#: without the compacted lower layer (``cases.BASE_OVERRIDES``), what a lab would tell the
#: analyst. ``--cli`` passes it with ``--set`` and leaves the numerics (grain size, time step,
#: packing) at the scenario's own, as a user of the command line would.
TEST_SETUP = {"container.diameter": BASE_OVERRIDES["container.diameter"],
              "physics.soil_layering.enabled": False}


def cli_case(effect: str | None, seed: int, out: str | Path, scenario: str | Path,
             extra: list[str] | tuple[str, ...] = (), filter_class: bool = False,
             raw: bool = False, fixed: dict[str, float] | None = None,
             recalibration: dict[str, float] | None = None, on_yade_bed: bool = False) -> dict:
    """Make (or load) one Yade case, write its lab channels as CSV and diagnose it through the
    command line (``python -m crashdem diagnose``, the judged path: its own baseline run,
    search, replicates and confirmations, on Dask workers) with ``--scenario scenario`` and
    ``TEST_SETUP``; returns the table row (``diagnose_case``'s keys where the report has them,
    plus ``how``, ``beds_deposited``, ``out``). ``filter_class``, ``raw``, ``fixed``,
    ``recalibration``: as ``diagnose_case``. ``extra``: more arguments of the command (e.g.
    ``--packing-cache DIR``, ``--full-search coarse``). ``on_yade_bed``: the scenario on the
    case's own Yade bed (``--set soil.packing_file=DIR/<case>/yade_bed.npz``)."""
    import subprocess

    from crashdem.recordings import write_recording
    from validation.diagnosis_yade.cases import write_yade_bed

    if on_yade_bed:
        _check_on_bed(effect)
    t0 = time.perf_counter()
    effect, case, values = make_case(effect, seed, filter_class, raw, fixed, recalibration)
    name = f"{'filter_class' if filter_class else effect or 'null'}_{seed}" + "".join(
        f"_{k.rsplit('.', 1)[1]}={v:g}" for k, v in sorted(case.recalibration.items())) + (
        "" if case.meta.get("contact_law", "linear") == "linear"
        else f"_{case.meta['contact_law']}")
    d = Path(out) / name
    d.mkdir(parents=True, exist_ok=True)
    rec = write_recording(d / "rec.csv", case.recording)
    t1 = time.perf_counter()
    cmd = [sys.executable, "-m", "crashdem", "diagnose", "--scenario", str(scenario),
           "--recording", str(rec), "--out", str(d / "out")]
    for k, v in TEST_SETUP.items():
        cmd += ["--set", f"{k}={str(v).lower() if isinstance(v, bool) else v}"]
    if on_yade_bed:
        bed, _, _ = write_yade_bed(case.meta, d / "yade_bed.npz")
        cmd += ["--set", f"soil.packing_file={bed}"]
    cmd += list(extra)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    t2 = time.perf_counter()
    (d / "diagnose.log").write_text(proc.stdout + proc.stderr)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}:\n"
                           f"{proc.stderr[-3000:]}")
    rep = json.loads((d / "out" / "report.json").read_text())
    claimed = rep["missing_physics"]
    hyps = rep["hypotheses"]
    top = hyps[0] if hyps else {"name": None, "delta_bic_vs_recalibration": 0.0}
    fitted = next((h["parameters"] for h in hyps if h["name"] == (claimed or top["name"])), {})
    fit, sims = rep["fit"], rep["simulations"]
    return {"truth": effect, "seed": seed, "drawn": case.drawn,
            "recalibration": case.recalibration, "claimed": claimed,
            "top_ranked": top["name"], "top_delta_bic": top["delta_bic_vs_recalibration"],
            "fitted": fitted, "parameter_errors": _errors(fitted, values),
            "named_search": fit.get("full_search", {}).get("named"),
            "score_before": fit["before"]["overall"],
            "score_after": fit.get("after_full", {}).get("overall", fit["after"]["overall"]),
            "full_simulations": sims.get("full_simulations"),
            "realisation_floor_delta_bic": fit.get("realisation", {}).get("floor_delta_bic"),
            "search_best": fit.get("full_search", {}).get("best", {}),
            "how": sims.get("full_search"),
            "beds_deposited": (sims.get("packing_cache") or {}).get("beds_deposited"),
            "runs_from_cache": (sims.get("run_cache") or {}).get("hits"),
            "grains": case.meta["grains"], "yade_dt_s": case.meta["dt"],
            "case_wall_s": t1 - t0, "diagnosis_wall_s": t2 - t1, "decision": rep["decision"],
            "out": str(d / "out")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--effects", nargs="*", default=sorted(YADE_EFFECT_DRAWS),
                    help="effects to conceal (default: all with a Yade truth)")
    ap.add_argument("--seeds", nargs="*", type=int, default=[11, 12])
    ap.add_argument("--nulls", nargs="*", type=int, default=[21, 22],
                    help="seeds of null cases (no concealed effect)")
    ap.add_argument("--filter-seeds", nargs="*", type=int, default=[21, 22],
                    help="null Yade runs re-acquired at another, undeclared filter class "
                         "(truth: sensor_dynamics, filter-class form)")
    ap.add_argument("--raw", action="store_true",
                    help="diagnose Yade's raw output (no lab acquisition: no noise, filter or "
                         "pre-trigger) instead of lab channels")
    ap.add_argument("--top-k", type=int, default=TOP_K)
    ap.add_argument("--fix", nargs="+", action="extend", default=[], metavar="NAME=VALUE",
                    help="pin a drawn parameter of the effect cases to a value, e.g. a stronger "
                         "effect than the drawn span: --effects cohesion --seeds 31 --fix "
                         "cohesion=1e6 (names: validation.diagnosis_yade.cases.YADE_EFFECT_DRAWS)")
    ap.add_argument("--recalibrate", nargs="+", action="extend", default=[],
                    metavar="KEY=VALUE",
                    help="give the null cases' Yade bed a soil value other than the scenario's, "
                         "e.g. --recalibrate soil.material.young=4e7: a wrong value of a "
                         "parameter the model has, answered right by no missing physics (keys: "
                         "crashdem.diagnosis.generator_dem.RECALIBRATION_KEYS)")
    ap.add_argument("--levels", action="store_true",
                    help="print each case's best full-model search level per effect")
    ap.add_argument("--scenario", default=None,
                    help="drop-test scenario of the Yade truth and crashdem's baseline (default: "
                         "validation/scenarios/drop_s2_h13p70.toml; e.g. drop_s2_h5p00.toml for "
                         "the 5 m drop)")
    ap.add_argument("--cli", metavar="DIR", default=None,
                    help="diagnose each recording through the command line instead of the "
                         "library: the lab channels written as DIR/<case>/rec.csv, then "
                         "'python -m crashdem diagnose --scenario SCENARIO --set "
                         "container.diameter=2.0 --set physics.soil_layering.enabled=false' "
                         "(the Yade test's tank and bed, the scenario's own grains; its own "
                         "baseline run, search and confirmations) into DIR/<case>/out")
    ap.add_argument("--cli-args", default="", metavar="ARGS",
                    help="more arguments of each 'crashdem diagnose' with --cli, one string, "
                         "e.g. \"--packing-cache /tmp/beds --full-search coarse\"")
    ap.add_argument("--truth-radius", type=float, default=None, metavar="R",
                    help="mean grain radius [m] about which the Yade truths draw theirs "
                         "(default 0.10, the small bed's; e.g. 0.075, the campaign scenario's, "
                         "with --cli: a recording on a finer bed than the coarse search tier's)")
    ap.add_argument("--contact-law", default="linear", choices=CONTACT_LAWS,
                    help="Yade's contact law for the truths: its linear Cundall-Strack law (the "
                         "model's) or its Hertz-Mindlin law, the default of most other DEM codes "
                         "(grains of cases.HERTZ_YOUNG_FACTOR x the Young's modulus, calibrated "
                         "on the penetration); its contact damping is the Hertz-Mindlin law's "
                         "own normal and shear dashpots of the drawn restitution; the cohesion "
                         "cases, made with a law of their own, are left out with it")
    ap.add_argument("--on-yade-bed", action="store_true",
                    help="crashdem's baseline and runs on each case's own Yade bed "
                         "(soil.packing_file; the deposition shared, what is left is the "
                         "dynamics); the floor cases, whose bed is the shallow bed itself, are "
                         "left out")
    args = ap.parse_args(argv)
    if args.cli_args and args.cli is None:
        ap.error("--cli-args needs --cli DIR")
    from crashdem.diagnosis.generator_dem import number_assignments, parse_recalibration

    try:
        fixed = number_assignments(args.fix, "cohesion=1e6")
    except ValueError as err:
        ap.error(f"--fix {err}")
    try:
        recal = parse_recalibration(args.recalibrate)
    except ValueError as err:
        ap.error(f"--recalibrate: {err}")
    for eff in args.effects if fixed else ():
        # every pin checked before the first Yade run, not when its case comes up
        try:
            check_fixed(eff, fixed)
        except ValueError as err:
            ap.error(f"--fix (effect {eff}): {err}")
    if args.truth_radius is not None:
        from validation.diagnosis_yade.cases import use_truth_radius

        try:
            use_truth_radius(args.truth_radius)
        except ValueError as err:
            ap.error(f"--truth-radius: {err}")
    if args.contact_law != "linear":
        from validation.diagnosis_yade.cases import use_contact_law

        use_contact_law(args.contact_law)
        left = [e for e in args.effects if e in OWN_LAW_EFFECTS]
        if left:
            print(f"--contact-law {args.contact_law}: {', '.join(left)} left out (Yade makes "
                  f"it with a law of its own)")
            args.effects = [e for e in args.effects if e not in OWN_LAW_EFFECTS]
    if args.scenario is not None:
        from crashdem.diagnosis.generator_dem import use_scenario

        use_scenario(args.scenario)
    if not yade_available():
        print("yade is not installed (apt-get install yade): nothing to do")
        print(json.dumps({"cases": [], "skipped": "yade not installed"}))
        return 0
    if args.cli is not None:
        import shlex

        from crashdem.diagnosis import generator_dem

        diagnose = functools.partial(cli_case, out=Path(args.cli),
                                     scenario=generator_dem.SCENARIO,
                                     extra=shlex.split(args.cli_args))
        if args.top_k != TOP_K:
            ap.error("--top-k: not with --cli (the command's --full-confirm decides)")
    else:
        diagnose = functools.partial(diagnose_case, top_k=args.top_k)
    if args.on_yade_bed:
        diagnose = functools.partial(diagnose, on_yade_bed=True)
        if "boundary_proximity" in args.effects:
            print("--on-yade-bed: the floor cases are left out (their Yade bed is the shallow "
                  "bed itself)")
            args.effects = [e for e in args.effects if e != "boundary_proximity"]
        if args.recalibrate:
            ap.error("--recalibrate: not with --on-yade-bed (the bed carries the recalibrated "
                     "deposition)")
    t0 = time.perf_counter()
    rows = []
    for eff in args.effects:
        for s in args.seeds:
            rows.append(diagnose(eff, s, raw=args.raw, fixed=fixed))
            r = rows[-1]
            print(f"{eff:20s} seed {s}: claimed={r['claimed']} top={r['top_ranked']} "
                  f"dBIC={r['top_delta_bic'] or 0.0:.1f} score {r['score_before']:.3f} -> "
                  f"{r['score_after']:.3f} fitted={ {k: round(v, 3) for k, v in r['fitted'].items()} } "
                  f"errors={ {k: f'{v:+.0%}' for k, v in r['parameter_errors'].items()} } "
                  f"realisation floor dBIC={r['realisation_floor_delta_bic'] or 0.0:.1f} "
                  f"full runs={r['full_simulations']} ({r['case_wall_s']:.0f} s + "
                  f"{r['diagnosis_wall_s']:.0f} s)", flush=True)
    for s in ([] if args.raw else args.filter_seeds):
        rows.append(diagnose(None, s, filter_class=True))
        r = rows[-1]
        print(f"{'filter class':20s} seed {s}: CFC {r['drawn']['filter_class']:g} claimed="
              f"{r['claimed']} top={r['top_ranked']} fitted={r['fitted']} score "
              f"{r['score_before']:.3f} -> {r['score_after']:.3f}", flush=True)
    for s in args.nulls:
        rows.append(diagnose(None, s, raw=args.raw, recalibration=recal))
        r = rows[-1]
        print(f"{'null' + (' ' + str(recal) if recal else ''):20s} seed {s}: claimed={r['claimed']} top={r['top_ranked']} "
              f"dBIC={r['top_delta_bic'] or 0.0:.1f} score {r['score_before']:.3f} -> "
              f"{r['score_after']:.3f}", flush=True)
    if args.levels:
        print("\nbest full-model search level per effect (value, Delta BIC over the reference, "
              "score; realisation floor = best replicate's Delta BIC):")
        for r in rows:
            best = r["search_best"]
            print(f"{str(r['truth'] or 'null'):20s} seed {r['seed']}: floor "
                  f"{r['realisation_floor_delta_bic'] or 0.0:.1f}; " + "; ".join(
                      f"{n} {b['value']:.4g} ({b['delta_bic_vs_reference']:.1f}, "
                      f"{b['score']:.3f})" for n, b in sorted(
                          best.items(), key=lambda kv: -kv[1]["delta_bic_vs_reference"])))
    conf = Counter((r["truth"] or "null", r["claimed"] or "none") for r in rows)
    print("\nYade truth -- confusion (truth -> claimed missing physics):")
    for (tr, cl), n in sorted(conf.items()):
        print(f"  {tr:20s} -> {cl:22s} x{n}")
    eff_rows = [r for r in rows if r["truth"] is not None]
    named = sum(r["claimed"] == r["truth"] for r in eff_rows)
    null_claims = sum(r["claimed"] is not None for r in rows if r["truth"] is None)
    wrong = sum(r["claimed"] not in (None, r["truth"]) for r in eff_rows)
    print(f"named {named}/{len(eff_rows)}, wrong names {wrong}, null claims "
          f"{null_claims}/{len(rows) - len(eff_rows)}")
    print(json.dumps({"cases": rows, "named": named, "effect_cases": len(eff_rows),
                      "wrong_names": wrong, "null_claims": null_claims,
                      "wall_s": time.perf_counter() - t0}, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
