"""Restart from checkpoints: a run killed with SIGKILL and resumed with ``crashdem run --resume``
is bit-identical to an uninterrupted run (issue 8).

Oracle throughout: identity with the uninterrupted computation (same inputs, same thread
count), compared with ``np.array_equal`` -- no tolerance, since the contract is bit-identity.
"""
from __future__ import annotations

import os
import pickle
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import bodies
import soil
from crashdem import checkpoint as ck
from crashdem import scenario as sc
from crashdem.results import open_result
from crashdem.run import run_scenario
from restart_checks import assert_results_identical, assert_tree_equal

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "validation/scenarios/drop_s2_h5p00.toml"

#: a tiny drop test (141 grains) that runs ~1500 DEM steps and ~30 checkpoints, so that a kill
#: after the first checkpoint (t >= 0.01 s, ~60 steps in) lands ~2 s before the end of the run
TINY = {
    "scenario.name": "tiny_restart",
    "scenario.threads": 1,
    "container.diameter": 1.3,
    "container.soil_depth": 0.45,
    "soil.radius": 0.075,
    "physics.soil_layering.enabled": False,
    "impactor.drop_height": 5.0,
    "solver.t_end": 0.3,
    "output.snapshots": 4,
    "output.plots": False,
    "output.checkpoint_every_s": 0.01,
}
#: wall-time limits of the subprocess stages [s]: generous bounds against a hung process on a
#: shared 2-core machine (the whole run takes ~5 s including interpreter start)
POLL_TIMEOUT = 60.0
RUN_TIMEOUT = 120.0
POLL_INTERVAL = 0.005  # [s]


def _cli(*args: str) -> list[str]:
    """``crashdem run`` of the TINY scenario as a command line (plots off via --no-plots)."""
    cmd = [sys.executable, "-m", "crashdem.cli", "--log-level", "WARNING", "run", str(SCENARIO),
           "--quiet", "--no-plots"]
    for k, v in TINY.items():
        if k == "output.plots":
            continue
        val = f'"{v}"' if isinstance(v, str) else ("false" if v is False else repr(v))
        cmd += ["--set", f"{k}={val}"]
    return cmd + list(args)


@pytest.fixture(scope="module")
def killed_and_resumed(tmp_path_factory):
    """An uninterrupted run (in process) and the same run killed by SIGKILL after its first
    checkpoint appeared, then resumed by ``crashdem run --resume`` (subprocesses)."""
    ref_dir = tmp_path_factory.mktemp("uninterrupted")
    scen = sc.load(SCENARIO, TINY)
    ref = run_scenario(scen, out_dir=ref_dir, progress=False)

    out = tmp_path_factory.mktemp("killed")
    shutil.copytree(ref_dir / "packings", out / "packings")  # same deposited bed, no re-deposit
    ckpt = ck.checkpoint_path(out / "tiny_restart.h5")
    env = dict(os.environ, PYTHONWARNINGS="error")
    proc = subprocess.Popen(_cli("--out", str(out)), env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    t0 = time.monotonic()
    while not ckpt.exists():
        if proc.poll() is not None:
            err = proc.stderr.read().decode()
            pytest.fail(f"the run ended (rc {proc.returncode}) before its first checkpoint: {err}")
        if time.monotonic() - t0 > POLL_TIMEOUT:
            proc.kill()
            pytest.fail("no checkpoint appeared")
        time.sleep(POLL_INTERVAL)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=RUN_TIMEOUT)
    killed_rc = proc.returncode
    with h5py.File(ckpt, "r") as f:
        t_ckpt = float(f.attrs["t"])
        ckpt_complete = bool(f.attrs["complete"])
    with open_result(out / "tiny_restart.h5") as res:
        killed_status = res.status
    done = subprocess.run(_cli("--out", str(out), "--resume"), env=env, capture_output=True,
                          timeout=RUN_TIMEOUT)
    assert done.returncode == 0, done.stderr.decode()
    return {"ref": ref, "resumed": out / "tiny_restart.h5", "killed_rc": killed_rc,
            "t_ckpt": t_ckpt, "ckpt_complete": ckpt_complete, "killed_status": killed_status,
            "ref_ckpt": ck.checkpoint_path(ref), "resumed_ckpt": ckpt}


def test_kill_then_resume_is_bit_identical(killed_and_resumed):
    """Oracle: identity with the uninterrupted run. The process was really killed mid-run
    (SIGKILL, result not complete, checkpoint not final), and after ``--resume`` every raw and
    filtered channel, the energy ledger, the particle snapshots, the body poses and the final
    DEM + coupling + Exudyn state equal the uninterrupted run's bit for bit."""
    k = killed_and_resumed
    assert k["killed_rc"] == -signal.SIGKILL
    assert k["killed_status"] == "running" and not k["ckpt_complete"]
    with open_result(k["ref"]) as a, open_result(k["resumed"]) as b:
        assert b.complete and a.complete
        assert list(b._f.attrs["resumed_at"]) == [k["t_ckpt"]]
        assert 0.0 < k["t_ckpt"] < float(a._f["run"].attrs["t_contact"]) + TINY["solver.t_end"]
        assert len(a.channels()) >= 10
        assert_results_identical(a, b, body="drop_mass", snapshots=TINY["output.snapshots"],
                                 min_samples=100)
    fa, fb = ck.read_checkpoint(k["ref_ckpt"]), ck.read_checkpoint(k["resumed_ckpt"])
    assert fa.complete and fb.complete and fa.t == fb.t
    assert_tree_equal(fa.soil, fb.soil, "soil")
    assert_tree_equal(fa.cosim, fb.cosim, "cosim")
    assert fa.loop == fb.loop
    for name in ("x", "v", "w", "f"):
        assert np.array_equal(fa.soil["particles"][name], fb.soil["particles"][name]), name


def test_checkpoints_do_not_change_the_results(killed_and_resumed, tmp_path):
    """Oracle: identity with a run without checkpoints -- writing checkpoints (which drain the
    sensors and flush the result at extra times) leaves every channel and ledger row as is."""
    shutil.copytree(killed_and_resumed["ref"].parent / "packings", tmp_path / "packings")
    scen = sc.load(SCENARIO, {**TINY, "output.checkpoint_every_s": None})
    plain = run_scenario(scen, out_dir=tmp_path, progress=False)
    assert not ck.checkpoint_path(plain).exists()
    with open_result(killed_and_resumed["ref"]) as a, open_result(plain) as b:
        assert a.channels() == b.channels()
        for name in a.channels():
            sa, sb = a.channel(name, filtered=False), b.channel(name, filtered=False)
            assert np.array_equal(sa.t, sb.t) and np.array_equal(sa.data, sb.data,
                                                                 equal_nan=True), name
        for term, sig in a.energy().items():
            assert np.array_equal(sig.data, b.energy()[term].data), term


def test_resume_of_a_complete_run_is_refused(killed_and_resumed):
    """Oracle: the documented contract -- a finished run (final checkpoint, complete result)
    has nothing to resume, and ``run_scenario(resume=True)`` says so."""
    scen = sc.load(SCENARIO, TINY)
    with pytest.raises(sc.ScenarioError, match="already complete"):
        run_scenario(scen, out_dir=killed_and_resumed["resumed"].parent, progress=False,
                     resume=True)


def test_resume_refuses_another_scenario(killed_and_resumed):
    """Oracle: the documented contract -- a checkpoint of another scenario is refused and the
    error names both hashes."""
    other = sc.load(SCENARIO, {**TINY, "soil.material.young": 3.1e7})
    saved = ck.read_checkpoint(killed_and_resumed["resumed_ckpt"])
    h_other = ck.scenario_hash(other)
    assert h_other != saved.scenario_hash
    with pytest.raises(ck.CheckpointError) as err:
        run_scenario(other, out_dir=killed_and_resumed["resumed"].parent, progress=False,
                     resume=True)
    assert h_other in str(err.value) and saved.scenario_hash in str(err.value)
    # fields that cannot change the results do not change the hash
    same = sc.load(SCENARIO, {**TINY, "output.checkpoint_every_s": 0.05, "output.plots": True})
    assert ck.scenario_hash(same) == saved.scenario_hash


def test_resume_without_checkpoint_names_the_file(tmp_path):
    """Oracle: the documented contract -- no checkpoint, a FileNotFoundError naming it."""
    scen = sc.load(SCENARIO, TINY)
    with pytest.raises(FileNotFoundError, match="tiny_restart.ckpt.h5"):
        run_scenario(scen, out_dir=tmp_path, progress=False, resume=True)


def _state_tree():
    rng = np.random.default_rng(8)
    return {
        "f64": rng.normal(size=(7, 3)), "nan": np.array([np.nan, -0.0, np.inf, 5e-324]),
        "i32": rng.integers(-9, 9, size=11).astype(np.int32), "empty": np.zeros((0, 3)),
        "bool": rng.random(5) > 0.5, "fortran": np.asfortranarray(rng.normal(size=(3, 4))),
        "zero_d": np.array(2.5), "np_scalar": np.float64(np.pi), "np_int": np.int64(-3),
        "py_float": 0.1 + 0.2, "py_int": 2**62, "big_int": 2**80, "flag": True, "none": None,
        "text": "ünïcode", "list": [1, 2.0, [np.arange(3)]], "tuple": (np.ones(2), "a"),
        "nested": {"a": {"b": rng.normal(size=2)}}, "int_keys": {1: "x", (2, 3): "y"},
        "object": soil.Plane((0.0, 0.0, 0.5), (0.0, 0.0, 1.0)),
    }


def test_state_tree_roundtrip_is_exact(tmp_path):
    """Oracle: identity -- the HDF5 encoding of a state tree returns the same types and the
    same bits (NaN, -0.0, subnormals, empty and Fortran-ordered arrays, big ints, objects)."""
    tree = _state_tree()
    c = ck.Checkpoint(t=0.125, soil=tree, cosim={"x": 1.0}, sensors=[1, 2],
                      loop={"steps": 11, "snap": 0}, scenario_hash="h", crashdem_version="v")
    ck.write_checkpoint(tmp_path / "a.ckpt.h5", c)
    back = ck.read_checkpoint(tmp_path / "a.ckpt.h5").soil
    for k, v in tree.items():
        assert type(back[k]) is type(v), k
    assert_tree_equal(tree, back, "tree")
    assert np.array_equal(back["nan"].view(np.uint64), tree["nan"].view(np.uint64))
    assert back["fortran"].flags.f_contiguous
    assert back["int_keys"] == tree["int_keys"] and back["big_int"] == 2**80
    assert pickle.dumps(back["object"]) == pickle.dumps(tree["object"])


def test_checkpoint_write_is_atomic(tmp_path):
    """Oracle: the atomic-replace contract -- a write that fails half-way (an unpicklable
    sensor set) leaves the previous checkpoint intact and no temporary file."""
    p = tmp_path / "run.ckpt.h5"
    good = ck.Checkpoint(t=1.0, soil={"x": np.arange(4.0)}, cosim={}, sensors="s",
                         loop={"steps": 1, "snap": 0}, scenario_hash="h1")
    ck.write_checkpoint(p, good)
    bad = ck.Checkpoint(t=2.0, soil={"x": np.arange(5.0)}, cosim={}, sensors=lambda: 0,
                        loop={"steps": 11, "snap": 0}, scenario_hash="h1")
    with pytest.raises((pickle.PicklingError, AttributeError, TypeError)):
        ck.write_checkpoint(p, bad)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["run.ckpt.h5"]
    back = ck.read_checkpoint(p)
    assert back.t == 1.0 and np.array_equal(back.soil["x"], np.arange(4.0))


def test_exudyn_body_restart_is_bit_exact():
    """Oracle: identity with the uninterrupted Exudyn integration -- a body rebuilt from
    ``ExudynRigidBody.state_dict`` (same reference configuration, exact ODE2 coordinates,
    velocities and solver clock) continues bit for bit under the same loads."""
    spec = bodies.drop_sphere()
    rng = np.random.default_rng(3)
    forces, torques = rng.normal(size=(40, 3)) * 1e4, rng.normal(size=(40, 3)) * 1e3
    h = 1.0e-5  # [s]

    def make():
        return bodies.ExudynRigidBody(spec, position=(0.1, 0.2, 1.0), velocity=(1.0, 0.0, -5.0),
                                      angular_velocity=(0.3, -2.0, 1.0))

    a = make()
    for k in range(20):
        a.apply(forces[k], torques[k])
        a.advance(a.time, a.time + h)
    b = make()
    b.load_state_dict(a.state_dict())
    for k in range(20, 40):
        for body in (a, b):
            body.apply(forces[k], torques[k])
            body.advance(body.time, body.time + h)
    for q in ("position", "rotation", "velocity", "angular_velocity"):
        assert np.array_equal(getattr(a, q)(), getattr(b, q)()), q
    assert a.time == b.time


@settings(max_examples=25, deadline=None)
@given(arr=hnp.arrays(dtype=st.sampled_from([np.float64, np.float32, np.int64, np.int32,
                                             np.uint8, np.bool_, np.complex128]),
                      shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4)),
       scalar=st.floats(allow_nan=True, allow_infinity=True) | st.integers(-2**63, 2**63 - 1))
def test_state_tree_roundtrip_property(arr, scalar):
    """Oracle: identity -- any numeric array (dtype, shape including 0-d and empty, NaN
    payloads) and any Python float/int comes back with the same type, dtype and bits."""
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "p.ckpt.h5"
        ck.write_checkpoint(p, ck.Checkpoint(t=0.0, soil={"a": arr, "s": scalar}, cosim={},
                                             sensors=None, loop={"steps": 1, "snap": 0}))
        back = ck.read_checkpoint(p).soil
    assert back["a"].dtype == arr.dtype and back["a"].shape == arr.shape
    assert back["a"].tobytes() == arr.tobytes()
    assert type(back["s"]) is type(scalar)
    if isinstance(scalar, float):
        assert np.float64(back["s"]).view(np.uint64) == np.float64(scalar).view(np.uint64)
    else:
        assert back["s"] == scalar
