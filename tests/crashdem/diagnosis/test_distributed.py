"""The diagnosis confirmation fanned out over Dask (``crashdem.diagnosis.distributed``, issue 8).

A real LocalCluster of two worker processes runs the 1 + top_k confirmation simulations of a
screening report as one ensemble. The "full simulator" is the diagnosis generator's truth
numerics driven through the *scenario* of each run (the catalogue's scenario overrides, the
calibration factors turned into soil values as ``crashdem diagnose`` does) and written as a
crashdem result, so each member costs a fraction of a second and the test exercises the Dask
machinery, the ensemble file and the scoring, not the DEM (as in ``tests/crashdem/
test_ensemble.py``).

Oracle: identity with the serial confirmation -- same runs, same channels through the same
HDF5 storage, same scoring code: the same scores (``==``), the same confirmed physics.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import cloudpickle
import h5py
import numpy as np
import pytest

from crashdem import ensemble as en
from crashdem import scenario as sc
from crashdem.diagnosis import screen_then_confirm
from crashdem.diagnosis.cli import rom_from_scenario
from crashdem.diagnosis.distributed import DaskFullSimulator, scenario_overrides
from crashdem.diagnosis.generator import acquire, concealed_case
from crashdem.diagnosis.rom import RomParams, simulate
from crashdem.recordings import read_recording
from crashdem.results import ResultWriter

# the worker processes cannot import this test module by name: ship its functions by value
cloudpickle.register_pickle_by_value(sys.modules[__name__])

SCENARIO_TOML = """
[scenario]
name = "diagnosis_dask_test"
kind = "drop_test"
[impactor]
impact_velocity = 16.4
"""
CHANNELS = {"accel_z": "accel_z", "velocity_z": "velocity_z"}
TOP_K = 2


def truth_signals(scen: sc.Scenario, base: sc.Scenario) -> dict:
    """The generator's truth numerics for a scenario: its physics switches via
    ``rom_from_scenario``, its soil values relative to ``base`` as the ROM scale factors."""
    m, m0 = scen["soil.material"], base["soil.material"]
    phi, phi0 = (math.radians(x["friction_angle_deg"]) for x in (m, m0))
    p = rom_from_scenario(scen).with_values({
        "stiffness_scale": m["young"] / m0["young"],
        "strength_scale": math.tan(phi) / math.tan(phi0),
        "drag_scale": m["density"] / m0["density"]})
    return acquire(p, np.random.default_rng(0), noise={"accel_z": 0.0, "velocity_z": 0.0})


def write_truth(scen: sc.Scenario, base: sc.Scenario, path: Path) -> None:
    """A crashdem result file holding the truth channels of ``scen``."""
    with ResultWriter(path, scenario=scen, default_cfc=None) as w:
        for name, s in truth_signals(scen, base).items():
            w.declare_channel(name, s.unit, s.fs, t0=float(s.t[0]), kind="synthetic")
            w.append_channel(name, s.t, s.data)


class TruthMember:
    """Ensemble member function: the truth numerics of the member's scenario."""

    def __init__(self, base: sc.Scenario) -> None:
        self.base = base

    def __repr__(self) -> str:
        return "TruthMember()"

    def __call__(self, member: en.Member, path: Path) -> None:
        write_truth(member.scenario, self.base, path)


@pytest.fixture(scope="module")
def client():
    """A real LocalCluster: two worker processes, one thread each (the ensemble default)."""
    with en.dask_client(en.ClusterSettings(n_workers=2, processes=True)) as c:
        c.wait_for_workers(2, timeout=60)
        yield c


@pytest.fixture(scope="module")
def layering_case():
    """A recording with concealed soil layering (the screening names it)."""
    return concealed_case(31, "soil_layering")


def test_dask_confirmation_equals_serial(client, layering_case, tmp_path):
    """Oracle: identity with the serial confirmation (each run's scenario built the same way,
    its result written and read through crashdem HDF5): same runs in the same order, same
    overrides, same per-channel and overall scores, same confirmed physics; the 1 + k runs are
    gathered in one complete ensemble file, spread over both workers."""
    base = sc.loads(SCENARIO_TOML)
    serial_runs: list[dict] = []

    def serial_full(ov):
        scen = base.with_overrides(scenario_overrides(base, ov))
        path = tmp_path / f"serial-{len(serial_runs)}.h5"
        write_truth(scen, base, path)
        serial_runs.append(dict(ov))
        res = read_recording(path)
        return {new: res[name] for name, new in CHANNELS.items()}

    baseline, rec = simulate(RomParams()), layering_case.recording
    # the 1 + k confirmation batch (the full-model search adds 30 level runs to the same batch and
    # is covered in test_report_confirm.py)
    a = screen_then_confirm(baseline, rec, serial_full, top_k=TOP_K, full_search=False)
    full = DaskFullSimulator(base, tmp_path / "confirmation.h5", channel_map=CHANNELS,
                             member_fn=TruthMember(base), client=client)
    b = screen_then_confirm(baseline, rec, full, top_k=TOP_K, full_search=False)
    assert a.hypotheses == b.hypotheses  # the (deterministic) screening is the same

    assert a.simulations["full_simulations"] == b.simulations["full_simulations"] == 1 + TOP_K
    assert full.calls == len(serial_runs) == 1 + TOP_K
    ca, cb = a.fit["confirmation"], b.fit["confirmation"]
    assert [r["hypothesis"] for r in ca] == [r["hypothesis"] for r in cb]
    assert ca[0]["hypothesis"] == "recalibration" and len(ca) == 1 + TOP_K
    for ra, rb in zip(ca, cb):
        assert ra["overrides"] == rb["overrides"]
        assert ra["score"] == rb["score"], ra["hypothesis"]
        assert ra["per_channel"] == rb["per_channel"], ra["hypothesis"]
    assert a.fit["confirmed_missing_physics"] == b.fit["confirmed_missing_physics"]
    assert a.missing_physics == b.missing_physics and a.decision == b.decision
    # a real confirmation: the concealed effect scores above the recalibration
    scores = {r["hypothesis"]: r["score"] for r in cb}
    assert scores["soil_layering"] > scores["recalibration"]

    assert full.ensembles == [tmp_path / "confirmation.h5"]
    with en.open_ensemble(full.ensembles[0]) as ens:
        assert ens.status == "complete" and ens.kind == "members"
        recs = ens.members()
        assert [r["status"] for r in recs] == ["complete"] * (1 + TOP_K)
        assert ens.spec["hypothesis_overrides"] == [r["overrides"] for r in cb]
        # the calibration factors arrive in the member scenarios as soil values
        assert "soil.material.young" in recs[0]["overrides"]
        assert not any(k.startswith("calibration.") for r in recs for k in r["overrides"])
        workers = {r["worker"] for r in recs}
    # every run was executed by a worker of this cluster (how the scheduler spreads 3 short
    # tasks over 2 workers depends on timing, so the spread itself is not asserted)
    import os

    assert workers and all(w.rsplit(":", 1)[-1].isdigit() for w in workers), workers
    assert all(int(w.rsplit(":", 1)[-1]) != os.getpid() for w in workers), workers
    info = full.describe()
    assert info["n_workers"] == 2 and info["ensembles"] == [str(tmp_path / "confirmation.h5")]


def test_failed_confirmation_run_is_named(client, tmp_path):
    """Oracle: the documented contract -- a confirmation run that fails cannot be scored; the
    error names the member, its overrides and the member's own error."""
    base = sc.loads(SCENARIO_TOML)

    class Boom:
        def __call__(self, member, path):
            raise FloatingPointError("synthetic divergence")

    full = DaskFullSimulator(base, tmp_path / "c.h5", member_fn=Boom(), client=client)
    with pytest.raises(RuntimeError, match=r"member 0 \(physics\.soil_layering\.enabled=True\)"
                                           r".*FloatingPointError: synthetic divergence"):
        full({"physics.soil_layering.enabled": True})
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f["members/0"].attrs["status"] == "failed"


class FakeRunMember:
    """Stands in for ``crashdem.ensemble.RunMember`` in the CLI test: the truth numerics of the
    member's scenario instead of a DEM run (same constructor)."""

    def __init__(self, threads=1, snapshots=False, run_cache=None) -> None:
        self.threads = threads

    def __repr__(self) -> str:
        return f"FakeRunMember(threads={self.threads})"

    def __call__(self, member: en.Member, path: Path) -> None:
        write_truth(member.scenario, sc.loads(SCENARIO_TOML), path)


def test_cli_full_confirm_on_a_running_cluster(client, tmp_path, monkeypatch, capsys):
    """``crashdem diagnose --full-confirm 3 --scheduler ADDRESS``: the confirmation runs go to
    that cluster as one ensemble ``OUT/confirmation.h5`` (3 complete members), and the report
    counts them and names the ensemble and the scheduler. The member function is the truth
    numerics (``FakeRunMember``; the DEM member is covered by the ensemble tests)."""
    import json

    from crashdem import cli
    from crashdem.recordings import write_recording

    monkeypatch.setattr(en, "RunMember", FakeRunMember)
    case = concealed_case(32, "soil_layering")
    rec_path = write_recording(tmp_path / "rec.csv", case.recording)
    scen = tmp_path / "s.toml"
    scen.write_text(SCENARIO_TOML)
    out = tmp_path / "out"
    assert cli.main(["diagnose", "--scenario", str(scen), "--recording", str(rec_path),
                     "--out", str(out), "--baseline", "rom", "--full-confirm", "3",
                     "--full-search", "off",
                     "--scheduler", client.scheduler.address, "--member-threads", "1"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["simulations"]["full_simulations"] == 3
    conf = rep["simulations"]["confirmation"]
    assert conf["ensembles"] == [str(out / "confirmation.h5")]
    assert conf["scheduler"] == client.scheduler.address and conf["n_workers"] == 2
    with en.open_ensemble(out / "confirmation.h5") as ens:
        assert [r["status"] for r in ens.members()] == ["complete"] * 3
        assert "FakeRunMember(threads=1)" in ens.spec["member_fn"]
    assert [r["hypothesis"] for r in rep["fit"]["confirmation"]][0] == "recalibration"
    assert rep["fit"]["confirmed_missing_physics"] == "soil_layering"
    assert not (out / "confirmation.h5.members").exists()  # removed after success
