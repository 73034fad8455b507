"""Ensembles on a real Dask LocalCluster (2 worker processes): sweeps gathered into one HDF5
file, a worker killed mid-member (rerun, nothing lost), resume of an interrupted ensemble,
validation before submission, and calibration to a known optimum.

The members are synthetic (``pulse_member``): each writes a small crashdem result with
``ResultWriter`` holding one half-sine pulse whose amplitude and duration are closed-form
functions of two scenario fields. That keeps each member at a few tens of ms, so the tests
exercise the Dask machinery, not the DEM (a full ``RunMember`` run costs minutes).
"""
from __future__ import annotations

import math
import os
import signal
import sys
import time
from pathlib import Path

import cloudpickle
import h5py
import numpy as np
import pytest

from crashdem import ensemble as en
from crashdem import scenario as sc
from crashdem.results import ResultWriter
from crashdem.signal import Signal

# the worker processes cannot import this test module by name: ship its functions by value
cloudpickle.register_pickle_by_value(sys.modules[__name__])

FS = 10_000.0  # [Hz] sample rate of the synthetic pulse
T_RECORD = 0.05  # [s] record length
A_REF = 50.0 * 9.80665  # [m/s^2] pulse amplitude at E = 2e7 Pa
YOUNG_REF = 2.0e7  # [Pa]


def pulse_params(young: float, phi_deg: float) -> tuple[float, float]:
    """Amplitude [m/s^2] and duration [s] of the synthetic member's pulse.

    A = A_REF sqrt(E / E_ref) (contact stiffness ~ E, peak ~ sqrt(k)); T = 0.6 / phi [s]
    (a duration that shortens with friction). Not physics: a smooth, known map for the tests.
    """
    return A_REF * math.sqrt(young / YOUNG_REF), 0.6 / phi_deg


def pulse(young: float, phi_deg: float) -> tuple[np.ndarray, np.ndarray]:
    a, dur = pulse_params(young, phi_deg)
    t = np.arange(int(round(T_RECORD * FS)) + 1) / FS
    x = np.where(t <= dur, a * np.sin(np.pi * np.clip(t / dur, 0.0, 1.0)), 0.0)
    return t, x


def _write_pulse(member: en.Member, path: Path, kill_marker: Path | None = None) -> None:
    young = member.overrides["soil.material.young"]
    phi = member.overrides["soil.material.friction_angle_deg"]
    t, x = pulse(young, phi)
    with ResultWriter(path, scenario=member.scenario, default_cfc=None, flush_every=100) as w:
        w.declare_channel("accel_z", "m/s^2", FS, kind="accelerometer")
        half = t.size // 2
        w.append_channel("accel_z", t[:half], x[:half])
        w.flush()  # the first half is on disk when the worker dies
        if kill_marker is not None and not kill_marker.exists():
            kill_marker.write_text(f"killed pid {os.getpid()}\n")
            os.kill(os.getpid(), signal.SIGKILL)  # the worker process dies mid-member
        w.append_channel("accel_z", t[half:], x[half:])


def pulse_member(member: en.Member, path: Path) -> None:
    """Synthetic member: one half-sine channel ``accel_z``."""
    _write_pulse(member, path)


class KillingMember:
    """Synthetic member that SIGKILLs its own worker on the first attempt of member ``victim``
    (first attempt detected through the marker file ``marker``)."""

    def __init__(self, victim: int, marker: Path) -> None:
        self.victim = victim
        self.marker = marker

    def __call__(self, member: en.Member, path: Path) -> None:
        _write_pulse(member, path, self.marker if member.index == self.victim else None)


class FailingMember:
    """Raises for one value of E (a deterministic member failure)."""

    def __init__(self, bad_young: float) -> None:
        self.bad_young = bad_young

    def __call__(self, member: en.Member, path: Path) -> None:
        if member.overrides["soil.material.young"] == self.bad_young:
            raise FloatingPointError("synthetic divergence")
        _write_pulse(member, path)


class CountingMember:
    """Writes one marker per call in ``calls_dir`` (to count which members really ran)."""

    def __init__(self, calls_dir: Path) -> None:
        self.calls_dir = calls_dir

    def __repr__(self) -> str:  # same ensemble spec for every instance (resume)
        return "CountingMember()"

    def __call__(self, member: en.Member, path: Path) -> None:
        (self.calls_dir / f"call-{member.index}-{time.time_ns()}").touch()
        _write_pulse(member, path)


@pytest.fixture(scope="module")
def client():
    """A real LocalCluster: two worker processes, one thread each (the ensemble default)."""
    with en.dask_client(en.ClusterSettings(n_workers=2, processes=True)) as c:
        c.wait_for_workers(2, timeout=60)
        yield c


@pytest.fixture()
def base() -> sc.Scenario:
    return sc.loads('[scenario]\nname = "ens"\n', source="test")


SWEEP = en.SweepSpec({"soil.material.young": [1e7, 2e7, 4e7],
                      "soil.material.friction_angle_deg": [20.0, 30.0]}, mode="grid")
#: the pulse is written with the same float64 arithmetic and stored as float64: exact copy
COPY_ATOL = 0.0


def _check_members(path: Path, spec: en.SweepSpec) -> list[dict]:
    """Every planned member is present, complete, with its overrides, its channel equal to the
    analytic pulse of its overrides and its peak scalar equal to the analytic amplitude."""
    with en.open_ensemble(path) as ens:
        assert ens.status == "complete"
        recs = ens.members()
        planned = spec.overrides()
        assert [r["index"] for r in recs] == list(range(len(planned)))
        for r, ov in zip(recs, planned):
            assert r["status"] == "complete", r
            assert r["overrides"] == ov
            t, x = pulse(ov["soil.material.young"], ov["soil.material.friction_angle_deg"])
            s = ens.channel(r["index"], "accel_z")
            np.testing.assert_array_equal(s.t, t)
            np.testing.assert_allclose(s.data, x, rtol=0, atol=COPY_ATOL)
            a, _ = pulse_params(ov["soil.material.young"], ov["soil.material.friction_angle_deg"])
            # 0.6/phi for phi = 20, 30 puts the crest on a sample: peak == A up to rounding
            assert r["scalars"]["accel_z.peak"] == pytest.approx(a, rel=1e-12)
        with h5py.File(path, "r") as f:
            assert f["summary/index"].shape == (len(planned),)
            assert f.attrs["n_planned"] == len(planned)
            assert f.attrs["git_hash"]
    return recs


def test_sweep_grid_gathers_every_member(tmp_path, base, client):
    """Oracle: the analytic pulse of each member's overrides (closed form), and the Cartesian
    product order of the grid (last field fastest)."""
    out = tmp_path / "sweep.h5"
    path = en.sweep(base, SWEEP, out, pulse_member, client=client)
    recs = _check_members(path, SWEEP)
    assert [r["overrides"]["soil.material.young"] for r in recs] == [1e7, 1e7, 2e7, 2e7, 4e7, 4e7]
    assert not (tmp_path / "sweep.h5.members").exists()  # cleaned after a full success
    with en.open_ensemble(path) as ens:
        assert ens.planned() == SWEEP.overrides()
        assert ens.spec["mode"] == "grid"


def test_worker_killed_mid_member_is_rerun_and_nothing_is_lost(tmp_path, base, client):
    """A worker SIGKILLed while writing member 2: the scheduler reruns the task on a live
    worker; all six members are present and equal to their analytic pulses (oracle), the
    killed member records two attempts, the others one."""
    out = tmp_path / "killed.h5"
    marker = tmp_path / "killed.marker"
    path = en.sweep(base, SWEEP, out, KillingMember(2, marker), client=client,
                    keep_members=True)
    assert marker.exists()  # the first attempt did die
    recs = _check_members(path, SWEEP)
    attempts = {r["index"]: r["attempts"] for r in recs}
    with en.open_ensemble(path) as ens:
        assert "attempts 2" in ens.summary().splitlines()[4 + 2]
    assert attempts[2] == 2
    assert all(a == 1 for k, a in attempts.items() if k != 2)
    # the dead attempt's half-written file was left under its own temporary name
    assert list((tmp_path / "killed.h5.members").glob("*.partial.h5"))


def test_map_overrides_with_objective_and_transfer(tmp_path, base, client):
    """Listed overrides (zip-like) with member files returned through Dask as bytes and an
    objective evaluated on the workers. Oracle: the RMS objective of a member against its own
    analytic pulse is 0; against the other member's it equals the closed-form relative RMS
    difference of the two pulses on the common 0.1 ms grid (the 10 kHz sample grid itself)."""
    ovs = [{"soil.material.young": 2e7, "soil.material.friction_angle_deg": 30.0},
           {"soil.material.young": 4e7, "soil.material.friction_angle_deg": 30.0}]
    t, x_ref = pulse(2e7, 30.0)
    obj = en.ChannelObjective(Signal("accel_z", t, x_ref, "m/s^2"), "accel_z", metric="rms")
    path, outs = en.map_overrides(base, ovs, tmp_path / "map.h5", pulse_member, client=client,
                                  objective_fn=obj, transfer=True)
    assert [o.status for o in outs] == ["complete", "complete"]
    x_other = pulse(4e7, 30.0)[1]
    expected = np.sqrt(np.mean((x_other - x_ref) ** 2)) / np.sqrt(np.mean(x_ref ** 2))
    with en.open_ensemble(path) as ens:
        recs = ens.members()
        assert ens.kind == "members"
    assert recs[0]["scalars"]["objective"] == pytest.approx(0.0, abs=1e-12)
    # sqrt(2) - 1 = 0.414...: amplitudes in ratio sqrt(2), same shape
    assert recs[1]["scalars"]["objective"] == pytest.approx(expected, rel=1e-9)
    assert expected == pytest.approx(math.sqrt(2) - 1, rel=1e-12)


class AlwaysKillingMember:
    """SIGKILLs its worker on every attempt of member ``victim`` (a run that always runs out of
    memory)."""

    def __init__(self, victim: int) -> None:
        self.victim = victim

    def __call__(self, member: en.Member, path: Path) -> None:
        if member.index == self.victim:
            os.kill(os.getpid(), signal.SIGKILL)
        _write_pulse(member, path)


def test_member_that_always_kills_its_worker_is_recorded_failed(tmp_path, base):
    """With allowed_failures=0 the scheduler gives up on the member after one worker death
    (KilledWorker): the member is stored as failed with that error, the ensemble completes and
    the other members are intact (oracle: analytic pulses)."""
    spec = en.SweepSpec({"soil.material.young": [1e7, 2e7],
                         "soil.material.friction_angle_deg": [30.0]})
    # one worker per member: a member queued on the worker that dies also "witnesses" the death
    # and, with allowed_failures=0, would be lost with it (seen with one shared worker; the
    # scheduler sends independent tasks to a worker regardless of worker-saturation)
    settings = en.ClusterSettings(n_workers=2, allowed_failures=0)
    path = en.sweep(base, spec, tmp_path / "oom.h5", AlwaysKillingMember(1), settings)
    with en.open_ensemble(path) as ens:
        recs = ens.members()
        assert ens.status == "complete"
        np.testing.assert_array_equal(ens.channel(0, "accel_z").data, pulse(1e7, 30.0)[1])
    assert recs[0]["status"] == "complete"
    assert recs[1]["status"] == "failed" and "KilledWorker" in recs[1]["error"]
    assert recs[1]["attempts"] == 1


def test_failed_member_is_recorded_not_fatal(tmp_path, base, client):
    """A member that raises is stored with status 'failed' and its error; the others are
    complete (oracle: analytic pulses)."""
    out = tmp_path / "failing.h5"
    path = en.sweep(base, SWEEP, out, FailingMember(4e7), client=client)
    with en.open_ensemble(path) as ens:
        recs = ens.members()
        assert ens.status == "complete"
    bad = [r for r in recs if r["status"] == "failed"]
    assert [r["overrides"]["soil.material.young"] for r in bad] == [4e7, 4e7]
    assert all("FloatingPointError: synthetic divergence" in r["error"] for r in bad)
    assert all(r["status"] == "complete" for r in recs if r not in bad)
    assert (tmp_path / "failing.h5.members").exists()  # kept: the sweep is not a full success


def test_resume_runs_only_missing_members(tmp_path, base, client):
    """An ensemble killed after two members is resumed: the two stored members are not rerun
    (oracle: the member function's call log), the four others are, and the final file holds
    all six analytic pulses."""
    out = tmp_path / "resumed.h5"
    calls1, calls2 = tmp_path / "calls1", tmp_path / "calls2"
    calls1.mkdir()
    calls2.mkdir()
    en.sweep(base, SWEEP, out, CountingMember(calls1), client=client)
    # make the file look like a gatherer killed after members 0 and 1 were written
    with h5py.File(out, "a") as f:
        for k in ("2", "3", "4", "5"):
            del f["members"][k]
        f.attrs["status"] = "running"
        f.attrs["complete"] = False
    with en.open_ensemble(out) as ens:
        assert ens.status == "running" and len(ens.members()) == 2
    en.sweep(base, SWEEP, out, CountingMember(calls2), client=client, resume=True)
    ran = sorted(int(p.name.split("-")[1]) for p in calls2.iterdir())
    assert ran == [2, 3, 4, 5]
    _check_members(out, SWEEP)


def test_writer_file_is_readable_between_members(tmp_path, base):
    """The gatherer closes the file after each member: a reader opens it while the ensemble is
    'running' and sees the members written so far (oracle: the analytic pulse)."""
    out = tmp_path / "partial.h5"
    ov = SWEEP.overrides()
    w = en.EnsembleWriter(out, "sweep", {"x": 1}, base, planned=ov)
    m = en.Member(0, ov[0], base.with_overrides(ov[0]), base.to_toml())
    pulse_member(m, tmp_path / "m0.h5")
    w.add_member(m, en.MemberOutcome(0, m.key, "complete", "", str(tmp_path / "m0.h5"), {}, 1,
                                     "here", 0.0))
    with en.open_ensemble(out) as ens:
        assert ens.status == "running"
        assert [r["index"] for r in ens.members()] == [0]
        np.testing.assert_array_equal(ens.channel(0, "accel_z").data, pulse(1e7, 20.0)[1])


def test_resume_refuses_another_ensemble(tmp_path, base):
    """Resuming into a file of a different spec is refused with both hashes named."""
    out = tmp_path / "a.h5"
    en.EnsembleWriter(out, "sweep", {"a": 1}, base).close()
    with pytest.raises(ValueError, match="another ensemble"):
        en.EnsembleWriter(out, "sweep", {"a": 2}, base, resume=True)


def test_invalid_override_rejected_before_submission(tmp_path, base):
    """A schema violation in any member is reported (field and value named) before a cluster
    is started or a file written."""
    spec = en.SweepSpec({"soil.material.young": [2e7, -3e7]})
    out = tmp_path / "bad.h5"
    with pytest.raises(sc.ScenarioError, match=r"soil\.material\.young=-3e7|-30000000"):
        en.sweep(base, spec, out, pulse_member,
                 cluster=en.ClusterSettings(scheduler="tcp://192.0.2.1:1"))
    assert not out.exists()
    with pytest.raises(sc.ScenarioError, match="unknown field 'soil.material.yung'"):
        en.sweep(base, en.SweepSpec({"soil.material.yung": [1.0]}), out, pulse_member,
                 cluster=en.ClusterSettings(scheduler="tcp://192.0.2.1:1"))


def test_default_member_preflight_checks_run_constraints(tmp_path, base):
    """With the default member function, run-level constraints (layering depth inside the
    soil layer) are checked before submission too."""
    spec = en.SweepSpec({"physics.soil_layering.depth": [0.5, 5.0]},
                        fixed={"physics.soil_layering.enabled": True})
    with pytest.raises(sc.ScenarioError, match=r"member 1 .*soil_layering\.depth=5\.0"):
        en.sweep(base, spec, tmp_path / "x.h5",
                 cluster=en.ClusterSettings(scheduler="tcp://192.0.2.1:1"))


def test_sweep_spec_and_cli_parsing():
    """Grid = Cartesian product, zip = pairs; --vary values are TOML values; argparse hooks."""
    assert en.parse_vary("soil.material.young=1e7,2e7, 4e7") == (
        "soil.material.young", [1e7, 2e7, 4e7])
    assert en.parse_vary("soil.rotation=\"free\",blocked") == ("soil.rotation",
                                                                ["free", "blocked"])
    assert en.parse_vary("a.b=[1,2],[3,4]") == ("a.b", [[1, 2], [3, 4]])
    z = en.SweepSpec({"a": [1, 2], "b": [3, 4]}, mode="zip").overrides()
    assert z == [{"a": 1, "b": 3}, {"a": 2, "b": 4}]
    with pytest.raises(ValueError, match="equal lengths"):
        en.SweepSpec({"a": [1, 2], "b": [3]}, mode="zip")
    with pytest.raises(ValueError, match="SweepSpec.mode='cube'"):
        en.SweepSpec({"a": [1]}, mode="cube")
    with pytest.raises(ValueError, match="ClusterSettings.n_workers=0"):
        en.ClusterSettings(n_workers=0)
    import argparse

    p = argparse.ArgumentParser()
    en.add_sweep_arguments(p)
    a = p.parse_args(["s.toml", "--vary", "soil.material.young=1e7,2e7", "--zip",
                      "--vary", "soil.material.friction_angle_deg=20,30", "--out", "e.h5",
                      "--workers", "2"])
    assert a.mode == "zip" and a.workers == 2 and len(a.vary) == 2
    p2 = argparse.ArgumentParser()
    en.add_calibrate_arguments(p2)
    a2 = p2.parse_args(["s.toml", "--recording", "r.csv", "--channel", "accel_z",
                        "--param", "soil.material.young=1e7:8e7:log", "--out", "c.h5"])
    fp = en.parse_fit_parameter(a2.param[0])
    assert fp == en.FitParameter("soil.material.young", 1e7, 8e7, log=True)
    assert fp.from_unit(fp.to_unit(3.3e7)) == pytest.approx(3.3e7, rel=1e-14)
    with pytest.raises(sc.ScenarioError, match="lower=5.0, upper=1.0"):
        en.parse_fit_parameter("x=5:1")


def test_sweep_command_rejects_bad_value_before_running(tmp_path):
    """The CLI hook names the member, field and value and starts nothing."""
    import argparse

    scen = tmp_path / "s.toml"
    scen.write_text('[scenario]\nname = "cli"\n')
    p = argparse.ArgumentParser()
    en.add_sweep_arguments(p)
    args = p.parse_args([str(scen), "--vary", "soil.material.friction_angle_deg=30,95",
                         "--out", str(tmp_path / "e.h5"), "--scheduler", "tcp://192.0.2.1:1"])
    with pytest.raises(sc.ScenarioError, match=r"member 1 .*friction_angle_deg=95"):
        en.sweep_command(args)


TRUTH = {"soil.material.young": 3.3e7, "soil.material.friction_angle_deg": 26.0}
#: the search stops when its poll step is below TOL_UNIT of each range; its resolution is then
#: E: (8e7/1e7)^1e-3 - 1 = 0.21 %, phi: 22 deg * 1e-3 = 0.022 deg. Allowed error: five times
#: that resolution (the compass-search stationarity bound carries the objective's condition
#: number, about 2-3 for this two-parameter RMS valley).
TOL_UNIT = 1e-3
YOUNG_RTOL = 5 * ((8e7 / 1e7) ** TOL_UNIT - 1)
PHI_ATOL = 5 * 22.0 * TOL_UNIT  # [deg]


def test_calibrate_recovers_known_optimum(tmp_path, base, client):
    """Oracle: the recording is the synthetic member at known (E, phi); the RMS objective is
    zero there, so calibration must return those values within the search resolution."""
    t, x = pulse(**{"young": TRUTH["soil.material.young"],
                    "phi_deg": TRUTH["soil.material.friction_angle_deg"]})
    rec = Signal("accel_z", t, x, "m/s^2")
    params = [en.FitParameter("soil.material.young", 1e7, 8e7, log=True),
              en.FitParameter("soil.material.friction_angle_deg", 18.0, 40.0)]
    obj = en.ChannelObjective(rec, "accel_z", metric="rms")
    res = en.calibrate(base, params, obj, tmp_path / "cal.h5", pulse_member, client=client,
                       tol=TOL_UNIT, max_evals=200, n_init=6)
    assert res.stop_reason.startswith("step"), res
    assert res.best["soil.material.young"] == pytest.approx(TRUTH["soil.material.young"],
                                                            rel=YOUNG_RTOL)
    assert res.best["soil.material.friction_angle_deg"] == pytest.approx(
        TRUTH["soil.material.friction_angle_deg"], abs=PHI_ATOL)
    with en.open_ensemble(res.path) as ens:
        cal = ens.calibration()
        recs = ens.members()
        summary = ens.summary()
        assert ens.kind == "calibration" and ens.status == "complete"
    assert len(recs) == res.n_evals
    cal_line = summary.splitlines()[-1]
    assert cal_line.startswith("  calibration: best ") and "soil.material.young=" in cal_line
    assert cal["history_x"].shape == (res.n_evals, 2)
    best_rec = min(recs, key=lambda r: r["scalars"]["objective"])
    assert best_rec["scalars"]["objective"] == pytest.approx(res.objective, rel=0, abs=0)
    # batches really ran in parallel generations
    assert res.generations >= 3 and max(r["generation"] for r in recs) == res.generations - 1


def test_channel_objective_iso18571_zero_at_identity(tmp_path, base):
    """ISO/TS 18571 of a channel against itself is R = 1 (objective 0), and a 20 % amplitude
    error lowers R (objective > 0). Oracle: the standard's rating of identical curves."""
    t, x = pulse(2e7, 30.0)
    rec = Signal("accel_z", t, x, "m/s^2")
    obj = en.ChannelObjective(rec, "accel_z", metric="iso18571")
    from crashdem.results import open_result

    m_same = en.Member(0, {"soil.material.young": 2e7, "soil.material.friction_angle_deg": 30.0},
                       base, "")
    m_off = en.Member(1, {"soil.material.young": 2e7 * 1.44,
                          "soil.material.friction_angle_deg": 30.0}, base, "")
    pulse_member(m_same, tmp_path / "a.h5")
    pulse_member(m_off, tmp_path / "b.h5")
    with open_result(tmp_path / "a.h5") as ra, open_result(tmp_path / "b.h5") as rb:
        assert obj(ra) == pytest.approx(0.0, abs=1e-12)
        assert obj(rb) > 0.05


MICRO_TOML = """
[scenario]
name = "micro"
threads = 1
[soil]
radius = 0.06
[container]
diameter = 1.6
soil_depth = 0.3
[impactor]
drop_height = 2.0
[solver]
t_end = 0.005
[output]
plots = false
"""
#: run facts are float64 attributes copied verbatim; the impact speed is computed by the
#: scenario as sqrt(2 g h) in float64 (same formula, other code path): a few ulps
SPEED_RTOL = 1e-12


@pytest.mark.slow
def test_sweep_command_runs_real_scenarios(tmp_path, capsys, client):
    """End to end through the CLI hook: two real (tiny) DEM + Exudyn runs on the two-worker
    LocalCluster, reached through ``--scheduler ADDRESS``, sharing one packing (built once
    under the file lock). Oracles: the impact
    speed of each member equals sqrt(2 g h) of its drop height (free fall, g = 9.81 m/s^2 as in
    crashdem.scenario), and the channels in the ensemble are identical to the member's own
    result file."""
    import argparse

    from crashdem.results import open_result

    scen = tmp_path / "micro.toml"
    scen.write_text(MICRO_TOML)
    out = tmp_path / "micro_sweep.h5"
    p = argparse.ArgumentParser()
    en.add_sweep_arguments(p)
    args = p.parse_args([str(scen), "--vary", "impactor.drop_height=2.0,3.0",
                         "--scheduler", client.scheduler.address,
                         "--out", str(out), "--keep-members"])
    assert en.sweep_command(args) == 0
    assert capsys.readouterr().out.strip().endswith("micro_sweep.h5")
    work = tmp_path / "micro_sweep.h5.members"
    assert len(list((work / "packings").glob("packing-*.h5"))) == 1
    with en.open_ensemble(out) as ens:
        recs = ens.members()
        assert [r["status"] for r in recs] == ["complete", "complete"]
        for r in recs:
            h = r["overrides"]["impactor.drop_height"]
            assert r["scalars"]["run.impact_velocity"] == pytest.approx(
                math.sqrt(2 * 9.81 * h), rel=SPEED_RTOL)
            with open_result(work / f"{r['key']}.h5") as res:
                assert ens.channels(r["index"]) == res.channels()
                for name in res.channels():
                    np.testing.assert_array_equal(ens.channel(r["index"], name).data,
                                                  res.channel(name).data)


def test_calibrate_command_wiring(tmp_path, monkeypatch, capsys):
    """The CLI hook reads the recording channel, builds the fit parameters and the objective
    from the options and prints the fitted values (``calibrate`` itself is replaced by a
    recorder: its numerics are covered by test_calibrate_recovers_known_optimum)."""
    import argparse

    from crashdem.recordings import write_recording

    t, x = pulse(2e7, 30.0)
    rec_path = write_recording(tmp_path / "rec.csv", [Signal("accel_z", t, x, "m/s^2")])
    scen = tmp_path / "s.toml"
    scen.write_text('[scenario]\nname = "cal"\n')
    seen = {}

    def fake_calibrate(base, params, objective, out, member_fn, cluster, **kw):
        seen.update(base=base, params=params, objective=objective, out=out,
                    member_fn=member_fn, cluster=cluster, kw=kw)
        return en.CalibrationResult({p.name: p.lower for p in params}, 0.125, 7, 3,
                                    "step 0.005 < tol 0.01", 0.005, Path(out))

    monkeypatch.setattr(en, "calibrate", fake_calibrate)
    p = argparse.ArgumentParser()
    en.add_calibrate_arguments(p)
    args = p.parse_args([str(scen), "--recording", str(rec_path), "--channel", "accel_z",
                         "--sim-channel", "drop_mass_accel_z", "--metric", "rms",
                         "--param", "soil.material.young=1e7:8e7:log",
                         "--param", "soil.material.friction_angle_deg=20:40:25",
                         "--t-window", "0,0.04", "--workers", "3", "--member-threads", "2",
                         "--set", "solver.t_end=0.05", "--out", str(tmp_path / "c.h5")])
    assert en.calibrate_command(args) == 0
    obj = seen["objective"]
    assert obj.channel == "drop_mass_accel_z" and obj.metric == "rms"
    assert obj.t_window == (0.0, 0.04)
    # CSV stores decimal text: equality up to the written digits (1e-9 is far looser than the
    # writer's round-trip repr and far tighter than anything a wiring slip would produce)
    np.testing.assert_allclose(obj.reference.data, x, rtol=1e-9, atol=1e-9)
    assert seen["params"][1] == en.FitParameter("soil.material.friction_angle_deg", 20, 40,
                                                initial=25.0)
    assert seen["member_fn"] == en.RunMember(threads=2)
    assert seen["cluster"].n_workers == 3 and seen["kw"]["fixed"] == {"solver.t_end": 0.05}
    assert "soil.material.young = 1e+07" in capsys.readouterr().out
    with pytest.raises(ValueError, match="ChannelObjective.metric='l2'"):
        en.ChannelObjective(obj.reference, "x", metric="l2")
    with pytest.raises(ValueError, match="RunMember.threads=-1"):
        en.RunMember(threads=-1)


def test_workers_stop_logging_the_scheduler_going_away_before_their_cluster_closes(client):
    """``dask_client`` closes a LocalCluster it made after its workers' shutdown loggers are
    raised to CRITICAL (``_quiet_shutdown``): a finished run no longer ends with heartbeat
    tracebacks on stderr. Checked on the workers themselves; this process's loggers are left
    as they were."""
    import logging

    def levels():
        return [logging.getLogger(n).level for n in en.SHUTDOWN_LOGGERS]

    here = levels()
    assert not any(lv == [logging.CRITICAL] * len(en.SHUTDOWN_LOGGERS)
                   for lv in client.run(levels).values())
    en._quiet_shutdown(client)
    assert all(lv == [logging.CRITICAL] * len(en.SHUTDOWN_LOGGERS)
               for lv in client.run(levels).values())
    assert levels() == here
