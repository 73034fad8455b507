"""Pinned draws of the Yade truth (``yade_case(fixed=...)``, ``diagnose_yade.py --fix``): a
stronger effect than the drawn span on an otherwise unchanged case; recalibrated beds
(``yade_case(recalibration=...)``, ``--recalibrate``); the script's ``--cli`` mode. No Yade run
is needed: the run is intercepted where the case hands its configuration to Yade (and the
command where the script hands it to ``crashdem diagnose``)."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from crashdem.beds import SURFACE_WALL_CLEARANCE
from validation.diagnosis_yade import cases  # noqa: E402

#: the Yade truth's tank radius [m] (the 2 m tank)
TANK = 1.0


class _Handed(Exception):
    pass


def _cfg(monkeypatch, tmp_path, *args, **kw) -> dict:
    """The configuration ``yade_case`` hands to Yade."""
    def intercept(cfg, cache):
        raise _Handed(cfg)

    monkeypatch.setattr(cases, "run_yade", intercept)
    with pytest.raises(_Handed) as got:
        cases.yade_case(*args, cache=tmp_path, **kw)
    return got.value.args[0]


def test_a_pinned_draw_changes_only_that_parameter(monkeypatch, tmp_path):
    drawn = _cfg(monkeypatch, tmp_path, 31, "cohesion")
    pinned = _cfg(monkeypatch, tmp_path, 31, "cohesion", fixed={"cohesion": 1.0e6})
    assert 1.0e5 <= drawn["cohesion"] <= 3.0e5 and pinned["cohesion"] == 1.0e6
    # the seed's other draws (grain radius, time step, Yade seed) are those of the drawn case
    assert {k: v for k, v in pinned.items() if k != "cohesion"} == \
        {k: v for k, v in drawn.items() if k != "cohesion"}
    bed = _cfg(monkeypatch, tmp_path, 32, "boundary_proximity", fixed={"bed_depth": 0.6})
    assert bed["bed_depth"] == 0.6


@pytest.mark.parametrize("effect, fixed, words", [
    ("cohesion", {"bed_depth": 0.6}, ["fixed['bed_depth']", "effect='cohesion'", "['cohesion']"]),
    (None, {"cohesion": 1e6}, ["fixed['cohesion']", "effect=None"]),
    ("boundary_proximity", {"bed_depth": 2.5}, ["fixed['bed_depth']=2.5", "(0.3, 2]", "[m]"]),
    ("cohesion", {"cohesion": -1.0}, ["fixed['cohesion']=-1.0", "[Pa]"]),
])
def test_a_pin_outside_the_truth_is_refused_with_its_name_and_range(monkeypatch, tmp_path,
                                                                    effect, fixed, words):
    monkeypatch.setattr(cases, "run_yade", lambda cfg, cache: pytest.fail("ran Yade"))
    with pytest.raises(ValueError) as err:
        cases.yade_case(21, effect, cache=tmp_path, fixed=fixed)
    for w in words:
        assert w in str(err.value), str(err.value)


@pytest.mark.parametrize("argv", [["--fix", "cohesion"], ["--fix", "cohesion=strong"],
                                  ["--effects", "cohesion", "--fix", "bed_depth=0.6"],
                                  # out of the truth's range: refused before any Yade run
                                  ["--effects", "boundary_proximity", "--fix", "bed_depth=2.5"],
                                  # a later --fix adds to an earlier one, not replaces it
                                  ["--effects", "cohesion", "--fix", "bed_depth=0.6",
                                   "--fix", "cohesion=1e6"]])
def test_the_script_refuses_a_malformed_pin(argv, capsys):
    from validation.diagnose_yade import main

    with pytest.raises(SystemExit) as ex:
        main(argv)
    assert ex.value.code == 2 and "--fix" in capsys.readouterr().err


def test_cli_mode_runs_the_command_a_user_types(monkeypatch, tmp_path):
    """``diagnose_yade.py --cli``: each case's lab channels go to ``<case>/rec.csv`` and through
    ``python -m crashdem diagnose`` with the Yade test's tank and bed (``TEST_SETUP``) and the
    extra arguments; the row is read from the report (the named hypothesis's parameters and
    their errors against the truth). No Yade and no diagnosis run: the case and the command
    are intercepted, the command line is parsed by the real parser."""
    import json
    import subprocess

    import numpy as np

    import validation.diagnose_yade as dy
    from crashdem import scenario as sc
    from crashdem.cli import build_parser
    from crashdem.diagnosis import generator_dem
    from crashdem.signal import Signal

    t = np.arange(0.0, 0.1, 1e-4)
    case = cases.YadeCase("boundary_proximity", {"floor_depth": 0.8}, 11,
                          {"accel_z": Signal("accel_z", t, np.sin(t), "m/s^2"),
                           "velocity_z": Signal("velocity_z", t, np.cos(t), "m/s")},
                          {"bed_depth": 0.8}, meta={"grains": 1600, "dt": 1e-5})
    monkeypatch.setattr(dy, "make_case", lambda *a, **k: ("boundary_proximity", case,
                                                          case.values))
    seen = {}
    real_run = subprocess.run

    def fake_run(cmd, **kw):
        if cmd[:2] != [sys.executable, "-m"]:  # e.g. platform.uname's
            return real_run(cmd, **kw)
        seen["cmd"] = cmd
        args = build_parser().parse_args(cmd[3:])
        seen["args"] = args
        out = Path(args.out)
        out.mkdir(parents=True)
        (out / "report.json").write_text(json.dumps({
            "missing_physics": "boundary_proximity",
            "hypotheses": [{"name": "cohesion", "parameters": {"cohesion": 1e5},
                            "delta_bic_vs_recalibration": 3.0},
                           {"name": "boundary_proximity", "parameters": {"floor_depth": 0.7},
                            "delta_bic_vs_recalibration": 2.0}],
            "decision": "boundary_proximity confirmed",
            "fit": {"before": {"overall": 0.6}, "after": {"overall": 0.7},
                    "after_full": {"overall": 0.8}},
            "simulations": {"full_simulations": 74, "full_search": "5 effects",
                            "packing_cache": {"beds_deposited": 3}}}))
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(subprocess, "run", fake_run)
    row = dy.cli_case("boundary_proximity", 11, tmp_path, generator_dem.SCENARIO,
                      extra=["--packing-cache", str(tmp_path / "beds")])
    cmd, args = seen["cmd"], seen["args"]
    assert cmd[:4] == [sys.executable, "-m", "crashdem", "diagnose"]
    assert Path(args.recording) == tmp_path / "boundary_proximity_11" / "rec.csv"
    assert Path(args.recording).is_file() and args.packing_cache == str(tmp_path / "beds")
    assert Path(args.scenario) == generator_dem.SCENARIO
    overrides = dict(sc.parse_override(s) for s in args.set)
    assert overrides == dy.TEST_SETUP == {"container.diameter": 2.0,
                                          "physics.soil_layering.enabled": False}
    sc.load(args.scenario, overrides)  # the scenario takes them
    assert row["claimed"] == "boundary_proximity" and row["top_ranked"] == "cohesion"
    assert row["fitted"] == {"floor_depth": 0.7}
    assert row["parameter_errors"] == {"floor_depth": pytest.approx(-0.125)}
    assert (row["score_before"], row["score_after"]) == (0.6, 0.8)
    assert (row["full_simulations"], row["beds_deposited"]) == (74, 3)
    # a failed command is an error with its output, not a row
    monkeypatch.setattr(subprocess, "run", lambda cmd, **kw: subprocess.CompletedProcess(
        cmd, 2, "", "crashdem diagnose: error: --recording: no such file")
        if cmd[:2] == [sys.executable, "-m"] else real_run(cmd, **kw))
    with pytest.raises(RuntimeError, match="no such file"):
        dy.cli_case(None, 21, tmp_path, generator_dem.SCENARIO)


def test_cli_args_need_cli(capsys):
    from validation.diagnose_yade import main

    with pytest.raises(SystemExit) as ex:
        main(["--cli-args", "--full-search coarse"])
    assert ex.value.code == 2 and "--cli-args needs --cli" in capsys.readouterr().err


def test_a_recalibrated_yade_bed_changes_only_its_soil_value(monkeypatch, tmp_path):
    """``yade_case(recalibration=...)``: the Yade bed gets another soil value (a stiffer bed, a
    higher friction angle); the seed's other draws stay; keys and ranges are
    ``generator_dem.check_recalibration``'s."""
    import math

    null = _cfg(monkeypatch, tmp_path, 21, None)
    stiff = _cfg(monkeypatch, tmp_path, 21, None, recalibration={"soil.material.young": 4.0e7})
    assert null["young"] == 2.0e7 and stiff["young"] == 4.0e7
    assert {k: v for k, v in stiff.items() if k != "young"} == \
        {k: v for k, v in null.items() if k != "young"}
    rough = _cfg(monkeypatch, tmp_path, 21, None,
                 recalibration={"soil.material.friction_angle_deg": 35.0})
    assert rough["friction_angle"] == pytest.approx(math.radians(35.0))
    assert {k: v for k, v in rough.items() if k != "friction_angle"} == \
        {k: v for k, v in null.items() if k != "friction_angle"}
    monkeypatch.setattr(cases, "run_yade", lambda cfg, cache: pytest.fail("ran Yade"))
    for bad, word in (({"soil.radius": 0.08}, "allowed"),
                      ({"soil.material.young": 1.0e9}, "[5e+06, 8e+07]")):
        with pytest.raises(ValueError, match=re.escape(word)):
            cases.yade_case(21, None, cache=tmp_path, recalibration=bad)


def test_contact_damping_hands_its_restitution_to_yade_alone(monkeypatch, tmp_path):
    """The Yade contact-damping truth hands Yade a restitution from its span (the grains become
    ``FrictViscoMat``); the other cases hand none (no dashpot); a pinned restitution outside
    (0, 1] is refused by name."""
    damped = _cfg(monkeypatch, tmp_path, 11, "contact_damping")
    lo, hi, _ = cases.YADE_EFFECT_DRAWS["contact_damping"]["restitution"]
    assert lo <= damped["restitution"] <= hi
    for effect in (None, "cohesion", "particle_rotation"):
        assert _cfg(monkeypatch, tmp_path, 11, effect)["restitution"] is None
    pinned = _cfg(monkeypatch, tmp_path, 11, "contact_damping", fixed={"restitution": 0.5})
    assert pinned["restitution"] == 0.5
    assert cases.COMPARED["restitution"] == "restitution"
    with pytest.raises(ValueError, match=re.escape("fixed['restitution']=1.5: must be in (0, 1]")):
        cases.yade_case(11, "contact_damping", cache=tmp_path, fixed={"restitution": 1.5})


def test_the_script_refuses_a_malformed_recalibration(capsys):
    from validation.diagnose_yade import main

    for argv in (["--recalibrate", "young"], ["--recalibrate", "soil.material.young=1e12"]):
        with pytest.raises(SystemExit) as ex:
            main(argv)
        assert ex.value.code == 2 and "--recalibrate" in capsys.readouterr().err


def _cubic_bed(r: float, layers: int, half_width: float = 1.0):
    """Simple cubic lattice of spheres of radius ``r`` (spacing 2r) on the floor z = 0."""
    g = np.arange(-half_width + r, half_width, 2.0 * r)
    gx, gy, gz = np.meshgrid(g, g, r + 2.0 * r * np.arange(layers), indexing="ij")
    x = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    return x, np.full(len(x), r)


@pytest.mark.parametrize("r, layers", [(0.05, 12), (0.08, 7)])
def test_bed_surface_of_a_cubic_lattice(r, layers):
    """Oracle: in a simple cubic lattice the solid fraction of a section at distance d from a
    layer's centre plane is pi (r^2 - d^2) / (4 r^2), its mean over the height 2 r^2 pi / (12
    r^2) = pi / 6; half of that is reached d = r sqrt(2/3) above the top layer's centres."""
    x, rad = _cubic_bed(r, layers)
    top = r + 2.0 * r * (layers - 1)
    assert cases.bed_surface(x, rad, TANK) == pytest.approx(top + r * np.sqrt(2.0 / 3.0),
                                                            abs=0.02 * r)
    # a grain layer more raises the surface by the spacing; the grains outside the footprint
    # (a wall ring 3 mean radii wide) do not count
    x2, rad2 = _cubic_bed(r, layers + 1)
    assert (cases.bed_surface(x2, rad2, TANK) - cases.bed_surface(x, rad, TANK)
            == pytest.approx(2 * r, abs=1e-9))
    ring = np.hypot(x2[:, 0], x2[:, 1]) > TANK - SURFACE_WALL_CLEARANCE * r
    keep = ~ring | (x2[:, 2] < top + r)
    assert cases.bed_surface(x2[keep], rad2[keep], TANK) == pytest.approx(
        cases.bed_surface(x2, rad2, TANK))


def test_bed_surface_is_the_imported_beds_surface():
    """One definition of a bed's surface: the Yade validation's is the one an imported bed's
    layer depth counts from (``crashdem.beds.free_surface``), for the same tank."""
    from crashdem.beds import free_surface
    from crashdem.scenario import load

    x, rad = _cubic_bed(0.05, 9)
    rng = np.random.default_rng(3)
    x = x + rng.normal(0.0, 0.005, x.shape)
    scen = load(ROOT / "validation/scenarios/drop_s2_h13p70.toml",
                {"container.diameter": 2 * TANK})
    assert cases.bed_surface(x, rad, TANK) == free_surface(scen, x, rad)


def test_bed_surface_needs_grains_under_the_footprint():
    x, rad = _cubic_bed(0.05, 3)
    far = x + np.array([5.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="0 grains in the central footprint of a tank of "
                                         "radius 1 m; need at least 10"):
        cases.bed_surface(far, rad, TANK)


def test_realised_depths_are_measured_on_the_yade_bed(tmp_path):
    """The compared floor depth of a Yade case is its bed's surface height (``bed_surface``:
    the floor wall at z = 0), not the drawn trim height; the interface depth is that surface's
    height above the level the Yade script makes stiffer (``surface_top - layer_depth``)."""
    r, layers = 0.05, 8
    x, rad = _cubic_bed(r, layers)
    f = tmp_path / "packing.npz"
    np.savez(f, x=x, radius=rad)
    surface = cases.bed_surface(x, rad, TANK)
    top = float(np.max(x[:, 2] + rad))
    assert cases.realised_depths({"bed_depth": top + 0.02}, f, top, TANK) == {
        "floor_depth": surface}
    got = cases.realised_depths({"layer_depth": 0.3, "layer_young_factor": 5.0}, f, top, TANK)
    assert got == {"interface_depth": pytest.approx(surface - (top - 0.3))}
    assert got["interface_depth"] < 0.3  # the highest grain top lies above the surface
    assert cases.realised_depths({"cohesion": 2e5}, f, top, TANK) == {}


def test_the_truth_radius_scales_only_the_grains(monkeypatch, tmp_path):
    """``use_truth_radius`` (``--truth-radius``): a case's grain radius is drawn about the given
    radius instead of 0.10 m, by the same factor of the seed; nothing else changes. Out of
    [0.03, 0.2] m it is refused by name, and the script refuses it before any Yade run."""
    from validation.diagnose_yade import main

    base = _cfg(monkeypatch, tmp_path, 21, None)
    monkeypatch.setattr(cases, "TRUTH_RADIUS", cases.TRUTH_RADIUS)  # restored after the test
    cases.use_truth_radius(0.075)
    fine = _cfg(monkeypatch, tmp_path, 21, None)
    assert fine["radius"] == pytest.approx(base["radius"] * 0.75, abs=1e-5)
    assert {k: v for k, v in fine.items() if k != "radius"} == \
        {k: v for k, v in base.items() if k != "radius"}
    for bad in (0.01, 0.5, float("nan")):
        with pytest.raises(ValueError, match=re.escape("truth_radius=") + ".*"
                           + re.escape("[0.03, 0.2] m")):
            cases.use_truth_radius(bad)
    monkeypatch.setattr(cases, "run_yade", lambda cfg, cache: pytest.fail("ran Yade"))
    with pytest.raises(SystemExit) as ex:
        main(["--truth-radius", "0.5"])
    assert ex.value.code == 2


def test_a_killed_yade_run_leaves_no_temporary_files_behind(monkeypatch, tmp_path):
    """``run_yade`` writes the history under ``<key>.tmp-<pid>`` and renames it when complete.
    The temporary files of a killed run (another pid) and of a failed one are removed the next
    time the same run is asked for, under the bed's lock; entries of other keys stay. Yade is
    stood in for by a fake that writes the files the script writes."""
    import subprocess

    monkeypatch.setattr(cases, "yade_available", lambda: True)
    fail = {"now": False}

    def fake_run(cmd, **kw):
        cfg = json.loads(Path(cmd[-1]).read_text())
        if not fail["now"]:
            np.save(cfg["out"] + ".npy", np.zeros((3, 4)))
            Path(cfg["out"] + ".json").write_text(json.dumps({"steps": 3}))
        else:
            np.save(cfg["out"] + ".npy", np.zeros((1, 4)))  # died before its .json
        return subprocess.CompletedProcess(cmd, 0 if not fail["now"] else 1, "", "boom")

    monkeypatch.setattr(subprocess, "run", fake_run)
    cfg = {"seed": 1, "radius": 0.1, "radius_spread": 0.1, "bed_depth": 1.0,
           "tank_radius": 0.5, "young": 1e7, "density": 2600.0, "friction_angle": 30.0,
           "stiffness_ratio": 0.25, "deposit_unbalanced": 0.01}
    hist, info = cases.run_yade(cfg, tmp_path)
    store = tmp_path / "diagnosis_yade"
    key = next(p.name[:-4] for p in store.glob("*.npy"))
    bed = Path(info["packing_npz"])
    # a driver killed after Yade wrote its files, and a bed half-written by another run
    stale = [store / f"{key}.tmp-424242.npy", store / f"{key}.tmp-424242.json",
             bed.parent / f"{bed.name}.tmp-424243.npz"]
    other = store / "otherkey.tmp-424242.npy"
    for f in (*stale, other):
        f.write_bytes(b"x")
    for f in (store / f"{key}.npy", store / f"{key}.json"):
        f.unlink()
    hist, info = cases.run_yade(cfg, tmp_path)
    assert hist.shape == (3, 4) and info["steps"] == 3
    assert not any(f.exists() for f in stale) and other.exists()
    assert not list(store.glob(f"{key}.tmp-*"))
    # a failed run raises and leaves neither an entry nor its temporary files
    for f in (store / f"{key}.npy", store / f"{key}.json"):
        f.unlink()
    fail["now"] = True
    with pytest.raises(RuntimeError, match="yade failed"):
        cases.run_yade(cfg, tmp_path)
    assert not (store / f"{key}.npy").exists() and not list(store.glob(f"{key}.tmp-*"))


def test_another_contact_law_changes_only_the_contact(monkeypatch, tmp_path, capsys):
    """``yade_case(contact_law="hertz_mindlin")`` (``--contact-law``): the case hands Yade the
    Hertz-Mindlin law, ``HERTZ_YOUNG_FACTOR`` x the Young's modulus and ``HERTZ_POISSON``, and
    nothing else changes (the seed's draws and the bed's keys, so the same bed as the linear
    law's; contact damping's restitution the same draw, which the script hands Hertz-Mindlin's
    own dashpots). Cohesion, which Yade makes with a law of its own, is refused by name, as is
    an unknown law; the script leaves those cases out before any Yade run."""
    import validation.diagnose_yade as dy

    assert cases.OWN_LAW_EFFECTS == ("cohesion",)
    for effect in (None, "soil_layering", "boundary_proximity", "contact_damping"):
        lin = _cfg(monkeypatch, tmp_path, 12, effect)
        hm = _cfg(monkeypatch, tmp_path, 12, effect, contact_law="hertz_mindlin")
        assert "contact_law" not in lin  # the linear law's runs keep their keys
        assert hm == {**lin, "contact_law": "hertz_mindlin",
                      "hertz_poisson": cases.HERTZ_POISSON,
                      "hertz_young": cases.HERTZ_YOUNG_FACTOR * lin["young"]}
    monkeypatch.setattr(cases, "CONTACT_LAW", cases.CONTACT_LAW)  # restored after the test
    cases.use_contact_law("hertz_mindlin")
    assert _cfg(monkeypatch, tmp_path, 21, None)["contact_law"] == "hertz_mindlin"
    assert "contact_law" not in _cfg(monkeypatch, tmp_path, 21, None, contact_law="linear")
    monkeypatch.setattr(cases, "run_yade", lambda cfg, cache: pytest.fail("ran Yade"))
    for effect in cases.OWN_LAW_EFFECTS:
        with pytest.raises(ValueError, match=re.escape(
                f"contact_law='hertz_mindlin' with effect={effect!r}")):
            cases.yade_case(11, effect, cache=tmp_path)
    with pytest.raises(ValueError, match=re.escape(
            "contact_law='hooke': allowed: ['linear', 'hertz_mindlin']")):
        cases.use_contact_law("hooke")
    with pytest.raises(SystemExit) as ex:
        dy.main(["--contact-law", "hooke"])
    assert ex.value.code == 2 and "--contact-law" in capsys.readouterr().err
    done = []
    monkeypatch.setattr(dy, "yade_available", lambda: True)

    def first_case(eff, s, **kw):  # stops the script at its first case
        done.append(eff)
        raise _Handed(eff)

    monkeypatch.setattr(dy, "diagnose_case", first_case)
    with pytest.raises(_Handed):
        dy.main(["--contact-law", "hertz_mindlin", "--effects", "contact_damping", "cohesion",
                 "sensor_dynamics", "--seeds", "11"])
    assert done == ["contact_damping"]
    assert "cohesion left out" in capsys.readouterr().out
