"""Drop-test calibration campaign (issue 5): thesis series S2 reproduced end to end.

An 850 kg, 0.90 m reinforced-concrete sphere hits 2 m of loose quarry gravel in a rigid tank at
9.90, 14.0, 16.4 and 19.0 m/s (Varriale 2019 §2.1, Tab 2.1).  For each speed the scenario in
``validation/scenarios/drop_s2_h*.toml`` runs through ``crashdem.run.run_scenario`` (packing
deposited once and cached; HDF5 with the drop-mass acceleration, velocity, penetration and the
floor load cells, sampled at 12.5 kHz, CFC 60), then:

  - figures: acceleration / velocity / penetration against time (four curves each), and the
    elasto-plastic soil against the cohesive soil (``physics.cohesion``);
  - comparison table: peak force, maximum penetration, impact duration, rebound onset, double
    peak; against the thesis facts, the Japanese and ASTRA formulas, Yade (anchors §8);
  - studies (``--studies``): tank diameter D vs 2 D over packing seeds, grain size vs cost
    (at the default resolution about an hour: a 12 m tank and a ~56,000-grain bed);
  - ``--calibrate``: Latin-hypercube design + Nelder-Mead on the reduced model, written to
    ``validation/soil_cards/calibrated_gravel.toml``.

Usage::

    python validation/drop_campaign.py --small           # ~800 grains, test-suite size
    python validation/drop_campaign.py                   # scenario files as written (<= 15 min)
    python validation/drop_campaign.py --studies         # + domain-size and grain-size studies
    python validation/drop_campaign.py --small --calibrate

The LAST printed line is JSON: for each speed ``peak_decel_g``, ``max_penetration_m``,
``t_rebound_s``, ``double_peak`` (+ more), and the total ``wall_s``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from validation.campaign import calibration as cal  # noqa: E402
from validation.campaign import studies as st  # noqa: E402

CARD = ROOT / "validation" / "soil_cards" / "calibrated_gravel.toml"
#: Grain radii of the particle-size study per mode [m] (the last is the reference).
GRAIN_RADII = {"small": (0.14, 0.12, 0.10), "default": (0.10, 0.075, 0.05)}


def _clean(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items() if not k.startswith("_")}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="reduced resolution (test suite)")
    ap.add_argument("--studies", action="store_true",
                    help="also run the domain-size and grain-size studies (at the default "
                         "resolution about an hour: a 12 m tank and a ~56,000-grain bed)")
    ap.add_argument("--no-studies", action="store_true",
                    help="skip the studies (the default; kept for older command lines)")
    ap.add_argument("--no-cohesion", action="store_true", help="skip the cohesive-soil runs")
    ap.add_argument("--calibrate", action="store_true", help="fit the soil (writes the soil card)")
    ap.add_argument("--calibrate-from", type=Path, default=None, metavar="CARD",
                    help="continue a calibration from a soil card (Nelder-Mead only)")
    ap.add_argument("--calibrate-evals", type=int, default=None,
                    help="Nelder-Mead evaluation budget (default 4 small / 16 default)")
    ap.add_argument("--yade", action="store_true",
                    help="also run every speed in Yade on the same packing (needs Debian's yade)")
    ap.add_argument("--card", type=Path, default=None,
                    help="run the series with this soil card's values")
    ap.add_argument("--out", type=Path, default=Path("runs/drop_campaign"))
    ap.add_argument("--cache", type=Path, default=st.DEFAULT_CACHE, help="packing cache")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="extra scenario override (repeatable)")
    args = ap.parse_args(argv)

    from crashdem.scenario import parse_override

    t0 = time.perf_counter()
    mode = "small" if args.small else "default"
    base = dict(st.RESOLUTIONS[mode])
    if args.card is not None:
        base.update(cal.load_soil_card(args.card))
    base.update(dict(parse_override(s) for s in args.set))
    out = args.out / mode
    out.mkdir(parents=True, exist_ok=True)
    print(f"drop campaign, mode {mode}, overrides {base}, output {out}", flush=True)

    print("series S2, elasto-plastic soil:", flush=True)
    series = st.run_series(base, out / "series", args.cache)
    cohesive = {}
    if not args.no_cohesion:
        print("series S2, cohesive soil (physics.cohesion.enabled):", flush=True)
        cohesive = st.run_series({**base, "physics.cohesion.enabled": True}, out / "cohesive",
                                 args.cache, tag="coh")
    figs = st.plot_series(series, out)
    if cohesive:
        figs.append(st.plot_cohesion(series, cohesive, out))
    print("figures: " + ", ".join(str(p) for p in figs))

    report: dict = {"mode": mode}
    if args.studies and not args.no_studies:
        print("domain-size study (19.0 m/s):", flush=True)
        report["domain_study"] = st.domain_study(base, out / "studies", args.cache)
        ds = report["domain_study"]
        print(f"  mean peak-force change with 2x diameter over {len(ds['seeds'])} packing "
              f"seeds: {100 * ds['peak_force_change']:.1f} % +/- "
              f"{100 * ds['peak_force_change_stderr']:.1f} % (must be < 5 %); seed-to-seed "
              f"scatter {100 * ds['seed_scatter']:.1f} %, penetration change "
              f"{100 * ds['penetration_change']:.1f} %")
        print("grain-size study (19.0 m/s):", flush=True)
        report["grain_study"] = st.grain_study(base, GRAIN_RADII[mode], out / "studies",
                                               args.cache)
    if args.calibrate:
        print("calibration (design + Nelder-Mead):", flush=True)
        n_design, max_nm = (4, 4) if mode == "small" else (8, 16)
        if args.calibrate_evals is not None:
            max_nm = args.calibrate_evals
        start = cal.load_soil_card(args.calibrate_from) if args.calibrate_from else None
        rep = cal.calibrate(base, out / "calibration", args.cache, n_design=n_design,
                            max_nm=max_nm, start=start)
        cal.write_soil_card(CARD, rep, mode)
        (out / "calibration.json").write_text(json.dumps(_clean(rep), indent=1))
        print(f"  best J = {rep['objective']:.3f} after {rep['evaluations']} evaluations: "
              + ", ".join(f"{k} = {v:.4g}" for k, v in rep["values"].items()))
        print("  residuals: " + ", ".join(f"{k} {v:+.2f}" for k, v in rep["terms"].items()))
        print(f"  soil card: {CARD}")
        report["calibration"] = {k: rep[k] for k in ("values", "terms", "objective",
                                                     "evaluations")}

    yade: dict = {}
    if args.yade:
        from validation.campaign import yade_compare as yc

        if not yc.yade_available():
            print("yade: not on PATH, comparison skipped")
        else:
            print("Yade 2023.02a on the same packings:", flush=True)
            for k, r in series.items():
                scen = st.load_scenario(k, base)
                y = yc.run_yade(scen, r, out / "yade" / k, args.cache)
                yade[k] = y
                print(f"  v = {k} m/s: peak {y['peak_force_N'] / 1e3:.1f} kN "
                      f"({100 * (r['peak_force_N'] / y['peak_force_N'] - 1):+.1f} % crashdem), "
                      f"penetration {y['max_penetration_m']:.3f} m, rebound "
                      f"{y['t_rebound_s']:.4f} s, double peak {y['double_peak']}", flush=True)

    print()
    print(st.table(series, cohesive, yade))
    print()
    print("thesis facts (§2.1.3):")
    facts = st.fact_checks(series)
    for f in facts:
        print(f"  [{'ok' if f['ok'] else 'NO'}] {f['fact']}: {f['value']}")
    print("momentum balance of the raw channels (m dv vs impulse of the force channel):")
    for k, r in series.items():
        ib = r["impulse"]
        err = abs(ib["impulse_force_Ns"] - ib["momentum_change_Ns"]) / ib["initial_momentum_Ns"]
        r["impulse_error"] = err
        print(f"  {k} m/s: m dv = {ib['momentum_change_Ns']:.1f} N s, int(F - mg) dt = "
              f"{ib['impulse_force_Ns']:.1f} N s, error {100 * err:.3f} % of m v0")
    full = {"series": series, "cohesive": cohesive, "facts": facts, "yade": yade, **report}
    (out / "report.json").write_text(json.dumps(_clean(full), indent=1))
    summary: dict = {}
    for k, r in series.items():
        summary[k] = {
            "peak_decel_g": r["peak_decel_g"],
            "max_penetration_m": r["max_penetration_m"],
            "t_rebound_s": r["t_rebound_s"],
            "t_max_penetration_s": r["t_max_penetration_s"],
            "t_last_s": r["t_last_s"],
            "double_peak": r["double_peak"],
            "peak_force_N": r["peak_force_N"],
            "impact_duration_s": r["impact_duration_s"],
            "t_peak_decel_s": r["t_peak_decel_s"],
            "impulse_error": r["impulse_error"],
            "particles": r["particles"],
        }
    if yade:
        summary["yade"] = {k: {m: y[m] for m in ("peak_decel_g", "max_penetration_m",
                                                 "t_rebound_s", "double_peak", "peak_force_N")}
                           for k, y in yade.items()}
    if "domain_study" in report:
        summary["domain_peak_force_change"] = report["domain_study"]["peak_force_change"]
    summary["formulas"] = [{k: v for k, v in row.items()} for row in st.formula_rows(series)]
    summary["mode"] = mode
    summary["wall_s"] = time.perf_counter() - t0
    print(json.dumps(_clean(summary)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
