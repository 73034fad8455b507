"""How much of the code-to-code difference is the bed, and how much the dynamics.

A Yade recording differs from crashdem's baseline in two ways at once: its bed was deposited
by Yade (another packing, grain size and deposition), and its impact was integrated by Yade
(contact laws as implemented, the facet tank, the integrator). This script separates them for
the Yade truth's cases (``cases.yade_case``): for each it runs

* **Yade** on its own bed (the truth's raw output);
* **crashdem on Yade's bed**: the same grains, imported with ``soil.packing_file``
  (``crashdem.beds``; grains that escaped Yade's facet tank are dropped), the same materials,
  impact speed and rotation setting -- what is left against Yade is the dynamics;
* **crashdem on Yade's bed in Yade's wall**: the tank as Yade's 64-facet cylinder presents it
  to a grain -- at the facets' inscribed radius, R cos(pi/64), and 4/3 as stiff, since a
  facet contact takes twice the grain's radius on the facet's side (k_n = 2 E (2r) E r /
  (3 E r)) where crashdem's analytic cylinder takes the grain's own;
* **crashdem on its own bed** at the case's grain radius (crashdem's deposition, packing seed
  1) -- what this adds is the deposition;
* with ``--tank-diameter D``: Yade and crashdem again on the same grains in a tank of diameter
  D (e.g. 6 m: no wall within the grains' reach), which takes the wall out of the comparison.

    python validation/diagnosis_yade/same_bed.py                 # nulls 21, 22; free rotation 21
    python validation/diagnosis_yade/same_bed.py --cases null:21 particle_rotation:22
    python validation/diagnosis_yade/same_bed.py --cases null:21 null:22 --tank-diameter 6

Prints per case the penetration (from first contact), its time, the velocity at 60 and 120 ms
and the mean specific force over windows of the impact, for the three runs; the LAST line is
JSON. Needs ``yade`` on the PATH for a case not in the cache (``cases.run_yade``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


#: windows [s after first contact] of the mean specific force
WINDOWS = ((0.0, 0.01), (0.01, 0.02), (0.02, 0.04), (0.04, 0.06), (0.06, 0.08), (0.08, 0.10),
           (0.10, 0.12))
#: segments of the Yade truth's ``facetCylinder`` tank (``yade_truth.py``)
YADE_TANK_SEGMENTS = 64
#: the cases of the default run: (effect or None, seed)
DEFAULT_CASES = ((None, 21), (None, 22), ("particle_rotation", 21))


def impact_metrics(t: np.ndarray, v: np.ndarray, a: np.ndarray) -> dict[str, float]:
    """Penetration and timing of one drop from its velocity ``v`` [m/s, z up] and specific
    force ``a`` [m/s^2] on the time axis ``t`` [s]. Time counts from first contact, the last
    sample before the first nonzero specific force (an accelerometer on the drop mass reads 0
    in free fall; Yade's and crashdem's outputs alike, so both codes share the definition):
    maximum penetration (trapezoidal integral of -v) and its time, the velocity at 60 and
    120 ms, the mean specific force over each of ``WINDOWS``."""
    hit = np.flatnonzero(a != 0.0)
    if len(hit) == 0 or len(t) - hit[0] < 2:
        raise ValueError("impact_metrics: no contact (the specific force is 0 throughout), or "
                         "fewer than two samples after it")
    k = max(int(hit[0]) - 1, 0)
    t, v, a = t[k:] - t[k], v[k:], a[k:]
    pen = np.concatenate([[0.0], np.cumsum(-0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    i = int(np.argmax(pen))
    out = {"penetration_m": float(pen[i]), "t_max_s": float(t[i]),
           "v_60ms": float(np.interp(0.06, t, v)), "v_120ms": float(np.interp(0.12, t, v))}
    for lo, hi in WINDOWS:
        w = (t >= lo) & (t < hi)
        out[f"a_{lo * 1e3:.0f}_{hi * 1e3:.0f}ms"] = float(a[w].mean()) if w.any() else float("nan")
    return out


def _crashdem(overrides: dict, out: Path) -> tuple[dict[str, float], dict]:
    """Metrics and run facts of one crashdem drop on the Yade truth's scenario."""
    import h5py

    from crashdem import scenario as sc
    from crashdem.diagnosis.generator_dem import BASE_OVERRIDES, SCENARIO
    from crashdem.results import open_result
    from crashdem.run import packing_cache, run_scenario, share_packings

    share_packings(out, packing_cache())
    scen = sc.load(SCENARIO, {**BASE_OVERRIDES, "solver.safety": 0.3, "solver.t_end": 0.13,
                              **overrides})
    path = run_scenario(scen, out_dir=out, progress=False)
    with h5py.File(path) as h:
        info = {k: (v.item() if hasattr(v, "item") else v) for k, v in h["run"].attrs.items()}
    with open_result(path) as res:
        v = res.channel("drop_mass_velocity_z", filtered=False)
        a = res.channel("drop_mass_accel_z", filtered=False)
        return impact_metrics(np.asarray(v.t), np.asarray(v.data), np.asarray(a.data)), info


def _yade_metrics(hist: np.ndarray, mass: float) -> dict[str, float]:
    """``impact_metrics`` of a Yade history (t, z, v_z, F_z) of a drop mass of ``mass``."""
    return impact_metrics(hist[:, 0], hist[:, 2], hist[:, 3] / mass)


def _own_beds(common: dict, name: str, d: Path, own_seeds: Sequence[int],
              own_overrides: dict | None) -> tuple[dict[str, float], list[dict[str, float]], int]:
    """crashdem's impact on its own beds (``scenario.seed`` in ``own_seeds``, with
    ``own_overrides``, e.g. another deposition friction): the metrics averaged over the beds,
    each bed's, and the first bed's grain count."""
    runs = []
    for k in own_seeds:
        m, info = _crashdem({**common, **(own_overrides or {}), "scenario.seed": int(k),
                             "scenario.name": f"{name}_own_bed_{k}"}, d)
        runs.append((m, int(info["particles"])))
    mean = {key: float(np.mean([m[key] for m, _ in runs])) for key in runs[0][0]}
    return mean, [m for m, _ in runs], runs[0][1]


def law_overrides(cfg: dict) -> dict:
    """crashdem's scenario values of a Yade case's impact law (``cfg``, the case's Yade
    configuration): {} for the linear law; for Hertz-Mindlin the law, the grains' Young's
    modulus and Poisson's ratio (the tank's and the drop mass's follow the grains', as in
    Yade's run)."""
    if cfg.get("contact_law", "linear") != "hertz_mindlin":
        return {}
    return {"soil.contact_law": "hertz_mindlin", "soil.material.young": float(cfg["hertz_young"]),
            "soil.poisson": float(cfg["hertz_poisson"])}


def same_bed(effect: str | None, seed: int, work: Path, tank_diameter: float | None = None,
             own_seeds: Sequence[int] = (1,), own_overrides: dict | None = None,
             contact_law: str | None = None) -> dict:
    """The runs of one Yade case (module docstring); returns the table row. ``own_seeds``:
    the packing seeds of crashdem's own beds (their metrics averaged; ``crashdem_own_beds``
    holds each), ``own_overrides``: scenario values of those beds only. ``contact_law``:
    the case's impact law (``cases.CONTACT_LAWS``; None = ``cases.CONTACT_LAW``); with
    ``"hertz_mindlin"`` crashdem runs its own Hertz-Mindlin law with the case's values
    (``law_overrides``), and the run in Yade's facet wall is left out (its 4/3 is the linear
    law's facet stiffness)."""
    from crashdem.diagnosis.generator_dem import cache_dir
    from validation.diagnosis_yade.cases import run_yade, write_yade_bed, yade_case

    t0 = time.perf_counter()
    case = yade_case(seed, effect, raw=True, contact_law=contact_law)
    meta = case.meta
    law = law_overrides(meta["cfg"])
    hist, info = run_yade(meta["cfg"], cache_dir())  # the case's run, cached by yade_case
    yade = _yade_metrics(hist, info["mass"])
    name = f"{effect or 'null'}_{seed}"
    d = work / name
    bed_file, n_yade, n_kept = write_yade_bed(meta, d / "yade_bed.npz")
    rot = ({"soil.rotation": "free", "soil.rolling_coefficient": 0.0}
           if effect == "particle_rotation" else {})
    if law:
        name += "_hertz"
        d = work / name
    common = {"soil.radius": meta["radius"], **rot, **law}
    imported = {**common, "soil.packing_file": str(bed_file)}
    on_yade, _ = _crashdem({**imported, "scenario.name": f"{name}_on_yade_bed"}, d)
    young = float(meta["cfg"]["young"])
    facets = None
    if not law:
        facets, _ = _crashdem({**imported, "scenario.name": f"{name}_in_yade_wall",
                               "container.diameter": 2.0 * meta["tank_radius"]
                               * math.cos(math.pi / YADE_TANK_SEGMENTS),
                               "container.wall_young": 4.0 / 3.0 * young}, d)
    own, each, n_own = _own_beds(common, name, d, own_seeds, own_overrides)
    row = {"truth": effect, "seed": seed, "radius_m": meta["radius"],
           "contact_law": meta["cfg"].get("contact_law", "linear"),
           "yade_grains": n_yade, "imported_grains": n_kept, "crashdem_own_grains": n_own,
           "own_seeds": [int(k) for k in own_seeds], "own_overrides": dict(own_overrides or {}),
           "yade": yade, "crashdem_on_yade_bed": on_yade, "crashdem_in_yade_wall": facets,
           "crashdem_own_bed": own, "crashdem_own_beds": each,
           "dynamics_penetration": on_yade["penetration_m"] / yade["penetration_m"] - 1.0,
           "dynamics_in_yade_wall": (facets["penetration_m"] / yade["penetration_m"] - 1.0
                                     if facets else float("nan")),
           "deposition_penetration": own["penetration_m"] / on_yade["penetration_m"] - 1.0}
    if tank_diameter is not None:
        wide_cfg = {**meta["cfg"], "tank_radius": 0.5 * float(tank_diameter)}
        hist_w, info_w = run_yade(wide_cfg, cache_dir(), packing_npz=meta["packing_npz"])
        row["yade_wide"] = _yade_metrics(hist_w, info_w["mass"])
        row["crashdem_wide"], _ = _crashdem({**imported, "scenario.name": f"{name}_wide",
                                             "container.diameter": float(tank_diameter)}, d)
        row["tank_diameter_wide_m"] = float(tank_diameter)
        row["dynamics_wide"] = (row["crashdem_wide"]["penetration_m"]
                                / row["yade_wide"]["penetration_m"] - 1.0)
    row["wall_s"] = time.perf_counter() - t0
    return row


def deposition_row(effect: str | None, seed: int, work: Path, own_seeds: Sequence[int],
                   own_overrides: dict | None = None, meta: dict | None = None) -> dict:
    """The deposition alone, on the bed of any Yade case: crashdem's impact (the baseline's
    physics, blocked rotations, whatever the case's effect) on Yade's grains against its
    impact on its own beds of the case's grain size (``own_seeds``, ``own_overrides``).
    Every 2 m bed a Yade case deposits is the same deposition (``yade_truth.py`` deposits
    with the baseline's material and sets the effect's afterwards), so effect cases add beds;
    a floor case's bed is shallower and is refused. ``meta``: the case's ``YadeCase.meta``
    when the caller has it already (else ``cases.yade_case`` makes it)."""
    if effect == "boundary_proximity":
        raise ValueError("deposition_row: effect='boundary_proximity' has a shallower bed than "
                         "crashdem's own beds of the baseline; use a case with the 2 m bed")
    from validation.diagnosis_yade.cases import write_yade_bed, yade_case

    t0 = time.perf_counter()
    if meta is None:
        meta = yade_case(seed, effect, raw=True).meta
    name = f"bed_{effect or 'null'}_{seed}"
    d = work / name
    bed_file, n_yade, n_kept = write_yade_bed(meta, d / "yade_bed.npz")
    common = {"soil.radius": meta["radius"]}
    on_yade, _ = _crashdem({**common, "soil.packing_file": str(bed_file),
                            "scenario.name": f"{name}_on_yade_bed"}, d)
    own, each, n_own = _own_beds(common, name, d, own_seeds, own_overrides)
    pen = np.array([m["penetration_m"] for m in each])
    return {"truth": effect, "seed": seed, "radius_m": meta["radius"],
            "yade_grains": n_yade, "imported_grains": n_kept, "crashdem_own_grains": n_own,
            "own_seeds": [int(k) for k in own_seeds], "own_overrides": dict(own_overrides or {}),
            "crashdem_on_yade_bed": on_yade, "crashdem_own_bed": own, "crashdem_own_beds": each,
            "own_penetration_sd": float(pen.std(ddof=1)) if len(pen) > 1 else float("nan"),
            "deposition_penetration": own["penetration_m"] / on_yade["penetration_m"] - 1.0,
            "wall_s": time.perf_counter() - t0}


def deposition_summary(rows: Sequence[dict]) -> dict[str, float]:
    """The deposition's share over several Yade beds (``deposition_row`` rows, or
    ``same_bed`` rows): the mean of crashdem's own beds over Yade's bed in crashdem's impact,
    as a relative penetration, with its standard error over the beds; the scatter of one of
    crashdem's own beds about their mean (relative, pooled over the cases: the realisation
    scatter the diagnosis's replicate packings measure) and that of the ratio between the
    cases. If Yade's beds scatter as crashdem's do, the latter is the former times
    sqrt(1 + 1/N) for N own beds per case; ``yade_bed_scatter`` is what the ratio's scatter
    implies for one Yade bed (relative), with crashdem's N-bed mean's share taken out."""
    ratio = np.array([r["deposition_penetration"] for r in rows])
    n_own = [len(r["own_seeds"]) for r in rows]
    within = [np.array([m["penetration_m"] for m in r["crashdem_own_beds"]]) for r in rows]
    rel = [w / w.mean() - 1.0 for w in within if len(w) > 1]
    s_own = (float(np.sqrt(sum(float((x ** 2).sum()) for x in rel)
                           / sum(len(x) - 1 for x in rel))) if rel else float("nan"))
    n = len(ratio)
    sd = float(ratio.std(ddof=1)) if n > 1 else float("nan")
    nbar = float(np.mean(n_own))
    early_y = np.array([r["crashdem_on_yade_bed"]["a_0_10ms"] for r in rows])
    early_o = np.array([r["crashdem_own_bed"]["a_0_10ms"] for r in rows])
    peak_y = np.array([r["crashdem_on_yade_bed"]["a_10_20ms"] for r in rows])
    peak_o = np.array([r["crashdem_own_bed"]["a_10_20ms"] for r in rows])
    return {"beds": n, "own_beds_per_bed": nbar,
            "deposition_mean": float(ratio.mean()),
            "deposition_stderr": sd / math.sqrt(n) if n > 1 else float("nan"),
            "deposition_sd": sd, "own_bed_scatter": s_own,
            "yade_bed_scatter": (float(math.sqrt(max(sd ** 2 - s_own ** 2 / nbar, 0.0)))
                                 if n > 1 and rel else float("nan")),
            "a_0_10ms_own_over_yade_bed": float(early_o.mean() / early_y.mean() - 1.0),
            "a_10_20ms_own_over_yade_bed": float(peak_o.mean() / peak_y.mean() - 1.0)}


def _deposition_table(rows: Sequence[dict], summary: dict[str, float]) -> str:
    lines = [f"{'case':>24s} {'radius':>8s} {'on Yade bed':>12s} {'own mean':>9s} "
             f"{'own sd':>7s} {'own/Yade':>9s} {'a 0-10 ms Yade/own':>20s}"]
    for r in rows:
        lines.append(f"{(r['truth'] or 'null') + ':' + str(r['seed']):>24s} "
                     f"{r['radius_m']:8.4f} {r['crashdem_on_yade_bed']['penetration_m']:12.3f} "
                     f"{r['crashdem_own_bed']['penetration_m']:9.3f} "
                     f"{r.get('own_penetration_sd', float('nan')):7.3f} "
                     f"{r['deposition_penetration']:+9.1%} "
                     f"{r['crashdem_on_yade_bed']['a_0_10ms']:9.0f} /"
                     f"{r['crashdem_own_bed']['a_0_10ms']:6.0f}")
    s = summary
    lines.append(f"deposition over {s['beds']} Yade beds x {s['own_beds_per_bed']:g} own beds: "
                 f"{s['deposition_mean']:+.1%} +- {s['deposition_stderr']:.1%} (standard "
                 f"error); between beds {s['deposition_sd']:.1%}; one own bed about its mean "
                 f"{s['own_bed_scatter']:.1%}, one Yade bed (implied) "
                 f"{s['yade_bed_scatter']:.1%}; first 10 ms "
                 f"{s['a_0_10ms_own_over_yade_bed']:+.1%}, 10-20 ms "
                 f"{s['a_10_20ms_own_over_yade_bed']:+.1%} (own over Yade's bed)")
    return "\n".join(lines)


def _table(rows: list[dict]) -> str:
    keys = ["penetration_m", "t_max_s", "v_60ms", "v_120ms"] + [
        f"a_{lo * 1e3:.0f}_{hi * 1e3:.0f}ms" for lo, hi in WINDOWS]
    lines = []
    for row in rows:
        lines.append(f"\n{row['truth'] or 'null'} {row['seed']} "
                     f"({row.get('contact_law', 'linear')}): radius {row['radius_m']:g} m, "
                     f"Yade {row['yade_grains']} grains ({row['imported_grains']} imported), "
                     f"crashdem's own bed {row['crashdem_own_grains']}")
        lines.append(f"  {'':24s}" + "".join(f"{k:>13s}" for k in keys))
        for who in ("yade", "crashdem_on_yade_bed", "crashdem_in_yade_wall",
                    "crashdem_own_bed", "yade_wide", "crashdem_wide"):
            if row.get(who):
                lines.append(f"  {who:24s}" + "".join(f"{row[who][k]:13.4g}" for k in keys))
        lines.append(f"  penetration: dynamics (crashdem / Yade on Yade's bed) "
                     f"{row['dynamics_penetration']:+.1%}, in Yade's wall "
                     f"{row['dynamics_in_yade_wall']:+.1%}"
                     + (f", in a {row['tank_diameter_wide_m']:g} m tank "
                        f"{row['dynamics_wide']:+.1%}" if "dynamics_wide" in row else "")
                     + f"; deposition (crashdem's bed / Yade's, in crashdem) "
                     f"{row['deposition_penetration']:+.1%}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="*", metavar="EFFECT:SEED",
                    help="cases as effect:seed ('null' for no effect); default: "
                         + " ".join(f"{e or 'null'}:{s}" for e, s in DEFAULT_CASES))
    ap.add_argument("--work", default=None, help="directory of the runs (default: a temporary one)")
    ap.add_argument("--tank-diameter", type=float, default=None, metavar="D",
                    help="also run both codes on the same grains in a tank of diameter D [m] "
                         "(e.g. 6: the wall out of reach); one more Yade run per case")
    ap.add_argument("--own-seeds", type=int, default=1, metavar="N",
                    help="crashdem's own beds per case: packing seeds 1..N, their metrics "
                         "averaged (default 1)")
    ap.add_argument("--own-set", action="append", default=[], metavar="KEY=VALUE",
                    help="a scenario value of crashdem's own beds only, e.g. "
                         "soil.deposition_friction_deg=35 (repeatable)")
    ap.add_argument("--contact-law", default=None, choices=("linear", "hertz_mindlin"),
                    help="the Yade cases' impact law (default: linear); hertz_mindlin: Yade's "
                         "Hertz-Mindlin against crashdem's (soil.contact_law), same values")
    ap.add_argument("--deposition", action="store_true",
                    help="the deposition alone, on the bed of each case (any effect: its "
                         "bed is deposited as a null's): crashdem on Yade's grains against its "
                         "own beds, and the summary over the cases; no further Yade run")
    a = ap.parse_args(argv)
    cases = DEFAULT_CASES
    if a.cases:
        from validation.diagnosis_yade.cases import YADE_EFFECT_DRAWS

        # a floor case's bed is shallower than crashdem's own beds of the baseline
        allowed = (("null", *(e for e in YADE_EFFECT_DRAWS if e != "boundary_proximity"))
                   if a.deposition else ("null", "particle_rotation"))
        cases = []
        for c in a.cases:
            eff, _, seed = c.partition(":")
            if not seed.isdigit() or eff not in allowed:
                ap.error(f"--cases {c!r}: must be EFFECT:SEED with EFFECT in {allowed}"
                         + ("" if a.deposition else " (the effects whose impact runs on the "
                            "bed as deposited; --deposition takes the bed of any case)"))
            cases.append((None if eff == "null" else eff, int(seed)))
    if a.tank_diameter is not None and not 0.3 <= a.tank_diameter <= 20.0:
        ap.error(f"--tank-diameter {a.tank_diameter!r}: must be in [0.3, 20] m "
                 "(container.diameter's range)")
    if not 1 <= a.own_seeds <= 50:
        ap.error(f"--own-seeds {a.own_seeds!r}: must be in [1, 50]")
    if a.deposition and a.own_seeds < 2:
        ap.error("--deposition needs --own-seeds of at least 2 (the scatter of crashdem's own "
                 "beds)")
    own_overrides = {}
    for kv in a.own_set:
        key, eq, val = kv.partition("=")
        if not eq or not key:
            ap.error(f"--own-set {kv!r}: must be KEY=VALUE")
        try:
            own_overrides[key] = json.loads(val)
        except json.JSONDecodeError:
            own_overrides[key] = val
    seeds = tuple(range(1, a.own_seeds + 1))
    work = Path(a.work) if a.work else Path(tempfile.mkdtemp(prefix="same_bed_"))
    if a.deposition:
        from validation.diagnosis_yade.cases import yade_case

        rows, seen = [], {}
        for e, s in cases:
            # cases of one seed and grain size share a bed: each bed counts once
            meta = yade_case(s, e, raw=True).meta
            bed = meta["packing_npz"]
            if bed in seen:
                print(f"{e or 'null'}:{s}: the bed of {seen[bed]}, counted once")
                continue
            seen[bed] = f"{e or 'null'}:{s}"
            rows.append(deposition_row(e, s, work, seeds, own_overrides, meta=meta))
        summary = deposition_summary(rows)
        print(_deposition_table(rows, summary))
        print(json.dumps({"cases": rows, "summary": summary}))
        return 0
    if a.deposition and a.contact_law:
        ap.error("--contact-law: not with --deposition (the beds are deposited with the linear "
                 "law either way)")
    rows = [same_bed(e, s, work, a.tank_diameter, seeds, own_overrides, a.contact_law)
            for e, s in cases]
    print(_table(rows))
    if len(rows) > 1 and a.own_seeds > 1:
        summary = deposition_summary(rows)
        print(_deposition_table(rows, summary))
        print(json.dumps({"cases": rows, "summary": summary}))
    else:
        print(json.dumps({"cases": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
