"""Same-packing comparison with Yade 2023.02a (Debian ``yade``) for one drop-test scenario.

API
---
``yade_available() -> bool``
``run_yade(scen, crashdem_result, work, cache) -> dict``  metrics of the Yade run, computed
with the same definitions (``signals.impact_metrics``) after sampling the Yade force and
velocity at the scenario rate and filtering at the scenario CFC.
"""
from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np

from validation.campaign import signals as sg

SCRIPT = Path(__file__).resolve().parent / "yade_drop.py"


def yade_available() -> bool:
    return shutil.which("yade") is not None


def run_yade(scen, crash: dict, work: Path, cache: Path, timeout: float = 1800) -> dict:
    """Run the scenario's impact in Yade on the crashdem packing; return its metrics.

    ``crash`` is the crashdem ``run_case`` output of the same scenario (its record gives the
    surface height, contact time, time step and mass).
    """
    import h5py

    from crashdem.filters import cfc_filter
    from crashdem.run import impact_materials, packing_spec
    from soil import packing as pk

    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    packing = pk.cached(packing_spec(scen), cache)
    mats = impact_materials(scen, packing)
    rec: sg.DropRecord = crash["_record"]
    with h5py.File(crash["path"], "r") as f:
        info = dict(f["run"].attrs)
    dt = float(info["dt"])
    R = 0.45
    gap = scen["impactor.gap"]
    v = scen.impact_velocity
    v0 = math.sqrt(max(v * v - 2 * 9.81 * gap, 0.0))
    surface = float(info["surface_z"])
    npz = work / "packing.npz"
    np.savez(npz, x=packing.x, radius=packing.radius, material=packing.material)
    cfg = {
        "packing_npz": str(npz),
        "materials": [{"young": m.young, "stiffness_ratio": m.stiffness_ratio,
                       "friction_angle": m.friction_angle, "density": m.density} for m in mats],
        "wall_material": len(packing.materials),
        "impactor_material": len(packing.materials) + 1,
        "tank_radius": 0.5 * scen["container.diameter"],
        "tank_height": scen["container.soil_depth"] + 2.0,
        "drop_radius": R,
        "drop_start": [0.0, 0.0, surface + R + gap],
        "drop_velocity": [0.0, 0.0, -v0],
        "gravity": 9.81,
        "dt": dt,
        "t_end": float(rec.t[-1]),
        "out": str(work / "yade_hist"),
    }
    # impactor density so that the Yade sphere has the drop mass
    cfg["materials"][cfg["impactor_material"]]["density"] = rec.mass / (4 / 3 * math.pi * R**3)
    cfg_path = work / "yade_config.json"
    cfg_path.write_text(json.dumps(cfg))
    proc = subprocess.run(["yade", "-n", "-j1", "-x", str(SCRIPT), str(cfg_path)],
                          capture_output=True, text=True, cwd=str(work), timeout=timeout)
    out = Path(cfg["out"] + ".npy")
    if not out.exists():
        raise RuntimeError(f"yade failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    h = np.load(out)
    fs = scen["instrumentation.sample_rate"]
    cfc = scen["instrumentation.cfc"]
    t = np.arange(0.0, h[-1, 0], 1.0 / fs)
    force = np.interp(t, h[:, 0], h[:, 3])
    vz = np.interp(t, h[:, 0], h[:, 2])
    z = np.interp(t, h[:, 0], h[:, 1])
    yrec = sg.DropRecord(
        t=t, decel=cfc_filter(force, fs, cfc) / rec.mass, v_z=cfc_filter(vz, fs, cfc),
        penetration=surface - (z - R), force=cfc_filter(force, fs, cfc),
        floor_force=np.zeros_like(t), t_contact=rec.t_contact, mass=rec.mass,
        impact_velocity=v, raw={"force": force, "v_z": vz, "decel": force / rec.mass})
    res = sg.impact_metrics(yrec)
    res["_record"] = yrec
    return res
