"""Concealed-effect recordings whose truth is the full DEM (crashdem's own soil engine).

The truth is the small-resolution sphere drop (``validation/scenarios/drop_s2_h13p70.toml``
with the campaign's ``small`` overrides: ~500-1,000 grains of 0.10 m mean radius in a 2 m tank)
run through ``crashdem.run.run_scenario`` with ONE ``physics.<effect>.*`` switch drawn from the
seed, and with numerics that differ from the baseline in three ways that are *not* the effect:

* another packing seed (``scenario.seed``: a different grain arrangement),
* a mean particle radius 10-15 % larger or smaller (sign and size drawn from the seed),
* another time step (``solver.safety`` 0.15-0.22 instead of 0.3 of the critical step).

The truth channels are sampled at 50 kHz by the run's sensors, then acquired like a lab channel
with :func:`crashdem.diagnosis.generator.acquire_samples`: integrating 12.5 kHz acquisition,
0.5 g / 0.05 m/s white noise, an 80 ms pre-trigger free-fall segment, a trigger offset of
+-2 ms and SAE J211 CFC 60. The baseline is the same scenario without the effect at the baseline
numerics (seed 1, radius 0.10 m, safety 0.3), its CFC 60 channels as the run writes them.

Both are cached on disk (``$CRASHDEM_CACHE/diagnosis_truth`` or
``~/.cache/crashdem/diagnosis_truth``) keyed by a hash of the scenario file, the overrides and
the sources of the simulation code (``soil``, ``bodies``, ``coupling``, ``crashdem/run.py``,
sensors, scenario, filters: a code change re-runs); packings are cached by ``soil.packing``
under ``.../packings``.

Which parameters are compared with the ROM's (``DemConcealedCase.values``)
--------------------------------------------------------------------------
Only quantities with the same physical meaning in the DEM scenario and in the ROM:
``soil_layering.depth`` -> ``interface_depth`` [m], ``boundary_proximity.floor_depth`` ->
``floor_depth`` [m], ``initial_conditions.velocity_offset`` -> ``speed_offset`` [m/s],
``sensor_dynamics.natural_frequency`` -> ``mount_frequency`` [Hz]. Not compared (drawn values
in ``DemConcealedCase.drawn``): the layering's ``lower_young_factor`` (a grain modulus ratio, the
ROM's ``strength_ratio`` is a bulk resistance ratio that also contains the lower layer's
compaction), the mount damping ratio (the run's sensor is a mass-spring low-pass
``wn^2/(s^2+2 zeta wn s+wn^2)``, the ROM's a base-excitation transmissibility; the two dampings
give the same resonance but differ in the transmitted high-frequency content), the contact
cohesion strengths [Pa on r^2] (the ROM's cohesion is a bulk Mohr-Coulomb c with a bearing
factor) and the contact restitution (the ROM's is a bulk soil-spring dashpot).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from crashdem.diagnosis.generator import TRIGGER_JITTER, acquire_samples
# the sources a cached run is keyed by, and the crashdem modules they import that do not shape a
# run (``crashdem.runcache``, which also keeps the finished result files)
from crashdem.runcache import CODE as _CODE, OUTPUT_ONLY as _OUTPUT_ONLY, _ROOT  # noqa: F401
from crashdem.runcache import source_digest as _code_fingerprint
from crashdem.signal import Signal

__all__ = ["DemConcealedCase", "DEM_EFFECT_DRAWS", "BASE_OVERRIDES", "BASELINE_NUMERICS", "impact_speed",
           "replicates", "use_scenario",
           "COMPARED", "dem_concealed_case", "dem_baseline", "run_dem", "scenario_path",
           "cache_dir", "dem_filter_class_case", "dem_baseline_raw", "FILTER_CLASS_DRAWS",
           "prefetch", "prefetch_cases", "diagnose_cases"]

#: the drop-test scenario of the truth and baseline
SCENARIO = Path(__file__).resolve().parents[2] / "validation" / "scenarios" / "drop_s2_h13p70.toml"


def use_scenario(path: str | Path) -> Path:
    """Make ``path`` (a ``drop_test`` scenario file, e.g. another drop height of the campaign)
    the scenario of the truth runs, the baseline and ``DemFullSimulator`` (and of the Yade
    cases, ``validation/diagnosis_yade``); returns the previous one. Runs are cached per
    scenario file (its bytes are part of the key)."""
    global SCENARIO
    new = Path(path).resolve()
    if not new.is_file():
        raise ValueError(f"scenario={str(path)!r}: no such file")
    old, SCENARIO = SCENARIO, new
    return old


#: small resolution (validation/campaign/studies.py RESOLUTIONS["small"] + COMMON); the layering
#: of the reference file is switched off: the baseline is a homogeneous bed
BASE_OVERRIDES: dict[str, Any] = {
    "soil.radius": 0.10, "soil.radius_spread": 0.10, "container.diameter": 2.0,
    "solver.t_end": 0.12, "output.snapshots": 0, "output.plots": False,
    "physics.soil_layering.enabled": False, "scenario.threads": 1,
}
#: numerics of the baseline simulation
BASELINE_NUMERICS: dict[str, Any] = {"scenario.seed": 1, "soil.radius": 0.10, "solver.safety": 0.3}
#: raw sampling of the truth run (the lab acquisition then integrates to 12.5 kHz)
TRUTH_SAMPLE_RATE = 50000.0
#: channels of the run -> diagnosis channel names
CHANNELS = {"drop_mass_accel_z": "accel_z", "drop_mass_velocity_z": "velocity_z"}

#: effect -> {scenario key under physics.<effect>: (low, high, "lin"|"log")}; magnitudes meant to
#: make the effect visible above the granular fluctuation of the small-resolution bed (a lab only
#: diagnoses visible mismatches), not tuned to the method. Measured (session 10): true for all
#: but cohesion -- a 1.2-1.3e5 Pa contact cohesion changes the truth's acceleration less than
#: another packing does (ISO/TS 18571 with and without it 0.96-0.97, between packings 0.73-0.81;
#: the diagnosis's own detectability limit, ``fit.detectability``, is 4.8e5 Pa). The range is kept
#: at moist-soil strengths rather than raised until it shows: at 0.8-2.4e6 Pa the bonded bed
#: stops and throws back the sphere like a floor 0.7 m down, and all 4 such recordings were
#: named wrongly (3 as a floor, 1 as layering; docs/diagnosis.md, "Detectability")
DEM_EFFECT_DRAWS: dict[str, dict[str, tuple[float, float, str]]] = {
    "soil_layering": {"depth": (0.25, 0.40, "lin"), "lower_young_factor": (4.0, 8.0, "log")},
    "boundary_proximity": {"floor_depth": (0.75, 0.90, "lin")},
    "initial_conditions": {"velocity_offset": (2.5, 4.0, "lin")},  # sign drawn separately
    "sensor_dynamics": {"natural_frequency": (40.0, 90.0, "log"),
                        "damping_ratio": (0.05, 0.15, "lin")},
    "cohesion": {"normal_strength": (1.0e5, 3.0e5, "log")},  # shear_strength = normal_strength
    "contact_damping": {"restitution": (0.1, 0.3, "lin")},
}
#: scenario key (under physics.<effect>) -> ROM parameter with the same physical meaning
COMPARED: dict[str, dict[str, str]] = {
    "soil_layering": {"depth": "interface_depth"},
    "boundary_proximity": {"floor_depth": "floor_depth"},
    "initial_conditions": {"velocity_offset": "speed_offset"},
    "sensor_dynamics": {"natural_frequency": "mount_frequency"},
    "cohesion": {},
    "contact_damping": {},
}
#: truth numerics: radius factor |f - 1| in this range (sign drawn), solver safety range
RADIUS_CHANGE = (0.10, 0.15)
SAFETY_RANGE = (0.15, 0.22)


@dataclass(frozen=True)
class DemConcealedCase:
    """A DEM-truth recording and its hidden truth (same interface as ``generator.ConcealedCase``).

    effect : the concealed catalogue effect (None for a null case)
    values : the effect's true parameters that are comparable with the ROM's (ROM names)
    recalibration : the truth's soil values that differ from the baseline's (scenario keys
        under ``soil.material``; ``dem_concealed_case(..., recalibration=...)``, else empty):
        a wrong value of a parameter the model has, which the issue reports as a
        recalibration, not as missing physics
    recording : the acquired channels (``accel_z``, ``velocity_z``)
    truth : the truth's scenario overrides (effect + numerics)
    drawn : every drawn scenario value of the effect (``physics.<effect>.<key>``)
    baseline : the baseline simulation channels (CFC 60, as the run writes them)
    """

    effect: str | None
    values: dict[str, float]
    recalibration: dict[str, float]
    seed: int
    recording: dict[str, Signal]
    truth: dict[str, Any]
    trigger_offset_s: float = 0.0
    meta: dict[str, Any] = field(default_factory=dict)
    drawn: dict[str, float] = field(default_factory=dict)
    baseline: dict[str, Signal] = field(default_factory=dict, repr=False)


def scenario_path() -> Path:
    """The drop-test scenario file used by the truth and the baseline."""
    return SCENARIO


def cache_dir() -> Path:
    """Disk cache root (``$CRASHDEM_CACHE`` or ``~/.cache/crashdem``)."""
    return Path(os.environ.get("CRASHDEM_CACHE", Path.home() / ".cache" / "crashdem"))


def packings_dir(cache: Path | None = None) -> Path:
    """The deposited beds of the runs made here: ``<cache root>/packings/<soil engine
    fingerprint>`` (``crashdem.run.packing_cache``), so a bed another version of the soil
    engine deposited in the same root (a cache kept across upgrades) is never offered to this
    one."""
    from crashdem.run import packing_cache

    return packing_cache(Path(cache or cache_dir()) / "packings")


def _draw(lo: float, hi: float, scale: str, rng: np.random.Generator) -> float:
    u = rng.uniform()
    return math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo))) if scale == "log" \
        else lo + u * (hi - lo)


def draw_dem_effect(effect: str, rng: np.random.Generator) -> dict[str, Any]:
    """Scenario overrides switching ``effect`` on with parameters drawn from ``rng``."""
    if effect not in DEM_EFFECT_DRAWS:
        raise ValueError(f"effect={effect!r}: no DEM truth for it; allowed: "
                         f"{sorted(DEM_EFFECT_DRAWS)}")
    out: dict[str, Any] = {f"physics.{effect}.enabled": True}
    for key, (lo, hi, scale) in DEM_EFFECT_DRAWS[effect].items():
        out[f"physics.{effect}.{key}"] = _draw(lo, hi, scale, rng)
    if effect == "initial_conditions" and rng.uniform() < 0.5:
        out["physics.initial_conditions.velocity_offset"] *= -1.0
    if effect == "cohesion":
        out["physics.cohesion.shear_strength"] = out["physics.cohesion.normal_strength"]
    if effect == "sensor_dynamics":  # which of the two standard sensor models (sensors.MOUNT_MODELS)
        out["physics.sensor_dynamics.model"] = "mount" if rng.uniform() < 0.5 else "lowpass"
    return out


def _key(overrides: dict[str, Any]) -> str:
    """Cache key: scenario file, overrides and the sources of the simulation code."""
    h = hashlib.sha256()
    h.update(SCENARIO.read_bytes())
    h.update(json.dumps(overrides, sort_keys=True, default=str).encode())
    h.update(_code_fingerprint())
    h.update(b"v1")
    return h.hexdigest()[:20]


def _cache_file(overrides: dict[str, Any], filtered: bool, cache: Path | None) -> Path:
    """The cache entry of ``run_dem(overrides, filtered=filtered, cache=cache)``."""
    key = _key({**BASE_OVERRIDES, **overrides, "_filtered": filtered})
    return (cache or cache_dir()) / "diagnosis_truth" / f"{key}.npz"


def _resolved(cache: Path | None) -> Path:
    """The cache root as an absolute path, for a worker whose environment and working directory
    are those of when it was started (``$CRASHDEM_CACHE`` may have changed since)."""
    return Path(cache or cache_dir()).expanduser().resolve()


def _prefetch_one(job: tuple[str, str, Any]) -> None:
    """Worker side of ``prefetch``: ``("run", scenario, (overrides, filtered, cache))`` runs
    ``run_dem``, ``("case", scenario, (seed, effect, cache))`` ``dem_concealed_case`` (the truth
    run; the baseline is in the cache already), each on the parent's scenario file."""
    kind, scenario, args = job
    if Path(scenario).resolve() != SCENARIO:
        use_scenario(scenario)
    if kind == "run":
        overrides, filtered, cache = args
        run_dem(overrides, filtered=filtered, cache=cache)
    else:
        seed, effect, cache = args
        dem_concealed_case(seed, effect, cache=cache)


def _fan_out(jobs: list[tuple[str, str, Any]], workers: int | None) -> int:
    """Run ``jobs`` on worker processes (``parallel.map_processes``; nothing when only one
    would run: the caller then runs them itself); a job that raises is left to the caller,
    who runs it again in its own process and so reports it as the serial path would. Returns
    the jobs dispatched."""
    from crashdem.diagnosis.parallel import check_workers, map_processes

    if min(check_workers(workers), len(jobs)) < 2:
        return 0
    map_processes(_prefetch_one, jobs, workers, return_exceptions=True)
    return len(jobs)


def prefetch(requests: list[tuple[dict[str, Any], bool]], *, cache: Path | None = None,
             workers: int | None = None) -> int:
    """Put the runs ``run_dem(overrides, filtered=filtered)`` of ``requests`` (pairs
    ``(overrides, filtered)``) in the disk cache, the missing ones in parallel on ``workers``
    processes (default ``parallel.default_workers()``: the cores, or
    ``$CRASHDEM_DEM_WORKERS``); the caller then loads them. Every run is the same
    deterministic single-threaded run wherever it executes, so the results do not depend on
    ``workers``. Returns the number of runs dispatched to the workers (0: none missing, one
    worker, or one run -- left to the caller)."""
    root = _resolved(cache)
    seen: set[Path] = set()
    jobs = []
    for ov, filtered in requests:
        f = _cache_file(ov, filtered, root)
        if f in seen or f.exists():
            continue
        seen.add(f)
        jobs.append(("run", str(SCENARIO), (dict(ov), bool(filtered), root)))
    return _fan_out(jobs, workers)


def prefetch_cases(cases: list[tuple[int, str | None]], *, cache: Path | None = None,
                   workers: int | None = None) -> int:
    """Run the truths of the DEM-truth cases ``(seed, effect)`` (``dem_concealed_case``) in
    parallel on ``workers`` processes so that generating them afterwards loads them from the
    cache (those whose truth is cached already are left out); the baseline is run first, here.
    Returns the cases dispatched."""
    dem_baseline(cache)
    root = _resolved(cache)
    jobs = [("case", str(SCENARIO), (int(seed), effect, root)) for seed, effect in cases
            if not _cache_file(_truth_draws(int(seed), effect, {})[2], False, root).exists()]
    return _fan_out(jobs, workers)


def _diagnose_dem_case(seed: int, effect: str | None, root: Path, top_k: int,
                       workers: int | None) -> tuple:
    """``(case, report, generation s, diagnosis s)`` of one DEM-truth case, its confirmation
    batches run on ``workers`` processes (``DemFullSimulator``)."""
    import time

    from crashdem.diagnosis import screen_then_confirm

    t0 = time.perf_counter()
    case = dem_concealed_case(seed, effect, cache=root)
    t1 = time.perf_counter()
    rep = screen_then_confirm(case.baseline, case.recording, DemFullSimulator(root, workers),
                              top_k=top_k, impact_speed=impact_speed(), replicates=replicates())
    return case, rep, t1 - t0, time.perf_counter() - t1


def _diagnosed_dem_case(job: tuple[int, str | None, str, Path, int]) -> tuple:
    """Worker side of ``diagnose_cases``: one case, its runs made in this process (one
    worker: no pool inside a pool)."""
    seed, effect, scenario, root, top_k = job
    if Path(scenario).resolve() != SCENARIO:
        use_scenario(scenario)
    return _diagnose_dem_case(seed, effect, root, top_k, 1)


def diagnose_cases(cases: list[tuple[int, str | None]], *, top_k: int = 2,
                   cache: Path | None = None, workers: int | None = None) -> list[tuple]:
    """``(case, report, generation s, diagnosis s)`` of each DEM-truth case ``(seed, effect)``
    of ``cases``, in order: ``dem_concealed_case`` diagnosed by ``screen_then_confirm`` with the
    full-DEM confirmation (``DemFullSimulator``), the replicate packings (``replicates()``) and
    the full-model search, as the library path does.

    The truths run first, one per worker (``prefetch_cases``). The first case is diagnosed
    here, its batches of runs on the workers (``DemFullSimulator.map``): it makes the runs
    every case shares (the baseline's replicates, the search levels on their beds). The others
    are then diagnosed one per worker, each making only its own runs (confirmations,
    refinements, the numerics check) and reading the shared ones from the cache. Every run is
    the same deterministic single-threaded run wherever it executes, so the reports do not
    depend on ``workers`` (but for their wall times)."""
    from crashdem.diagnosis.parallel import check_workers, map_processes

    cases = [(int(seed), effect) for seed, effect in cases]
    if not cases:
        return []
    prefetch_cases(cases, cache=cache, workers=workers)
    root = _resolved(cache)
    out = [_diagnose_dem_case(*cases[0], root, top_k, workers)]
    jobs = [(seed, effect, str(SCENARIO), root, top_k) for seed, effect in cases[1:]]
    if min(check_workers(workers), len(jobs)) < 2:
        return out + [_diagnosed_dem_case(j) for j in jobs]
    return out + map_processes(_diagnosed_dem_case, jobs, workers)


def run_dem(overrides: dict[str, Any], *, filtered: bool, cache: Path | None = None
            ) -> tuple[dict[str, Signal], dict[str, Any]]:
    """Run (or load from the disk cache) the drop scenario with ``overrides`` on top of
    ``BASE_OVERRIDES``; returns the ``accel_z`` / ``velocity_z`` channels (raw or CFC-filtered as
    written by the run) on a time axis with t = 0 at first contact, and the run facts."""
    from crashdem import scenario as sc

    ov = {**BASE_OVERRIDES, **overrides}
    root = (cache or cache_dir())
    f = _cache_file(overrides, filtered, cache)
    key, store = f.stem, f.parent
    store.mkdir(parents=True, exist_ok=True)
    if f.exists():
        try:
            z = np.load(f, allow_pickle=False)
            info = json.loads(str(z["info"]))
            sigs = {name: Signal(name, z["t"], z[name], z[f"{name}__unit"].item(),
                                 info.get("cfc") if filtered else None,
                                 {"source": "crashdem DEM (cached)", "cache": str(f)})
                    for name in CHANNELS.values()}
            return sigs, info
        except (OSError, KeyError, ValueError):
            pass
    from crashdem.results import open_result
    from crashdem.run import share_packings

    # one run directory per process: two processes asking for the same run on a cold cache
    # would otherwise collide on its HDF5 file (measured: an HDF5 lock error stopped one of two
    # validation processes); the cache entry below is written atomically
    runs = store / "runs" / f"pid{os.getpid()}"
    runs.mkdir(parents=True, exist_ok=True)
    share_packings(runs, packings_dir(root))
    ov["scenario.name"] = f"diag_{key}"
    scen = sc.load(SCENARIO, ov)
    # the result file goes to the run cache (``crashdem.runcache``): the raw and the filtered
    # request of one run, and a ``crashdem diagnose`` of the same scenario, read it there
    from crashdem.runcache import RunCache

    path = RunCache(root / "runs").run(scen, runs, keep=False)
    import h5py

    with h5py.File(path, "r") as h:
        info = {k: (v.item() if hasattr(v, "item") else v) for k, v in h["run"].attrs.items()}
    info = {k: (v if isinstance(v, (int, float, str)) else str(v)) for k, v in info.items()}
    info["cfc"] = float(scen["instrumentation.cfc"])
    sigs = {}
    with open_result(path) as res:
        for name, short in CHANNELS.items():
            s = res.channel(name, filtered=filtered)
            sigs[short] = Signal(short, np.asarray(s.t) - info["t_contact"], np.asarray(s.data),
                                 s.unit, info["cfc"] if filtered else None,
                                 {"source": f"crashdem DEM {path.name}"})
    t = sigs["accel_z"].t
    tmp = store / f"{key}.pid{os.getpid()}.tmp.npz"
    np.savez(tmp, t=t, info=json.dumps(info),
             **{n: s.data for n, s in sigs.items()},
             **{f"{n}__unit": np.array(s.unit) for n, s in sigs.items()})
    os.replace(tmp, f)
    return sigs, info


def replicates() -> list[dict[str, Any]]:
    """Overrides of the baseline's replicate realisations, as ``crashdem diagnose`` makes them
    (``cli.DEFAULT_REPLICATES`` packing seeds after the baseline's
    ``BASELINE_NUMERICS["scenario.seed"]``: 2-5): the realisation floor of
    ``screen_then_confirm``."""
    from crashdem.diagnosis import replicate_overrides
    from crashdem.diagnosis.cli import DEFAULT_REPLICATES

    return replicate_overrides(BASELINE_NUMERICS["scenario.seed"], DEFAULT_REPLICATES)


def impact_speed() -> float:
    """Impact speed of the baseline scenario [m/s] (what the diagnosed simulation assumed)."""
    from crashdem import scenario as sc

    return float(sc.load(SCENARIO, dict(BASE_OVERRIDES)).impact_velocity)


def dem_baseline(cache: Path | None = None) -> dict[str, Signal]:
    """The baseline simulation (homogeneous bed, baseline numerics), CFC 60 channels."""
    sigs, _ = run_dem(dict(BASELINE_NUMERICS), filtered=True, cache=cache)
    return sigs


def truth_numerics(rng: np.random.Generator, seed: int) -> dict[str, Any]:
    """Numerics of a truth run that differ from ``BASELINE_NUMERICS``."""
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    f = 1.0 + sign * rng.uniform(*RADIUS_CHANGE)
    return {"scenario.seed": 1000 + int(seed), "soil.radius": round(0.10 * f, 5),
            "solver.safety": round(float(rng.uniform(*SAFETY_RANGE)), 4),
            "instrumentation.sample_rate": TRUTH_SAMPLE_RATE}


#: soil values a recalibration truth may change (``dem_concealed_case(recalibration=...)``):
#: the scenario's own material parameters, each by a factor in this range
RECALIBRATION_KEYS = ("soil.material.young", "soil.material.friction_angle_deg",
                      "soil.material.density", "soil.material.stiffness_ratio")
RECALIBRATION_FACTOR = (0.25, 4.0)


def check_recalibration(recalibration: dict[str, float] | None) -> dict[str, float]:
    """``recalibration`` as floats; ValueError naming the key when it is not one of
    ``RECALIBRATION_KEYS`` or its value is not within ``RECALIBRATION_FACTOR`` x the
    scenario's, and the scenario's own error when the value is outside the field's range
    (e.g. a friction angle of 90 deg or more)."""
    from crashdem import scenario as sc

    out: dict[str, float] = {}
    if not recalibration:
        return out
    base = sc.load(SCENARIO, dict(BASE_OVERRIDES))
    lo, hi = RECALIBRATION_FACTOR
    for k, v in recalibration.items():
        if k not in RECALIBRATION_KEYS:
            raise ValueError(f"recalibration[{k!r}]: not a soil value the truth may change; "
                             f"allowed: {list(RECALIBRATION_KEYS)}")
        ref = float(base.get(k))
        if not (math.isfinite(float(v)) and lo * ref <= float(v) <= hi * ref):
            raise ValueError(f"recalibration[{k!r}]={v!r}: must be in [{lo * ref:g}, "
                             f"{hi * ref:g}] ({lo:g}-{hi:g} x the scenario's {ref:g})")
        out[k] = float(v)
    base.with_overrides(out)  # the scenario's own ranges
    return out


def number_assignments(items, example: str) -> dict[str, float]:
    """Command-line ``KEY=VALUE`` strings with a number as ``{key: float}`` (a later key
    replaces an earlier one); ValueError naming the item and ``example`` otherwise. Used by the
    validation scripts' ``--fix`` and ``--recalibrate``."""
    out: dict[str, float] = {}
    for item in items:
        key, sep, value = item.partition("=")
        try:
            out[key] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise ValueError(f"{item!r}: must be KEY=VALUE with a number, e.g. {example}")
    return out


def parse_recalibration(items) -> dict[str, float]:
    """``--recalibrate KEY=VALUE ...`` of the validation scripts: ``number_assignments``, then
    ``check_recalibration``."""
    return check_recalibration(number_assignments(items, "soil.material.young=4e7"))


def dem_concealed_case(seed: int, effect: str | None = "random", *, cache: Path | None = None,
                       recalibration: dict[str, float] | None = None) -> DemConcealedCase:
    """Generate a DEM-truth recording with one concealed effect (or none: ``effect=None``).

    Parameters
    ----------
    seed : seeds the effect choice (``effect == "random"``), its parameters, the truth numerics,
        the noise and the trigger offset
    effect : a name of ``DEM_EFFECT_DRAWS``, ``"random"`` or None (null case: only numerics differ)
    cache : cache root (default ``cache_dir()``)
    recalibration : soil values of the truth other than the scenario's (``RECALIBRATION_KEYS``,
        e.g. ``{"soil.material.friction_angle_deg": 35.0}``): a wrong value of a parameter
        the model already has; with ``effect=None`` the right answer is no missing physics.
        The seed's draws are those of the case without it.
    """
    recal = check_recalibration(recalibration)
    rng = np.random.default_rng(seed)
    effect, eff_ov, truth_ov = _truth_draws(seed, effect, recal, rng)
    rec, meta, offset = _acquired_truth(truth_ov, rng, cache)
    values: dict[str, float] = {}
    drawn: dict[str, float] = {}
    if effect is not None:
        for key, rom_name in COMPARED[effect].items():
            values[rom_name] = float(eff_ov[f"physics.{effect}.{key}"])
        drawn = {k: (v if isinstance(v, str) else float(v)) for k, v in eff_ov.items()
                 if not k.endswith(".enabled")}
    return DemConcealedCase(effect, values, recal, seed, rec, truth_ov, offset, meta, drawn,
                            dem_baseline(cache))


def _truth_draws(seed: int, effect: str | None, recal: dict[str, float],
                 rng: np.random.Generator | None = None
                 ) -> tuple[str | None, dict[str, Any], dict[str, Any]]:
    """The effect, its overrides and the truth run's overrides of ``dem_concealed_case(seed,
    effect)``, drawn from ``rng`` (default: a fresh generator of ``seed``, as the case draws)."""
    rng = np.random.default_rng(seed) if rng is None else rng
    if effect == "random":
        names = sorted(DEM_EFFECT_DRAWS)
        effect = names[int(rng.integers(len(names)))]
    eff_ov = draw_dem_effect(effect, rng) if effect is not None else {}
    num = truth_numerics(rng, seed)
    return effect, eff_ov, {**num, **eff_ov, **recal}


def _acquired_truth(truth_ov: dict[str, Any], rng: np.random.Generator, cache: Path | None,
                    cfc: float = 60.0) -> tuple[dict[str, Signal], dict[str, Any], float]:
    """Run (or load) the truth with scenario overrides ``truth_ov`` (its numerics included),
    draw the trigger offset from ``rng`` and acquire the channels like a lab at class ``cfc``;
    returns the recording, the run facts and the trigger offset."""
    raw, info = run_dem(truth_ov, filtered=False, cache=cache)
    offset = float(rng.uniform(-TRIGGER_JITTER, TRIGGER_JITTER))
    acc, vel = raw["accel_z"], raw["velocity_z"]
    rec = acquire_samples(acc.t, {"accel_z": (acc.data, "m/s^2"), "velocity_z": (vel.data, "m/s")},
                          float(-vel.data[0]), rng, trigger_offset=offset, cfc=cfc,
                          source=f"crashdem DEM truth (seed {truth_ov['scenario.seed']}, radius "
                                 f"{truth_ov['soil.radius']:g} m, safety "
                                 f"{truth_ov['solver.safety']:g})"
                                 + (f", CFC {cfc:g}" if cfc != 60.0 else ""))
    meta = {"particles": info.get("particles"), "dt": info.get("dt"), "wall_s": info.get("wall_s")}
    return rec, meta, offset


#: filter classes a "different filter class" recording is drawn from [Hz] (the baseline: CFC 60)
FILTER_CLASS_DRAWS = (180.0, 600.0, 1000.0)


def dem_filter_class_case(seed: int, *, declared: bool = False, cache: Path | None = None
                          ) -> DemConcealedCase:
    """A DEM-truth recording of the baseline physics whose lab filtered it with another CFC
    class (``sensor_dynamics`` in its filter-class form): the truth numerics of
    :func:`dem_concealed_case`, the class drawn from ``FILTER_CLASS_DRAWS``; the recording
    declares its class only with ``declared`` (a CSV without a header says nothing).
    ``values``: ``{"filter_class": class}``."""
    rng = np.random.default_rng(10_000 + int(seed))
    cfc = float(FILTER_CLASS_DRAWS[int(rng.integers(len(FILTER_CLASS_DRAWS)))])
    num = truth_numerics(rng, seed)
    rec, meta, offset = _acquired_truth(num, rng, cache, cfc)
    if not declared:
        rec = {k: Signal(s.name, s.t, s.data, s.unit, None, s.meta) for k, s in rec.items()}
    return DemConcealedCase("sensor_dynamics", {"filter_class": cfc}, {}, seed, rec, num, offset,
                            meta, {"filter_class": cfc}, dem_baseline(cache))


def dem_baseline_raw(cache: Path | None = None) -> dict[str, Signal]:
    """The baseline simulation's unfiltered channels (to re-filter it at another class)."""
    sigs, _ = run_dem(dict(BASELINE_NUMERICS), filtered=False, cache=cache)
    return sigs


class DemFullSimulator:
    """The full DEM behind the ``screen_then_confirm`` interface: ``f(overrides) -> signals``.

    ``overrides`` are scenario keys (``physics.<name>.*``) and ``calibration.*_scale`` factors,
    applied to the baseline scenario (baseline numerics) as ``crashdem diagnose --full-confirm``
    does (``cli._apply_scales``). Runs are cached like the truth runs; ``calls`` counts requests.
    A batch (``map``: the search levels, the replicates) runs its uncached runs on ``workers``
    processes first (``prefetch``; default the cores): the same signals, bit for bit, as one by
    one (``tests/crashdem/diagnosis/test_dem_prefetch.py``).
    """

    def __init__(self, cache: Path | None = None, workers: int | None = None):
        from crashdem import scenario as sc

        from crashdem.diagnosis.parallel import check_workers

        self.cache = cache
        self.calls = 0
        self.workers = check_workers(workers)
        self.scenario = sc.load(SCENARIO, {**BASE_OVERRIDES, **BASELINE_NUMERICS})

    def _run_overrides(self, overrides: dict[str, Any]) -> dict[str, Any]:
        from crashdem.diagnosis.distributed import scenario_overrides

        return {**BASELINE_NUMERICS, **scenario_overrides(self.scenario, overrides)}

    def __call__(self, overrides: dict[str, Any]) -> dict[str, Signal]:
        self.calls += 1
        sigs, _ = run_dem(self._run_overrides(overrides), filtered=True, cache=self.cache)
        return sigs

    def map(self, batch: list[dict[str, Any]]) -> list[dict[str, Signal]]:
        """``[self(ov) for ov in batch]``, the uncached runs first run in parallel on
        ``self.workers`` processes (``prefetch``); the same signals as one by one."""
        reqs = []
        for ov in batch:
            try:
                reqs.append((self._run_overrides(ov), True))
            except Exception:  # noqa: BLE001 - not representable: raised by self(ov) below
                pass
        prefetch(reqs, cache=self.cache, workers=self.workers)
        return [self(ov) for ov in batch]
