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

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from crashdem.beds import inside_cylinder  # noqa: E402

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


def same_bed(effect: str | None, seed: int, work: Path, tank_diameter: float | None = None
             ) -> dict:
    """The runs of one Yade case (module docstring); returns the table row."""
    from crashdem.diagnosis.generator_dem import cache_dir
    from validation.diagnosis_yade.cases import run_yade, yade_case

    t0 = time.perf_counter()
    case = yade_case(seed, effect, raw=True)
    meta = case.meta
    hist, info = run_yade(meta["cfg"], cache_dir())  # the case's run, cached by yade_case
    yade = _yade_metrics(hist, info["mass"])
    bed = np.load(meta["packing_npz"])
    x, r = bed["x"], bed["radius"]
    keep = inside_cylinder(x, r, meta["tank_radius"])  # what the import accepts
    name = f"{effect or 'null'}_{seed}"
    d = work / name
    d.mkdir(parents=True, exist_ok=True)
    np.savez(d / "yade_bed.npz", x=x[keep], radius=r[keep])
    rot = ({"soil.rotation": "free", "soil.rolling_coefficient": 0.0}
           if effect == "particle_rotation" else {})
    common = {"soil.radius": meta["radius"], **rot}
    imported = {**common, "soil.packing_file": str(d / "yade_bed.npz")}
    on_yade, _ = _crashdem({**imported, "scenario.name": f"{name}_on_yade_bed"}, d)
    young = float(meta["cfg"]["young"])
    facets, _ = _crashdem({**imported, "scenario.name": f"{name}_in_yade_wall",
                           "container.diameter": 2.0 * meta["tank_radius"]
                           * math.cos(math.pi / YADE_TANK_SEGMENTS),
                           "container.wall_young": 4.0 / 3.0 * young}, d)
    own, info_o = _crashdem({**common, "scenario.name": f"{name}_own_bed",
                             "scenario.seed": 1}, d)
    row = {"truth": effect, "seed": seed, "radius_m": meta["radius"],
           "yade_grains": int(len(r)), "imported_grains": int(keep.sum()),
           "crashdem_own_grains": int(info_o["particles"]),
           "yade": yade, "crashdem_on_yade_bed": on_yade, "crashdem_in_yade_wall": facets,
           "crashdem_own_bed": own,
           "dynamics_penetration": on_yade["penetration_m"] / yade["penetration_m"] - 1.0,
           "dynamics_in_yade_wall": facets["penetration_m"] / yade["penetration_m"] - 1.0,
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


def _table(rows: list[dict]) -> str:
    keys = ["penetration_m", "t_max_s", "v_60ms", "v_120ms"] + [
        f"a_{lo * 1e3:.0f}_{hi * 1e3:.0f}ms" for lo, hi in WINDOWS]
    lines = []
    for row in rows:
        lines.append(f"\n{row['truth'] or 'null'} {row['seed']}: radius {row['radius_m']:g} m, "
                     f"Yade {row['yade_grains']} grains ({row['imported_grains']} imported), "
                     f"crashdem's own bed {row['crashdem_own_grains']}")
        lines.append(f"  {'':24s}" + "".join(f"{k:>13s}" for k in keys))
        for who in ("yade", "crashdem_on_yade_bed", "crashdem_in_yade_wall",
                    "crashdem_own_bed", "yade_wide", "crashdem_wide"):
            if who in row:
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
    a = ap.parse_args(argv)
    cases = DEFAULT_CASES
    if a.cases:
        cases = []
        for c in a.cases:
            eff, _, seed = c.partition(":")
            if not seed.isdigit() or eff not in ("null", "particle_rotation"):
                ap.error(f"--cases {c!r}: must be null:SEED or particle_rotation:SEED (the "
                         "effects whose impact runs on the bed as deposited)")
            cases.append((None if eff == "null" else eff, int(seed)))
    if a.tank_diameter is not None and not 0.3 <= a.tank_diameter <= 20.0:
        ap.error(f"--tank-diameter {a.tank_diameter!r}: must be in [0.3, 20] m "
                 "(container.diameter's range)")
    work = Path(a.work) if a.work else Path(tempfile.mkdtemp(prefix="same_bed_"))
    rows = [same_bed(e, s, work, a.tank_diameter) for e, s in cases]
    print(_table(rows))
    print(json.dumps({"cases": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
