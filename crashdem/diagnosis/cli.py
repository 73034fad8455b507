"""``crashdem diagnose --scenario S.toml --recording REC [--channel NAME[:ROMCHANNEL] ...] --out DIR``.

The baseline is the scenario's full result when it exists (``crashdem.run.default_output``,
holding the diagnosed channels; the ROM is then first calibrated to it), else the scenario's
reduced-order model (``rom_from_scenario``); the screening fits
every catalogue hypothesis to the recording and writes ``DIR/report.json``, ``DIR/report.md``
and overlay PNGs. With ``--full-confirm N`` the top hypotheses are re-run with the full DEM
(``crashdem.run.run_scenario`` with the hypothesis's ``physics.*`` overrides; at most N+1 runs),
in parallel on Dask (``crashdem.diagnosis.distributed``: a LocalCluster of ``--workers``
processes, or the cluster at ``--scheduler ADDRESS``; runs gathered in ``DIR/confirmation.h5``);
``--workers 0`` runs them one after the other in this process.

A recorded channel is matched to a ROM channel (``accel_z``: specific force along +z of the
impactor [m/s^2]; ``velocity_z`` [m/s]) by name, or explicitly with ``NAME:accel_z``. A
``glider_crash`` scenario is screened with the planar model (``planar_from_scenario``) on
``accel_x`` / ``accel_z`` / ``pitch_rate`` (the glider's ``rear_accel_x`` / ``rear_accel_z`` /
``pitch_rate``) with the planar catalogue (``catalogue.planar_catalogue``).
"""
from __future__ import annotations

import argparse
import functools
import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from crashdem.diagnosis.rom import ACCEL, VELOCITY, RomParams, RomSettings, simulate
from crashdem.diagnosis.rom_planar import PLANAR_CHANNELS, PlanarParams, simulate_planar
from crashdem.signal import Signal

if TYPE_CHECKING:
    from crashdem.diagnosis.catalogue import BedFloor

__all__ = ["diagnose_command", "rom_from_scenario", "planar_from_scenario", "planar_geometry",
           "DROP_SPHERE_RADIUS", "DROP_SPHERE_MASS"]

#: the PoliMi drop mass (anchors.md section 1.1, architecture: bodies.drop_sphere)
DROP_SPHERE_MASS = 850.0
DROP_SPHERE_RADIUS = 0.45


def rom_from_scenario(scen) -> RomParams:
    """ROM parameters of a ``drop_test`` scenario (impactor, impact speed, soil depth and every
    enabled ``physics.*`` switch that the ROM represents).

    A ``glider_crash`` scenario gives the planar model (``planar_from_scenario``).

    Raises
    ------
    ValueError for scenario kinds no screening model represents.
    """
    if scen.get("scenario.kind") == "glider_crash" and scen.get("impactor.body") == "glider":
        return planar_from_scenario(scen)
    if scen.get("scenario.kind") != "drop_test" or scen.get("impactor.body") != "drop_sphere":
        raise ValueError("diagnose: the reduced-order models cover the sphere drop test "
                         "(scenario.kind='drop_test', impactor.body='drop_sphere') and the glider "
                         "crash ('glider_crash', 'glider'); got "
                         f"scenario.kind={scen.get('scenario.kind')!r}, "
                         f"impactor.body={scen.get('impactor.body')!r}")
    mass = scen.get("impactor.mass") or DROP_SPHERE_MASS
    v = scen.get("impactor.impact_velocity")
    if v is None:
        v = math.sqrt(2.0 * 9.81 * scen.get("impactor.drop_height"))
    vals: dict[str, Any] = {"mass": mass, "radius": DROP_SPHERE_RADIUS, "impact_speed": v,
                            "floor_depth": scen.get("container.soil_depth")}
    g = lambda k: scen.get(f"physics.{k}")  # noqa: E731
    if g("soil_layering.enabled"):
        vals["interface_depth"] = g("soil_layering.depth")
        vals["strength_ratio"] = g("soil_layering.lower_young_factor")
    if g("boundary_proximity.enabled") and g("boundary_proximity.floor_depth") is not None:
        vals["floor_depth"] = g("boundary_proximity.floor_depth")
    vals.update(_physics_values(scen))
    return RomParams(**vals)


def _physics_values(scen) -> dict[str, Any]:
    """ROM soil-record fields of the enabled ``physics.*`` switches shared by the drop and the
    planar model (cohesion, rotation, damping, sensor, crush, impact-speed offset)."""
    vals: dict[str, Any] = {}
    g = lambda k: scen.get(f"physics.{k}")  # noqa: E731
    if g("cohesion.enabled"):
        vals["cohesion"] = g("cohesion.normal_strength")
    if g("particle_rotation.enabled"):
        from crashdem.diagnosis.catalogue import friction_ratio_from_rolling

        vals["friction_ratio"] = friction_ratio_from_rolling(g("particle_rotation.rolling_coefficient"))
    if g("contact_damping.enabled"):
        vals["restitution"] = g("contact_damping.restitution")
    if g("sensor_dynamics.enabled"):
        vals["mount_frequency"] = g("sensor_dynamics.natural_frequency")
        vals["mount_damping"] = g("sensor_dynamics.damping_ratio")
        vals["mount_form"] = 1.0 if g("sensor_dynamics.model") == "mount" else 0.0
    if g("structural_crush.enabled"):
        vals["crush_strength"] = g("structural_crush.crush_force")
        vals["crush_stroke"] = g("structural_crush.stroke")
    if g("initial_conditions.enabled"):
        vals["speed_offset"] = g("initial_conditions.velocity_offset")
    return vals


def planar_from_scenario(scen) -> PlanarParams:
    """Planar-model parameters of a ``glider_crash`` scenario, with the facts of the full model
    (``crashdem.glider``): the fuselage's mass and pitch inertia (``glider_spec``), its first
    contact point on the slope (the support vertex along the slope's inward normal at the
    contact attitude) as the lowest point of a nose sphere of the fuselage's half width, the
    rear accelerometer's position, the path angle and attitude after the free flight, the
    skin friction, the rear wall's distance ahead of the contact point and its plate stiffness
    (``glider.wall_panels``), and the enabled ``physics.*`` switches the model represents.

    The soil law's constants are the drop model's defaults (bulk density from the grains and
    the packing porosity): the screening model is calibrated to the baseline run before any
    fit. The horizontal compaction layers are not represented (the impact point lies in the
    compacted part, thesis section 2.4); ``soil_layering`` is not in the planar catalogue.
    """
    import bodies

    from crashdem.glider import (NOSE_CUT_STATION, _support_vertex, glider_spec, pitch_rotation,
                                 wall_panels)

    spec = glider_spec(scen)
    gl = scen.get("glider")
    alpha = math.radians(scen.get("container.slope_deg"))
    speed, path, pitch = gl["release_speed"], scen.get("impactor.angle_deg"), \
        scen.get("impactor.pitch_deg")
    if scen.get("physics.initial_conditions.enabled"):
        path += scen.get("physics.initial_conditions.angle_offset_deg")
        pitch += scen.get("physics.initial_conditions.pitch_offset_deg")
    t_ff = gl["free_flight_time"]
    a = math.radians(path)
    vx, vz = speed * math.cos(a), -speed * math.sin(a) - 9.81 * t_ff
    theta = math.radians(pitch) + math.radians(gl["release_pitch_rate_deg_s"]) * t_ff
    rot = pitch_rotation(theta)
    n_out = np.array([-math.sin(alpha), 0.0, math.cos(alpha)])
    r_sup = _support_vertex(spec.vertices, rot, -n_out)  # world offset from the CG
    rn = 0.5 * float(spec.reference_dimensions["width"])
    centre_body = rot.T @ (r_sup + rn * n_out)
    mount = next(m.position for m in spec.sensors if m.name == "rear_accel_x")
    # rear wall: horizontal distance from the first contact point to the wall face, less the
    # nose tip's lead over the nose sphere's front at the contact attitude
    length = scen.get("container.length")
    h_imp = gl["impact_height"]
    tip_x = float(np.max((np.asarray(spec.vertices) @ rot.T)[:, 0]))
    sphere_front = float(r_sup[0] + rn * n_out[0]) + rn
    wall = length - h_imp / math.tan(alpha) - (tip_x - sphere_front)
    panel = wall_panels(scen)["rear_wall"]
    porosity = scen.get("physics.soil_layering.lower_porosity") if \
        scen.get("physics.soil_layering.enabled") else None
    density = scen.get("soil.material.density") * (1.0 - (porosity or 0.38))
    soil_vals: dict[str, Any] = {"mass": float(spec.mass), "radius": rn,
                                 "impact_speed": math.hypot(vx, vz), "density": density,
                                 "floor_depth": h_imp / math.cos(alpha)}
    # the crushable nose of the full model (glider.NOSE_CUT_STATION; physics.structural_crush)
    _, nose = bodies.split_nose(spec, NOSE_CUT_STATION,
                                bodies.GliderBuildUp().laminate_areal_density)
    soil_vals["nose_mass_fraction"] = float(nose.mass) / float(spec.mass)
    soil_vals.update(_physics_values(scen))
    mu = math.tan(math.radians(min(gl["skin_friction_deg"],
                                   scen.get("soil.material.friction_angle_deg"))))
    return PlanarParams(soil=RomParams(**soil_vals), pitch_inertia=float(spec.inertia[1, 1]),
                        nose_offset=float(centre_body[0]), nose_height=float(centre_body[2]),
                        slope=alpha, path_angle=math.atan2(-vz, vx), pitch=theta, friction=mu,
                        wall_distance=max(0.05, wall), wall_stiffness=float(panel.stiffness),
                        mount_x=float(mount[0]), mount_z=float(mount[2]))


def planar_geometry(scen) -> dict[str, float]:
    """Scenario facts that map the planar catalogue's wall parameters to scenario keys
    (``catalogue.planar_catalogue``)."""
    from crashdem.run import PLYWOOD_YOUNG

    return {"impact_height": scen.get("glider.impact_height"),
            "slope": math.radians(scen.get("container.slope_deg")),
            "wall_young": scen.get("container.wall_young") or PLYWOOD_YOUNG}


def _si_unit(unit: str | None) -> str | None:
    from crashdem.signal import UNIT_TO_SI

    return UNIT_TO_SI.get(unit, (None, None))[1] if unit else None


#: what a drop channel may be recorded as: (SI unit, ISO/TS 13499 dimension) in order of
#: preference; a force is the contact force on the impactor (divided by its mass), a length its
#: position or penetration (differentiated), see ``_convert``
_RECORDED_AS: dict[str, tuple[tuple[str, str], ...]] = {
    ACCEL: (("m/s^2", "AC"), ("N", "FO")),
    VELOCITY: (("m/s", "VE"), ("m", "DS")),
}


def _unit_channel(rec: dict[str, Signal], si: str, iso: str) -> str | None:
    """The one recorded channel with ISO/TS 13499 dimension ``iso`` along Z, else the one with
    SI unit ``si``, else the one of those whose name ends in z; None otherwise."""
    iso_hits = [n for n in rec if len(n) == 16 and n[12:14].upper() == iso
                and n[14].upper() == "Z"]
    if len(iso_hits) == 1:
        return iso_hits[0]
    unit_hits = [n for n, sig in rec.items() if _si_unit(sig.unit) == si]
    if len(unit_hits) == 1:
        return unit_hits[0]
    z_hits = [n for n in unit_hits if n.lower().rstrip("_0123456789").endswith("z")]
    return z_hits[0] if len(z_hits) == 1 else None


def _auto_channel(rec: dict[str, Signal], model: str) -> str | None:
    """The recorded channel standing for ``model`` (``accel_z`` / ``velocity_z``) when the
    recording does not use crashdem's names: crashdem's impactor channel, an ISO/TS 13499 code
    (dimension ``AC``/``VE``, direction ``Z``), or the one channel with the right SI unit whose
    name says z. Failing those, another code's output: a contact force [N] on the impactor for
    ``accel_z`` (ISO ``FO``), a position or penetration [m] for ``velocity_z`` (ISO ``DS``),
    converted by ``_convert``. None when nothing or more than one channel qualifies."""
    alt = sim_channel(rec, model)
    if alt is not None:
        return alt
    for si, iso in _RECORDED_AS[model]:
        hit = _unit_channel(rec, si, iso)
        if hit is not None:
            return hit
    return None


def _convert(sig: Signal, model: str, mass: float | None) -> tuple[Signal, str | None]:
    """A recorded channel as the model channel ``model``, and how it was converted (None: as
    recorded). A force [N, kN] standing for ``accel_z`` is divided by the impactor's mass (the
    contact force on the body over its mass is the specific force an accelerometer on it reads;
    a force that includes the weight reads -g in free fall, like a kinematic acceleration, and
    is handled as that: ``diagnose`` adds g back, ``_free_fall_convention``); a position or
    penetration [m, mm] standing for ``velocity_z`` is differentiated (central differences; its sign is settled by the sign-convention check).
    Any other unit is an error naming the channel, its unit and the units accepted."""
    from crashdem.signal import to_si

    si = _si_unit(sig.unit)
    allowed = _RECORDED_AS.get(model, ((None, None),))
    if si == allowed[0][0] or model not in _RECORDED_AS:
        return sig, None
    if model == ACCEL and si == "N" and mass:
        data, _ = to_si(sig.data, sig.unit)
        return (Signal(sig.name, sig.t, data / mass, "m/s^2", sig.cfc, dict(sig.meta)),
                f"contact force [{sig.unit}] / impactor mass {mass:g} kg")
    if model == VELOCITY and si == "m":
        data, _ = to_si(sig.data, sig.unit)
        return (Signal(sig.name, sig.t, np.gradient(data, sig.t), "m/s", sig.cfc, dict(sig.meta)),
                f"time derivative of the recorded length [{sig.unit}]")
    units = " or ".join(u for u, _ in allowed)
    raise ValueError(f"--channel {sig.name}:{model}: the channel's unit {sig.unit!r} cannot stand "
                     f"for {model!r}; allowed: a unit convertible to {units}")


def _channel_map(specs: list[str] | None, rec: dict[str, Signal],
                 planar: bool = False) -> dict[str, str]:
    """recorded name -> ROM channel name.

    Drop test: without ``--channel``, the channels named ``accel_z`` / ``velocity_z``; else, for
    each of the two, crashdem's impactor channel, a unique ISO-MME code or a unique channel
    with the right unit (see ``_auto_channel``). Glider (``planar``): the channels named
    ``accel_x`` / ``accel_z`` / ``pitch_rate``, else the glider's ``rear_accel_x`` /
    ``rear_accel_z`` / ``pitch_rate``; other names need ``--channel NAME:accel_x``."""
    out: dict[str, str] = {}
    models = PLANAR_CHANNELS if planar else (ACCEL, VELOCITY)
    if not specs:
        find = sim_channel if planar else _auto_channel
        for model in models:
            name = model if model in rec else find(rec, model)
            if name is not None and name not in out:
                out[name] = model
        if planar and PLANAR_CHANNELS[0] not in out.values():
            raise ValueError(f"diagnose: no recorded channel found for 'accel_x' (the glider's "
                             f"longitudinal acceleration; also looked for 'rear_accel_x'); "
                             f"recorded: {sorted(rec)}; map one with --channel NAME:accel_x")
        if not out:
            raise ValueError(f"diagnose: no recorded channel found for {ACCEL!r} (an acceleration "
                             f"along z) or {VELOCITY!r}; recorded: {sorted(rec)} with units "
                             f"{[rec[n].unit for n in sorted(rec)]}; map one with "
                             f"--channel NAME:{ACCEL}")
        return out
    for spec in specs:
        name, _, rom_name = spec.partition(":")
        rom_name = rom_name or name
        if name not in rec:
            raise ValueError(f"--channel {spec!r}: {name!r} not in the recording ({sorted(rec)})")
        if rom_name not in models:
            raise ValueError(f"--channel {spec!r}: model channel {rom_name!r} must be one of "
                             f"{list(models)}")
        out[name] = rom_name
    return out


def diagnose_command(args: argparse.Namespace) -> int:
    """Entry point used by ``crashdem.cli`` (``crashdem diagnose ...``): one diagnosis at a
    time per output directory (``DIR/report.lock``, ``crashdem.run.output_lock``; its runs
    write fixed file names there)."""
    from crashdem.run import output_lock

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with output_lock(out / "report", "another diagnosis is writing into this directory now"):
        return _diagnose_command(args)


def _diagnose_command(args: argparse.Namespace) -> int:
    from crashdem import scenario as sc
    from crashdem.diagnosis import diagnose, screen_then_confirm, working_rate, write_report
    from crashdem.diagnosis.confirm import GRAIN_CHECK_AGREE
    from crashdem.recordings import read_recording
    from crashdem.runcache import from_option as run_cache_option

    overrides = dict(sc.parse_override(s) for s in (getattr(args, "set", None) or []))
    scen = sc.load(args.scenario, overrides)
    units = {}
    for spec in getattr(args, "unit", None) or []:
        name, sep, unit = spec.partition("=")
        if not sep or not name.strip() or not unit.strip():
            raise ValueError(f"--unit {spec!r}: must be NAME=UNIT, e.g. accel_z=g")
        units[name.strip()] = unit.strip()
    skipped: dict[str, str] = {}
    raw = read_recording(args.recording, units=units or None, skipped=skipped)
    base_params = rom_from_scenario(scen)
    planar = isinstance(base_params, PlanarParams)
    # a channel left out that the diagnosis reads by name (a model channel's own name, or one
    # given with --channel) is an error: diagnosing without it would answer another question
    named = set(PLANAR_CHANNELS if planar else (ACCEL, VELOCITY)) | {
        spec.split(":", 1)[0] for spec in getattr(args, "channel", None) or []}
    needed = sorted(named & set(skipped))
    if needed:
        raise ValueError(skipped[needed[0]])
    why_skipped = "; ".join(skipped.values())
    try:
        cmap = _channel_map(getattr(args, "channel", None), raw, planar)
    except ValueError as e:
        if not skipped:
            raise
        # a channel the diagnosis needed may be among those left out: say why each was
        raise ValueError(f"{e}; channels of the recording left out as unusable: "
                         f"{why_skipped}") from None
    if skipped:
        import logging

        logging.getLogger(__name__).warning(
            "diagnose: channels of the recording not used (unusable): %s", why_skipped)
    rec: dict[str, Signal] = {}
    conversions: dict[str, str] = {}
    for name, rom_name in cmap.items():
        sig, how = _convert(raw[name], rom_name, None if planar else base_params.mass)
        meta = {**sig.meta, "recorded_name": name}
        if how is not None:
            meta["converted"] = conversions[rom_name] = how
        rec[rom_name] = Signal(rom_name, sig.t, sig.data, sig.unit, sig.cfc, meta)
    rec, decimated = working_rate(rec)  # the rate the screening works at (RomSettings below)
    # primary channel first (the longitudinal acceleration of the glider, the drop's vertical)
    primary = PLANAR_CHANNELS[0] if planar else ACCEL
    rec = dict(sorted(rec.items(), key=lambda kv: kv[0] != primary))
    first = next(iter(rec.values()))
    cat_kw: dict[str, Any] = {}
    if planar:
        from crashdem.diagnosis.catalogue import planar_catalogue

        cat_kw["catalog"] = planar_catalogue(base_params, planar_geometry(scen))
    settings = RomSettings(t_pre=max(0.0, -float(first.t[0])) + 0.005,
                           t_end=float(first.t[-1]) + 0.01, sample_rate=first.fs,
                           cfc=first.cfc if first.cfc is not None else scen.get("instrumentation.cfc"))
    pcache = _packing_cache(getattr(args, "packing_cache", None))
    rcache = run_cache_option(getattr(args, "run_cache", None))
    # the beds already in each directory runs deposit in (the count of report.json)
    own = (pcache if pcache is not None else Path(args.out) / "baseline" / "packings").resolve()
    beds_before = {own: _cached_beds(own)}
    if (not planar and scen.get("soil.packing_file") and getattr(args, "full_confirm", None) != 0
            and _search_on_itself(scen, getattr(args, "full_search", None) or "auto")[0]):
        _one_bed(scen, None, args)  # options that would repeat the one bed, before any run
    baseline, source = _baseline(scen, cmap, base_params, settings,
                                 mode=getattr(args, "baseline", None) or "run",
                                 out_dir=Path(args.out), packing_cache=pcache,
                                 run_cache=rcache)
    # unfiltered baseline channels, to compare at a recording's other filter class
    base_raw = (_simulate(base_params, replace(settings, cfc=None)) if source == "rom"
                else _baseline_raw(source, cmap))
    n_full = getattr(args, "full_confirm", None)
    if n_full is None:
        # default: confirm the two best screened candidates with the full DEM (1 + 2 runs)
        # whenever the baseline is a full simulation (the screening alone cannot see what the
        # reduced-order model lacks; measured on DEM truth, docs/diagnosis.md)
        n_full = 0 if source == "rom" else DEFAULT_FULL_CONFIRM
    if n_full < 0:
        raise ValueError(f"--full-confirm={n_full!r}: must be >= 0 (0 = screening only)")
    if n_full:
        dask = getattr(args, "workers", None) != 0
        linked = _share_packings(source, [Path(args.out) / ("confirmation.h5.members" if dask
                                                            else "full_runs")], pcache)
        if linked is not None and linked not in beds_before:  # a result's own beds
            beds_before[linked] = _cached_beds(linked)
        full = _local_runner(scen, cmap, Path(args.out) / "full_runs", rcache)
        if getattr(args, "workers", None) != 0:  # Dask: LocalCluster, or --scheduler ADDRESS
            from crashdem.diagnosis.distributed import full_simulator_from_args

            local = full
            full = _LocalFallback(full_simulator_from_args(args, scen, cmap, rcache), local,  # type: ignore[assignment]
                                  lambda: _share_packings(source, [Path(args.out) / "full_runs"],
                                                          pcache))
        searched, search_sim, search_how = _search_setup(
            scen, planar, getattr(args, "full_search", None) or "auto", cmap, Path(args.out),
            packing_cache=pcache, run_cache=rcache)
        bed_floor = _bed_floor(scen, searched)
        reps = _replicates(scen, getattr(args, "replicates", None), bool(searched))
        numerics = _numerics_scales(getattr(args, "numerics_check", None))
        grain = _grain_scales(getattr(args, "grain_check", None))
        gfit = _grain_fit_scales(getattr(args, "grain_fit", None))
        lfit, lfit_law, lfit_own = _law_fit_factors(scen, getattr(args, "law_fit", None))
        if getattr(args, "law_fit_stiffness", "on") == "off":
            lfit_own = ()
        level_beds = _level_beds(getattr(args, "level_beds", None))
        one_bed = _one_bed(scen, search_sim, args) if searched else None
        if one_bed is not None:
            reps, numerics, grain, gfit, level_beds = [], (), (), (), 1
        gfit_sim, gfit_how = _grain_fit_setup(
            scen, search_sim, gfit, getattr(args, "grain_fit_tier", None) or "search", cmap,
            Path(args.out), packing_cache=pcache, run_cache=rcache, full_sim=full)
        rep = screen_then_confirm(baseline, rec, full, top_k=max(1, int(n_full) - 1),
                                  rom_base=base_params, calibrate_to_baseline=source != "rom",
                                  baseline_raw=base_raw, full_search=searched,
                                  search_simulator=search_sim, replicates=reps,
                                  numerics=numerics, level_beds=level_beds,
                                  grain_check=grain, grain_fit=gfit,
                                  grain_fit_simulator=gfit_sim,
                                  law_fit=lfit, law_fit_law=lfit_law,
                                  law_fit_stiffness=lfit_own, bed_floor=bed_floor,
                                  grain_agree=getattr(args, "grain_check_agree", None)
                                  or GRAIN_CHECK_AGREE, **cat_kw)
        rep.simulations["full_search"] = search_how
        if gfit_how is not None:
            rep.simulations["grain_fit"] = gfit_how
        if one_bed is not None:
            rep.simulations["imported_bed"] = one_bed
        if hasattr(full, "describe"):
            rep.simulations["confirmation"] = full.describe()
    else:
        rep = diagnose(baseline, rec, rom_base=base_params, calibrate_to_baseline=source != "rom",
                       baseline_raw=base_raw, **cat_kw)
    rep.simulations["baseline_source"] = source
    rep.simulations["run_cache"] = rcache.describe() if rcache is not None else {
        "directory": "off"}
    rep.simulations["packing_cache"] = {
        "directory": "off" if pcache is None else str(own),
        "beds_deposited": sum(len(_cached_beds(d) - b) for d, b in beds_before.items()),
        "directories": [str(d) for d in beds_before]}
    if decimated:  # done here, before the baseline's settings, so diagnose() saw none to do
        rep.fit["decimated"] = decimated
    if skipped:
        rep.fit["recorded_channels_skipped"] = dict(skipped)
    rep.fit["recorded_channels"] = {rom: {"recorded": name, "converted": conversions.get(rom)}
                                    for name, rom in cmap.items()}
    paths = write_report(rep, args.out)
    print(paths["json"])
    print(paths["md"])
    for p in paths["plots"]:
        print(p)
    return 0


#: replicate packings of the baseline run with the full-model search (the realisation floor,
#: ``screen_then_confirm(..., replicates=...)``): 4 seeds, on the coarse search tier about a
#: second each once their beds are deposited
DEFAULT_REPLICATES = 4


def _replicates(scen, n: int | None, searched: bool) -> list[dict[str, Any]]:
    """``--replicates``: the overrides of the replicate realisations (``scenario.seed`` + 1 ...
    + n); by default ``DEFAULT_REPLICATES`` when the full-model search runs, else none (they
    would cost full runs at the scenario's resolution; ask for them explicitly)."""
    if n is None:
        n = DEFAULT_REPLICATES if searched else 0
    if not 0 <= n <= 32:
        raise ValueError(f"--replicates={n!r}: must be in [0, 32] (replicate packings of the "
                         f"baseline)")
    from crashdem.diagnosis import replicate_overrides

    return replicate_overrides(scen.get("scenario.seed"), n)


def _one_bed(scen, search_sim, args) -> dict[str, Any] | None:
    """The search on an imported bed itself (``soil.packing_file``, no coarse tier): the
    recording's bed is the model's, one realisation, so there are no replicate packings (another
    ``scenario.seed`` repeats the bed), one bed per level and no numerics check (a grain-radius
    factor does not change an imported bed). Returns what the report records (the bed and the
    reasons), None when the search deposits its beds. An explicit ``--replicates``,
    ``--level-beds`` or ``--numerics-check`` that would repeat the bed is refused."""
    from crashdem.beds import FIELD as field

    bed = imported_bed(scen)
    if bed is None or search_sim is not None:
        return None
    for opt, val, none in (("--replicates", getattr(args, "replicates", None), (None, 0)),
                           ("--level-beds", getattr(args, "level_beds", None), (None, 1))):
        if val not in none:
            raise ValueError(f"{opt}={val!r}: the scenario's bed is imported ({field}="
                             f"{bed['packing_file']!r}), one realisation that another packing "
                             f"seed repeats; allowed: {none[1]} (or leave it out)")
    for opt, val, parse in (("--numerics-check", getattr(args, "numerics_check", None),
                             _numerics_scales),
                            ("--grain-check", getattr(args, "grain_check", None), _grain_scales),
                            ("--grain-fit", getattr(args, "grain_fit", None), _grain_fit_scales)):
        if val is not None and parse(val):
            raise ValueError(f"{opt}={val!r}: the scenario's bed is imported ({field}), whose "
                             "grain radii a radius factor does not change; allowed: off (or "
                             "leave it out)")
    return {**bed, "replicates": 0, "level_beds": 1, "numerics_check": "off",
            "why": ("the recording's bed is the model's (imported, one realisation): no "
                    "replicate packings or realisation floor, one bed per search level, no "
                    "grain-radius numerics check; what is left between the two is the "
                    "dynamics, which the noise and model-error floor weigh")}


def _level_beds(n: int | None) -> int | None:
    """``--level-beds``: beds per search level of a deposited effect (None: the default of
    ``screen_then_confirm``, ``confirm.LEVEL_BEDS`` when the search runs on the scenario
    itself, ``confirm.SEARCH_TIER_LEVEL_BEDS`` on the coarse search tier; used up to 1 + the
    number of replicates)."""
    if n is None:
        return None
    if not 1 <= n <= 33:
        raise ValueError(f"--level-beds={n!r}: must be in [1, 33] (beds per search level of a "
                         "floor or interface depth; 1 = one bed)")
    return int(n)


def _numerics_scales(text: str | None) -> tuple[float, ...]:
    """``--numerics-check``: the grain-radius factors of the numerics check of a named value
    (default ``confirm.NUMERICS_RADIUS_SCALES``; ``off`` = none)."""
    from crashdem.diagnosis.confirm import NUMERICS_RADIUS_SCALES

    return _radius_factors(text, "--numerics-check", NUMERICS_RADIUS_SCALES)


def _grain_scales(text: str | None) -> tuple[float, ...]:
    """``--grain-check``: the grain-radius factors at which the whole confirmation of a named
    soil effect is made again (default ``confirm.GRAIN_CHECK_SCALES``; ``off`` = none)."""
    from crashdem.diagnosis.confirm import GRAIN_CHECK_SCALES

    return _radius_factors(text, "--grain-check", GRAIN_CHECK_SCALES)


def _grain_fit_scales(text: str | None) -> tuple[float, ...]:
    """``--grain-fit``: the grain-radius factors at which the baseline's realisations are run
    to find the grain size that fits the recording (default ``confirm.GRAIN_FIT_SCALES``;
    ``off`` = none)."""
    from crashdem.diagnosis.confirm import GRAIN_FIT_SCALES

    return _radius_factors(text, "--grain-fit", GRAIN_FIT_SCALES)


def _law_fit_factors(scen, text: str | None
                     ) -> tuple[tuple[float, ...], str, tuple[float, ...]]:
    """``--law-fit``: the factors on the scenario's grain modulus at which the baseline's
    realisations run in the other contact law (default ``confirm.LAW_FIT_FACTORS``; ``off`` =
    none), as the absolute ``soil.impact_young_factor`` values (times the scenario's own);
    that law: Hertz-Mindlin for a linear scenario, linear for a Hertz-Mindlin one; and the
    same values but the scenario's own (factor 1), at which they run in the scenario's law."""
    from crashdem.diagnosis.confirm import IMPACT_YOUNG_KEY, LAW_FIT_FACTORS, impact_young_range

    own = float(scen[IMPACT_YOUNG_KEY])
    law = "linear" if scen["soil.contact_law"] == "hertz_mindlin" else "hertz_mindlin"
    lo, hi = impact_young_range()
    out = _factors(text, "--law-fit", lo / own, hi / own, "factors on the grains' modulus",
                   "2,4,8", f"with the scenario's {IMPACT_YOUNG_KEY}={own:g}, the modulus "
                   f"factor must stay in [{lo:g}, {hi:g}]")
    ks = LAW_FIT_FACTORS if out is None else out
    return tuple(own * k for k in ks), law, tuple(own * k for k in ks if k != 1.0)


def _radius_factors(text: str | None, opt: str, default: Sequence[float]
                    ) -> tuple[float, ...]:
    """Comma-separated grain-radius factors of option ``opt`` (``off`` = none, None = the
    default), each in ``distributed.RADIUS_SCALE_RANGE``."""
    from crashdem.diagnosis.distributed import RADIUS_SCALE_RANGE

    out = _factors(text, opt, *RADIUS_SCALE_RANGE, "grain-radius factors", "0.9,1.1",
                   "a factor on the scenario's grain radius")
    return tuple(default) if out is None else out


def _factors(text: str | None, opt: str, lo: float, hi: float, what: str, example: str,
             why: str) -> tuple[float, ...] | None:
    """Comma-separated factors of option ``opt`` (None: not given; ``off`` = none), each in
    [lo, hi]; a value that is not a number, or out of range, is refused naming the option, the
    value and the range (``what``: the factors' name, ``example``: a valid value, ``why``: what
    the range means)."""
    if text is None:
        return None
    if text.strip().lower() in ("off", "none", ""):
        return ()
    try:
        out = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"{opt}={text!r}: must be comma-separated {what} in [{lo:g}, {hi:g}] "
                         f"(e.g. {example}) or off") from None
    bad = [f for f in out if not lo <= f <= hi]
    if bad:
        raise ValueError(f"{opt}={text!r}: factor {bad[0]:g} is outside [{lo:g}, {hi:g}] "
                         f"({why})")
    return out


#: the coarse resolution of the full-model search (validation/campaign/studies.py "small":
#: 0.10 m grains in a 2 m tank, ~700 grains, about a second per impact once deposited)
SEARCH_COARSE: dict[str, Any] = {"soil.radius": 0.10, "soil.radius_spread": 0.10,
                                 "container.diameter": 2.0, "container.length": 2.0,
                                 "container.width": 2.0}

#: ``--full-search auto`` also searches on a scenario finer than ``SEARCH_COARSE`` itself when
#: one impact costs at most as much as one in a bed of this many grains of the campaign soil at
#: 0.075 m and safety 0.3 (``search_load``): there the whole search, its deposited levels on 5
#: beds each, fits the budget. Measured (session 17, 2-core VM, cold): 0.075 m grains in the 2 m
#: tank (load 2,051; 1,613 grains deposited) 263-298 s and 73-79 full runs per diagnosis, 491 s
#: at most (a refinement on 5 beds), so about 10 min at most at the gate; the same tank with the
#: campaign's 1 m compacted layer (E x 3: 3,553) and the 6 m tank (18,462; 16,336 deposited)
#: stay on the coarse tier
AUTO_FULL_LOAD = 2500
#: ``--grain-fit-tier tier`` runs the grain fit on ``grain_fit_tier`` when one impact there costs
#: at most this (``search_load``). The grain fit is 5 realisations at each of 4 grain sizes, 20
#: runs against the search's 73-79, so at this load it costs about what 40 search runs at
#: ``AUTO_FULL_LOAD`` do, about half the search's measured 263-298 s. The drop scenarios'
#: 0.075 m grains with their 1 m compacted layer (E x 3) in the 2 m tank: 3,553
GRAIN_FIT_TIER_LOAD = 5000
#: the solid fraction ``bed_grains`` assumes (deposited beds: 0.55-0.6)
BED_SOLID_FRACTION = 0.6
#: the grain ``AUTO_FULL_LOAD`` counts in: the campaign soil's smallest grain (0.075 m,
#: spread 0.2: 0.06 m; E = 2.0e7 Pa, 2650 kg/m^3) at safety 0.3, whose DEM step is the reference
_LOAD_REFERENCE = {"radius": 0.06, "young": 2.0e7, "density": 2650.0, "safety": 0.3}


def _bed_grains(spec) -> float:
    depth = sum(layer.thickness for layer in spec.layers)
    return BED_SOLID_FRACTION * spec.container.area * depth / spec.radius.mean_volume


def imported_bed(scen) -> dict[str, Any] | None:
    """The scenario's imported bed (``soil.packing_file``, ``crashdem.beds``): its path, grain
    count and smallest radius [m]; None when the scenario deposits its bed. The file is read
    once per version of it (``_bed_facts``), however often a diagnosis asks."""
    path = scen.get("soil.packing_file")
    if not path:
        return None
    try:
        st = Path(path).stat()
    except OSError:
        st = None  # read_bed names the missing file
    grains, r_min = _bed_facts(str(path), st and st.st_mtime_ns, st and st.st_size)
    return {"packing_file": str(path), "grains": grains, "r_min": r_min}


@functools.lru_cache(maxsize=8)
def _bed_facts(path: str, mtime_ns: int | None, size: int | None) -> tuple[int, float]:
    """Grain count and smallest radius of the bed file ``path`` (its modification time and
    size in the key, so an edited file is read again)."""
    from crashdem.beds import read_bed

    _, r = read_bed(Path(path))
    return int(len(r)), float(r.min())


def bed_grains(scen) -> float:
    """Estimated number of grains in the scenario's bed: ``BED_SOLID_FRACTION`` x the bed's
    volume (container cross-section x soil depth, or the floor depth of a switched-on
    ``boundary_proximity``) / the mean grain volume of its radius distribution. Deterministic
    (no deposition); it does not undercount: the 2 m and 6 m tanks at 0.075 m deposit 79 % and
    88 % of it. An imported bed (``soil.packing_file``) counts its file's grains."""
    from crashdem.run import packing_spec

    bed = imported_bed(scen)
    if bed is not None:
        return float(bed["grains"])
    return _bed_grains(packing_spec(scen))


def search_load(scen) -> float:
    """The cost of one impact of the scenario in grains of the reference bed
    (``_LOAD_REFERENCE``): ``bed_grains`` x the reference step / the scenario's step. The step
    is ``solver.dt``, else ``solver.safety`` x the P-wave step
    (``soil.timestep.pwave_time_step``) of the smallest grain in the stiffest soil material (a
    run's critical step is that or the contact-stiffness step, which scales the same way); an
    imported bed counts its file's grains and smallest radius."""
    from soil.timestep import pwave_time_step

    from crashdem.run import packing_spec

    ref = _LOAD_REFERENCE
    ref_dt = ref["safety"] * pwave_time_step(np.array([ref["radius"]]), np.array([ref["young"]]),
                                             np.array([ref["density"]]))
    spec = packing_spec(scen)
    bed = imported_bed(scen)
    dt = scen.get("solver.dt")
    if dt is None:
        mats = spec.materials
        r_min = spec.radius.r_min if bed is None else bed["r_min"]
        dt = scen.get("solver.safety") * pwave_time_step(
            np.full(len(mats), r_min), np.array([m.young for m in mats]),
            np.array([m.density for m in mats]))
    return (_bed_grains(spec) if bed is None else float(bed["grains"])) * ref_dt / dt


def search_tier(scen) -> dict[str, Any]:
    """The overrides of the coarse search tier for ``scen``: ``SEARCH_COARSE``, but never finer
    or larger than the scenario itself -- the grain radius at least the scenario's, the radius
    spread and the container (a cylinder's diameter; a box's length and width, each) at most
    the scenario's. A tier wider than the scenario's container would move its walls away from
    the impact, and one with finer grains would cost more than the scenario. A scenario on an
    imported bed (``soil.packing_file``) is searched on deposited coarse beds."""
    box = scen.get("container.shape") == "box"
    out: dict[str, Any] = {
        "soil.radius": max(SEARCH_COARSE["soil.radius"], float(scen.get("soil.radius"))),
        "soil.radius_spread": min(SEARCH_COARSE["soil.radius_spread"],
                                  float(scen.get("soil.radius_spread")))}
    for k in (("container.length", "container.width") if box else ("container.diameter",)):
        out[k] = min(SEARCH_COARSE[k], float(scen.get(k)))
    if scen.get("soil.packing_file"):
        # an imported bed is the scenario's grains: the coarse tier deposits its own beds
        out["soil.packing_file"] = ""
    return out


def _search_on_itself(scen, mode: str) -> tuple[bool, float | None]:
    """Whether the full-model search of ``--full-search mode`` runs on the scenario itself,
    and the load the ``auto`` gate measured for it (None when none was needed): ``full`` yes,
    ``coarse`` no; ``auto`` yes for a scenario no finer than the coarse tier (its radius spread
    alone does not count) that deposits its bed, else when ``search_load`` is at most
    ``AUTO_FULL_LOAD`` (an imported bed always goes through the gate: its grains are the
    file's, not the scenario's radius)."""
    if mode == "full":
        return True, None
    if mode != "auto":
        return False, None
    coarse = search_tier(scen)
    finer = any(not math.isclose(v, float(scen.get(k)), rel_tol=1e-3)
                for k, v in coarse.items() if k not in ("soil.radius_spread", "soil.packing_file"))
    if not finer and not scen.get("soil.packing_file"):
        return True, None
    load = search_load(scen)
    return load <= AUTO_FULL_LOAD, load


#: the form (``catalogue.FullSearch.forms``) a search on an imported bed keeps
IMPORTED_BED_FORM = "stiffness"


def _search_setup(scen, planar: bool, mode: str, cmap: dict[str, str], out: Path,
                  packing_cache: Path | None = None, run_cache: Any = None
                  ) -> tuple[dict[str, Any], Any, str]:
    """The full-model search of ``crashdem diagnose`` (``--full-search``): the effects searched
    (the drop catalogue's ``full_search`` minus the physics the scenario already has switched
    on), the simulator it runs on (None: the full simulator) and a one-line description.

    ``auto`` (default) searches on the scenario itself when it is no finer than the coarse
    resolution (``SEARCH_COARSE``) or when its impacts are cheap (``search_load`` at most
    ``AUTO_FULL_LOAD``), else on the scenario at the coarse resolution, whose best levels
    are then confirmed at the scenario's own (``screen_then_confirm``'s ``search_simulator``;
    coarse runs instead of full ones: at the default resolution, 16,300 grains, one full run
    takes about two minutes); ``full`` always on the scenario; ``coarse`` always coarse;
    ``off`` none. The coarse runs deposit their beds in ``packing_cache`` when given
    (``_packing_cache``), else in ``out/search_runs/packings``, and are kept in / taken from
    ``run_cache`` (``crashdem.runcache.RunCache``) when given."""
    from crashdem.diagnosis.catalogue import DROP, HERTZ_FLOOR_YOUNG_FACTOR

    if mode not in ("auto", "full", "coarse", "off"):
        raise ValueError(f"--full-search={mode!r}: must be one of auto, full, coarse, off")
    if planar or mode == "off":
        return {}, None, "off" if mode == "off" else "not available for the glider"
    searched = {}
    unsearched = []
    bed = imported_bed(scen)
    for k, fs in DROP.full_search.items():
        if scen.get(f"physics.{k}.enabled") or (k == "particle_rotation"
                                                and scen.get("soil.rotation") == "free"):
            continue
        if bed is not None and fs.forms and IMPORTED_BED_FORM in dict(fs.forms):
            # an imported bed is not re-deposited: its layer is the stiffness form alone
            # (crashdem.beds), and the other form would repeat its runs
            fs = fs.with_form(IMPORTED_BED_FORM)
        # levels the scenario cannot take are dropped (a floor above its layering interface is
        # taken: it ends the column there, distributed.scenario_overrides; an imported bed takes
        # no floor depth, crashdem.beds.check_scenario)
        ok = tuple(x for x in fs.values if _runnable(scen, fs.overrides(x)))
        if len(ok) >= 2:
            searched[k] = replace(fs, values=ok) if ok != fs.values else fs
        else:
            unsearched.append(k)
    coarse = search_tier(scen)

    def top_row(radius: Any) -> dict[str, Any]:
        # the layering levels' bed's top grain row (the realisation floor's bed stiffer below
        # it, catalogue.stiffer_soil_depths): one mean grain diameter of the simulator that
        # runs the levels; an imported bed keeps the shallowest level
        if "soil_layering" in searched and bed is None and radius:
            searched["soil_layering"] = replace(searched["soil_layering"],
                                                top_row_depth=2.0 * float(radius))
        # the realisation floor's bed with the other contact law (the recording's code may use
        # Hertz-Mindlin, most codes' default): a linear scenario's only
        if "soil_layering" in searched and scen.get("soil.contact_law") == "linear":
            searched["soil_layering"] = replace(searched["soil_layering"],
                                                hertz_floor=HERTZ_FLOOR_YOUNG_FACTOR)
        return searched

    note = ""
    if unsearched:
        why = ("the imported bed (soil.packing_file) has its own floor" if bed is not None
               else "none of its levels runs on this scenario")
        note = f"; not searched: {', '.join(unsearched)} ({why})"
    itself, load = _search_on_itself(scen, mode)
    if itself and load is None:
        return (top_row(scen.get("soil.radius")), None,
                f"{len(searched)} effects on the scenario itself{note}")
    if itself:
        what = (f"the imported bed: {bed_grains(scen):,.0f} grains" if bed is not None
                else f"a small bed: about {bed_grains(scen):,.0f} grains")
        return top_row(scen.get("soil.radius")), None, (
            f"{len(searched)} effects on the scenario itself ({what}, load {load:,.0f} <= "
            f"{AUTO_FULL_LOAD:,}){note}")
    search, tier = _tier_runner(scen, coarse, cmap, out / "search_runs", packing_cache,
                                run_cache)
    return top_row(coarse.get("soil.radius", scen.get("soil.radius"))), search, (
        f"{len(searched)} effects at the coarse resolution ({tier}), the leading ones confirmed "
        f"at the scenario's" + (" (the coarse tier on deposited beds: the imported bed is the "
                                "scenario's only)" if bed is not None else "") + note)


def _bed_floor(scen, searched: Mapping[str, Any]) -> BedFloor | None:
    """The realisation floor's stiffer soil (``catalogue.BedFloor``) for a search in which the
    layering is not searched because the scenario has its own (the reference campaign's
    compacted lower part): the whole bed x2 / x5 stiffer through the grains' impact modulus,
    and for a linear scenario the whole bed in the Hertz-Mindlin law at
    ``HERTZ_FLOOR_YOUNG_FACTOR``, as the layering's stiffness form gives them on a uniform
    bed. None when nothing is searched, the layering is searched, or the scenario has no
    layering of its own."""
    from crashdem.diagnosis.catalogue import HERTZ_FLOOR_YOUNG_FACTOR, BedFloor

    if not searched or "soil_layering" in searched or not scen.get(
            "physics.soil_layering.enabled"):
        return None
    return BedFloor(hertz=HERTZ_FLOOR_YOUNG_FACTOR
                    if scen.get("soil.contact_law") == "linear" else None)


def grain_fit_tier(scen) -> dict[str, Any]:
    """The overrides of the grain fit's tier for ``scen``: the coarse search tier's container
    (``search_tier``) with the scenario's own grains (radius and spread). The grain fit asks
    how the response changes when the scenario's grains are made coarser or finer; on the
    coarse tier, whose grains are already coarser, a factor makes another change (measured:
    a crashdem truth at 1.25 x the scenario's grains rated worst of the larger sizes there,
    docs/diagnosis.md "The grain fit")."""
    return {k: v for k, v in search_tier(scen).items()
            if k not in ("soil.radius", "soil.radius_spread")}


def _grain_fit_setup(scen, search_sim, factors: tuple[float, ...], mode: str,
                     cmap: dict[str, str], out: Path, packing_cache: Path | None = None,
                     run_cache: Any = None, full_sim: Any = None) -> tuple[Any, str | None]:
    """The simulator the grain fit runs on (``--grain-fit-tier``; None: the one the search
    runs on) and a one-line description (None when there is no grain fit). When the search runs
    on a separate coarse tier: ``search`` (default) on it; ``tier`` on ``grain_fit_tier`` when
    one impact there costs at most ``GRAIN_FIT_TIER_LOAD`` (``search_load``), else on the
    search's simulator; ``full`` on the scenario itself (``full_sim``, the confirmation's
    simulator: 5 full runs per grain size, the model's grains too). Neither ``tier`` nor
    ``full`` found the grain size of a recording at the default resolution (docs/diagnosis.md
    "The grain fit": the packings of one grain size scatter more than the sizes differ); they
    are there to measure that on other recordings."""
    if mode not in ("search", "tier", "full"):
        raise ValueError(f"--grain-fit-tier={mode!r}: must be one of search, tier, full")
    if not factors:
        return None, None
    if search_sim is None:
        return None, "on the simulator the search runs on (the scenario itself)"
    if mode == "full":
        if full_sim is None:
            raise ValueError("--grain-fit-tier=full: no full simulator to run it on")
        return full_sim, "on the scenario itself (--grain-fit-tier full), anchored on the baseline"
    if mode == "search":
        return None, "on the coarse search tier (--grain-fit-tier search)"
    ov = grain_fit_tier(scen)
    load = search_load(scen.with_overrides(ov))
    if load > GRAIN_FIT_TIER_LOAD:
        return None, (f"on the coarse search tier (the scenario's grains in its container: load "
                      f"{load:,.0f} > {GRAIN_FIT_TIER_LOAD:,})")
    sim, what = _tier_runner(scen, ov, cmap, out / "grain_fit_runs", packing_cache, run_cache)
    return sim, (f"on the scenario's grains in the coarse tier's container ({what}; load "
                 f"{load:,.0f} <= {GRAIN_FIT_TIER_LOAD:,}), anchored on the baseline")


def _tier_runner(scen, ov: dict[str, Any], cmap: dict[str, str], out_dir: Path,
                 packing_cache: Path | None, run_cache: Any) -> tuple[Any, str]:
    """A local runner (``_local_runner``) of ``scen`` with the tier's overrides ``ov`` into
    ``out_dir``, its beds deposited in ``packing_cache`` when given, and ``ov`` as text."""
    sim = _local_runner(scen.with_overrides(ov), cmap, out_dir, run_cache)
    if packing_cache is not None:
        from crashdem.run import share_packings

        share_packings(out_dir, packing_cache)
    return sim, ", ".join(f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v!r}"
                          for k, v in ov.items())


def _local_runner(scen, cmap: dict[str, str], out_dir: Path, run_cache: Any = None):
    """``f(overrides) -> channels``: ``scen`` with a hypothesis's overrides
    (``distributed.scenario_overrides``: ``calibration.*`` factors made absolute) run in this
    process into ``out_dir``, its diagnosed channels read back (``_result_channels``); with a
    ``run_cache`` (``crashdem.runcache.RunCache``) a run made before is read from the cache
    and a new one kept there (the runs are read, not kept in ``out_dir``)."""
    def run(ov: dict[str, Any]) -> dict[str, Signal]:
        from crashdem.diagnosis.distributed import scenario_overrides
        from crashdem.run import run_scenario

        s = scen.with_overrides(scenario_overrides(scen, ov))
        path = (run_scenario(s, out_dir=out_dir, progress=False) if run_cache is None
                else run_cache.run(s, out_dir, keep=False))
        return {k: v for k, v in _result_channels(path, cmap).items() if v is not None}

    return run


def _runnable(scen, overrides: dict[str, Any]) -> bool:
    """True when the scenario with ``overrides`` is valid and its bed can be specified (the
    checks ``crashdem.run`` makes before any deposition)."""
    from crashdem.diagnosis.distributed import scenario_overrides
    from crashdem.run import packing_spec
    from crashdem.scenario import ScenarioError

    try:
        s = scen.with_overrides(scenario_overrides(scen, overrides))
        packing_spec(s)
        if s.get("soil.packing_file"):
            from crashdem.beds import check_scenario

            check_scenario(s)
    except (ScenarioError, ValueError):
        return False
    return True


class _LocalFallback:
    """The Dask confirmation simulator, falling back to runs in this process when the cluster
    cannot be used at all (it does not start, the scheduler is unreachable); failed *runs*
    (``RuntimeError`` naming them) are not retried here: the confirmation reports them."""

    def __init__(self, dask_sim, local, prepare_local):
        self.dask, self.local, self.prepare_local = dask_sim, local, prepare_local
        self.fallback_reason: str | None = None

    def map(self, batch):
        if self.fallback_reason is None:
            try:
                return self.dask.map(batch)
            except RuntimeError:
                raise
            except Exception as e:  # noqa: BLE001 - any cluster start-up / transport failure
                self.fallback_reason = f"{type(e).__name__}: {e}"
                import logging

                logging.getLogger(__name__).warning(
                    "diagnose: Dask confirmation unavailable (%s); running the full simulations "
                    "in this process", self.fallback_reason)
                self.prepare_local()
        return [self.local(ov) for ov in batch]

    def __call__(self, overrides):
        return self.map([overrides])[0]

    def describe(self):
        d = dict(self.dask.describe()) if hasattr(self.dask, "describe") else {}
        if self.fallback_reason is not None:
            d["fallback_in_process"] = self.fallback_reason
        return d


#: full simulations of the default confirmation (the recalibrated run + the two best candidates)
DEFAULT_FULL_CONFIRM = 3


def _packing_cache(text: str | None) -> Path | None:
    """The packing cache of ``--packing-cache`` (``crashdem.run.packing_cache``): None (the
    default) -> the user's shared cache, ``off`` -> None (each diagnosis deposits its beds in
    its own output directory), a directory -> that directory (under the engine's fingerprint)."""
    from crashdem.run import packing_cache

    if text is None:
        return packing_cache()
    if text.strip().lower() in ("off", "none", ""):
        return None
    return packing_cache(text)


def _cached_beds(cache: Path | None) -> set[Path]:
    return set(cache.glob("packing-*.h5")) if cache is not None and cache.is_dir() else set()


def _share_packings(source: str, run_dirs: list[Path], cache: Path | None = None
                    ) -> Path | None:
    """Let the confirmation runs reuse deposited beds: link the packing cache of each
    confirmation run directory (``OUT/confirmation.h5.members`` on Dask, ``OUT/full_runs`` in
    process), when it does not exist yet, to the baseline run's (``<baseline dir>/packings``:
    the runs then take the baseline's own bed; for a baseline run by this diagnosis that is
    ``cache`` when given), else to ``cache``. Returns the directory linked to (resolved), or
    None."""
    from crashdem.run import share_packings

    target = None
    if source.startswith("full run ") or source.startswith("full result "):
        base = Path(source.split(" ", 2)[2]).parent / "packings"
        if base.is_dir():
            target = base.resolve()
    if target is None and cache is not None:
        target = cache
    if target is not None:
        for d in run_dirs:
            share_packings(d, target)
    return target


#: simulation channels that stand for each model channel when the recording's names differ
#: (drop mass first, then the glider's rear accelerometer pair and gyro; a result holds one)
SIM_CHANNELS: dict[str, tuple[str, ...]] = {
    ACCEL: ("drop_mass_accel_z", "rear_accel_z"), VELOCITY: ("drop_mass_velocity_z",),
    "accel_x": ("rear_accel_x",), "pitch_rate": ("pitch_rate",)}


def sim_channel(names, rom_name: str) -> str | None:
    """The first simulation channel among ``names`` standing for ``rom_name``, or None."""
    return next((n for n in SIM_CHANNELS.get(rom_name, ()) if n in names), None)


def _simulate(params: RomParams | PlanarParams, settings: RomSettings) -> dict[str, Signal]:
    """The screening model's channels (drop or planar)."""
    if isinstance(params, PlanarParams):
        return simulate_planar(params, settings)
    return simulate(params, settings)


def _baseline(scen, cmap: dict[str, str], rom_params: RomParams | PlanarParams,
              settings: RomSettings,
              mode: str = "run", out_dir: Path | None = None,
              packing_cache: Path | None = None, run_cache: Any = None
              ) -> tuple[dict[str, Signal], str]:
    """The baseline simulation the recording is compared with.

    ``mode``:
      * ``"run"`` (default): the scenario's full result (``crashdem.run.default_output``) when
        it exists and holds the diagnosed channels, else the scenario is run now with the full
        coupled DEM (one simulation, written under ``out_dir/baseline``). The screening model is
        then calibrated to it and anchored on it, which is what makes the screening valid for
        recordings made by another code;
      * ``"result"``: the existing full result only (error when missing);
      * ``"rom"``: the scenario's reduced-order model (fast; no anchor, so model-form
        differences of another code are not separated from missing physics).

    A run made here deposits its bed in ``packing_cache`` when given, else in
    ``out_dir/baseline/packings``; with a ``run_cache`` (``crashdem.runcache.RunCache``) the
    run is taken from it when made before (copied to ``out_dir/baseline``) and kept there.
    """
    if mode not in ("run", "result", "rom"):
        raise ValueError(f"--baseline={mode!r}: must be one of 'run', 'result', 'rom'")
    if mode == "rom":
        return _simulate(rom_params, settings), "rom"
    from crashdem.run import default_output, run_scenario

    def channels(path):
        got = _result_channels(path, cmap)
        return got if all(v is not None for v in got.values()) else None

    path = default_output(scen, None)
    if path.exists():
        got = channels(path)
        if got is not None:
            return got, f"full result {path}"
    if mode == "result":
        raise ValueError(f"--baseline=result: no full result of the scenario with the diagnosed "
                         f"channels at {path}; run `crashdem run` first or use --baseline run")
    out = Path(out_dir if out_dir is not None else ".") / "baseline"
    if packing_cache is not None:
        from crashdem.run import share_packings

        share_packings(out, packing_cache)
    base = scen.with_overrides({"output.snapshots": 0})
    path = (run_scenario(base, out_dir=out, progress=False, plots=False) if run_cache is None
            else run_cache.run(base, out, plots=False))
    got = channels(path)
    if got is None:
        raise ValueError(f"diagnose: the baseline run {path} has none of the diagnosed channels "
                         f"{sorted(cmap)} (nor {sorted(sum(SIM_CHANNELS.values(), ()))}); map them with "
                         f"--channel NAME:{next(iter(cmap.values()))}")
    return got, f"full run {path}"


def _result_channels(path: Path, cmap: dict[str, str],
                     filtered: bool = True) -> dict[str, Signal | None]:
    """The diagnosed channels of a crashdem result file (CFC-filtered as written, or raw), by
    model channel name (None where missing): the recorded name, else the simulation channel
    standing for the model channel (``sim_channel``). Only these channels are read: another
    channel of the run may legitimately hold NaN (an accelerometer marked failed past its full
    scale, e.g. the glider's nose pair), which must not make the run unusable."""
    from crashdem.results import open_result

    res = open_result(Path(path))
    try:
        out: dict[str, Signal | None] = {}
        for name, rom_name in cmap.items():
            n = name if name in res else sim_channel(res, rom_name)
            if n is None:
                out[rom_name] = None
                continue
            s = res.channel(n, filtered=filtered)
            out[rom_name] = Signal(rom_name, np.asarray(s.t), np.asarray(s.data), s.unit, s.cfc,
                                   {**s.meta, "recorded_name": n})
        return out
    finally:
        res.close()


def _baseline_raw(source: str, cmap: dict[str, str]) -> dict[str, Signal] | None:
    """The baseline run's unfiltered channels (model channel names), read from its result file,
    so that the diagnosis can re-filter the baseline at a recording's other CFC class; None
    for a ROM baseline or a file without them."""
    if not (source.startswith("full run ") or source.startswith("full result ")):
        return None
    try:
        got = _result_channels(Path(source.split(" ", 2)[2]), cmap, filtered=False)
    except (ImportError, OSError, ValueError, KeyError):
        return None
    return {k: v for k, v in got.items() if v is not None} or None


def _apply_scales(scen, scales: dict[str, float]) -> dict[str, Any]:
    """Turn ``calibration.*_scale`` factors into absolute scenario values."""
    out: dict[str, Any] = {}
    for key, f in scales.items():
        name = key.split(".", 1)[1]
        if name == "stiffness_scale":
            out["soil.material.young"] = scen.get("soil.material.young") * f
        elif name == "strength_scale":
            phi = math.radians(scen.get("soil.material.friction_angle_deg"))
            out["soil.material.friction_angle_deg"] = math.degrees(math.atan(min(50.0, f * math.tan(phi))))
        elif name == "drag_scale":
            out["soil.material.density"] = scen.get("soil.material.density") * f
    return out
