"""Tests of crashdem.results: HDF5 schema, incremental writing, crash safety, reader API."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

from crashdem.filters import cfc_filter
from crashdem.results import (
    FORMAT_NAME,
    ResultWriter,
    compare,
    iso_code_for_cfc,
    open_result,
)
from crashdem.sensors import (
    Accelerometer,
    BodyState,
    BoundaryContacts,
    Gyroscope,
    LoadCell,
    SensorSet,
)
from crashdem.signal import G0, Signal

FS = 12500.0
TOML = 'title = "drop"\n[instrumentation]\nsample_rate = 12500.0\ncfc = 60.0\n'
PARAMS = {"title": "drop", "instrumentation": {"sample_rate": 12500.0, "cfc": 60.0},
          "physics": {"cohesion": {"enabled": False, "normal_strength": 1e4},
                      "layers": {"depth": None, "values": [0.1, 0.2]}},
          "names": ["a", "b"], "count": 3}


def make_sensors() -> SensorSet:
    return SensorSet([
        Accelerometer(name="rear_accel_x", body="glider", position=(-2.0, 0, 0.1),
                      axis=(1, 0, 0), full_scale=250 * G0, cfc=60, iso_code="10VEHC0000REACX0"),
        Accelerometer(name="front_accel_z", body="glider", position=(1.5, 0, 0), axis=(0, 0, 1),
                      full_scale=5 * G0, failure_factor=1.2, cfc=60),
        Gyroscope(name="pitch_rate", body="glider", cfc=20),
        LoadCell(name="floor_1", boundary="floor", radius=0.2),
    ], fs=FS)


def drive(sensors: SensorSet, writer: ResultWriter | None, t_end: float = 0.06,
          dt: float = 3.1e-5) -> None:
    """A pulse of 0..15 g along x and z with a pitch rate, and a floor force."""
    n = int(t_end / dt)
    for i in range(n):
        t = i * dt
        pulse = 15 * G0 * math.sin(math.pi * t / t_end) ** 2
        st = BodyState(position=(0, 0, 1), rotation=np.eye(3), acceleration=(pulse, 0, pulse),
                       angular_velocity=(0, -2 * math.sin(40 * t), 0))
        sensors.record(t, {"glider": st}, {"floor": BoundaryContacts([[0.1, 0, 0]],
                                                                     [[0, 0, -pulse]])})
        if writer is not None and i % 50 == 0:
            writer.append_sensors(sensors)
            writer.append_energy(t, {"kinetic": 0.5 * t, "work_gravity": -t})
    if writer is not None:
        writer.append_sensors(sensors)


def write_run(path, **kw) -> SensorSet:
    ss = make_sensors()
    with ResultWriter(path, scenario_toml=TOML, parameters=PARAMS, seed=42, threads=2, **kw) as w:
        w.declare_sensors(ss)
        drive(ss, w)
    return ss


def test_round_trip_schema_units_and_provenance(tmp_path):
    """Oracle: identity -- raw channels read back equal the SensorSet samples bit for bit; every
    dataset carries a unit; scenario text and parsed parameters round-trip; provenance keys and
    the completion flag are present (schema of docs/results_schema.md)."""
    path = tmp_path / "run.h5"
    ss = write_run(path)
    ref = ss.signals()
    with open_result(path) as res:
        assert res.channels() == list(ref)
        for name, s in ref.items():
            raw = res.channel(name, filtered=False)
            assert np.array_equal(raw.t, s.t)
            assert np.array_equal(raw.data, s.data, equal_nan=True)
            assert raw.unit == s.unit
        assert res.scenario_toml == TOML
        assert res.parameters == PARAMS
        assert res.complete and res.status == "complete" and res.error == ""
        p = res.provenance
        for key in ("crashdem_version", "git_hash", "numba_version", "exudyn_version",
                    "numpy_version", "hostname", "start_time", "end_time", "wall_time"):
            assert p[key] not in ("", None), key
        assert p["seed"] == 42 and p["threads"] == 2 and p["format"] == FORMAT_NAME
        gh = p["git_hash"].removesuffix("-dirty")
        assert gh == "unknown" or (len(gh) == 40 and int(gh, 16) >= 0)
        assert p["wall_time"] > 0
        en = res.energy()
        assert set(en) == {"kinetic", "work_gravity"}
        assert en["kinetic"].unit == "J"
        assert np.allclose(en["kinetic"].data, 0.5 * en["kinetic"].t, rtol=0, atol=1e-15)
        assert res["rear_accel_x"].meta["position"] == [-2.0, 0.0, 0.1]
        text = res.summary()
        assert "complete" in text and "rear_accel_x" in text and "FAILED" in text
    with h5py.File(path, "r") as f:
        missing = []
        f.visititems(lambda n, o: missing.append(n)
                     if isinstance(o, h5py.Dataset) and "unit" not in o.attrs else None)
        assert missing == []


def test_filtered_channels_equal_the_j211_filter_of_the_raw_data(tmp_path):
    """Oracle: independent call of crashdem.filters.cfc_filter on the raw samples (the stored
    filtered channel must be exactly that); a failed sensor's NaN tail stays NaN and only the
    valid prefix is filtered; ISO-MME filter letter D for CFC 60, L for CFC 20."""
    path = tmp_path / "run.h5"
    write_run(path)
    with open_result(path) as res:
        raw = res.channel("rear_accel_x", filtered=False)
        filt = res["rear_accel_x"]
        assert filt.cfc == 60.0
        ref = cfc_filter(raw, cfc=60)
        assert np.array_equal(filt.data, ref.data)
        assert filt.meta["iso_code"] == "10VEHC0000REACXD"
        assert filt.meta["filter"]["standard"] == "SAE J211-1 Appendix C"
        # failed channel
        raw_f = res.channel("front_accel_z", filtered=False)
        assert "failed_at" in raw_f.meta
        ok = np.isfinite(raw_f.data)
        n_ok = int(ok.sum())
        assert 3 <= n_ok < raw_f.data.size and ok[:n_ok].all()
        f_f = res["front_accel_z"]
        assert np.all(np.isnan(f_f.data[n_ok:]))
        head = cfc_filter(Signal("x", raw_f.t[:n_ok], raw_f.data[:n_ok], "m/s^2"), cfc=60)
        assert np.array_equal(f_f.data[:n_ok], head.data)
        # on-the-fly filtering with another class equals the filter module too
        assert np.array_equal(res.filter("rear_accel_x", 180).data, cfc_filter(raw, cfc=180).data)
        # no CFC declared -> stays raw
        assert res["floor_1"].cfc is None
        # a well-known channel name without an explicit code gets the crashdem default code
        # (crashdem.isomme.CRASHDEM_CODES), filter letter L for CFC 20
        assert res["pitch_rate"].meta["iso_code"] == "10VEHCCG0000AVYL"
        assert res.channel("pitch_rate", filtered=False).meta["iso_code"] == "10VEHCCG0000AVY0"
    assert iso_code_for_cfc("10VEHCCG0000AVYP", 20) == "10VEHCCG0000AVYL"
    assert iso_code_for_cfc("10VEHCCG0000AVYP", None) == "10VEHCCG0000AVY0"


def test_resample_on_exact_grid(tmp_path):
    """Oracle: linear interpolation reproduces a linear function exactly; the new grid is
    exactly t0 + k/fs inside the channel's time range."""
    path = tmp_path / "lin.h5"
    with ResultWriter(path) as w:
        w.declare_channel("ramp", "m", FS, t0=0.0, kind="kinematics")
        t = np.arange(1, 1001) / FS
        w.append_channel("ramp", t, 3.0 * t + 1.0)
    with open_result(path) as res:
        r = res.resample("ramp", 1000.0)
        k0 = math.ceil(t[0] * 1000.0)
        assert np.array_equal(r.t, np.arange(k0, k0 + r.t.size) / 1000.0)
        assert r.t[-1] <= t[-1] and r.t[-1] + 1e-3 > t[-1]
        assert np.allclose(r.data, 3.0 * r.t + 1.0, rtol=1e-14, atol=1e-14)
        assert res["ramp"].cfc is None  # no CFC class: shown raw


def test_compare_peak_timing_and_rms(tmp_path):
    """Oracle: analytic -- b(t) = 1.1 a(t - 2 ms) for a Gaussian pulse a: peak ratio 1.1,
    time-of-peak difference 2 ms; for b = 1.1 a (no shift) the RMS difference is 0.1 RMS(a)."""
    t = np.arange(0, 0.1, 1 / FS)

    def pulse(tt):
        return 100.0 * np.exp(-((tt - 0.04) / 0.005) ** 2)

    def write(path, data):
        with ResultWriter(path) as w:
            w.declare_channel("a", "m/s^2", FS)
            w.declare_channel("b", "N", FS)
            w.append_channel("a", t, data)
            w.append_channel("b", t, pulse(t))
        return open_result(path)

    ra = write(tmp_path / "a.h5", pulse(t))
    rb = write(tmp_path / "b.h5", 1.1 * pulse(t - 0.002))
    rc = write(tmp_path / "c.h5", 1.1 * pulse(t))
    try:
        c = compare(ra, rb, ["a"])["a"]
        assert c.peak_ratio == pytest.approx(1.1, rel=1e-12)
        # the peak sits on a sample for both (0.04 and 0.042 are multiples of 1/fs)
        assert c.time_of_peak_difference == pytest.approx(0.002, abs=1e-12)
        c2 = compare(ra, rc)
        assert set(c2) == {"a", "b"}
        assert c2["a"].relative_rms == pytest.approx(0.1, rel=1e-12)
        assert c2["b"].rms_difference == 0.0 and c2["b"].unit == "N"
        # ISO/TS 18571 through crashdem.metrics: identical signals rate 1 (definition of the
        # four sub-scores), a 10 % magnitude error rates lower
        assert c2["b"].iso18571["overall"] == pytest.approx(1.0, abs=1e-12)
        assert 0.0 <= c2["a"].iso18571["overall"] < 1.0
        # a window around the second half only: both peaks lie outside it
        c3 = compare(ra, rb, ["a"], t_window=(0.07, 0.1))["a"]
        assert c3.t_peak_a >= 0.07 and c3.peak_a < 0.01 * c.peak_a
    finally:
        for r in (ra, rb, rc):
            r.close()


def test_failed_run_is_marked_failed_with_message(tmp_path):
    """Oracle: the status contract -- an exception inside the writer block marks the file
    failed with the message, keeps the data written so far, and propagates."""
    path = tmp_path / "fail.h5"
    ss = make_sensors()
    with pytest.raises(RuntimeError, match="contact explosion"):
        with ResultWriter(path) as w:
            w.declare_sensors(ss)
            drive(ss, w, t_end=0.01)
            raise RuntimeError("contact explosion at step 123")
    with open_result(path) as res:
        assert res.status == "failed" and not res.complete
        assert res.error == "RuntimeError: contact explosion at step 123"
        assert res.channel("pitch_rate", filtered=False).t.size == ss.n_samples


def test_declaration_after_start_and_undeclared_channel_raise(tmp_path):
    """Oracle: the SWMR and ordering contract -- with strict_swmr, after the first flush only
    appends are allowed; otherwise a ledger declared by its first row after a flush works; an
    undeclared channel is named; channel time increases strictly; an energy row at
    the same instant replaces the previous one (buffered or flushed), an earlier one raises."""
    with ResultWriter(tmp_path / "strict.h5", strict_swmr=True) as w:
        w.declare_channel("a", "N", FS)
        w.flush()
        with pytest.raises(RuntimeError, match="after the first flush"):
            w.declare_channel("b", "N", FS)
    with ResultWriter(tmp_path / "x.h5") as w:
        w.declare_channel("a", "N", FS)
        w.flush()
        with pytest.raises(KeyError, match="channel 'zz' not declared"):
            w.append_channel("zz", [0.0], [1.0])
        with pytest.raises(ValueError, match="flush_every=0"):
            ResultWriter(tmp_path / "y.h5", flush_every=0)
        w.append_channel("a", [0.0, 1e-4], [1.0, 2.0])
        with pytest.raises(ValueError, match="time must increase strictly"):
            w.append_channel("a", [1e-4], [3.0])
        w.append_energy(0.0, {"k": 1.0})
        w.flush()
        w.append_energy(0.0, {"k": 2.0})  # same instant: replaces the flushed row
        w.append_energy(1.0, {"k": 3.0})
        w.append_energy(1.0, {"k": 4.0})  # same instant: replaces the buffered row
        with pytest.raises(ValueError, match="before the previous row"):
            w.append_energy(0.5, {"k": 5.0})
    with open_result(tmp_path / "x.h5") as res:
        e = res.energy()["k"]
        assert np.array_equal(e.t, [0.0, 1.0]) and np.array_equal(e.data, [2.0, 4.0])


@pytest.mark.parametrize("dtype, rtol", [("float32", 2 ** -23), ("float64", 0.0)])
def test_snapshots_compressed_with_documented_precision(tmp_path, dtype, rtol):
    """Oracle: IEEE 754 -- float32 positions are the float64 ones rounded to nearest
    (relative error <= 2^-24 < 2^-23), float64 are exact; radii stored once, exactly."""
    rng = np.random.default_rng(0)
    n = 3000
    radius = rng.uniform(0.004, 0.006, n)
    xs = [rng.uniform(-1, 1, (n, 3)) for _ in range(3)]
    vs = [rng.normal(0, 1, (n, 3)) for _ in range(3)]
    path = tmp_path / "snap.h5"
    with ResultWriter(path, snapshot_dtype=dtype) as w:
        w.declare_snapshots(radius, velocities=True)
        for i in range(3):
            w.write_snapshot(0.01 * i, xs[i], vs[i])
    with open_result(path) as res:
        assert np.array_equal(res.snapshot_times(), [0.0, 0.01, 0.02])
        for i in range(3):
            s = res.snapshot(i)
            assert np.array_equal(s["radius"], radius)
            assert np.all(np.abs(s["x"] - xs[i]) <= rtol * np.abs(xs[i]))
            assert np.all(np.abs(s["v"] - vs[i]) <= rtol * np.abs(vs[i]))
    with h5py.File(path, "r") as f:
        assert f["snapshots/x"].compression == "gzip" and f["snapshots/x"].dtype == dtype


WRITER_SCRIPT = textwrap.dedent("""
    import sys, time
    import numpy as np
    from crashdem.results import ResultWriter
    fs = 12500.0
    w = ResultWriter(sys.argv[1], scenario_toml="x = 1\\n", flush_every=100,
                     flush_seconds=1e9)
    w.declare_channel("ramp", "m/s^2", fs, cfc_class=60.0)
    k = 0
    while True:
        t = np.arange(k, k + 25) / fs
        w.append_channel("ramp", t, 2.0 * np.arange(k, k + 25))
        if k >= 200:  # the ledger is declared by its first row, after the first flush (SWMR)
            w.append_energy(t[0], {"kinetic": float(k)})
        k += 25
        if k % 100 == 0:   # flush_every = 100 samples -> the writer flushed inside append
            print(k, flush=True)
        time.sleep(0.002)
""")


def test_sigkill_mid_run_keeps_everything_up_to_the_last_flush(tmp_path):
    """Oracle: crash consistency -- a real writer subprocess is killed with SIGKILL mid-run;
    reopening the file must give status 'running', complete False, and every sample up to the
    last flush it reported, with the exact values it wrote (data[k] = 2k)."""
    script = tmp_path / "writer.py"
    script.write_text(WRITER_SCRIPT)
    path = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        last = 0
        for i in range(20):
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
            last = int(line)
            if i == 10:  # a reader while the writer runs (``crashdem info`` on a live run)
                with open_result(path) as live:
                    assert live.opened_swmr and live.status == "running"
                    n_live = live.channel("ramp", filtered=False).t.size
                    assert n_live >= last
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    with open_result(path) as res:
        assert res.opened_swmr
        assert res.status == "running" and not res.complete
        raw = res.channel("ramp", filtered=False)
        assert raw.t.size >= last
        k = np.arange(raw.t.size)
        assert np.array_equal(raw.t, k / 12500.0)
        assert np.array_equal(raw.data, 2.0 * k)
        # rows from k = 200 on; the row of the last block is appended after the flush the
        # channel triggered
        e = res.energy()["kinetic"]
        assert e.t.size >= (last - 200) // 25 - 1
        assert np.array_equal(e.data, 200.0 + 25.0 * np.arange(e.t.size))
        # filtered on demand (the killed writer never wrote filtered data)
        filt = res["ramp"]
        assert filt.cfc == 60.0 and filt.t.size == raw.t.size
        assert "running" in res.summary()


def test_scenario_object_round_trips(tmp_path):
    """Oracle: identity -- a crashdem Scenario stored through ResultWriter(scenario=...) reads
    back with parameters equal to Scenario.data (every field, defaults included), its complete
    TOML and its source text; the stored TOML parses back to the same scenario."""
    from crashdem import scenario as sc

    text = "[instrumentation]\nsample_rate = 10000.0\n[physics.cohesion]\nenabled = true\n"
    scen = sc.loads(text)
    path = tmp_path / "scen.h5"
    with ResultWriter(path, scenario=scen):
        pass
    with open_result(path) as res:
        assert res.parameters == scen.data
        assert res.scenario_toml == scen.to_toml()
        assert sc.loads(res.scenario_toml).data == scen.data
        with h5py.File(path, "r") as f:
            assert f["scenario/source_toml"][()].decode() == text


def test_resume_after_sigkill_continues_the_same_file(tmp_path):
    """Oracle: identity -- after SIGKILL, resuming from a checkpoint time keeps every sample up
    to it, and the continued run ends complete with one sample per grid instant (no gap, no
    duplicate) and the exact values data[k] = 2k."""
    script = tmp_path / "writer.py"
    script.write_text(WRITER_SCRIPT)
    path = tmp_path / "killed.h5"
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(8):
            line = proc.stdout.readline()
            assert line, proc.stderr.read()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stdout.close()
        proc.stderr.close()
    k_ckpt = 450  # checkpoint at sample 450 (< 8 * 100 flushed samples)
    t_ckpt = k_ckpt / FS
    w = ResultWriter.resume(path, t_ckpt)
    with w:
        k = np.arange(k_ckpt + 1, 1500)
        w.append_channel("ramp", k / FS, 2.0 * k)
        w.append_energy(k[0] / FS, {"kinetic": float(k[0])})
    with open_result(path) as res:
        assert res.complete and not res.opened_swmr
        raw = res.channel("ramp", filtered=False)
        assert np.array_equal(raw.t, np.arange(1500) / FS)
        assert np.array_equal(raw.data, 2.0 * np.arange(1500))
        assert res.provenance["resumed_at"] == [t_ckpt]
        assert res.scenario_toml == "x = 1\n"
        assert res["ramp"].cfc == 60.0
        e = res.energy()["kinetic"]
        assert np.all(np.diff(e.t) > 0) and e.t[-1] == k[0] / FS
    assert not (tmp_path / "killed.h5.resume.tmp").exists()


def test_resume_with_restored_sensor_set_equals_uninterrupted_run(tmp_path):
    """Oracle: identity with an uninterrupted run -- a run that fails after a checkpoint
    (SensorSet pickled at step n_ckpt) and is resumed from it with the restored SensorSet
    produces channels bit-identical to the same run without interruption."""
    import pickle

    dt, n_total, n_ckpt = 3.1e-5, 1500, 700

    def state(i):
        t = i * dt
        return {"glider": BodyState(position=(0, 0, 1), rotation=np.eye(3),
                                    acceleration=(50 * math.sin(300 * t), 0, 9.0),
                                    angular_velocity=(0, -math.sin(40 * t), 0))}

    def step(ss, w, i):
        ss.record(i * dt, state(i), {"floor": BoundaryContacts([[0.1, 0, 0]], [[0, 0, -i]])})
        if i % 40 == 0:
            w.append_sensors(ss)

    ref_ss = make_sensors()
    with ResultWriter(tmp_path / "ref.h5") as w:
        w.declare_sensors(ref_ss)
        for i in range(n_total):
            step(ref_ss, w, i)
        w.append_sensors(ref_ss)
    path = tmp_path / "run.h5"
    ss = make_sensors()
    with pytest.raises(RuntimeError, match="node lost"):
        with ResultWriter(path, flush_every=256) as w:
            w.declare_sensors(ss)
            for i in range(1000):
                step(ss, w, i)
                if i == n_ckpt:
                    ckpt = pickle.dumps(ss)
            raise RuntimeError("node lost")
    ss2 = pickle.loads(ckpt)
    with ResultWriter.resume(path, n_ckpt * dt, sensor_set=ss2) as w:
        for i in range(n_ckpt + 1, n_total):
            step(ss2, w, i)
        w.append_sensors(ss2)
    with open_result(tmp_path / "ref.h5") as ref, open_result(path) as res:
        assert res.complete and res.channels() == ref.channels()
        for name in ref.channels():
            a, b = ref.channel(name, False), res.channel(name, False)
            assert np.array_equal(a.t, b.t)
            assert np.array_equal(a.data, b.data, equal_nan=True)
            assert np.array_equal(ref[name].data, res[name].data, equal_nan=True)


def test_j211_sign_attribute(tmp_path):
    """Oracle: SAE J211 axes (x forward, y right, z down) vs crashdem body axes (x forward,
    y left, z up): a z-up accelerometer under a ...ACZ. code is J211-negative, an x one
    positive, a J211-z one (direction (0, 0, -1)) positive; no code -> 0."""
    with ResultWriter(tmp_path / "s.h5") as w:
        w.declare_channel("up", "m/s^2", FS, iso_code="10VEHCFR0000ACZ0", direction=[0, 0, 1],
                          frame="body")
        w.declare_channel("down", "m/s^2", FS, iso_code="10VEHCFR0000ACZ0",
                          direction=[0, 0, -1], frame="body")
        w.declare_channel("fwd", "m/s^2", FS, iso_code="10VEHCFR0000ACX0", direction=[1, 0, 0],
                          frame="body")
        w.declare_channel("left", "rad/s", FS, iso_code="10VEHCCG0000AVY0",
                          direction=[0, 1, 0], frame="body")
        w.declare_channel("plain", "N", FS, direction=[0, 0, 1], frame="world")
    with h5py.File(tmp_path / "s.h5", "r") as f:
        signs = {n: int(f["channels"][n].attrs["j211_sign"]) for n in f["channels"]}
    assert signs == {"up": -1, "down": 1, "fwd": 1, "left": -1, "plain": 0}


def test_result_with_a_failed_sensor_reads_as_a_recording(tmp_path):
    """A result whose accelerometer failed (NaN tail by design) is a valid recording
    (``crashdem.recordings.read_recording``, e.g. ``crashdem diagnose --recording run.h5``):
    the failed channel ends at its failure, like a broken transducer's lab channel, with the
    same samples as the result before it; the other channels are whole."""
    from crashdem.recordings import read_recording

    path = tmp_path / "run.h5"
    write_run(path)
    rec = read_recording(path)
    with open_result(path) as res:
        full = res["front_accel_z"]
        n_ok = int(np.argmin(np.isfinite(full.data)))
        assert 0 < n_ok < full.data.size
        f = rec["front_accel_z"]
        assert f.data.size == n_ok and np.array_equal(f.data, full.data[:n_ok])
        assert f.meta["truncated_at_failure"] == pytest.approx(float(full.t[n_ok]))
        # the first NaN sample is the one whose acquisition interval holds the failure
        assert abs(f.meta["truncated_at_failure"] - f.meta["failed_at"]) <= 1.0 / FS
        assert np.array_equal(rec["rear_accel_x"].data, res["rear_accel_x"].data)
        assert "truncated_at_failure" not in rec["rear_accel_x"].meta
