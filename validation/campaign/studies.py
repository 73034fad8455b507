"""The drop-test campaign runs: four impact speeds, cohesion switch, domain and grain studies.

API
---
``SPEEDS``                                   label -> scenario file of series S2
``RESOLUTIONS``                              "small" / "default" scenario overrides
``run_case(scen, out_dir, cache) -> dict``   one impact: HDF5 via ``crashdem.run.run_scenario``,
                                             metrics, impulse balance, wall time
``run_series(...)``                          the four speeds (optionally with extra overrides)
``domain_study(...)``, ``grain_study(...)``  the two convergence studies of the issue
``fact_checks(series) -> list[dict]``        the thesis's qualitative facts as pass/fail lines
``formula_rows(series) -> list[dict]``       Japan / ASTRA values and back-calculated moduli
``plot_series(...)``, ``plot_cohesion(...)`` the PNG figures
``table(series, ...) -> str``                the comparison table (text)
"""
from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

from validation.campaign import formulas as fm
from validation.campaign import signals as sg

HERE = Path(__file__).resolve().parent.parent
SCENARIOS = HERE / "scenarios"
#: Series S2 (thesis Tab 2.1): impact speed label -> scenario file.
SPEEDS = {
    "9.90": SCENARIOS / "drop_s2_h5p00.toml",
    "14.0": SCENARIOS / "drop_s2_h10p00.toml",
    "16.4": SCENARIOS / "drop_s2_h13p70.toml",
    "19.0": SCENARIOS / "drop_s2_h18p45.toml",
}
#: Resolution presets (scenario overrides).  "small": 0.10 m grains in a 2.0 m tank (about
#: 800 grains, for the test suite); the spread is 0.1 instead of 0.2 because the packing's
#: porosity-trial column cannot hold the 0.2-spread lattice (reported to the soil owner).
#: "default": the scenario files as written (0.075 m grains, 6.0 m tank, about 16,300 grains).
RESOLUTIONS: dict[str, dict] = {
    "small": {"soil.radius": 0.10, "soil.radius_spread": 0.10, "container.diameter": 2.0,
              "solver.t_end": 0.12},
    "default": {},
}
COMMON = {"output.snapshots": 0, "output.plots": False}
DEFAULT_CACHE = Path(os.environ.get("CRASHDEM_CACHE",
                                    Path.home() / ".cache" / "crashdem")) / "packings"


def load_scenario(label: str, overrides: dict):
    from crashdem import scenario as sc

    return sc.load(SPEEDS[label], {**COMMON, **overrides})


def run_case(scen, out_dir: Path, cache: Path = DEFAULT_CACHE, tag: str = "") -> dict:
    """Run one impact and return its metrics (see :func:`signals.impact_metrics`), the impulse
    balance, the particle count, the HDF5 path and the wall time [s]."""
    from crashdem.run import run_scenario

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cache = Path(cache)
    cache.mkdir(parents=True, exist_ok=True)
    link = out_dir / "packings"  # run_scenario caches packings next to its output
    if not link.exists():
        link.symlink_to(cache, target_is_directory=True)
    if tag:
        scen = scen.with_overrides({"scenario.name": f"{scen['scenario.name']}_{tag}"})
    t0 = time.perf_counter()
    path = run_scenario(scen, out_dir, progress=False, plots=False)
    wall = time.perf_counter() - t0
    rec = sg.read_drop_record(path)
    import h5py

    with h5py.File(path, "r") as f:
        n = int(f["run"].attrs["particles"])
        steps = int(f["run"].attrs["dem_steps"])
    out = sg.impact_metrics(rec)
    out.update(impulse=sg.impulse_balance(rec), particles=n, dem_steps=steps,
               particle_steps=n * steps, path=str(path), wall_s=wall)
    out["_record"] = rec
    return out


def run_series(overrides: dict, out_dir: Path, cache: Path = DEFAULT_CACHE, tag: str = "",
               log=print) -> dict[str, dict]:
    """The four S2 impacts with the same overrides (same packing: deposited once, cached)."""
    res = {}
    for label in SPEEDS:
        scen = load_scenario(label, overrides)
        r = run_case(scen, out_dir, cache, tag)
        log(f"  v = {label} m/s{' [' + tag + ']' if tag else ''}: peak {r['peak_decel_g']:.1f} g, "
            f"penetration {r['max_penetration_m']:.3f} m, rebound at {r['t_rebound_s']:.4f} s, "
            f"double peak {r['double_peak']}, {r['particles']} grains, {r['wall_s']:.1f} s")
        res[label] = r
    return res


def relative_change(a: float, b: float) -> float:
    """|b - a| / |a| [-]."""
    return abs(b - a) / abs(a) if a else float("inf")


def domain_study(base: dict, out_dir: Path, cache: Path = DEFAULT_CACHE, label: str = "19.0",
                 seeds=(1, 2, 3), log=print) -> dict:
    """Peak force with the tank diameter D and 2 D (issue: the change must be < 5 %).

    One packing is one random realisation: at 4,000 grains the peak force of a single impact
    varies by several per cent from one packing seed to the next, as much as the effect being
    measured.  Each diameter therefore runs with every seed of ``seeds`` (``scenario.seed`` is
    the packing seed) and the *means* are compared; the seed-to-seed standard deviation and the
    standard error of the change are reported with it, so the reader sees whether the change is
    resolved.  ``passes_5pct``: the mean change is below 5 %.
    """
    from crashdem import scenario as sc

    scen = load_scenario(label, base)
    d0 = scen["container.diameter"]
    rows = []
    for k, d in enumerate((d0, min(2.0 * d0, sc.SCHEMA["container"]["diameter"].hi))):
        for seed in seeds:
            r = run_case(scen.with_overrides({"container.diameter": d, "scenario.seed": seed}),
                         out_dir / f"domain_{k}_s{seed}", cache)
            rows.append({"diameter_m": d, "seed": seed, "peak_force_N": r["peak_force_N"],
                         "max_penetration_m": r["max_penetration_m"],
                         "t_rebound_s": r["t_rebound_s"], "particles": r["particles"],
                         "wall_s": r["wall_s"]})
            log(f"  domain D = {d:.2f} m, seed {seed}: peak {r['peak_force_N'] / 1e3:.1f} kN, "
                f"penetration {r['max_penetration_m']:.3f} m, {r['particles']} grains")
    out: dict = {"rows": rows, "seeds": list(seeds)}
    stats = []
    for d in sorted({row["diameter_m"] for row in rows}):
        pk = np.array([row["peak_force_N"] for row in rows if row["diameter_m"] == d])
        pen = np.array([row["max_penetration_m"] for row in rows if row["diameter_m"] == d])
        sd = float(pk.std(ddof=1)) if len(pk) > 1 else float("nan")
        stats.append({"diameter_m": d, "peak_force_mean_N": float(pk.mean()),
                      "peak_force_std_N": sd, "penetration_mean_m": float(pen.mean()),
                      "penetration_std_m": float(pen.std(ddof=1)) if len(pen) > 1 else float("nan"),
                      "n": int(len(pk))})
    a, b = stats[0], stats[1]
    ch = relative_change(a["peak_force_mean_N"], b["peak_force_mean_N"])
    se = math.sqrt(a["peak_force_std_N"] ** 2 / a["n"] + b["peak_force_std_N"] ** 2 / b["n"]) / \
        a["peak_force_mean_N"] if a["n"] > 1 and b["n"] > 1 else float("nan")
    out.update({
        "stats": stats,
        "peak_force_change": ch,
        "peak_force_change_stderr": se,
        "seed_scatter": a["peak_force_std_N"] / a["peak_force_mean_N"],
        "penetration_change": relative_change(a["penetration_mean_m"], b["penetration_mean_m"]),
        "passes_5pct": bool(ch < 0.05),
    })
    return out


def grain_study(base: dict, radii, out_dir: Path, cache: Path = DEFAULT_CACHE,
                label: str = "19.0", log=print) -> dict:
    """Error against cost for several grain radii (thesis Tab 4.1 analogue); the finest run is
    the reference.  Cost: particle-steps of the impact phase (machine-independent) and the wall
    time of the run (which includes the deposition when the packing was not cached)."""
    rows = []
    for r_mean in radii:
        scen = load_scenario(label, {**base, "soil.radius": r_mean})
        r = run_case(scen, out_dir / f"grain_{r_mean:g}", cache)
        rows.append({"radius_m": r_mean, "particles": r["particles"], "wall_s": r["wall_s"],
                     "particle_steps": r["particle_steps"],
                     "peak_force_N": r["peak_force_N"],
                     "max_penetration_m": r["max_penetration_m"],
                     "t_rebound_s": r["t_rebound_s"]})
        log(f"  grain r = {r_mean:g} m: {r['particles']} grains, {r['wall_s']:.1f} s, peak "
            f"{r['peak_force_N'] / 1e3:.1f} kN, penetration {r['max_penetration_m']:.3f} m")
    ref = min(rows, key=lambda x: x["radius_m"])
    for row in rows:
        row["peak_force_error"] = relative_change(ref["peak_force_N"], row["peak_force_N"])
        row["penetration_error"] = relative_change(ref["max_penetration_m"],
                                                   row["max_penetration_m"])
    return {"rows": rows, "reference_radius_m": ref["radius_m"]}


# ---------------------------------------------------------------------------------------------
# comparison with the thesis facts and the empirical formulas
# ---------------------------------------------------------------------------------------------

#: Thesis §2.1.3 facts, as numbers (F = stated fact, A = our numeric reading of it).
REBOUND_WINDOW = (0.06, 0.08)  # [s] F: "around 0.06 s and 0.08 s"
DEEP_PENETRATION = 1.0  # [m] F: "exceeds one meter" (at the higher energies)


def fact_checks(series: dict[str, dict]) -> list[dict]:
    """Each thesis fact with the measured value and pass/fail."""
    labels = list(series)
    pk = [series[k]["peak_force_N"] for k in labels]
    pen = [series[k]["max_penetration_m"] for k in labels]
    tpk = [series[k]["t_peak_decel_s"] for k in labels]
    out = [
        {"fact": "peak force grows with height", "value": [round(p / 1e3, 1) for p in pk],
         "ok": bool(np.all(np.diff(pk) > 0))},
        {"fact": "penetration grows with height", "value": [round(p, 3) for p in pen],
         "ok": bool(np.all(np.diff(pen) > 0))},
        {"fact": "peak sharpens with height (earlier peak)", "value": [round(t, 4) for t in tpk],
         "ok": bool(tpk[-1] < tpk[0])},
        {"fact": "penetration > 1 m at the highest energy", "value": round(pen[-1], 3),
         "ok": bool(pen[-1] > DEEP_PENETRATION)},
    ]
    for k in labels:
        t = series[k]["t_rebound_s"]
        out.append({"fact": f"rebound onset in 0.06-0.08 s at {k} m/s", "value": round(t, 4),
                    "ok": bool(REBOUND_WINDOW[0] <= t <= REBOUND_WINDOW[1])})
        out.append({"fact": f"double-peak deceleration at {k} m/s",
                    "value": [round(x, 4) for x in series[k]["decel_peaks_s"]],
                    "ok": bool(series[k]["double_peak"])})
    return out


#: Formula inputs: Japan design default (soft sand) and ASTRA defaults of anchors.md §1.1.
LAME_DEFAULT = 1.0e6  # [Pa]
ME_DEFAULT = 1.0e7  # [Pa]
PHI_ASTRA = math.radians(40.0)  # [rad]
LAYER = 2.0  # [m]
MASS, RADIUS = 850.0, 0.45  # [kg], [m]


def formula_rows(series: dict[str, dict]) -> list[dict]:
    """Japan and ASTRA peak forces at the design defaults, and the cushion moduli that make
    each formula reproduce the DEM peak force (F ~ lambda^0.4, F ~ M_E^0.4)."""
    rows = []
    for k, r in series.items():
        v = float(k)
        h = fm.fall_height(v)
        fj = fm.japan_force(MASS, h, LAME_DEFAULT)
        fa = fm.astra_force(MASS, v, RADIUS, LAYER, ME_DEFAULT, PHI_ASTRA)
        f = r["peak_force_N"]
        rows.append({"speed": k, "dem_N": f, "japan_N": fj, "astra_N": fa,
                     "lame_equivalent_Pa": LAME_DEFAULT * (f / fj) ** 2.5,
                     "me_equivalent_Pa": ME_DEFAULT * (f / fa) ** 2.5,
                     "astra_penetration_m": fm.triangular_penetration(MASS, v, fa)})
    return rows


#: Yade 2023.02a on a similar loose bed (anchors.md §8: single 2 m layer, porosity 0.40, E = 2e7,
#: phi = 30 deg, box): speed -> (peak g, max penetration m); not the same packing.
YADE_ANCHOR = {"14.0": (53.0, 0.31), "19.0": (74.0, 0.39)}


def table(series: dict[str, dict], cohesive: dict[str, dict] | None = None,
          yade: dict[str, dict] | None = None) -> str:
    """Comparison table: one line per impact speed."""
    fr = {r["speed"]: r for r in formula_rows(series)}
    head = (f"{'v [m/s]':>8} {'F_pk [kN]':>9} {'a_pk [g]':>8} {'pen [m]':>7} {'dur [s]':>7} "
            f"{'t_reb [s]':>9} {'2-peak':>6} | {'Japan':>6} {'ASTRA':>6} [kN] "
            f"{'lam_eq [MPa]':>12} {'ME_eq [MPa]':>11} | {'Yade§8 g/m':>11}")
    lines = [head, "-" * len(head)]
    for k, r in series.items():
        f = fr[k]
        yd = YADE_ANCHOR.get(k)
        lines.append(
            f"{k:>8} {r['peak_force_N'] / 1e3:9.1f} {r['peak_decel_g']:8.1f} "
            f"{r['max_penetration_m']:7.3f} {r['impact_duration_s']:7.4f} {r['t_rebound_s']:9.4f} "
            f"{str(r['double_peak']):>6} | {f['japan_N'] / 1e3:6.0f} "
            f"{f['astra_N'] / 1e3:6.0f}      "
            f"{f['lame_equivalent_Pa'] / 1e6:12.3f} {f['me_equivalent_Pa'] / 1e6:11.3f} | "
            f"{(f'{yd[0]:.0f}/{yd[1]:.2f}' if yd else '-'):>11}")
    for name, extra in (("Yade 2023.02a, same packing", yade),
                        ("cohesive soil (physics.cohesion)", cohesive)):
        if not extra:
            continue
        lines.append(name + ":")
        for k, r in extra.items():
            lines.append(f"{k:>8} {r['peak_force_N'] / 1e3:9.1f} {r['peak_decel_g']:8.1f} "
                         f"{r['max_penetration_m']:7.3f} {r['impact_duration_s']:7.4f} "
                         f"{r['t_rebound_s']:9.4f} {str(r['double_peak']):>6}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# plots
# ---------------------------------------------------------------------------------------------


def _curves(rec: sg.DropRecord):
    t = rec.t - rec.t_contact
    return t, rec.decel / sg.G0, rec.v_z, rec.penetration


def plot_series(series: dict[str, dict], out_dir: Path, suffix: str = "") -> list[Path]:
    """Acceleration, velocity and penetration against time, four heights per figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, (what, ylabel) in enumerate((("acceleration", "deceleration [g] (CFC 60)"),
                                        ("velocity", "vertical velocity [m/s] (CFC 60)"),
                                        ("displacement", "penetration [m]"))):
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for k, r in series.items():
            c = _curves(r["_record"])
            ax.plot(c[0], c[i + 1], label=f"{k} m/s")
        ax.set_xlabel("time from contact [s]")
        ax.set_ylabel(ylabel)
        ax.set_xlim(left=-0.005)
        ax.grid(True, alpha=0.3)
        ax.legend()
        ax.set_title(f"Drop tests, series S2: {what}{suffix}")
        p = out_dir / f"drop_{what}{suffix.replace(' ', '_')}.png"
        fig.tight_layout()
        fig.savefig(p, dpi=120)
        plt.close(fig)
        paths.append(p)
    return paths


def plot_cohesion(series: dict[str, dict], cohesive: dict[str, dict], out_dir: Path) -> Path:
    """Elasto-plastic against cohesive soil (thesis Ch. 5 comparison): 3 panels, 4 heights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.5))
    labels = ("deceleration [g]", "velocity [m/s]", "penetration [m]")
    for n, k in enumerate(series):
        col = f"C{n}"
        for res, ls, name in ((series, "-", "elasto-plastic"), (cohesive, "--", "cohesive")):
            if k not in res:
                continue
            c = _curves(res[k]["_record"])
            for i in range(3):
                axes[i].plot(c[0], c[i + 1], ls, color=col, label=f"{k} m/s {name}")
    for ax, lab in zip(axes, labels):
        ax.set_xlabel("time from contact [s]")
        ax.set_ylabel(lab)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Elasto-plastic (Cundall-Strack) vs cohesive soil")
    fig.tight_layout()
    p = Path(out_dir) / "drop_cohesion_comparison.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p
