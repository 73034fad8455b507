"""End-to-end run of a tiny drop test: scenario -> packing -> coupled DEM/Exudyn -> sensors ->
HDF5 -> CLI info/plot. Small scene (a few hundred grains) so it runs in seconds once compiled."""
from pathlib import Path

import numpy as np
import pytest

from crashdem import cli
from crashdem import scenario as sc
from crashdem.results import open_result
from crashdem.run import run_scenario

ROOT = Path(__file__).resolve().parents[2]

TINY = {
    "scenario.name": "tiny_drop",
    "container.diameter": 1.3,
    "container.soil_depth": 0.45,
    "soil.radius": 0.075,
    "physics.soil_layering.enabled": False,
    "impactor.drop_height": 5.0,
    "solver.t_end": 0.03,
    "output.snapshots": 2,
    "output.plots": False,
}


@pytest.fixture(scope="module")
def tiny_result(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    scen = sc.load(ROOT / "validation/scenarios/drop_s2_h5p00.toml", TINY)
    return run_scenario(scen, out_dir=out, progress=False)


def test_result_is_complete_with_channels(tiny_result):
    with open_result(tiny_result) as res:
        assert res.complete
        names = res.channels()
        for ch in ("drop_mass_accel_z", "drop_mass_velocity_z", "drop_mass_contact_force_z",
                   "floor_load_cell_1"):
            assert ch in names
        s = res.channel("drop_mass_accel_z", filtered=False)
        assert s.unit == "m/s^2"
        assert np.allclose(np.diff(s.t), 1 / 12500.0, rtol=1e-9, atol=1e-12)
        assert res["drop_mass_accel_z"].cfc == 60.0
        assert len(res.snapshot_times()) == 2


def test_accelerometer_reads_specific_force_of_dem_contact_force(tiny_result):
    """Oracle: Newton's second law at the CG — an accelerometer measures the specific force
    a - g = F_contact / m. Its channel (body kinematics -> specific force -> body axis -> box
    sampling) must equal the DEM's contact-force channel divided by the mass to round-off: a
    sign error, gravity counted twice, or a one-step lag between the two would show here."""
    with open_result(tiny_result) as res:
        a = res.channel("drop_mass_accel_z", filtered=False).data
        f = res.channel("drop_mass_contact_force_z", filtered=False).data
    m = 850.0
    scale = np.max(np.abs(f)) / m
    assert scale > 5 * 9.81, "the sphere must actually hit the soil"
    # both channels are box-averaged over the same windows: only round-off may differ
    assert np.max(np.abs(a - f / m)) < 1e-9 * scale


def _impulse_balance(path):
    """The drop mass's Delta v_z over the record and the integral of (F_z/m - g) dt, and its
    contact force channel."""
    with open_result(path) as res:
        v = res.channel("drop_mass_velocity_z", filtered=False)
        f = res.channel("drop_mass_contact_force_z", filtered=False)
    dt = 1 / 12500.0
    return v.data[-1] - v.data[0], np.sum(f.data[1:] / 850.0 - 9.81) * dt, f.data


def test_velocity_change_equals_impulse(tiny_result):
    """Oracle: impulse–momentum theorem. Delta v_z = integral of (F_z/m - g) dt over the
    sampled record (box sampling preserves the integral of the DEM-rate signal)."""
    dv, dv_pred, _ = _impulse_balance(tiny_result)
    assert dv == pytest.approx(dv_pred, rel=0.03, abs=0.05)
    assert dv > 1.0  # the soil slowed the sphere by a clear margin


def test_cli_info_and_plot(tiny_result, tmp_path, capsys):
    assert cli.main(["info", str(tiny_result)]) == 0
    assert "drop_mass_accel_z" in capsys.readouterr().out
    assert cli.main(["plot", str(tiny_result), "--out", str(tmp_path)]) == 0
    pngs = list(tmp_path.glob("*.png"))
    assert pngs and all(p.stat().st_size > 1000 for p in pngs)


def test_cli_bad_field_exits_2(capsys):
    rc = cli.main(["run", str(ROOT / "validation/scenarios/drop_s2_h5p00.toml"),
                   "--set", "soil.material.young=-1"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "soil.material.young" in err and "-1" in err


def test_a_second_run_into_the_same_file_is_refused(tiny_result, tmp_path):
    """While a run writes its result, another run of the same file (two commands given the same
    output directory) is refused naming the file and its lock, before it builds anything; the
    lock goes when its holder ends (here: the holder closes it), and a finished run leaves no
    lock file behind. Measured before the lock: two `crashdem diagnose` into one --out crashed
    one of them in HDF5 ("addr overflow") while both wrote the same search-run file."""
    import fcntl
    import os

    from crashdem.run import output_lock
    from crashdem.scenario import ScenarioError

    assert not Path(f"{tiny_result}.lock").exists()
    scen = sc.load(ROOT / "validation/scenarios/drop_s2_h5p00.toml", TINY)
    path = tmp_path / "tiny_drop.h5"
    fd = os.open(f"{path}.lock", os.O_RDWR | os.O_CREAT)  # another process's hold
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    try:
        with pytest.raises(ScenarioError, match="another run is writing this file"):
            run_scenario(scen, out_dir=tmp_path, progress=False)
        assert not path.exists()
    finally:
        os.close(fd)
    with output_lock(path):  # free again once the holder is gone
        with pytest.raises(ScenarioError, match=r"tiny_drop\.h5\.lock"):
            with output_lock(path):
                pass
    assert not Path(f"{path}.lock").exists()


def test_hertz_mindlin_scenario_runs_with_the_law_on_every_impact_material(tiny_result,
                                                                          tmp_path):
    """Oracle: ``soil.contact_law = "hertz_mindlin"`` reaches every material of the impact phase
    (grains, wall, impactor) with ``soil.poisson``, and a linear scenario's materials stay
    linear; the coupled run keeps the impulse-momentum balance (Delta v = integral of
    F/m - g, 3 %) and its contact force differs from the linear law's on the same bed."""
    from types import SimpleNamespace

    from crashdem.run import impact_materials, soil_material

    base = ROOT / "validation/scenarios/drop_s2_h5p00.toml"
    over = dict(TINY, **{"soil.contact_law": "hertz_mindlin", "soil.poisson": 0.3,
                         "scenario.name": "tiny_hertz"})
    scen = sc.load(base, over)
    bed = SimpleNamespace(materials=(soil_material(scen),))
    mats = impact_materials(scen, bed)
    assert [m.contact_law for m in mats] == ["hertz_mindlin"] * 3
    assert {m.poisson for m in mats} == {0.3}
    assert {m.contact_law for m in impact_materials(sc.load(base, TINY), bed)} == {"linear"}
    path = run_scenario(scen, out_dir=tmp_path, progress=False)
    with open_result(path) as res:
        assert res.complete
    dv, dv_pred, f = _impulse_balance(path)
    assert dv == pytest.approx(dv_pred, rel=0.03, abs=0.05)
    assert dv > 1.0
    f_lin = _impulse_balance(tiny_result)[2]
    n = min(len(f_lin), len(f))
    assert np.max(np.abs(f[:n] - f_lin[:n])) > 0.05 * np.max(np.abs(f_lin[:n]))


def test_impact_young_factor_stiffens_the_impact_on_the_same_bed(tiny_result, tmp_path):
    """``soil.impact_young_factor`` multiplies the grains' modulus (both layers) and a wall of
    the soil's modulus in the impact phase only: the deposition spec (the packing cache key) is
    the factor-1 scenario's, the run is on the same bed (same grains, same free surface), the
    impactor's modulus and a wall of its own modulus are untouched. Oracles: the P-wave time
    step scales as 1/sqrt(E) (x0.5 at 4 x), the impulse-momentum balance holds, and the stiffer
    grains stop the sphere sooner (a higher peak contact force)."""
    from types import SimpleNamespace

    from crashdem.run import impact_materials, packing_spec, soil_material

    base = ROOT / "validation/scenarios/drop_s2_h5p00.toml"
    one = sc.load(base, TINY)
    four = sc.load(base, dict(TINY, **{"soil.impact_young_factor": 4.0,
                                       "scenario.name": "tiny_stiff"}))
    assert packing_spec(four) == packing_spec(one)
    bed = SimpleNamespace(materials=(soil_material(one), soil_material(one, lower=True)))
    m1, m4 = impact_materials(one, bed), impact_materials(four, bed)
    assert [b.young / a.young for a, b in zip(m1, m4)] == [4.0, 4.0, 4.0, 1.0]
    walled = sc.load(base, dict(TINY, **{"soil.impact_young_factor": 4.0,
                                         "container.wall_young": 3.0e7}))
    assert impact_materials(walled, bed)[2].young == 3.0e7
    with pytest.raises(sc.ScenarioError, match="soil.impact_young_factor"):
        sc.load(base, dict(TINY, **{"soil.impact_young_factor": 0.0}))

    import h5py

    path = run_scenario(four, out_dir=tmp_path, progress=False)
    with open_result(path) as res:
        assert res.complete
    with h5py.File(path, "r") as h4, h5py.File(tiny_result, "r") as h1:
        r4, r1 = dict(h4["run"].attrs), dict(h1["run"].attrs)
    assert r4["particles"] == r1["particles"] and r4["surface_z"] == r1["surface_z"]
    assert r4["dt_critical"] / r1["dt_critical"] == pytest.approx(0.5, rel=1e-9)
    dv, dv_pred, f = _impulse_balance(path)
    assert dv == pytest.approx(dv_pred, rel=0.03, abs=0.05)
    f_lin = _impulse_balance(tiny_result)[2]
    assert np.max(np.abs(f)) > 1.2 * np.max(np.abs(f_lin))


def test_shear_dashpot_from_the_scenario(tmp_path):
    """``physics.contact_damping.shear`` gives the grains a shear dashpot at the contact
    damping's restitution, ``soil.shear_restitution`` one of its own (the wall and the impactor
    take none: a pair takes the smaller value, the grains'); off by default. Oracles: the
    impulse-momentum balance of the drop mass holds with it, and its contact force differs from
    the run with the normal dashpot alone on the same bed."""
    from types import SimpleNamespace

    from crashdem.run import impact_materials, soil_material

    base = ROOT / "validation/scenarios/drop_s2_h5p00.toml"
    damped = dict(TINY, **{"physics.contact_damping.enabled": True,
                           "physics.contact_damping.restitution": 0.3,
                           "scenario.name": "tiny_damped"})
    normal = sc.load(base, damped)
    shear = sc.load(base, dict(damped, **{"physics.contact_damping.shear": True,
                                          "scenario.name": "tiny_shear"}))
    bed = SimpleNamespace(materials=(soil_material(normal),))
    assert [m.shear_restitution for m in impact_materials(normal, bed)] == [None] * 3
    assert [m.shear_restitution for m in impact_materials(shear, bed)] == [0.3, None, None]
    own = sc.load(base, dict(TINY, **{"soil.shear_restitution": 0.6}))
    assert impact_materials(own, bed)[0].shear_restitution == 0.6
    assert impact_materials(own, bed)[0].restitution is None
    with pytest.raises(sc.ScenarioError, match="soil.shear_restitution"):
        sc.load(base, dict(TINY, **{"soil.shear_restitution": 0.0}))
    forces = []
    for scen in (normal, shear):
        path = run_scenario(scen, out_dir=tmp_path, progress=False)
        dv, dv_pred, f = _impulse_balance(path)
        assert dv == pytest.approx(dv_pred, rel=0.03, abs=0.05)
        forces.append(f)
    n = min(len(forces[0]), len(forces[1]))
    assert np.max(np.abs(forces[1][:n] - forces[0][:n])) > 0.02 * np.max(np.abs(forces[0][:n]))
