"""Concealed-effect drop-test recordings made by another DEM code (Yade 2023.02a).

The diagnosis (issue 7) will be judged on recordings made by a DEM code other than crashdem's.
This module makes such recordings with Debian's Yade: its own deposition (``makeCloud`` +
damped settling), its own contact laws (``Law2_ScGeom_FrictPhys_CundallStrack``;
``Law2_ScGeom6D_CohFrictPhys_CohesionMoment`` for cohesion), its own integrator and time step
(``dt_factor x PWaveTimeStep``), and its own implementation of each effect:

=====================  ==================================================================
effect                 Yade truth (drawn from the seed)
=====================  ==================================================================
soil_layering          grains deeper than 0.25-0.40 m get 4-8 x the Young's modulus (no
                       extra compaction: crashdem's layering also compacts the lower layer)
boundary_proximity     a bed of 0.75-0.90 m instead of 2 m (the floor nearer)
cohesion               ``CohFrictMat`` bonded bed, normal = shear cohesion 1-3e5 Pa
particle_rotation      free grain rotations, no rolling resistance (crashdem: blocked)
contact_damping        ``FrictViscoMat`` grains: a normal dashpot of restitution 0.1-0.3 on
                       every grain contact (``Law2_ScGeom_FrictViscoPhys_CundallStrackVisco``,
                       whose dashpot may pull; crashdem's contact force never does); with
                       the Hertz-Mindlin law, ``MindlinPhys``'s dashpots of that restitution
                       in the normal and the shear direction (``en`` = ``es``), as EDEM's
                       and LIGGGHTS's Hertz-Mindlin laws damp (see ``yade_truth.py``)
initial_conditions     impact speed offset +-2.5-4 m/s
sensor_dynamics        the acceleration seen through ``MountDynamics`` 40-90 Hz, zeta
                       0.05-0.15, model "lowpass" or "mount"
=====================  ==================================================================

Numerics unlike the baseline (crashdem, 0.10 m grains, packing seed 1, safety 0.3): Yade's
deposition with seed ``2000 + seed``, mean radius 0.10 x (1 +- 0.10-0.15) (``TRUTH_RADIUS``),
``dt_factor`` 0.2-0.4. The drop-mass history is acquired like a lab channel
(``generator.acquire_samples``: integrating 12.5 kHz acquisition, 0.5 g / 0.05 m/s noise, 80 ms
pre-trigger, +-2 ms trigger offset, CFC 60). The baseline is crashdem's small-resolution drop
(``generator_dem.dem_baseline``).

Runs are cached in ``<cache>/diagnosis_yade`` keyed by the configuration and this module's and
the Yade script's sources.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from crashdem.diagnosis.generator import TRIGGER_JITTER, acquire_samples
from crashdem.diagnosis import generator_dem
from crashdem.diagnosis.generator_dem import BASE_OVERRIDES, cache_dir, dem_baseline
from crashdem.signal import Signal
from soil.packing import _build_lock

SCRIPT = Path(__file__).resolve().parent / "yade_truth.py"
HISTORY = Path(__file__).resolve().parents[1] / "yade_history.py"

#: effect -> drawn parameters (low, high, scale); the parameter names are this module's
YADE_EFFECT_DRAWS: dict[str, dict[str, tuple[float, float, str]]] = {
    "soil_layering": {"layer_depth": (0.25, 0.40, "lin"), "layer_young_factor": (4.0, 8.0, "log")},
    "boundary_proximity": {"bed_depth": (0.75, 0.90, "lin")},
    "cohesion": {"cohesion": (1.0e5, 3.0e5, "log")},
    "particle_rotation": {},
    "contact_damping": {"restitution": (0.1, 0.3, "lin")},
    "initial_conditions": {"speed_offset": (2.5, 4.0, "lin")},
    "sensor_dynamics": {"natural_frequency": (40.0, 90.0, "log"),
                        "damping_ratio": (0.05, 0.15, "lin")},
}
#: drawn parameter -> (exclusive low, high, unit) a pinned value (``yade_case(fixed=...)``) may
#: take: the bed stays under the 2 m tank's soil, the layer inside the bed, the speed offset
#: leaves a positive impact speed, the mount within the 12.5 kHz acquisition
FIXED_LIMITS: dict[str, tuple[float, float, str]] = {
    "layer_depth": (0.0, 1.5, "m"), "layer_young_factor": (0.0, 100.0, "1"),
    "bed_depth": (0.3, 2.0, "m"), "cohesion": (0.0, 1.0e8, "Pa"),
    "speed_offset": (-10.0, 10.0, "m/s"), "natural_frequency": (1.0, 2000.0, "Hz"),
    "damping_ratio": (0.0, 2.0, "1"), "restitution": (0.0, 1.0, "1"),
}
#: drawn parameter -> ROM parameter with the same meaning (compared by the validation); the
#: two depths are compared as the Yade bed realises them (``realised_depths``), not as drawn
COMPARED = {"layer_depth": "interface_depth", "bed_depth": "floor_depth",
            "speed_offset": "speed_offset", "natural_frequency": "mount_frequency",
            "restitution": "restitution"}
RADIUS_CHANGE = (0.10, 0.15)
#: mean grain radius [m] about which a case draws its own (``RADIUS_CHANGE``): 0.10 m, the
#: small bed's; ``use_truth_radius`` (``diagnose_yade.py --truth-radius``) sets another, e.g.
#: the campaign scenario's 0.075 m for recordings on a finer bed than the coarse search tier's
TRUTH_RADIUS = 0.10
#: the radii ``use_truth_radius`` accepts [m]: at least 0.03 m (about 80,000 grains in the 2 m
#: tank), at most 0.2 m (four grains across the 0.45 m sphere's radius)
TRUTH_RADIUS_LIMITS = (0.03, 0.2)
DT_FACTOR = (0.2, 0.4)
#: the contact laws a Yade truth is made with: Yade's linear Cundall-Strack law (the thesis's and
#: crashdem's) or its Hertz-Mindlin law (``Law2_ScGeom_MindlinPhys_Mindlin``, the default of
#: most other DEM codes: LIGGGHTS, EDEM, MercuryDPM, Chrono's DEM)
CONTACT_LAWS = ("linear", "hertz_mindlin")
#: Poisson's ratio of the Hertz-Mindlin grains [-] (a quarry gravel's; the linear law's
#: ``stiffness_ratio`` is ks/kn, not a Poisson's ratio)
HERTZ_POISSON = 0.25
#: Young's modulus of the Hertz-Mindlin grains over the linear law's [-], calibrated the way a
#: user of such a code would: on the drop test's penetration. Yade null 21 at 13.7 m (its bed
#: of 0.111 m grains) penetrates 0.609 m with the linear law and 0.728 / 0.659 / 0.601 / 0.524 /
#: 0.477 / 0.429 m with the Hertz law at 2 / 3 / 4 / 6 / 9 / 14 x its modulus (peak force
#: 500 kN linear, 462-808 kN Hertz). At 4 x the penetration matches within 1.5 % and the pulse
#: still differs: its peak is 25 % higher and 3 ms earlier, and the sphere is still sinking at
#: 0.2 m/s at 150 ms, where the linear law's has stopped (docs/diagnosis.md, "Another contact
#: law")
HERTZ_YOUNG_FACTOR = 4.0
#: the contact law of every later case that does not name one (``use_contact_law``)
CONTACT_LAW = "linear"
#: effects Yade makes with a law of their own (cohesion: ``CohFrictMat``'s linear springs and
#: bonds), so not with another contact law. Contact damping is made with either law: the linear
#: law's ``FrictViscoMat`` dashpot, or the Hertz-Mindlin law's own restitution dashpots
OWN_LAW_EFFECTS = ("cohesion",)


def bed_surface(x: np.ndarray, radius: np.ndarray, tank_radius: float) -> float:
    """Height [m] of a deposited bed's free surface above its floor (z = 0) in a cylindrical
    tank of ``tank_radius``: ``crashdem.beds.footprint_surface``, the definition an imported
    bed's layer depth counts from (the tank's cross-section, 3 mean radii clear of its wall).

    This is the soil thickness a floor depth means whatever code made the bed. crashdem cuts a
    deposited layer where the grain *centres* pass its top, and this level then lies within
    0.035 m of the nominal top (measured on 105 of crashdem's 0.6-1.25 m beds of 0.07-0.11 m
    grains: -0.034 to +0.024 m, mean -0.005 m), so crashdem's ``floor_depth`` is a thickness of
    this kind. The Yade truth removes the grains whose *top* passes the drawn bed depth, so its
    surface lies about a grain radius lower than drawn (measured: beds drawn at 0.764 / 0.825 /
    2.0 m with 0.114 / 0.088 m grains have their surface at 0.637 / 0.732 / 1.909-1.912 m).
    ``ValueError`` with fewer than ``crashdem.beds.SURFACE_MIN_GRAINS`` grains in the
    footprint."""
    from crashdem.beds import SURFACE_MIN_GRAINS, footprint_surface

    z, n = footprint_surface(x, radius, radius=tank_radius)
    if z is None:
        raise ValueError(f"bed_surface: {n} grains in the central footprint of a tank of radius "
                         f"{tank_radius:g} m; need at least {SURFACE_MIN_GRAINS}")
    return z


def realised_depths(drawn: Mapping[str, Any], packing_npz: str | Path,
                    surface_top: float, tank_radius: float) -> dict[str, float]:
    """The drawn floor and interface depths of a Yade case as its bed realises them, in the
    ROM's names: ``floor_depth`` the bed's surface height (``bed_surface``; the floor wall is at
    z = 0), ``interface_depth`` that surface's height above the level below which the grains
    are stiffer (the Yade script's ``surface - layer_depth``, ``surface`` = ``surface_top``, the
    highest grain top)."""
    if "bed_depth" not in drawn and "layer_depth" not in drawn:
        return {}
    z = np.load(packing_npz)
    surface = bed_surface(z["x"], z["radius"], tank_radius)
    out: dict[str, float] = {}
    if "bed_depth" in drawn:
        out["floor_depth"] = surface
    if "layer_depth" in drawn:
        out["interface_depth"] = surface - (float(surface_top) - float(drawn["layer_depth"]))
    return out


def drawn_values(drawn: Mapping[str, Any]) -> dict[str, float]:
    """The comparable truth of a case's draws in the ROM's names (``COMPARED``), as drawn."""
    return {COMPARED[k]: float(v) for k, v in drawn.items() if k in COMPARED}


def write_yade_bed(meta: Mapping[str, Any], path: str | Path) -> tuple[Path, int, int]:
    """A Yade case's bed (``YadeCase.meta``: ``packing_npz``, ``tank_radius``) written as
    ``soil.packing_file`` reads it (``.npz`` with ``x``, ``radius``; floor at z = 0, tank on
    the z axis), without the grains that escaped Yade's 64-facet tank further than the import
    accepts (``crashdem.beds.inside_cylinder``: 7 of 449 on null 21). Returns the file and the
    grain counts before and after."""
    from crashdem.beds import inside_cylinder

    bed = np.load(meta["packing_npz"])
    x, r = bed["x"], bed["radius"]
    keep = inside_cylinder(x, r, float(meta["tank_radius"]))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, x=x[keep], radius=r[keep])
    return path, int(len(r)), int(keep.sum())


def yade_available() -> bool:
    """True when the ``yade`` executable is on the PATH."""
    return shutil.which("yade") is not None


@dataclass(frozen=True)
class YadeCase:
    """A Yade-made recording and its hidden truth (``generator.ConcealedCase`` interface).

    ``values``: the comparable truth in the ROM's names, the floor and interface depths as the
    bed realises them (``realised_depths``; ``drawn`` keeps the drawn ones)."""

    effect: str | None
    values: dict[str, float]
    seed: int
    recording: dict[str, Signal]
    drawn: dict[str, Any]
    baseline: dict[str, Signal] = field(repr=False, default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    recalibration: dict[str, float] = field(default_factory=dict)


def _draw(lo: float, hi: float, scale: str, rng: np.random.Generator) -> float:
    u = rng.uniform()
    return math.exp(math.log(lo) + u * math.log(hi / lo)) if scale == "log" else lo + u * (hi - lo)


def _scenario():
    from crashdem import scenario as sc

    return sc.load(generator_dem.SCENARIO, dict(BASE_OVERRIDES))


def _fingerprint() -> str:
    """Version of the Yade runs: the Yade script and its shared history recorder (every input
    of a run is in its ``cfg``, which is part of the cache key; the acquisition in this module
    does not change a run)."""
    return hashlib.sha256(SCRIPT.read_bytes() + HISTORY.read_bytes()).hexdigest()[:12]


def _remove_leftovers(store: Path, key: str, packing_npz: Path) -> list[Path]:
    """Remove the temporary files a killed run of ``key`` (history ``<key>.tmp-<pid>.npy`` /
    ``.json``) or of its bed (``<bed>.npz.tmp-<pid>.npz``) left behind; call with the bed's lock
    held. Returns what was removed."""
    gone = [*store.glob(f"{key}.tmp-*"), *packing_npz.parent.glob(f"{packing_npz.name}.tmp-*")]
    for f in gone:
        f.unlink(missing_ok=True)
    return gone


def run_yade(cfg: dict[str, Any], cache: Path, packing_npz: str | Path | None = None
             ) -> tuple[np.ndarray, dict[str, Any]]:
    """Run (or load) one Yade impact; returns the history (t, z, vz, Fz) and the run facts.
    ``packing_npz``: impact on this bed (an earlier run's ``info["packing_npz"]``) instead of
    the one deposited for ``cfg`` (e.g. the same grains in another tank)."""
    store = cache / "diagnosis_yade"
    store.mkdir(parents=True, exist_ok=True)
    if packing_npz is None:
        pk_key = hashlib.sha256(json.dumps({k: cfg[k] for k in (
            "seed", "radius", "radius_spread", "bed_depth", "tank_radius", "young", "density",
            "friction_angle", "stiffness_ratio", "deposit_unbalanced")}, sort_keys=True).encode()
            + _fingerprint().encode()).hexdigest()[:16]
        packing_npz = store / f"packing-{pk_key}.npz"
    elif not Path(packing_npz).is_file():
        raise FileNotFoundError(f"run_yade: packing_npz={str(packing_npz)!r} does not exist")
    cfg = dict(cfg, packing_npz=str(packing_npz))
    key = hashlib.sha256((json.dumps(cfg, sort_keys=True) + _fingerprint()).encode()).hexdigest()[:20]
    out = store / key
    if not Path(str(out) + ".npy").exists():
        if not yade_available():
            raise RuntimeError("yade is not installed (Debian: apt-get install yade)")
        # one process at a time deposits a bed and runs on it (two processes asking for the
        # same run, or for runs on one bed that is not deposited yet, read a half-written file
        # otherwise); the history is written under a temporary name and renamed when complete,
        # so a killed run leaves no entry that looks finished
        with _build_lock(Path(packing_npz)):
            if not Path(str(out) + ".npy").exists():
                # under the bed's lock no other process writes this key or this bed: any
                # temporary file of them is a killed run's leftover
                _remove_leftovers(store, key, Path(packing_npz))
                tmp = store / f"{key}.tmp-{os.getpid()}"
                cfg["out"] = str(tmp)
                cfg_path = store / f"{key}.cfg.json"
                cfg_path.write_text(json.dumps(cfg))
                proc = subprocess.run(["yade", "-n", "-j1", "-x", str(SCRIPT), str(cfg_path)],
                                      capture_output=True, text=True, cwd=str(store),
                                      timeout=3600)
                if not (Path(str(tmp) + ".npy").exists() and Path(str(tmp) + ".json").exists()):
                    _remove_leftovers(store, key, Path(packing_npz))
                    raise RuntimeError(f"yade failed:\n{proc.stdout[-3000:]}\n"
                                       f"{proc.stderr[-3000:]}")
                os.replace(str(tmp) + ".json", str(out) + ".json")
                os.replace(str(tmp) + ".npy", str(out) + ".npy")
    info = json.loads(Path(str(out) + ".json").read_text())
    info["packing_npz"] = cfg["packing_npz"]
    return np.load(str(out) + ".npy"), info


#: sample rate of the raw Yade output of ``yade_case(..., raw=True)`` [Hz]
RAW_SAMPLE_RATE = 20000.0


def check_fixed(effect: str | None, fixed: Mapping[str, float] | None) -> dict[str, float]:
    """``fixed`` (pinned draws of ``effect``, ``yade_case``) as floats; ValueError naming the
    parameter when ``effect`` does not draw it or the value is outside ``FIXED_LIMITS``."""
    allowed = YADE_EFFECT_DRAWS.get(effect, {}) if effect is not None else {}
    out: dict[str, float] = {}
    for k, v in (fixed or {}).items():
        if k not in allowed:
            raise ValueError(f"fixed[{k!r}]: not a drawn parameter of effect={effect!r}; "
                             f"allowed: {sorted(allowed)}")
        lim = FIXED_LIMITS[k]
        if not (math.isfinite(float(v)) and lim[0] < float(v) <= lim[1]):
            raise ValueError(f"fixed[{k!r}]={v!r}: must be in ({lim[0]:g}, {lim[1]:g}] "
                             f"[{lim[2]}]")
        out[k] = float(v)
    return out


def use_truth_radius(radius: float) -> None:
    """Draw every later case's grain radius about ``radius`` [m] instead of 0.10 m (the seed's
    draws are otherwise unchanged; the Yade run is keyed by its radius)."""
    global TRUTH_RADIUS
    lo, hi = TRUTH_RADIUS_LIMITS
    if not (math.isfinite(float(radius)) and lo <= float(radius) <= hi):
        raise ValueError(f"truth_radius={radius!r}: must be in [{lo:g}, {hi:g}] m")
    TRUTH_RADIUS = float(radius)


def check_contact_law(contact_law: str, effect: str | None = None) -> None:
    """ValueError naming ``contact_law`` unless it is one of ``CONTACT_LAWS`` and ``effect``
    can be made with it (``OWN_LAW_EFFECTS`` only with the linear law)."""
    if contact_law not in CONTACT_LAWS:
        raise ValueError(f"contact_law={contact_law!r}: allowed: {list(CONTACT_LAWS)}")
    if contact_law != "linear" and effect in OWN_LAW_EFFECTS:
        raise ValueError(f"contact_law={contact_law!r} with effect={effect!r}: Yade makes that "
                         f"effect with its own linear law; allowed effects: "
                         f"{sorted(set(YADE_EFFECT_DRAWS) - set(OWN_LAW_EFFECTS))} or None")


def use_contact_law(contact_law: str) -> None:
    """Make every later case that names no law with ``contact_law`` (``CONTACT_LAWS``)."""
    global CONTACT_LAW
    check_contact_law(contact_law)
    CONTACT_LAW = contact_law


def yade_case(seed: int, effect: str | None, *, cache: Path | None = None,
              cfc: float = 60.0, declare_cfc: bool = True, raw: bool = False,
              fixed: Mapping[str, float] | None = None,
              recalibration: Mapping[str, float] | None = None,
              contact_law: str | None = None) -> YadeCase:
    """A Yade recording with ``effect`` (a ``YADE_EFFECT_DRAWS`` name, or None for a null case)
    drawn from ``seed``, acquired like a lab channel; ``baseline`` is crashdem's DEM baseline.

    ``cfc``: the lab's filter class (the baseline's is 60: another class is the
    ``sensor_dynamics`` filter-class form); ``declare_cfc=False`` leaves it out of the channels
    (a CSV without a header). ``raw=True``: the recording is Yade's own output instead of a
    lab channel -- the drop mass's specific force and velocity from the start of the Yade run
    (the sphere 1 cm above the grains, so under 1 ms before contact), linearly resampled at
    ``RAW_SAMPLE_RATE``, no noise, no filter, no trigger offset (the sensor effect still
    applied).

    ``fixed`` pins drawn parameters of ``effect`` (names of ``YADE_EFFECT_DRAWS[effect]``) to
    given values, e.g. a stronger effect than the drawn span (``{"cohesion": 1e6}``); the seed
    still draws everything else as without it (the draws are made, then replaced).

    ``recalibration`` gives the Yade bed soil values other than the scenario's (the keys and
    limits of ``generator_dem.check_recalibration``: ``soil.material.young``,
    ``friction_angle_deg``, ``density``, ``stiffness_ratio``), e.g. a stiffer bed: a wrong
    value of a parameter the model has, which is a recalibration, not missing physics. The
    seed's draws are unchanged; the deposition uses them too (another bed).

    ``contact_law`` (``CONTACT_LAWS``; None: ``CONTACT_LAW``, set by ``use_contact_law``):
    ``"hertz_mindlin"`` makes the impact with Yade's
    Hertz-Mindlin law, its grains of ``HERTZ_YOUNG_FACTOR`` x the linear law's Young's modulus
    and ``HERTZ_POISSON``, on the bed the linear law's case of the
    same seed deposits; a null of it is a recording of the same physics by a code with another
    contact law. Its contact damping is the Hertz-Mindlin law's own dashpots (the drawn
    restitution in the normal and the shear direction, ``yade_truth.py``); not with cohesion
    (another law in Yade)."""
    contact_law = CONTACT_LAW if contact_law is None else contact_law
    check_contact_law(contact_law, effect)
    if effect is not None and effect not in YADE_EFFECT_DRAWS:
        raise ValueError(f"effect={effect!r}: no Yade truth for it; allowed: "
                         f"{sorted(YADE_EFFECT_DRAWS)} or None")
    fixed = check_fixed(effect, fixed)
    recal = generator_dem.check_recalibration(dict(recalibration or {}))
    cache = Path(cache or cache_dir())
    rng = np.random.default_rng(10_000 + seed)
    drawn: dict[str, Any] = {}
    if effect is not None:
        for k, (lo, hi, sc_) in YADE_EFFECT_DRAWS[effect].items():
            drawn[k] = _draw(lo, hi, sc_, rng)
        if effect == "initial_conditions" and rng.uniform() < 0.5:
            drawn["speed_offset"] *= -1.0
        drawn.update(fixed)
        if effect == "sensor_dynamics":
            drawn["model"] = "mount" if rng.uniform() < 0.5 else "lowpass"
        if effect == "particle_rotation":
            drawn["free_rotation"] = True
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    radius = round(TRUTH_RADIUS * (1.0 + sign * rng.uniform(*RADIUS_CHANGE)), 5)
    dt_factor = round(float(rng.uniform(*DT_FACTOR)), 4)
    offset = float(rng.uniform(-TRIGGER_JITTER, TRIGGER_JITTER))
    scen = _scenario()
    m = {**scen["soil.material"],
         **{k.rsplit(".", 1)[1]: v for k, v in recal.items()}}
    v_imp = scen.impact_velocity + float(drawn.get("speed_offset", 0.0))
    cfg: dict[str, Any] = {
        "seed": 2000 + int(seed), "radius": radius, "radius_spread": scen["soil.radius_spread"],
        "bed_depth": float(drawn.get("bed_depth", scen["container.soil_depth"])),
        "tank_radius": 0.5 * scen["container.diameter"],
        "tank_height": scen["container.soil_depth"] + 2.0,
        "young": m["young"], "density": m["density"],
        "friction_angle": math.radians(m["friction_angle_deg"]),
        "stiffness_ratio": m["stiffness_ratio"], "deposit_unbalanced": 0.02, "gravity": 9.81,
        "drop_radius": 0.45, "drop_mass": 850.0, "impactor_young": scen["impactor.material_young"],
        "gap": 0.01, "impact_speed": v_imp, "dt_factor": dt_factor,
        "t_end": scen["solver.t_end"] + 0.01,
        "cohesion": drawn.get("cohesion"), "layer_depth": drawn.get("layer_depth"),
        "layer_young_factor": drawn.get("layer_young_factor", 1.0),
        "free_rotation": bool(drawn.get("free_rotation", False)),
        "restitution": drawn.get("restitution"),
    }
    if contact_law != "linear":
        # only then: the linear law's runs keep their configurations (and cache keys)
        cfg.update(contact_law=contact_law, hertz_poisson=HERTZ_POISSON,
                   hertz_young=HERTZ_YOUNG_FACTOR * m["young"])
    hist, info = run_yade(cfg, cache)
    t, vz, fz = hist[:, 0], hist[:, 2], hist[:, 3]
    k_c = int(np.argmax(fz > 0.0))  # first step with a contact force
    t0 = t[max(k_c - 1, 0)]
    sel = slice(max(k_c - 1, 0), None)
    t_raw = t[sel] - t0
    acc = fz[sel] / info["mass"]
    if effect == "sensor_dynamics":
        from crashdem.sensors import MountDynamics

        acc = MountDynamics(drawn["natural_frequency"], drawn["damping_ratio"],
                            drawn["model"]).apply(Signal("a", t_raw, acc, "m/s^2")).data
    if raw:
        tu = np.arange(0.0, float(t[-1]) - float(t[0]), 1.0 / RAW_SAMPLE_RATE)
        a_full = np.interp(t, t[sel], acc, left=0.0)  # free fall before contact: 0
        rec = {"accel_z": Signal("accel_z", tu, np.interp(tu + t[0], t, a_full), "m/s^2", None,
                                 {"source": "Yade 2023.02a output (raw)"}),
               "velocity_z": Signal("velocity_z", tu, np.interp(tu + t[0], t, vz), "m/s", None,
                                    {"source": "Yade 2023.02a output (raw)"})}
        offset = 0.0
    else:
        rec = acquire_samples(t_raw, {"accel_z": (acc, "m/s^2"), "velocity_z": (vz[sel], "m/s")},
                              float(-vz[sel][0]), rng, trigger_offset=offset, cfc=cfc,
                              t_end=float(scen["solver.t_end"]),
                              source=f"Yade 2023.02a truth (seed {cfg['seed']}, radius "
                                     f"{radius:g} m, dt {info['dt']:.3g} s)")
        if not declare_cfc:
            rec = {k: Signal(v.name, v.t, v.data, v.unit, None, v.meta) for k, v in rec.items()}
    values = drawn_values(drawn)
    realised = realised_depths(drawn, info["packing_npz"], info["surface_z"], cfg["tank_radius"])
    values.update(realised)
    return YadeCase(effect, values, seed, rec, drawn, dem_baseline(cache),
                    {"grains": info["grains"], "dt": info["dt"], "radius": radius,
                     "dt_factor": dt_factor, "trigger_offset_s": offset, "raw": raw,
                     "realised": realised, "packing_npz": info["packing_npz"],
                     "tank_radius": cfg["tank_radius"], "cfg": dict(cfg),
                     "contact_law": contact_law},
                    recal)
