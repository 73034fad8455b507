"""How much of the code-to-code difference is the bed, and how much the dynamics.

A Yade recording differs from crashdem's baseline in two ways at once: its bed was deposited
by Yade (another packing, grain size and deposition), and its impact was integrated by Yade
(contact laws as implemented, the facet tank, the integrator). This script separates them for
the Yade truth's cases (``cases.yade_case``): for each it runs

* **Yade** on its own bed (the truth's raw output);
* **crashdem on Yade's bed**: the same grains, imported with ``soil.packing_file``
  (``crashdem.beds``; grains that escaped Yade's facet tank are dropped), the same materials,
  impact speed and rotation setting -- what is left against Yade is the dynamics;
* **crashdem on its own bed** at the case's grain radius (crashdem's deposition, packing seed
  1) -- what this adds is the deposition.

    python validation/diagnosis_yade/same_bed.py                 # nulls 21, 22; free rotation 21
    python validation/diagnosis_yade/same_bed.py --cases null:21 particle_rotation:22

Prints per case the penetration (from first contact), its time, the velocity at 60 and 120 ms
and the mean specific force over windows of the impact, for the three runs; the LAST line is
JSON. Needs ``yade`` on the PATH for a case not in the cache (``cases.run_yade``).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from crashdem.beds import WALL_OVERLAP  # noqa: E402

#: windows [s after first contact] of the mean specific force
WINDOWS = ((0.0, 0.01), (0.01, 0.02), (0.02, 0.04), (0.04, 0.06), (0.06, 0.08), (0.08, 0.10),
           (0.10, 0.12))
#: the cases of the default run: (effect or None, seed)
DEFAULT_CASES = ((None, 21), (None, 22), ("particle_rotation", 21))


def inside_tank(x: np.ndarray, r: np.ndarray, tank_radius: float) -> np.ndarray:
    """Mask of the grains inside a cylinder tank of ``tank_radius`` on the z axis, above the
    floor z = 0, within ``crashdem.beds.WALL_OVERLAP`` of their radius (what the import
    accepts)."""
    tol = WALL_OVERLAP * r
    return (np.hypot(x[:, 0], x[:, 1]) + r - tank_radius <= tol) & (x[:, 2] - r >= -tol)


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


def same_bed(effect: str | None, seed: int, work: Path) -> dict:
    """The three runs of one Yade case (module docstring); returns the table row."""
    from validation.diagnosis_yade.cases import yade_case

    t0 = time.perf_counter()
    case = yade_case(seed, effect, raw=True)
    meta = case.meta
    rec = case.recording
    yade = impact_metrics(np.asarray(rec["velocity_z"].t), np.asarray(rec["velocity_z"].data),
                          np.asarray(rec["accel_z"].data))
    bed = np.load(meta["packing_npz"])
    x, r = bed["x"], bed["radius"]
    keep = inside_tank(x, r, meta["tank_radius"])
    name = f"{effect or 'null'}_{seed}"
    d = work / name
    d.mkdir(parents=True, exist_ok=True)
    np.savez(d / "yade_bed.npz", x=x[keep], radius=r[keep])
    rot = ({"soil.rotation": "free", "soil.rolling_coefficient": 0.0}
           if effect == "particle_rotation" else {})
    common = {"soil.radius": meta["radius"], **rot}
    on_yade, info_y = _crashdem({**common, "scenario.name": f"{name}_on_yade_bed",
                                 "soil.packing_file": str(d / "yade_bed.npz")}, d)
    own, info_o = _crashdem({**common, "scenario.name": f"{name}_own_bed",
                             "scenario.seed": 1}, d)
    return {"truth": effect, "seed": seed, "radius_m": meta["radius"],
            "yade_grains": int(len(r)), "imported_grains": int(keep.sum()),
            "crashdem_own_grains": int(info_o["particles"]),
            "yade": yade, "crashdem_on_yade_bed": on_yade, "crashdem_own_bed": own,
            "dynamics_penetration": on_yade["penetration_m"] / yade["penetration_m"] - 1.0,
            "deposition_penetration": own["penetration_m"] / on_yade["penetration_m"] - 1.0,
            "wall_s": time.perf_counter() - t0}


def _table(rows: list[dict]) -> str:
    keys = ["penetration_m", "t_max_s", "v_60ms", "v_120ms"] + [
        f"a_{lo * 1e3:.0f}_{hi * 1e3:.0f}ms" for lo, hi in WINDOWS]
    lines = []
    for row in rows:
        lines.append(f"\n{row['truth'] or 'null'} {row['seed']}: radius {row['radius_m']:g} m, "
                     f"Yade {row['yade_grains']} grains ({row['imported_grains']} imported), "
                     f"crashdem's own bed {row['crashdem_own_grains']}")
        lines.append(f"  {'':24s}" + "".join(f"{k:>13s}" for k in keys))
        for who in ("yade", "crashdem_on_yade_bed", "crashdem_own_bed"):
            lines.append(f"  {who:24s}" + "".join(f"{row[who][k]:13.4g}" for k in keys))
        lines.append(f"  penetration: dynamics (crashdem / Yade on Yade's bed) "
                     f"{row['dynamics_penetration']:+.1%}, deposition (crashdem's bed / "
                     f"Yade's, in crashdem) {row['deposition_penetration']:+.1%}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="*", metavar="EFFECT:SEED",
                    help="cases as effect:seed ('null' for no effect); default: "
                         + " ".join(f"{e or 'null'}:{s}" for e, s in DEFAULT_CASES))
    ap.add_argument("--work", default=None, help="directory of the runs (default: a temporary one)")
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
    work = Path(a.work) if a.work else Path(tempfile.mkdtemp(prefix="same_bed_"))
    rows = [same_bed(e, s, work) for e, s in cases]
    print(_table(rows))
    print(json.dumps({"cases": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
