"""Cost and answer of ``crashdem diagnose`` at the drop scenario's own (default) resolution
(issue 7: one drop-test recording in at most 15 minutes on 2 cores).

    python validation/diagnose_cost.py                        # contact damping, e = 0.15
    python validation/diagnose_cost.py --effect initial_conditions --value -3.0
    python validation/diagnose_cost.py --effect particle_rotation --value 0.1   # rolling coeff.
    python validation/diagnose_cost.py --effect sensor_dynamics --value 60      # mount [Hz]
    python validation/diagnose_cost.py --warm    # and again, with the beds of the first run
    python validation/diagnose_cost.py --effect none --recalibrate soil.material.young=4e7
    python validation/diagnose_cost.py --effect none --truth-grains 1.25 \
        --cli-args "--grain-fit 0.8,1.25,1.5"      # a truth of coarser grains
    python validation/diagnose_cost.py --effect none --truth-law hertz_mindlin \
        --truth-young-factor 8                      # a truth in another contact law

Truth: ``validation/scenarios/drop_s2_h13p70.toml`` at its resolution (0.075 m grains, 6 m
tank, the compacted layer below 1 m) with another packing seed (7), ``solver.safety`` 0.2
(baseline 0.3), the concealed effect switched on (``--effect none``: no effect; ``--recalibrate KEY=VALUE``:
a soil value other than the scenario's, ``generator_dem.check_recalibration``, a
recalibration that must not be named missing physics; ``--truth-grains F``: grains F x the
scenario's 0.075 m, as another code's recording has grains the scenario does not know;
``--truth-law hertz_mindlin --truth-young-factor F``: the truth's impact in the Hertz-Mindlin
law, most DEM codes' default, at F x the grains' modulus on the same kind of bed, a law and a
stiffness the scenario does not have),
sampled at 50 kHz and acquired like a lab channel (``generator.acquire_samples``: 12.5 kHz,
noise, +-2 ms trigger, CFC 60), written as CSV. Then the command a user runs, ``crashdem diagnose
--scenario drop_s2_h13p70.toml --recording rec.csv --out DIR``, is run as a subprocess and timed:
the baseline run (its deposition included), the screening, the coarse full-model search and the
full-resolution confirmation runs on Dask. The truth run is cached
(``~/.cache/crashdem/diagnosis_truth``); the diagnosis is not: a fresh ``DIR`` and a fresh,
empty ``--packing-cache`` (``DIR/..`` ``/packing_cache``), so every bed is deposited, as on a
user's first diagnosis, and
``--run-cache off``, so every run is made. With ``--warm`` the same command is then run again
into another directory with that packing cache (a user's next recording of the same scenario:
no bed deposited) and its answer is checked against the first's; its runs are still all made
(with the default run cache a next recording would take the baseline, replicate and search
runs from it as well, ``crashdem.runcache``). The budget is absolute (15 min); the ratio printed beside it is the
diagnosis's wall time over that of the one full simulation of the scenario it ran itself (its
baseline's impact, deposition excluded, measured in the same run on the same machine), i.e.
its cost in full runs. The LAST line is JSON: wall times, the ratio, the answer, its
parameters and the run counts.
"""
from __future__ import annotations

import argparse
import json
import math
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

#: the scenario's own resolution (undoing generator_dem.BASE_OVERRIDES' small bed)
DEFAULT_RESOLUTION = {"soil.radius": 0.075, "soil.radius_spread": 0.2, "container.diameter": 6.0,
                      "solver.t_end": 0.15, "physics.soil_layering.enabled": True}
#: effect -> scenario key of its main parameter
EFFECT_KEYS = {"contact_damping": "physics.contact_damping.restitution",
               "initial_conditions": "physics.initial_conditions.velocity_offset",
               "cohesion": "physics.cohesion.normal_strength",
               "boundary_proximity": "physics.boundary_proximity.floor_depth",
               "particle_rotation": "physics.particle_rotation.rolling_coefficient",
               "sensor_dynamics": "physics.sensor_dynamics.natural_frequency"}
#: the effect's other truth values (the sensor: a resonant mount, damping ratio 0.1, the
#: DEM-truth generator's span 0.05-0.15)
EFFECT_EXTRA = {"sensor_dynamics": {"physics.sensor_dynamics.model": "mount",
                                    "physics.sensor_dynamics.damping_ratio": 0.1}}


#: the span of ``--truth-grains`` (a factor on the scenario's grain radius)
TRUTH_GRAINS = (0.8, 1.5)


def check_grains(grains: float) -> float:
    """``grains`` (the truth's grain radius over the scenario's) as a float; ValueError naming
    it and ``TRUTH_GRAINS`` when it is outside (or not a number)."""
    lo, hi = TRUTH_GRAINS
    if not lo <= float(grains) <= hi:
        raise ValueError(f"grains={grains!r}: must be in [{lo:g}, {hi:g}] (the truth's grain "
                         "radius over the scenario's)")
    return float(grains)


def check_law(law: str, young_factor: float) -> tuple[str, float]:
    """The truth's contact law and impact modulus factor (``--truth-law``,
    ``--truth-young-factor``); ValueError naming the field and what it may be."""
    from crashdem.diagnosis.catalogue import impact_young_range
    from crashdem.scenario import SCHEMA

    laws = SCHEMA["soil"]["contact_law"].choices
    if law not in laws:
        raise ValueError(f"law={law!r}: must be one of {', '.join(laws)} (soil.contact_law)")
    lo, hi = impact_young_range()
    if not (math.isfinite(float(young_factor)) and lo <= float(young_factor) <= hi):
        raise ValueError(f"young_factor={young_factor!r}: must be in [{lo:g}, {hi:g}] "
                         "(soil.impact_young_factor)")
    return law, float(young_factor)


def truth_recording(effect: str | None, value: float, out: Path, threads: int,
                    recalibration: dict[str, float] | None = None,
                    grains: float = 1.0, law: str = "linear",
                    young_factor: float = 1.0) -> Path:
    """Run (or load) the default-resolution truth and write the lab recording as CSV
    (``effect`` None: no effect; ``recalibration``: the truth's other soil values; ``grains``:
    the truth's grain radius over the scenario's, within ``TRUTH_GRAINS``; ``law`` and
    ``young_factor``: the contact law of its impact and the factor on the grains' modulus
    there, ``soil.contact_law`` and ``soil.impact_young_factor``, the bed deposited as the
    scenario's)."""
    import numpy as np

    from crashdem.diagnosis.generator import acquire_samples
    from crashdem.diagnosis.generator_dem import check_recalibration, run_dem
    from crashdem.recordings import write_recording

    ov = {**DEFAULT_RESOLUTION, "scenario.seed": 7, "solver.safety": 0.2,
          "instrumentation.sample_rate": 50000.0, "scenario.threads": threads,
          **check_recalibration(recalibration)}
    grains = check_grains(grains)
    if grains != 1.0:
        ov["soil.radius"] = DEFAULT_RESOLUTION["soil.radius"] * grains
    law, young_factor = check_law(law, young_factor)
    if law != "linear" or young_factor != 1.0:
        ov.update({"soil.contact_law": law, "soil.impact_young_factor": float(young_factor)})
    if effect is not None:
        ov.update({f"physics.{effect}.enabled": True, EFFECT_KEYS[effect]: value,
                   **EFFECT_EXTRA.get(effect, {})})
    if effect == "cohesion":
        ov["physics.cohesion.shear_strength"] = value
    if effect == "boundary_proximity" and value <= 1.0:
        # a floor above the scenario's 1 m layer interface ends the column there: no lower layer
        ov["physics.soil_layering.enabled"] = False
    raw, _ = run_dem(ov, filtered=False)
    rng = np.random.default_rng(7)
    acc, vel = raw["accel_z"], raw["velocity_z"]
    rec = acquire_samples(acc.t, {"accel_z": (acc.data, "m/s^2"), "velocity_z": (vel.data, "m/s")},
                          float(-vel.data[0]), rng, trigger_offset=float(rng.uniform(-0.002, 0.002)),
                          source="crashdem DEM truth at the default resolution ("
                                 + (f"{effect} = {value:g}" if effect else "no effect")
                                 + "".join(f", {k} = {v:g}" for k, v in
                                           (recalibration or {}).items())
                                 + (f", grains {grains:g} x the scenario's" if grains != 1.0
                                    else "")
                                 + (f", {law} law at {young_factor:g} x the modulus"
                                    if law != "linear" or young_factor != 1.0 else "") + ")")
    out.mkdir(parents=True, exist_ok=True)
    return write_recording(out / "rec.csv", rec)


def baseline_wall(diag: Path) -> float | None:
    """Wall time [s] of the baseline simulation the diagnosis ran itself (``diag/baseline``,
    the result file's ``wall_time`` attribute: the coupled impact, written after the bed is
    built, so the deposition is not in it): the same-run reference of the benchmark's ratio.
    None when the diagnosis took an existing result instead."""
    import h5py

    for path in sorted((diag / "baseline").glob("*.h5")):
        with h5py.File(path, "r") as f:
            w = float(f.attrs.get("wall_time", float("nan")))
        if math.isfinite(w) and w > 0:
            return w
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--effect", choices=[*sorted(EFFECT_KEYS), "none"],
                    default="contact_damping")
    ap.add_argument("--value", type=float, default=0.15)
    ap.add_argument("--out", default="runs/diagnose_cost")
    ap.add_argument("--threads", type=int, default=2, help="threads of the truth run")
    ap.add_argument("--warm", action="store_true",
                    help="diagnose again with the packing cache the first diagnosis filled")
    ap.add_argument("--recalibrate", nargs="+", action="extend", default=[],
                    metavar="KEY=VALUE",
                    help="a soil value of the truth other than the scenario's, e.g. "
                         "soil.material.young=4e7 (keys: generator_dem.RECALIBRATION_KEYS)")
    ap.add_argument("--truth-grains", type=float, default=1.0, metavar="F",
                    help="the truth's grain radius as F x the scenario's 0.075 m (in "
                         f"[{TRUTH_GRAINS[0]:g}, {TRUTH_GRAINS[1]:g}]; default 1)")
    ap.add_argument("--truth-law", choices=["linear", "hertz_mindlin"], default="linear",
                    help="the contact law of the truth's impact (default linear, the "
                         "scenario's)")
    ap.add_argument("--truth-young-factor", type=float, default=1.0, metavar="F",
                    help="the truth's grain modulus in its impact as F x the scenario's "
                         "(soil.impact_young_factor; its bed is deposited as the scenario's)")
    ap.add_argument("--cli-args", default="", metavar="ARGS",
                    help="more options of crashdem diagnose, e.g. \"--grain-check 1.1,0.9 "
                         "--grain-check-agree any\"")
    args = ap.parse_args(argv)
    from crashdem.diagnosis.generator_dem import parse_recalibration

    try:
        recal = parse_recalibration(args.recalibrate)
    except ValueError as err:
        ap.error(f"--recalibrate: {err}")
    effect = None if args.effect == "none" else args.effect
    out = Path(args.out)
    t0 = time.perf_counter()
    try:
        check_grains(args.truth_grains)
    except ValueError as err:
        ap.error(f"--truth-grains: {err}")
    try:
        check_law(args.truth_law, args.truth_young_factor)
    except ValueError as err:
        ap.error(f"--truth-law / --truth-young-factor: {err}")
    rec = truth_recording(effect, args.value, out, args.threads, recal, args.truth_grains,
                          args.truth_law, args.truth_young_factor)
    t_truth = time.perf_counter() - t0
    cache = out / "packing_cache"
    shutil.rmtree(cache, ignore_errors=True)

    def diagnose(diag: Path) -> tuple[float, dict]:
        shutil.rmtree(diag, ignore_errors=True)
        cmd = [sys.executable, "-m", "crashdem", "diagnose", "--scenario",
               str(ROOT / "validation" / "scenarios" / "drop_s2_h13p70.toml"),
               "--recording", str(rec), "--out", str(diag), "--packing-cache", str(cache),
               "--run-cache", "off", *shlex.split(args.cli_args)]
        t1 = time.perf_counter()
        subprocess.run(cmd, check=True)
        return time.perf_counter() - t1, json.loads((diag / "report.json").read_text())

    wall, rep = diagnose(out / "diagnosis")
    base_wall = baseline_wall(out / "diagnosis")
    warm = None
    if args.warm:
        from crashdem.diagnosis.report import without_wall_times

        wall_w, rep_w = diagnose(out / "diagnosis_warm")
        same = (rep_w["missing_physics"] == rep["missing_physics"]
                and without_wall_times(rep_w["hypotheses"]) == without_wall_times(rep["hypotheses"])
                and rep_w["fit"]["before"] == rep["fit"]["before"])
        warm = {"diagnosis_wall_s": wall_w, "same_report": same,
                "beds_deposited": rep_w["simulations"]["packing_cache"]["beds_deposited"]}
        print(f"again with the cached beds: {wall_w:.0f} s ({warm['beds_deposited']} beds "
              f"deposited), {'the same' if same else 'ANOTHER'} answer and hypotheses")
    named = next((h for h in rep["hypotheses"] if h["name"] == rep["missing_physics"]), None)
    row = {"truth": effect, "value": args.value if effect else None,
           "recalibration": recal, "truth_grains": args.truth_grains,
           "truth_law": args.truth_law, "truth_young_factor": args.truth_young_factor,
           "claimed": rep["missing_physics"],
           "parameters": named["parameters"] if named else None,
           "score_before": rep["fit"]["before"]["overall"],
           "score_after": (rep["fit"].get("after_full") or rep["fit"]["after"])["overall"],
           "full_simulations": rep["simulations"]["full_simulations"],
           "search_simulations": rep["simulations"].get("search_simulations"),
           "diagnosis_wall_s": wall, "truth_wall_s": t_truth, "decision": rep["decision"],
           "baseline_run_wall_s": base_wall,
           "diagnosis_over_baseline_run": wall / base_wall if base_wall else None,
           "beds_deposited": rep["simulations"]["packing_cache"]["beds_deposited"], "warm": warm,
           "grain_check": rep["fit"].get("grain_check"),
           "grain_check_simulations": rep["simulations"].get("grain_check_simulations"),
           "grain_fit": {k: v for k, v in (rep["fit"].get("grain_fit") or {}).items()
                         if k != "at_model_grains"} or None,
           "grain_fit_simulations": rep["simulations"].get("grain_fit_simulations")}
    print(f"diagnosis of a default-resolution recording: {wall:.0f} s "
          f"({'within' if wall <= 900 else 'OVER'} the 15 min budget); claimed "
          f"{row['claimed']} {row['parameters']}; full runs {row['full_simulations']}, search "
          f"runs {row['search_simulations']}")
    if base_wall:
        print(f"baseline: the diagnosis's own full run of the scenario (impact, deposition "
              f"excluded) took {base_wall:.1f} s; "
              f"the diagnosis took {wall / base_wall:.1f} x that run")
    print(json.dumps(row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
