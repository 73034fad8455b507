"""Diagnosis of glider-crash recordings made by the full coupled DEM (issue 7, the glider).

Baseline: ``validation/scenarios/glider_real.toml`` at the small resolution (0.1 m grains,
``glider_crash.py --small``), run once. Truth per case: the same scenario with one concealed
effect switched on, another packing seed and a 10 % larger grain radius (another deposition),
its raw rear accelerometers and gyro acquired like the lab (12.5 kHz integrating acquisition,
0.5 g / 0.5 deg/s raw noise, trigger offset, CFC 60) and written as a CSV with the glider's
channel names. Diagnosis: ``crashdem diagnose`` exactly as a user runs it (the planar
screening model built from the scenario, calibrated to and anchored on the baseline run, then
the two best candidates confirmed by full small-glider runs in this process).

    python validation/diagnose_glider.py                       # every case
    python validation/diagnose_glider.py --cases crush,null    # some
    python validation/diagnose_glider.py --full-confirm 0      # screening only

The last printed line is JSON: per case the truth, the claim, the fitted parameters, the
scores before/after and the number of full simulations; ``named`` / ``cases`` and
``null_claims``. Cost: about 1 + 4 x (1 + 3) small glider runs (each a deposition of ~800
grains reused by its confirmation runs, and a 0.3 s impact).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
SCENARIO = ROOT / "scenarios" / "glider_real.toml"
#: the small resolution of validation/glider_crash.py (MODES["small"])
SMALL = {"soil.radius": 0.1, "soil.radius_spread": 0.1, "output.snapshots": 0,
         "output.plots": False}
#: the truth's numerics (not the effect): another packing and a 10 % larger grain
TRUTH_NUMERICS = {"scenario.seed": 2, "soil.radius": 0.11}
#: concealed effects (scenario keys) and the catalogue name the diagnosis should give
CASES: dict[str, tuple[str | None, dict]] = {
    "crush": ("structural_crush", {"physics.structural_crush.enabled": True,
                                   "physics.structural_crush.crush_force": 6.0e4,
                                   "physics.structural_crush.stroke": 0.15}),
    "pitch": ("initial_conditions", {"physics.initial_conditions.enabled": True,
                                     "physics.initial_conditions.pitch_offset_deg": -5.0}),
    "sensor": ("sensor_dynamics", {"physics.sensor_dynamics.enabled": True,
                                   "physics.sensor_dynamics.natural_frequency": 60.0,
                                   "physics.sensor_dynamics.damping_ratio": 0.1,
                                   "physics.sensor_dynamics.model": "mount"}),
    "null": (None, {}),
}
#: the glider's recorded channels -> model channels
CHANNELS = {"rear_accel_x": "accel_x", "rear_accel_z": "accel_z", "pitch_rate": "pitch_rate"}


def _sets(ov: dict) -> list[str]:
    out = []
    for k, v in ov.items():
        out += ["--set", f"{k}={json.dumps(v) if isinstance(v, (bool, str)) else v}"]
    return out


def truth_recording(name: str, overrides: dict, out: Path, seed: int,
                    numerics: dict | None = None) -> Path:
    """Run the truth and write its lab-acquired recording (CSV, glider channel names)."""
    import h5py

    from crashdem import recordings
    from crashdem import scenario as sc
    from crashdem.diagnosis.generator import TRIGGER_JITTER, acquire_samples
    from crashdem.diagnosis.generator_planar import RAW_NOISE_PLANAR
    from crashdem.results import open_result
    from crashdem.run import packing_cache, run_scenario, share_packings

    runs = out / "truth_runs"
    share_packings(runs, packing_cache())
    num = TRUTH_NUMERICS if numerics is None else numerics
    scen = sc.load(SCENARIO, {**SMALL, **num, **overrides,
                              "scenario.name": f"glider_truth_{name}"})
    path = run_scenario(scen, out_dir=runs, progress=False, plots=False)
    rng = np.random.default_rng(seed)
    with h5py.File(path, "r") as h:
        t_contact = float(h["run"].attrs["t_contact"])
    with open_result(path) as res:
        raw = {n: res.channel(n, filtered=False) for n in CHANNELS}
    t = np.asarray(raw["rear_accel_x"].t) - t_contact
    rec = acquire_samples(t, {CHANNELS[n]: (np.asarray(s.data), s.unit) for n, s in raw.items()},
                          scen["glider.release_speed"], rng, t_pre=0.018, t_end=float(t[-1]),
                          trigger_offset=float(rng.uniform(-TRIGGER_JITTER, TRIGGER_JITTER)),
                          noise=RAW_NOISE_PLANAR, source=f"crashdem glider DEM truth {name}")
    return recordings.write_recording(out / f"{name}.csv",
                                      {n: replace(rec[m], name=n) for n, m in CHANNELS.items()})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma list of {list(CASES)}")
    ap.add_argument("--out", default="runs/diagnose_glider", help="output directory")
    ap.add_argument("--full-confirm", type=int, default=3,
                    help="full simulations per diagnosis (0 = screening only)")
    ap.add_argument("--same-packing", action="store_true",
                    help="truths on the baseline's packing and grain size (the effect is then "
                         "the only difference: separates the packing scatter from the model)")
    args = ap.parse_args(argv)
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    for c in cases:
        if c not in CASES:
            ap.error(f"--cases: {c!r} unknown; known: {list(CASES)}")
    from crashdem import cli
    from crashdem import scenario as sc
    from crashdem.run import packing_cache, run_scenario, share_packings

    out = Path(args.out).resolve()
    t0 = time.perf_counter()
    base_dir = out / "baseline_run"
    share_packings(base_dir, packing_cache())
    base_ov = {**SMALL, "output.directory": str(base_dir), "scenario.name": "glider_small"}
    base_path = base_dir / "glider_small.h5"
    if not base_path.exists():
        run_scenario(sc.load(SCENARIO, base_ov), out_dir=base_dir, progress=False, plots=False)
    print(f"baseline: {base_path} ({time.perf_counter() - t0:.0f} s)", flush=True)
    rows = []
    for i, name in enumerate(cases):
        effect, ov = CASES[name]
        t1 = time.perf_counter()
        rec = truth_recording(name, ov, out, seed=100 + i,
                              numerics={} if args.same_packing else None)
        t2 = time.perf_counter()
        d_out = out / f"diagnosis_{name}"
        rc = cli.main(["diagnose", "--scenario", str(SCENARIO), "--recording", str(rec),
                       "--out", str(d_out), "--workers", "0",
                       "--full-confirm", str(args.full_confirm), *_sets(base_ov)])
        rep = json.loads((d_out / "report.json").read_text()) if rc == 0 else {}
        h = rep.get("hypotheses", [{}])[0]
        after = (rep.get("fit", {}).get("after_full") or rep.get("fit", {}).get("after") or {})
        row = {"case": name, "truth": effect, "truth_values": ov,
               "claimed": rep.get("missing_physics"), "top_ranked": h.get("name"),
               "parameters": h.get("parameters"),
               "delta_bic": h.get("delta_bic_vs_recalibration"),
               "score_before": rep.get("fit", {}).get("before", {}).get("overall"),
               "score_after": after.get("overall"),
               "full_simulations": rep.get("simulations", {}).get("full_simulations"),
               "decision": rep.get("decision"), "truth_s": round(t2 - t1, 1),
               "diagnosis_s": round(time.perf_counter() - t2, 1)}
        rows.append(row)
        print(f"{name}: truth={effect} claimed={row['claimed']} top={row['top_ranked']} "
              f"dBIC={row['delta_bic']} score {row['score_before']} -> {row['score_after']} "
              f"params={row['parameters']} ({row['truth_s']} s truth, {row['diagnosis_s']} s "
              f"diagnosis)", flush=True)
    effect_rows = [r for r in rows if r["truth"] is not None]
    summary = {"cases": len(effect_rows),
               "named": sum(r["claimed"] == r["truth"] for r in effect_rows),
               "null_claims": sum(r["claimed"] is not None for r in rows if r["truth"] is None),
               "wall_s": round(time.perf_counter() - t0, 1), "rows": rows}
    print(json.dumps(summary, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
