"""Reference glider crash (issue 6): the 343 kg fuselage into the 45 deg soil container.

Runs ``validation/scenarios/glider_real.toml`` through ``crashdem.run.run_scenario`` (cached
slope packing, coupled DEM/Exudyn, compliant plywood walls, HDF5 at 12.5 kHz with CFC 60
channels, particle snapshots for ParaView, plots), then extracts the reference features of
Varriale (2019) §2.2.4 and checks the physics of the record:

  - two longitudinal deceleration peaks (primary impact, nose on the rear wall), max ~20 g;
  - pitch: negative at first, then about +1.6 deg; event ~0.25 s;
  - oracles: momentum (contact impulse = m dv), rear-accelerometer kinematic identity, gyro
    integral = exact pitch (planar motion), free-flight pitch rate = release rate (0), front
    accelerometers clipped at 250 g.

Sensitivity studies (``--studies``, 0.1 m grains whatever the mode): compaction direction
(horizontal layers vs layers normal to the slope, thesis §2.4), container size (the ideal 4.8 m
vs the real one, width kept), particle size (0.1 vs 0.08 m), and the pitch-up diagnosis: pitch
inertia 2x / 4x the build-up's (the whole aircraft's, thesis Tab. 2.3), crushable nose with
and without it; and the candidate ingredients of the pitch-up (docs/glider.md "What would make
the fuselage penetrate"): a nose-down pitch rate at release, the nose's side-view asymmetry
(``glider.nose_droop``), a lower skin friction, free grain rotations with rolling resistance, a
looser upper layer, the card's (drop tank's) compaction height. One change at a time from the
small baseline (docs/glider.md).

Usage::

    python validation/glider_crash.py --small       # test-suite size (~800 grains, < 2 min)
    python validation/glider_crash.py               # default resolution
    python validation/glider_crash.py --small --studies   # + sensitivity studies
    python validation/glider_crash.py --set physics.structural_crush.enabled=true  # crushable nose

The soil card ``validation/soil_cards/calibrated_gravel.toml`` is used when it exists (unless
``--no-card``); otherwise the drop scenarios' soil of the scenario file. The card's soil
properties are applied; its upper-layer thickness (``physics.soil_layering.depth``, the drop
tank's re-worked layer) is not: the glider container's compaction geometry is the scenario's
(thesis §2.2.2: compacted up to ~1 m above the floor), unless ``--card-layer-depth``. The LAST
printed line is JSON with ``peak_ax_g``, ``second_peak_ax_g``, ``t_peaks_s``, ``pitch_min_deg``,
``pitch_max_deg``, ``duration_s``, ``wall_s`` (+ ``checks``, ``errors``, ``studies``...).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from validation.campaign.calibration import load_soil_card  # noqa: E402

SCENARIO = ROOT / "validation" / "scenarios" / "glider_real.toml"
CARD = ROOT / "validation" / "soil_cards" / "calibrated_gravel.toml"
#: Card keys describing where the drop tank's compaction stopped, not the soil itself: the
#: glider container's compaction height is a property of its filling (thesis §2.2.2: the
#: compaction failed once the soil was ~1 m thick; §2.4: acceptable compaction at the 0.85 m
#: impact point), kept from the scenario (``physics.soil_layering.depth`` = 1.4 m below the
#: 2.4 m top, i.e. compacted up to 1.0 m) unless ``--card-layer-depth`` (docs/glider.md)
CARD_CONTAINER_KEYS = ("physics.soil_layering.depth",)
DEFAULT_CACHE = Path(os.environ.get("CRASHDEM_CACHE", Path.home() / ".cache" / "crashdem")) \
    / "packings"
#: Overrides per mode. small: 0.1 m grains (~800 in the slope), no snapshots/plots.
MODES: dict[str, dict] = {
    "small": {"soil.radius": 0.1, "soil.radius_spread": 0.1, "output.snapshots": 0,
              "output.plots": False},
    "default": {},
}
#: Reference features, Varriale (2019) §2.2.4 (anchors §1.3)
REFERENCE = {"peak_ax_g": 20.0, "pitch_max_deg": 1.6, "duration_s": 0.25}
#: The ideal container (thesis §2.2.2: 4.8 m to avoid boundary effects); width kept at the
#: real container's for CPU reasons (see docs/glider.md)
IDEAL = {"container.length": 4.8, "container.height": 4.8, "container.soil_depth": 4.8,
         "physics.soil_layering.depth": 3.8}
#: Grain radii of the particle-size study [m] (0.06 m needs a 12+ min deposition per packing
#: on the shared 2-core machine: the default run gives that point)
GRAIN_RADII = (0.1, 0.08)
COARSE = {"soil.radius": 0.1, "soil.radius_spread": 0.1, "output.snapshots": 0,
          "output.plots": False}


#: Length of the primary-impact window after the first contact over which the planar-motion
#: oracles are evaluated [s]: the impact is planar by symmetry until grain asymmetry builds up
#: roll and yaw; later the fuselage may tumble, where the elevation angle ("exact" pitch, in
#: [-90, 90] deg) and the integrated body rate legitimately part.
PLANAR_WINDOW = 0.05


def checks(sig: dict, spec_mass: float, mounts: dict, t_contact: float, full_scale_g: float,
           nose_mass: float | None = None, release_rate: float = 0.0) -> dict:
    """Physics checks of a record (raw channels); each entry holds the numbers compared.
    ``release_rate``: the pitch rate given at release [rad/s] (``glider.release_pitch_rate_deg_s``),
    which the free-flight gyro must keep."""
    from crashdem.glider import G0, kinematic_identity
    from crashdem.signal import Signal

    out: dict = {}
    t = sig["contact_force_x"].t

    def trap(y):
        return float(np.sum(0.5 * np.diff(t) * (y[1:] + y[:-1])))

    # momentum along x over the whole record: int F_x dt = m (v_x(end) - v_x(0))
    fx = sig["contact_force_x"].data
    vx = sig["cg_velocity_x"].data
    out["momentum_x"] = {"impulse_Ns": trap(fx), "m_dv_Ns": spec_mass * float(vx[-1] - vx[0])}
    if nose_mass is not None:
        # crushable nose: soil + wall impulse on the aircraft = change of the momentum of the
        # fuselage and the nose; the fuselage alone: every load on it incl. the crush element
        vn = sig["nose_velocity_x"].data
        out["momentum_x"]["m_dv_Ns"] += nose_mass * float(vn[-1] - vn[0])
        out["momentum_x_fuselage"] = {"impulse_Ns": trap(sig["fuselage_force_x"].data),
                                      "m_dv_Ns": spec_mass * float(vx[-1] - vx[0])}
    # planar-motion oracles over the primary impact
    n = int(np.searchsorted(t, t_contact + PLANAR_WINDOW))
    win = {k: Signal(v.name, v.t[:n], v.data[:n], v.unit, v.cfc, v.meta) for k, v in sig.items()}
    win["pitch_angle"] = win["pitch_angle_integrated"]
    out["rear_accel_identity"] = kinematic_identity(win, mounts["rear_accel_x"])
    out["rear_accel_identity"]["window_s"] = PLANAR_WINDOW
    th = sig["pitch_angle"].data[:n]
    thi = sig["pitch_angle_integrated"].data[:n]
    out["pitch_integrated_vs_exact_deg"] = float(np.degrees(np.max(np.abs(thi - th))))
    out["pitch_excursion_deg"] = float(np.degrees(np.max(np.abs(th - th[0]))))
    q = sig["pitch_rate"].data
    pre = t < t_contact
    # torque-free flight: the gyro keeps the release rate (max deviation from it)
    out["free_flight_rate_max"] = (float(np.max(np.abs(q[pre] - release_rate))) if pre.any()
                                   else float("nan"))
    out["free_flight_samples"] = int(pre.sum())
    # unclipped nose z specific force from the rear channel and the gyro (planar rigid body:
    # f_front_z = f_rear_z + dx q', dx = front - rear station along the body x axis)
    dx = float(mounts["front_accel_z"][0] - mounts["rear_accel_z"][0])
    pred = sig["rear_accel_z"].data + dx * np.gradient(q, t)
    out["front_z_predicted_max_g"] = float(np.nanmax(np.abs(pred)) / G0)
    front = {}
    for name in ("front_accel_x", "front_accel_z"):
        d = sig[name].data
        fin = d[np.isfinite(d)]
        front[name] = {"max_abs_g": float(np.max(np.abs(fin)) / G0) if fin.size else 0.0,
                       "failed_at": sig[name].meta.get("failed_at"),
                       "nan_samples": int(np.sum(~np.isfinite(d)))}
    out["front"] = front
    out["full_scale_g"] = full_scale_g
    return out


def run_one(overrides: dict, out_dir: Path, cache: Path, tag: str) -> dict:
    """Run the scenario with overrides; features, checks, wall time, HDF5 path."""
    from crashdem import run as rn
    from crashdem import scenario as sc
    from crashdem.glider import crash_features
    from crashdem.results import open_result

    scen = sc.load(SCENARIO, {"scenario.name": f"glider_{tag}", **overrides})
    # the slope packing: from the shared cache when it holds it, and into it when deposited here
    import shutil

    pk_name = f"packing-{rn.packing_spec(scen).hash()[:20]}.h5"
    # the shared cache is keyed by the soil engine: another engine's bed is never copied in
    cache = rn.packing_cache(cache)
    local = Path(out_dir) / "packings"
    local.mkdir(parents=True, exist_ok=True)
    if (Path(cache) / pk_name).exists() and not (local / pk_name).exists():
        shutil.copy(Path(cache) / pk_name, local / pk_name)
    t0 = time.perf_counter()
    path = rn.run_scenario(scen, out_dir, progress=False)
    wall = time.perf_counter() - t0
    if (local / pk_name).exists() and not (Path(cache) / pk_name).exists():
        Path(cache).mkdir(parents=True, exist_ok=True)
        shutil.copy(local / pk_name, Path(cache) / pk_name)
    from crashdem.glider import coupled_specs

    with open_result(path) as res:
        sig = res.signals(filtered=False)
        import h5py

        with h5py.File(path, "r") as f:
            run_info = dict(f["run"].attrs)
    t_contact = float(run_info["t_contact"])
    feats = crash_features(sig, t_contact, cfc=scen["instrumentation.cfc"])
    # the coupled fuselage: the whole body, or its rear part with the crushable nose (whose
    # element load is then part of the recorded fuselage force)
    _, spec, nose_spec = coupled_specs(scen)
    mounts = {m.name: m.position for m in spec.sensors}
    ch = checks(sig, spec.mass, mounts, feats["t_first_contact_s"],
                scen["instrumentation.accel_full_scale_g"],
                None if nose_spec is None else nose_spec.mass,
                math.radians(scen["glider.release_pitch_rate_deg_s"]))
    walls = {}
    for name in ("rear_wall", "left_wall", "right_wall"):
        walls[name] = {"max_force_N": float(np.max(sig[f"{name}_force"].data)),
                       "max_deflection_m": float(np.max(np.abs(sig[f"{name}_deflection"].data)))}
    nose = sig["nose_rear_wall_force"]
    on = np.flatnonzero(nose.data > 0.0)
    walls["nose_on_rear_wall"] = {
        "max_force_N": float(np.max(nose.data)),
        "t_first_s": float(nose.t[on[0]] - feats["t_first_contact_s"]) if on.size else None}
    if nose_spec is not None:
        load = sig["nose_crush_load"].data
        stroke = sig["nose_crush_stroke"].data
        limit = scen["physics.structural_crush.stroke"]
        # before the first sample whose compression reaches the stroke the element cannot
        # have bottomed (compression >= plastic stroke): its load is capped at crush_force
        n_b = int(np.argmax(stroke >= limit)) if np.any(stroke >= limit) else stroke.size
        walls["nose_crush"] = {
            "crush_force_N": scen["physics.structural_crush.crush_force"],
            "stroke_limit_m": limit,
            "max_load_N": float(np.max(load)),
            "max_load_before_bottoming_N": float(np.max(load[:n_b])) if n_b else 0.0,
            "t_bottoming_s": (float(sig["nose_crush_stroke"].t[n_b] - feats["t_first_contact_s"])
                              if n_b < stroke.size else None),
            "max_stroke_m": float(np.max(stroke)),
            "energy_J": float(np.sum(0.5 * np.diff(stroke) * (load[1:] + load[:-1]))),
            "nose_mass_kg": float(nose_spec.mass)}
    # pitch-up diagnosis: peak gyro rate, pitch rate and vertical / longitudinal contact impulse
    # over the first 20 ms after the first contact (raw channels)
    tq, q = sig["pitch_rate"].t, sig["pitch_rate"].data
    t1 = feats["t_first_contact_s"]
    w20 = (tq >= t1) & (tq <= t1 + 0.02)
    tc, fz, fx = sig["contact_force_z"].t, sig["contact_force_z"].data, \
        sig["contact_force_x"].data
    c20 = (tc >= t1) & (tc <= t1 + 0.02)

    def _imp(y, m):
        return float(np.sum(0.5 * np.diff(tc[m]) * (y[m][1:] + y[m][:-1])))

    diag = {"pitch_rate_max_deg_s": float(np.degrees(np.nanmax(q))),
            "pitch_rate_at_20ms_deg_s": float(np.degrees(q[w20][-1])) if w20.any() else None,
            "impulse_z_20ms_Ns": _imp(fz, c20), "impulse_x_20ms_Ns": _imp(fx, c20),
            "pitch_inertia_kg_m2": float(spec.inertia[1, 1])}
    return {"features": feats, "checks": ch, "walls": walls, "wall_s": wall, "hdf5": str(path),
            "diagnosis": diag,
            "particles": int(run_info["particles"]), "dt": float(run_info["dt"]),
            "dem_steps": int(run_info["dem_steps"])}


def _errors(feats: dict) -> dict:
    return {k: {"value": feats[k], "reference": ref,
                "error": feats[k] - ref, "relative": (feats[k] - ref) / ref}
            for k, ref in REFERENCE.items()}


#: Pitch inertia of the build-up (``bodies.glider_fuselage``, components within 3 m) [kg m^2]
#: and the factors of the pitch-inertia study: the thesis's ballast restored the WHOLE
#: aircraft's pitch inertia (wings and tail included; Tab. 2.3 values missing from the text)
PITCH_INERTIA_BUILD_UP = 230.0
PITCH_INERTIA_FACTORS = (2.0, 4.0)
#: Crushable nose (``physics.structural_crush``, schema defaults: 50 kN, 0.2 m)
CRUSH = {"physics.structural_crush.enabled": True}


def study_cases() -> list[tuple[str, str, dict]]:
    """The sensitivity cases (study, label, overrides on the small baseline), cheapest first
    (cases on the baseline's packing, then the ones needing a new deposition)."""
    cases: list[tuple[str, str, dict]] = []
    for f in PITCH_INERTIA_FACTORS:
        cases.append(("pitch_inertia", f"{f:g}x",
                      {"glider.pitch_inertia": f * PITCH_INERTIA_BUILD_UP}))
    cases.append(("crushable_nose", "on", dict(CRUSH)))
    f = PITCH_INERTIA_FACTORS[-1]
    cases.append(("crushable_nose", f"on_pitch_inertia_{f:g}x",
                  {**CRUSH, "glider.pitch_inertia": f * PITCH_INERTIA_BUILD_UP}))
    cases.append(("compaction", "slope_normal", {"container.compaction": "slope_normal"}))
    for rad in GRAIN_RADII:
        if rad != COARSE["soil.radius"]:
            cases.append(("particle_size", f"{rad:g}", {"soil.radius": rad}))
    cases.append(("container_size", "ideal_4.8m", dict(IDEAL)))
    # why the fuselage rides up the slope (docs/glider.md, "What would make it penetrate"):
    # one candidate ingredient at a time
    cases.append(("release_rate", f"{RELEASE_RATE_STUDY:g}deg_s",
                  {"glider.release_pitch_rate_deg_s": RELEASE_RATE_STUDY}))
    for d in NOSE_DROOP_STUDY:
        cases.append(("nose_shape", f"droop_{d:g}", {"glider.nose_droop": d}))
    cases.append(("skin_friction", f"{SKIN_FRICTION_STUDY:g}deg",
                  {"glider.skin_friction_deg": SKIN_FRICTION_STUDY}))
    cases.append(("particle_rotation", "free_mu0.1",
                  {"soil.rotation": "free", "soil.rolling_coefficient": 0.1}))
    cases.append(("upper_layer", "porosity_0.44", {"soil.porosity_target": 0.44}))
    cases.append(("compaction_height", "card_0.6m", {"physics.soil_layering.depth": 0.6}))
    return cases


#: Candidate ingredients of the pitch-up study: a nose-down pitch rate at release [deg/s]
#: (thesis §2.2.4: negative pitch first), the nose's side-view asymmetry (glider.nose_droop),
#: a composite-on-gravel skin friction of mu 0.3 [deg]
RELEASE_RATE_STUDY = -50.0
NOSE_DROOP_STUDY = (0.5, 1.0)
SKIN_FRICTION_STUDY = 17.0

#: Baseline label of each study (the small run: real container, horizontal layers compacted
#: up to 1.0 m, 0.1 m grains, rigid fuselage, build-up pitch inertia, symmetric nose, zero
#: release rate, skin friction 30 deg, blocked grain rotations, upper layer as deposited)
BASELINE_LABEL = {"pitch_inertia": "1x", "crushable_nose": "off", "compaction": "horizontal",
                  "particle_size": "0.1", "container_size": "real", "release_rate": "0deg_s",
                  "nose_shape": "symmetric", "skin_friction": "30deg",
                  "particle_rotation": "blocked", "upper_layer": "as_deposited",
                  "compaction_height": "1.0m"}


def _study_features(r: dict) -> dict:
    f = r["features"]
    out = {k: f[k] for k in ("peak_ax_g", "second_peak_ax_g", "t_peaks_s", "pitch_min_deg",
                             "pitch_max_deg", "duration_s")}
    out["errors"] = {k: e["relative"] for k, e in _errors(f).items()}
    out.update(particles=r["particles"], wall_s=r["wall_s"],
               nose_on_rear_wall_N=r["walls"]["nose_on_rear_wall"]["max_force_N"],
               rear_wall_max_force_N=r["walls"]["rear_wall"]["max_force_N"],
               rear_wall_max_deflection_m=r["walls"]["rear_wall"]["max_deflection_m"],
               **r.get("diagnosis", {}))
    mom = r["checks"]["momentum_x"]  # the physics oracle of every case: int F_x dt = m dv_x
    out["momentum_x_rel_error"] = abs(mom["impulse_Ns"] - mom["m_dv_Ns"]) / abs(mom["m_dv_Ns"])
    if "nose_crush" in r["walls"]:
        nc = r["walls"]["nose_crush"]
        out["nose_crush"] = {k: nc[k] for k in ("max_stroke_m", "t_bottoming_s", "energy_J")}
    return out


def studies(base: dict, out: Path, cache: Path, baseline: dict | None = None,
            only: set[str] | None = None) -> dict:
    """The sensitivity studies at the small resolution (0.1 m grains): pitch inertia (2x, 4x
    the build-up's), crushable nose (with and without the larger inertia), compaction
    direction, particle size, container size. ``baseline`` = the small run's ``run_one``
    result (run here when None). Returns features per study and case; the baseline appears in
    every study under ``BASELINE_LABEL``."""
    rep: dict = {}
    base = {**base, **COARSE}
    out.mkdir(parents=True, exist_ok=True)
    if baseline is None:
        baseline = run_one(base, out, cache, "baseline")
    b = _study_features(baseline)
    for study, label, ov in study_cases():
        if only is not None and study not in only:
            continue
        rep.setdefault(study, {BASELINE_LABEL[study]: b})
        r = run_one({**base, **ov}, out, cache, f"{study}_{label}".replace(".", "p"))
        rep[study][label] = _study_features(r)
        print(f"  {study} {label}: {json.dumps(_clean(rep[study][label]))}", flush=True)
    return rep


def _clean(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.generic):
        return _clean(x.item())
    return x


def card_overrides(card: dict, layer_depth: bool = False, ignored: dict | None = None) -> dict:
    """The soil card's overrides for the glider: all of them with ``layer_depth``, else without
    ``CARD_CONTAINER_KEYS`` (collected in ``ignored``)."""
    out = dict(card)
    if not layer_depth:
        for k in CARD_CONTAINER_KEYS:
            if k in out:
                v = out.pop(k)
                if ignored is not None:
                    ignored[k] = v
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="reduced resolution (test suite)")
    ap.add_argument("--studies", action="store_true", help="run the sensitivity studies")
    ap.add_argument("--study", action="append", default=[],
                    choices=sorted(BASELINE_LABEL),
                    help="with --studies: run only this study (repeatable)")
    ap.add_argument("--no-card", action="store_true", help="ignore the calibrated soil card")
    ap.add_argument("--card-layer-depth", action="store_true",
                    help="also take the card's upper-layer thickness (the drop tank's) instead "
                         "of the glider container's compaction height")
    ap.add_argument("--out", type=Path, default=Path("runs/glider_crash"))
    ap.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="packing cache")
    ap.add_argument("--threads", type=int, default=0, help="Numba threads (0 = scenario)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="extra scenario override (repeatable)")
    args = ap.parse_args(argv)

    from crashdem.scenario import parse_override

    t0 = time.perf_counter()
    mode = "small" if args.small else "default"
    base = dict(MODES[mode])
    card = None
    card_ignored: dict = {}
    if CARD.exists() and not args.no_card:
        base.update(card_overrides(load_soil_card(CARD), args.card_layer_depth, card_ignored))
        card = str(CARD)
    if args.threads:
        base["scenario.threads"] = args.threads
    base.update(dict(parse_override(s) for s in args.set))
    out = args.out / mode
    out.mkdir(parents=True, exist_ok=True)
    print(f"glider crash, mode {mode}, soil card {card or 'none (scenario soil)'}, overrides "
          f"{base}, output {out}", flush=True)
    r = run_one(base, out, args.cache, mode)
    f = r["features"]
    print(f"  {r['particles']} grains, dt {r['dt']:.3g} s, {r['dem_steps']} steps, "
          f"{r['wall_s']:.1f} s; HDF5 {r['hdf5']}", flush=True)
    for k, e in _errors(f).items():
        print(f"  {k}: {e['value']:.3g} (reference {e['reference']:g}, error "
              f"{100 * e['relative']:+.0f} %)", flush=True)
    print(f"  second peak {f['second_peak_ax_g']:.3g} g, peaks at {f['t_peaks_s']} s after "
          f"contact, pitch min {f['pitch_min_deg']:.3g} deg", flush=True)
    report = {k: f[k] for k in ("peak_ax_g", "second_peak_ax_g", "t_peaks_s", "pitch_min_deg",
                                "pitch_max_deg", "duration_s")}
    report.update(mode=mode, soil_card=card, soil_card_keys_not_applied=card_ignored,
                  particles=r["particles"], dt=r["dt"],
                  hdf5=r["hdf5"], checks=r["checks"], errors=_errors(f), walls=r["walls"],
                  t_first_contact_s=f["t_first_contact_s"])
    if args.studies:
        print("sensitivity studies (small resolution, 0.1 m grains):", flush=True)
        base_s = {k: v for k, v in base.items() if not k.startswith("output.")}
        report["studies"] = studies(base_s, out / "studies", args.cache,
                                    baseline=r if mode == "small" else None,
                                    only=set(args.study) if args.study else None)
    report["wall_s"] = time.perf_counter() - t0
    print(json.dumps(_clean(report)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
