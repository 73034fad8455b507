"""Restart of the glider crash: a ``crashdem run`` of a small glider scenario killed with
SIGKILL mid-run and resumed with ``crashdem run --resume`` is bit-identical to an
uninterrupted run (issue 8), for the rigid fuselage and with the crushable nose
(``physics.structural_crush``, issue 6: two Exudyn bodies and the crush element's plastic
history). The glider keeps state outside the DEM and the coupling (the compliant wall panels,
the fuselage-wall contacts, the crush exchange's value store): the checkpoint carries it
through the component protocol of ``crashdem.checkpoint``.

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
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from crashdem import checkpoint as ck
from crashdem import scenario as sc
from crashdem.glider import BodyWallContact, CompliantWall, PlywoodPanel
from crashdem.results import open_result
from crashdem.run import packing_cache, packing_spec, run_scenario
from restart_checks import assert_results_identical, assert_tree_equal
from soil import packing as pk

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "validation/scenarios/glider_real.toml"
#: the packing cache shared with tests/validation/test_glider_crash.py (same 0.1 m slope bed)
CACHE = packing_cache()

#: the glider at the test-suite resolution (0.1 m grains, ~750 in the slope; the bed of
#: ``validation/glider_crash.py --small``), 1 thread, 0.06 s after the first contact: ~620 DEM
#: steps, a checkpoint every 5 ms of simulated time
SMALL = {
    "scenario.name": "glider_restart",
    "scenario.threads": 1,
    "soil.radius": 0.1,
    "soil.radius_spread": 0.1,
    "solver.t_end": 0.06,
    "output.snapshots": 3,
    "output.plots": False,
    "output.checkpoint_every_s": 0.005,
}
#: the process is killed at the first checkpoint at least this long after the start [s]: past
#: the first contact (0.02 s), so that walls, contact and filters carry impact state
KILL_AFTER_T = 0.03
#: the variants: rigid fuselage, crushable nose (schema's 50 kN / 0.2 m element)
VARIANTS = {"rigid": {}, "crush": {"physics.structural_crush.enabled": True}}
#: components a killed checkpoint carries, per variant
COMPONENTS = {"rigid": ["wall.left_wall", "wall.rear_wall", "wall.right_wall", "wall_contact"],
              "crush": ["crush_store", "nose_wall_contact", "wall.left_wall", "wall.rear_wall",
                        "wall.right_wall", "wall_contact"]}
POLL_TIMEOUT = 120.0  # [s] generous bounds against a hung process on a shared 2-core machine
RUN_TIMEOUT = 300.0
POLL_INTERVAL = 0.005  # [s]


def _cli(*args: str, extra: dict | None = None) -> list[str]:
    cmd = [sys.executable, "-m", "crashdem.cli", "--log-level", "WARNING", "run", str(SCENARIO),
           "--quiet", "--no-plots"]
    for k, v in {**SMALL, **(extra or {})}.items():
        if k == "output.plots":
            continue
        val = (f'"{v}"' if isinstance(v, str) else str(v).lower() if isinstance(v, bool)
               else repr(v))
        cmd += ["--set", f"{k}={val}"]
    return cmd + list(args)


def _seed_packing(scen: sc.Scenario, out: Path) -> None:
    """Copy the (cached, else deposited once) slope packing into ``out/packings``."""
    spec = packing_spec(scen)
    pk.cached(spec, CACHE)
    src = CACHE / f"packing-{spec.hash()[:20]}.h5"
    (out / "packings").mkdir(parents=True, exist_ok=True)
    shutil.copy(src, out / "packings" / src.name)


@pytest.fixture(scope="module", params=list(VARIANTS))
def glider_killed_and_resumed(request, tmp_path_factory):
    variant = VARIANTS[request.param]
    scen = sc.load(SCENARIO, {**SMALL, **variant})
    ref_dir = tmp_path_factory.mktemp("glider_uninterrupted")
    _seed_packing(scen, ref_dir)
    ref = run_scenario(scen, out_dir=ref_dir, progress=False)

    out = tmp_path_factory.mktemp("glider_killed")
    shutil.copytree(ref_dir / "packings", out / "packings")
    ckpt = ck.checkpoint_path(out / "glider_restart.h5")
    env = dict(os.environ, PYTHONWARNINGS="error")
    proc = subprocess.Popen(_cli("--out", str(out), extra=variant), env=env,
                            stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    t0 = time.monotonic()
    while True:
        if proc.poll() is not None:
            pytest.fail(f"the run ended (rc {proc.returncode}) before a checkpoint at t >= "
                        f"{KILL_AFTER_T} s: {proc.stderr.read().decode()[-2000:]}")
        if time.monotonic() - t0 > POLL_TIMEOUT:
            proc.kill()
            pytest.fail("no checkpoint appeared")
        if ckpt.exists():
            try:
                with h5py.File(ckpt, "r") as f:
                    if float(f.attrs["t"]) >= KILL_AFTER_T:
                        break
            except (OSError, KeyError):  # replaced between exists() and open: poll again
                pass
        time.sleep(POLL_INTERVAL)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=RUN_TIMEOUT)
    killed = ck.read_checkpoint(ckpt)
    with open_result(out / "glider_restart.h5") as res:
        killed_status = res.status
    done = subprocess.run(_cli("--out", str(out), "--resume", extra=variant), env=env,
                          capture_output=True,
                          timeout=RUN_TIMEOUT)
    assert done.returncode == 0, done.stderr.decode()[-3000:]
    return {"ref": ref, "resumed": out / "glider_restart.h5", "killed_rc": proc.returncode,
            "killed": killed, "killed_status": killed_status,
            "ref_ckpt": ck.checkpoint_path(ref), "resumed_ckpt": ckpt,
            "variant": request.param, "overrides": variant}


def test_glider_kill_then_resume_is_bit_identical(glider_killed_and_resumed):
    """Oracle: identity with the uninterrupted run. The glider run was really killed after
    the first contact (SIGKILL, result running, checkpoint not final, walls deflecting), and
    after ``--resume`` every raw and filtered channel (accelerometers, gyro, pitch, contact
    forces, wall forces and deflections, nose-wall force), the energy ledger, the snapshots and
    body poses, and the final DEM, coupling, Exudyn and wall/contact states equal the
    uninterrupted run's bit for bit."""
    k = glider_killed_and_resumed
    assert k["killed_rc"] == -signal.SIGKILL
    kc = k["killed"]
    assert k["killed_status"] == "running" and not kc.complete
    assert KILL_AFTER_T <= kc.t < SMALL["solver.t_end"] + 0.02
    # the killed state carries wall and contact state that the restart must restore
    assert sorted(kc.components) == COMPONENTS[k["variant"]]
    if k["variant"] == "crush":
        # the crush element is mid-stroke at the kill: its plastic history must come back
        crush = kc.cosim["model"]
        assert crush["s_p"] > 0.0 and crush["load"] > 0.0
        assert ck.MODEL_REF in kc.sensors.refs
    rear = kc.components["wall.rear_wall"]
    assert rear["u"] != 0.0 and rear["v"] != 0.0 and rear["t_last"] is not None
    assert isinstance(kc.sensors, ck.PickledSensors) and "wall.rear_wall" in kc.sensors.refs
    with open_result(k["ref"]) as a, open_result(k["resumed"]) as b:
        assert a.complete and b.complete
        assert list(b._f.attrs["resumed_at"]) == [kc.t]
        names = a.channels()
        assert names == b.channels()
        for must in ("rear_accel_x", "pitch_rate", "rear_wall_force", "rear_wall_deflection",
                     "nose_rear_wall_force", "contact_force_x"):
            assert must in names, must
        if k["variant"] == "crush":
            for must in ("nose_crush_load", "nose_crush_stroke", "fuselage_force_x",
                         "nose_velocity_x"):
                assert must in names, must
        assert np.any(a.channel("rear_wall_deflection", filtered=False).data != 0.0)
        assert_results_identical(a, b, body="glider", snapshots=SMALL["output.snapshots"],
                                 min_samples=500)
    fa, fb = ck.read_checkpoint(k["ref_ckpt"]), ck.read_checkpoint(k["resumed_ckpt"])
    assert fa.complete and fb.complete and fa.t == fb.t
    assert_tree_equal(fa.soil, fb.soil, "soil")
    assert_tree_equal(fa.cosim, fb.cosim, "cosim")
    assert_tree_equal(fa.components, fb.components, "components")
    assert fa.loop == fb.loop


def test_glider_checkpoints_do_not_change_the_results(glider_killed_and_resumed, tmp_path):
    """Oracle: identity with a glider run without checkpoints -- capturing the walls, the
    contact and the sensors (and flushing the result at extra times) changes no channel and
    no ledger row."""
    shutil.copytree(glider_killed_and_resumed["ref"].parent / "packings", tmp_path / "packings")
    scen = sc.load(SCENARIO, {**SMALL, **glider_killed_and_resumed["overrides"],
                              "output.checkpoint_every_s": None})
    plain = run_scenario(scen, out_dir=tmp_path, progress=False)
    assert not ck.checkpoint_path(plain).exists()
    with open_result(glider_killed_and_resumed["ref"]) as a, open_result(plain) as b:
        assert a.channels() == b.channels()
        for name in a.channels():
            sa, sb = a.channel(name, filtered=False), b.channel(name, filtered=False)
            assert np.array_equal(sa.t, sb.t) and np.array_equal(sa.data, sb.data,
                                                                 equal_nan=True), name
        for term, sig in a.energy().items():
            assert np.array_equal(sig.data, b.energy()[term].data), term


# ------------------------------------------------------------------ component protocol (fast)
class _Body:
    """A stand-in coupled boundary body (what CompliantWall reads and moves)."""

    def __init__(self):
        self.position = np.zeros(3)
        self.velocity = np.zeros(3)
        self.force = np.zeros(3)

    def set_kinematics(self, x, r, v, w):
        self.position = np.array(x)
        self.velocity = np.array(v)


class _Sim:
    def __init__(self, boundaries):
        self.boundaries = boundaries


def _drive(wall, contact, steps, k0, h=1e-4):
    """A few wall updates under a varying soil load and a fuselage pressing on the wall."""
    out = []
    for k in range(k0, k0 + steps):
        t = k * h
        wall.body.position = wall.body.position + h * wall.body.velocity  # the DEM's move
        wall.body.force[:] = (-2.0e4 * (1.0 + np.sin(300.0 * t)), 0.0, 0.0)
        x = np.array([0.99 + 0.0005 * k, 0.0, 0.5])  # the body moves into the wall at x = 1.1
        f, tq, loads = contact.evaluate(t, x, np.eye(3), np.zeros(3), np.zeros(3))
        wall.update(t, loads.get("rear", 0.0))
        out.append((wall.u, wall.v, f.copy(), tq.copy()))
    return out


def test_wall_and_contact_state_roundtrip_is_exact(tmp_path):
    """Oracle: identity -- a CompliantWall + BodyWallContact pair saved mid-contact through a
    checkpoint file (state dicts, sensor pickle with component references) and loaded into
    fresh objects continues bit for bit like the uninterrupted pair; the wall channel in the
    restored sensor pickle reads the live (restored) wall, not a copy."""
    from crashdem.glider import WallChannel

    def make():
        body = _Body()
        wall = CompliantWall("rear", PlywoodPanel(2.0, 2.4), body, (1.0, 0.0, 0.0))
        verts = np.array([[0.1, 0.0, 0.0], [0.08, 0.02, 0.0], [-0.3, 0.0, 0.0]])
        contact = BodyWallContact(verts, 343.0, [("rear", (1.1, 0.0, 0.0), (-1.0, 0.0, 0.0),
                                                   wall)])
        return body, wall, contact

    body, wall, contact = make()
    _drive(wall, contact, 40, 0)
    assert contact.forces["rear"] > 0.0 and wall.u != 0.0  # mid-contact, wall moving
    chan = WallChannel(name="rear_wall_deflection", wall=wall, contact=contact,
                       quantity="deflection")
    comps = {"wall.rear": wall, "wall_contact": contact}
    c = ck.Checkpoint(t=0.004, soil={}, cosim={}, sensors=[chan], loop={"steps": 1, "snap": 0},
                      components={n: o.state_dict() for n, o in comps.items()}, refs=comps)
    ck.write_checkpoint(tmp_path / "c.ckpt.h5", c)
    back = ck.read_checkpoint(tmp_path / "c.ckpt.h5")
    assert back.sensors.refs == ["wall.rear", "wall_contact"]
    body2, wall2, contact2 = make()
    body3 = _Body()  # the panel body of the DEM rebuilt from its state dict
    body3.position = body.position.copy()
    body3.velocity = body.velocity.copy()
    body3.force = body.force.copy()
    wall2.rebind(_Sim([_Body(), body2]), _Sim([_Body(), body3]))  # same index, new object
    assert wall2.body is body3
    live = {"wall.rear": wall2, "wall_contact": contact2}
    for n, o in live.items():
        o.load_state_dict(back.components[n])
    chan2 = back.sensors.load(live)[0]
    assert chan2.wall is wall2 and chan2.contact is contact2
    ra = _drive(wall, contact, 30, 40)
    rb = _drive(wall2, contact2, 30, 40)
    for (ua, va, fa, ta), (ub, vb, fb, tb) in zip(ra, rb):
        assert ua == ub and va == vb and np.array_equal(fa, fb) and np.array_equal(ta, tb)
    assert pickle.dumps(wall.state_dict()) == pickle.dumps(wall2.state_dict())
    assert contact.state_dict() == contact2.state_dict()


def test_restore_refuses_undeclared_state():
    """Oracle: the documented contract -- a model with per-step state outside the DEM
    (pre_record) but no declared components cannot be checkpointed silently."""
    from types import SimpleNamespace

    m = SimpleNamespace(pre_record=lambda *a: None, extra={}, components={})
    with pytest.raises(ck.CheckpointError, match="declares no components"):
        ck.Checkpoint(t=0.0, soil={}, cosim={}, sensors=None).restore(m)
    bad = SimpleNamespace(pre_record=None, extra={}, components={"nose": object()})
    with pytest.raises(ck.CheckpointError, match="'nose'.*state_dict"):
        ck.Checkpoint(t=0.0, soil={}, cosim={}, sensors=None,
                      components={"nose": {}}).restore(bad)


def test_dict_component_and_model_reference_roundtrip(tmp_path):
    """Oracle: identity -- a plain-dict component (a per-step value store read by sensors)
    comes back with the same items, and sensors that hold the dict or the coupled Exudyn model
    are reconnected to the resumed model's objects (the model itself, unpicklable here, is
    never pickled)."""
    import threading
    from types import SimpleNamespace

    store = {"contact_force": np.array([1.0, -2.5, 3e-300]), "k": 7}
    exu = threading.Lock()  # stands for the Exudyn model: not picklable
    m = SimpleNamespace(sim=SimpleNamespace(state_dict=dict), cosim=SimpleNamespace(
        state_dict=dict), sensors=[store, exu], pre_record=lambda *a: None, extra={},
        components={"crush_store": store}, model=exu)
    ck.write_checkpoint(tmp_path / "d.ckpt.h5",
                        ck.Checkpoint.capture(m, 0.25, {"steps": 1, "snap": 0}))
    back = ck.read_checkpoint(tmp_path / "d.ckpt.h5")
    assert back.sensors.refs == sorted([ck.MODEL_REF, "crush_store"])
    store2, exu2 = {"stale": 1}, threading.Lock()
    m2 = SimpleNamespace(model=exu2, components={"crush_store": store2})
    ck._load_state(store2, back.components["crush_store"])
    sensors = back.sensors.load(ck._refs(m2, m2.components))
    assert sensors[0] is store2 and sensors[1] is exu2
    assert list(store2) == ["contact_force", "k"] and store2["k"] == 7
    assert store2["contact_force"].tobytes() == store["contact_force"].tobytes()
