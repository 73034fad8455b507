"""Speed and equality benchmark of the crashdem DEM engine against Yade 2023.02a.

The impact phase of the thesis's drop test on a deposited loose bed: an 850 kg, 0.90 m sphere at
19 m/s on r = 0.05 m +/- 20 % spheres (E = 2e7 Pa, phi = 30 deg, ks/kn = 0.25, rho = 2650 kg/m^3,
rotations blocked, dt = 2.3e-4 s, no damping), at about 50,000 and 200,000 particles.

Both codes load the same packing (deposited once by ``soil.packing``, cached on disk), the same
walls (planes with the sphere's own radius on the wall side = Yade ``utils.wall``), the same law
(linear Cundall-Strack, kn = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2), ks = ratio kn, tan(min phi)) and
the same drop mass: in Yade a sphere body of density m / (4/3 pi R^3); in crashdem a
``SphereBoundary`` on a coupled boundary body integrated here with the same leapfrog as Yade's
NewtonIntegrator (v += (F/m + g) dt; x += v dt).  Only the impact steps are timed (first step,
JIT compilation and loading excluded in both codes).  Each run is a subprocess (crashdem with
NUMBA_NUM_THREADS, Yade with -j), so its peak RSS is its own.

``--contact-law hertz_mindlin``: both codes with the Hertz-Mindlin law instead (Yade
``Ip2_FrictMat_FrictMat_MindlinPhys`` + ``Law2_ScGeom_MindlinPhys_Mindlin``; Poisson's ratio
0.25). Yade takes R* = r / 2 on a wall (it treats the wall as a sphere of the grain's radius),
crashdem the sphere-on-plane r, so the wall contacts differ by sqrt(2) in stiffness there.

Usage::

    python validation/bench_dem.py --quick                # ~4,000 particles, seconds
    python validation/bench_dem.py                        # 50,000 particles, 1 and 2 threads
    python validation/bench_dem.py --sizes 50000,200000   # both sizes
    python validation/bench_dem.py --sizes 200000 --yade-steps 200000:120   # Yade: rate only

Memory per particle: net = (peak RSS of the impact phase - baseline) / N, the baseline being
the worker's RSS after imports and JIT warm-up, before the scene exists; gross = peak / N;
engine = ``Simulation.memory_bytes()["total"]`` / N (docs/performance.md).

Prints a table; the LAST line is a JSON object (headline: 50k, equal threads; all runs in
``runs``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
YADE_SCRIPT = HERE / "yade_scripts" / "impact_bench.py"
DEFAULT_CACHE = Path(os.environ.get("CRASHDEM_CACHE", Path.home() / ".cache" / "crashdem"))

# thesis-like parameters (Varriale 2019 ch. 3-4; anchors §8)
YOUNG = 2.0e7  # [Pa]
DENSITY = 2650.0  # [kg/m^3]
FRICTION = math.radians(30.0)  # [rad]
STIFFNESS_RATIO = 0.25  # ks/kn [-]
POISSON = 0.25  # Poisson's ratio [-] (--contact-law hertz_mindlin)
RADIUS_MEAN = 0.05  # [m]
RADIUS_SPREAD = 0.20  # [-]
DROP_MASS = 850.0  # [kg]
DROP_RADIUS = 0.45  # [m]
DROP_SPEED = 19.0  # [m/s]
DT = 2.3e-4  # [s]
GRAVITY = 9.81  # [m/s^2]
DURATION = 0.16  # [s] until the mass has stopped (0.50-porosity bed: ~0.15 s; 48 ms in anchors §8)
BED_POROSITY_GUESS = 0.40  # only to size the container for a particle count
CLEARANCE = 1.0e-3  # [m] gap between the drop mass and the highest grain under it at t = 0


def materials(law: str = "linear"):
    """(soil, wall, drop mass) materials, identical in both codes; ``law``: the contact law
    (``"hertz_mindlin"``: Poisson's ratio ``POISSON``)."""
    from soil.params import Material

    kw = {"contact_law": law, "poisson": POISSON}
    soil_mat = Material(young=YOUNG, density=DENSITY, friction_angle=FRICTION,
                        stiffness_ratio=STIFFNESS_RATIO, name="soil", **kw)
    wall = Material(young=YOUNG, density=DENSITY, friction_angle=FRICTION,
                    stiffness_ratio=STIFFNESS_RATIO, name="wall", **kw)
    rho_mass = DROP_MASS / (4.0 / 3.0 * math.pi * DROP_RADIUS**3)
    mass = Material(young=YOUNG, density=rho_mass, friction_angle=0.0,
                    stiffness_ratio=STIFFNESS_RATIO, name="drop_mass", **kw)
    return soil_mat, wall, mass


def bench_spec(n_particles: int, depth: float | None = None):
    """Packing spec of a square loose bed holding about ``n_particles`` grains."""
    from soil import packing as pk

    if depth is None:
        depth = 2.0 if n_particles >= 20_000 else 1.0
    dist = pk.RadiusDistribution(RADIUS_MEAN, RADIUS_SPREAD)
    area = n_particles * dist.mean_volume / ((1.0 - BED_POROSITY_GUESS) * depth)
    side = round(math.sqrt(area), 2)
    soil_mat, _, _ = materials()
    return pk.PackingSpec(
        container=pk.BoxRegion((0.0, 0.0, 0.0), (side, side, depth + 1.0)),
        materials=(soil_mat,),
        layers=(pk.LayerSpec(depth),),
        radius=dist,
        seed=2019,
        deposition=pk.DepositionSettings(dt=DT, threshold=0.01, check_every=200, max_steps=400_000),
    )


def _scene(pk_obj, spec):
    """Box, drop start position, surface height [m] shared by both codes."""
    lo, hi = np.array(spec.container.lo), np.array(spec.container.hi)
    c = 0.5 * (lo[:2] + hi[:2])
    x, r = pk_obj.x, pk_obj.radius
    under = np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) <= DROP_RADIUS + r
    surface = float(np.max(x[under, 2] + r[under]))
    start = np.array([c[0], c[1], surface + DROP_RADIUS + CLEARANCE])
    return lo, hi, start, surface


def _rss_mb(key: str = "VmHWM") -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_peak_rss() -> bool:
    """Reset this process's VmHWM to its current RSS (Linux ``clear_refs`` value 5)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


# ---------------------------------------------------------------------------------------------
# crashdem worker (runs in its own process)
# ---------------------------------------------------------------------------------------------


def _impact_sim(x, r, lo, hi, start, threads, law="linear"):
    import soil

    soil_mat, wall, mass = materials(law)
    parts = soil.Particles(x=x, radius=r, material=np.zeros(len(r), np.int32),
                           rotation_blocked=True)
    floor_walls = soil.BoundaryBody(
        shapes=[
            soil.Plane(point=tuple(lo), normal=(0.0, 0.0, 1.0)),
            soil.Plane(point=tuple(lo), normal=(1.0, 0.0, 0.0)),
            soil.Plane(point=tuple(hi), normal=(-1.0, 0.0, 0.0)),
            soil.Plane(point=tuple(lo), normal=(0.0, 1.0, 0.0)),
            soil.Plane(point=tuple(hi), normal=(0.0, -1.0, 0.0)),
        ],
        material=1,
    )
    drop = soil.BoundaryBody(shapes=[soil.SphereBoundary(DROP_RADIUS)], material=2,
                             motion="coupled", position=start,
                             velocity=(0.0, 0.0, -DROP_SPEED))
    sim = soil.Simulation(parts, materials=[soil_mat, wall, mass],
                          boundaries=[floor_walls, drop], gravity=(0.0, 0.0, -GRAVITY), dt=DT,
                          global_damping=0.0, threads=threads)
    return sim, drop


def crashdem_worker(cfg: dict) -> dict:
    """Impact phase in crashdem: warm-up (compile), then the timed steps.

    Memory per particle (docs/performance.md):

    - baseline = RSS after the imports and the JIT warm-up on a small patch, before the scene's
      arrays exist (interpreter + NumPy + Numba/LLVM + compiled kernels);
    - peak = peak RSS of the impact phase (VmHWM reset after the baseline, then read after the
      last step: scene set-up and all steps);
    - ``bytes_per_particle`` (net) = (peak - baseline) / N, ``gross_bytes_per_particle`` =
      peak / N, ``engine_bytes_per_particle`` = ``Simulation.memory_bytes()["total"] / N``
      after the run (the engine's own buffers at their capacity).
    """
    import gc

    import numba

    import soil  # noqa: F401  (import cost outside the timing)

    lo, hi, start = (np.array(cfg[k]) for k in ("box_lo", "box_hi", "drop_start"))
    threads = int(cfg["threads"])
    # warm-up on a small patch of the same scene: compiles (or loads) every kernel used below
    with np.load(cfg["packing_npz"]) as data:
        x, r = data["x"], data["radius"]
        sel = np.hypot(x[:, 0] - start[0], x[:, 1] - start[1]) < 0.8
        sel &= x[:, 2] > start[2] - DROP_RADIUS - 0.6
        xw, rw = x[sel].copy(), r[sel].copy()
        n = int(len(r))
        del x, r, sel
    wlo = np.array([xw[:, 0].min() - 0.1, xw[:, 1].min() - 0.1, xw[:, 2].min() - 0.1])
    whi = np.array([xw[:, 0].max() + 0.1, xw[:, 1].max() + 0.1, start[2] + 1.0])
    wsim, _ = _impact_sim(xw, rw, wlo, whi, start, threads, cfg.get("contact_law", "linear"))
    wsim.step(3)
    del wsim, xw, rw
    gc.collect()
    rss_base = _rss_mb("VmRSS")
    hwm_reset = _reset_peak_rss()
    with np.load(cfg["packing_npz"]) as data:
        x, r = data["x"], data["radius"]
    sim, drop = _impact_sim(x, r, lo, hi, start, threads, cfg.get("contact_law", "linear"))
    del x, r
    m = DROP_MASS
    g = np.array([0.0, 0.0, -GRAVITY])
    pos = start.astype(float).copy()
    vel = np.array([0.0, 0.0, -DROP_SPEED])
    n_steps = int(cfg["steps"])
    hist = np.zeros((n_steps + 1, 5))
    hist[0] = (0.0, pos[2], vel[2], 0.0, 0.0)
    contacts = []
    elapsed = 0.0
    eye = np.eye(3)
    zero = np.zeros(3)
    for k in range(1, n_steps + 1):
        t0 = time.perf_counter()
        sim.step(1)
        f = np.array(drop.force, dtype=float)
        vel = vel + (f / m + g) * DT  # Yade NewtonIntegrator (leapfrog), damping 0
        pos = pos + vel * DT
        drop.set_kinematics(pos, eye, vel, zero)
        if k > 1:  # first step untimed (neighbour-list build), as in the Yade script
            elapsed += time.perf_counter() - t0
        hist[k] = (sim.time, pos[2], vel[2], f[2], 0.0)
        if k % 25 == 0:
            contacts.append(_sim_contacts_len(sim))
    peak = _rss_mb("VmHWM")
    mem = sim.memory_bytes()
    mib = 1024.0 * 1024.0
    out = {
        "code": "crashdem",
        "threads": threads,
        "particles": n,
        "steps_timed": n_steps - 1,
        "elapsed_s": elapsed,
        "particle_steps_per_s": n * (n_steps - 1) / elapsed,
        "contacts_per_step": float(np.mean(contacts)) if contacts else 0.0,
        "peak_rss_mb": peak,
        "rss_baseline_mb": rss_base,
        "peak_rss_reset": hwm_reset,
        "bytes_per_particle": (peak - rss_base) * mib / n,
        "gross_bytes_per_particle": peak * mib / n,
        "engine_bytes_per_particle": mem["per_particle"],
        "engine_bytes": {k: mem.get(k, 0) for k in ("particles", "pairs", "scratch",
                                                    "boundary")},
        "pairs_per_particle": mem["pairs_per_particle"],
        "threading_layer": numba.threading_layer(),
        "drop_mass": m,
    }
    np.save(cfg["out"] + ".npy", hist)
    with open(cfg["out"] + ".json", "w") as fh:
        json.dump(out, fh)
    return out


# ---------------------------------------------------------------------------------------------
# driver
# ---------------------------------------------------------------------------------------------


def _sim_contacts_len(sim) -> int:
    return sim.n_contacts()


def metrics(hist: np.ndarray, surface: float, mass: float) -> dict:
    """Peak deceleration [g], its time [s], maximum penetration [m] and its time [s]."""
    t, z, vz, fz = hist[:, 0], hist[:, 1], hist[:, 2], hist[:, 3]
    decel = fz / (mass * GRAVITY)
    pen = surface - (z - DROP_RADIUS)
    k, j = int(np.argmax(decel)), int(np.argmax(pen))
    return {
        "peak_decel_g": float(decel[k]),
        "t_peak_s": float(t[k]),
        "max_penetration_m": float(pen[j]),
        "t_max_penetration_s": float(t[j]),
        "rebound_speed_m_s": float(vz[-1]),
    }


def run_crashdem(cfg_path: Path, threads: int) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads))
    proc = subprocess.run([sys.executable, __file__, "--worker", str(cfg_path)], env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"crashdem worker failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    cfg = json.loads(cfg_path.read_text())
    return json.loads(Path(cfg["out"] + ".json").read_text())


def run_yade(cfg_path: Path, threads: int) -> dict:
    yade = shutil.which("yade")
    proc = subprocess.run([yade, "-n", f"-j{threads}", "-x", str(YADE_SCRIPT), str(cfg_path)],
                          capture_output=True, text=True, cwd=str(cfg_path.parent))
    cfg = json.loads(cfg_path.read_text())
    out = Path(cfg["out"] + ".json")
    if not out.exists():
        raise RuntimeError(f"yade run failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return json.loads(out.read_text())


def bench_size(n: int, threads_list, cache: Path, work: Path, use_yade: bool, log,
               yade_steps: int | None = None, law: str = "linear") -> list[dict]:
    """Both codes at about ``n`` particles for each thread count.

    ``yade_steps`` (None = all) caps Yade's steps: its rate is then measured on the first
    ``yade_steps`` impact steps only, and the equal-results columns are left empty for this
    size (they need the full impact).
    """
    from soil import packing as pk

    spec = bench_spec(n)
    t0 = time.perf_counter()
    packing = pk.cached(spec, cache, progress=log)
    t_dep = time.perf_counter() - t0
    log(f"[{n}] packing: {len(packing)} grains, porosity {packing.porosity:.3f}, "
        f"{t_dep:.1f} s (cache {cache})")
    lo, hi, start, surface = _scene(packing, spec)
    npz = work / f"packing_{n}.npz"
    np.savez(npz, x=packing.x, radius=packing.radius)
    soil_mat, wall, mass = materials(law)
    steps = int(round(DURATION / DT))
    y_steps = steps if yade_steps is None else min(steps, int(yade_steps))
    runs = []
    for threads in threads_list:
        rec = {"requested_particles": n, "particles": len(packing), "threads": threads,
               "steps": steps, "porosity": packing.porosity, "deposition_s": t_dep}
        for code in ("crashdem", "yade"):
            if code == "yade" and not use_yade:
                continue
            cfg = {
                "packing_npz": str(npz),
                "materials": [
                    {k: getattr(mm, k) for k in ("young", "stiffness_ratio", "friction_angle",
                                                  "density", "poisson")}
                    for mm in (soil_mat, wall, mass)
                ],
                "contact_law": law,
                "box_lo": lo.tolist(), "box_hi": hi.tolist(),
                "drop_start": start.tolist(), "drop_radius": DROP_RADIUS,
                "drop_velocity": [0.0, 0.0, -DROP_SPEED],
                "gravity": GRAVITY, "dt": DT, "threads": threads,
                "steps": steps if code == "crashdem" else y_steps,
                "out": str(work / f"{code}_{n}_{threads}"),
            }
            cfg_path = work / f"{code}_{n}_{threads}.cfg.json"
            cfg_path.write_text(json.dumps(cfg))
            log(f"[{n}] {code} {threads} thread(s) ...")
            runner = run_crashdem if code == "crashdem" else run_yade
            res = runner(cfg_path, threads)
            hist = np.load(cfg["out"] + ".npy")
            res.update(metrics(hist, surface, DROP_MASS))
            rec[code] = res
            log(f"[{n}] {code} {threads}T: {res['particle_steps_per_s']:.3g} p-steps/s, "
                f"peak {res['peak_decel_g']:.1f} g at {1e3 * res['t_peak_s']:.1f} ms, "
                f"pen {res['max_penetration_m']:.3f} m, RSS {res['peak_rss_mb']:.0f} MB")
        c = rec["crashdem"]
        rec["contacts_per_step"] = c["contacts_per_step"]
        rec["crashdem_particle_steps_per_s"] = c["particle_steps_per_s"]
        rec["peak_rss_mb"] = c["peak_rss_mb"]
        rec["crashdem_bytes_per_particle"] = c["bytes_per_particle"]
        rec["crashdem_gross_bytes_per_particle"] = c["gross_bytes_per_particle"]
        rec["crashdem_engine_bytes_per_particle"] = c["engine_bytes_per_particle"]
        rec["rss_baseline_mb"] = c["rss_baseline_mb"]
        if "yade" in rec:
            y = rec["yade"]
            rec["yade_steps"] = y["steps_timed"] + 1
            rec["yade_particle_steps_per_s"] = y["particle_steps_per_s"]
            rec["ratio"] = c["particle_steps_per_s"] / y["particle_steps_per_s"]
            if y_steps == steps:
                rec["peak_decel_rel_diff"] = (
                    (c["peak_decel_g"] - y["peak_decel_g"]) / y["peak_decel_g"])
                rec["max_penetration_rel_diff"] = (
                    (c["max_penetration_m"] - y["max_penetration_m"]) / y["max_penetration_m"]
                )
            else:  # partial Yade run: rate only
                rec["peak_decel_rel_diff"] = None
                rec["max_penetration_rel_diff"] = None
                for k in ("peak_decel_g", "max_penetration_m", "t_peak_s",
                          "t_max_penetration_s"):
                    y[k] = None
            rec["yade_peak_rss_mb"] = y["peak_rss_mb"]
        else:
            for k in ("yade_particle_steps_per_s", "ratio", "peak_decel_rel_diff",
                      "max_penetration_rel_diff"):
                rec[k] = None
        runs.append(rec)
    return runs


def table(runs: list[dict]) -> str:
    """One line per (size, threads).  Memory columns [B/particle]: net = (peak RSS - baseline)
    / N, gross = peak RSS / N, engine = the engine's own buffers / N (crashdem)."""
    head = (f"{'N':>8} {'thr':>3} {'contacts':>9} {'crashdem p-s/s':>15} {'yade p-s/s':>12} "
            f"{'y steps':>7} {'ratio':>6} {'cd peak g':>9} {'yade peak g':>11} {'d peak':>7} "
            f"{'cd pen m':>8} {'yade pen m':>10} {'d pen':>7} {'cd RSS MB':>9} {'net B/p':>7} "
            f"{'gross B/p':>9} {'eng B/p':>7} {'yade RSS':>8}")
    lines = [head, "-" * len(head)]
    for r in runs:
        c, y = r["crashdem"], r.get("yade")

        def f(v, fmt):
            return format(v, fmt) if v is not None else "-"

        lines.append(
            f"{r['particles']:>8} {r['threads']:>3} {r['contacts_per_step']:>9.0f} "
            f"{c['particle_steps_per_s']:>15.3g} "
            f"{f(y and y['particle_steps_per_s'], '12.3g'):>12} "
            f"{f(r.get('yade_steps'), '7d'):>7} {f(r['ratio'], '6.2f'):>6} "
            f"{c['peak_decel_g']:>9.2f} {f(y and y['peak_decel_g'], '11.2f'):>11} "
            f"{f(r['peak_decel_rel_diff'], '+7.3f'):>7} {c['max_penetration_m']:>8.4f} "
            f"{f(y and y['max_penetration_m'], '10.4f'):>10} "
            f"{f(r['max_penetration_rel_diff'], '+7.3f'):>7} {c['peak_rss_mb']:>9.0f} "
            f"{r['crashdem_bytes_per_particle']:>7.0f} "
            f"{r['crashdem_gross_bytes_per_particle']:>9.0f} "
            f"{r['crashdem_engine_bytes_per_particle']:>7.0f} "
            f"{f(y and y['peak_rss_mb'], '8.0f'):>8}"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    from crashdem.run import packing_cache  # the beds of this soil engine under --cache

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="50000", help="comma-separated particle counts")
    ap.add_argument("--threads", default="1,2", help="comma-separated thread counts")
    ap.add_argument("--quick", action="store_true", help="one small bed (about 4,000 grains)")
    ap.add_argument("--no-yade", action="store_true", help="skip Yade even if on PATH")
    ap.add_argument("--yade-steps", default=None,
                    help="cap Yade's steps per size, e.g. '200000:120' (rate only at that size)")
    ap.add_argument("--cache", default=str(DEFAULT_CACHE / "packings"),
                    help="packing cache root (beds under <root>/<soil engine fingerprint>)")
    ap.add_argument("--keep", default=None, help="directory to keep the run files in")
    ap.add_argument("--contact-law", default="linear", choices=("linear", "hertz_mindlin"),
                    help="both codes' contact law (hertz_mindlin: Yade's MindlinPhys, "
                         "crashdem's soil.Material.contact_law; Poisson's ratio 0.25)")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        crashdem_worker(json.loads(Path(a.worker).read_text()))
        return 0
    sizes = [4000] if a.quick else [int(s) for s in a.sizes.split(",")]
    threads = [int(t) for t in a.threads.split(",")]
    use_yade = (not a.no_yade) and shutil.which("yade") is not None

    def log(msg):
        print(msg, flush=True)

    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench_dem_"))
    work.mkdir(parents=True, exist_ok=True)
    yade_steps = {}
    for item in (a.yade_steps.split(",") if a.yade_steps else []):
        size, _, k = item.partition(":")
        yade_steps[int(size)] = int(k)
    runs = []
    for n in sizes:
        runs += bench_size(n, threads, packing_cache(a.cache), work, use_yade, log,
                           yade_steps.get(n), a.contact_law)
    print(table(runs))
    if not a.keep:
        shutil.rmtree(work, ignore_errors=True)
    key = min(runs, key=lambda r: (abs(r["requested_particles"] - 50_000), r["threads"] != 1))
    keys = ("particles", "contacts_per_step", "steps", "threads", "crashdem_particle_steps_per_s",
            "yade_particle_steps_per_s", "ratio", "peak_rss_mb", "peak_decel_rel_diff",
            "max_penetration_rel_diff")
    summary = {k: key[k] for k in keys}
    mem_keys = ("crashdem_bytes_per_particle", "crashdem_gross_bytes_per_particle",
                "crashdem_engine_bytes_per_particle", "rss_baseline_mb")
    for k in mem_keys:
        summary[k] = key[k]
    summary["runs"] = [
        {k: r[k] for k in keys + mem_keys}
        | {"yade_steps": r.get("yade_steps")}
        | {f"crashdem_{m}": r["crashdem"][m] for m in ("peak_decel_g", "max_penetration_m",
                                                      "t_peak_s", "t_max_penetration_s")}
        | ({f"yade_{m}": r["yade"].get(m) for m in ("peak_decel_g", "max_penetration_m",
                                                     "t_peak_s", "t_max_penetration_s",
                                                     "peak_rss_mb")}
           if "yade" in r else {})
        for r in runs
    ]
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # a process that ran Numba kernels can spin in thread-pool teardown at interpreter exit
    # (seen twice on this machine); everything is written and flushed, so leave at once
    os._exit(code)
