"""Tests of recordings I/O and validation (crashdem.recordings).

Round trips write signals generated here and read them back; the oracle is the input itself
(bit-exact data for CSV/HDF5/ISO-MME, which all write 17 significant digits or binary float64).
Each bad-recording problem has its own test with the message checked.
"""
from __future__ import annotations

import sys

import h5py
import numpy as np
import pytest

from crashdem.filters import cfc_filter
from crashdem.recordings import (
    RecordingError,
    detect_format,
    read_recording,
    validate,
    write_recording,
)
from crashdem.signal import Signal

#: ISO-MME rebuilds time as t0 + i*dt: a few ulp of t_end
TIME_ATOL = 1e-15


def _signals(fs=10_000.0, n=1200):
    t = np.arange(n) / fs
    acc = Signal("cg_accel_z", t, 25.0 * np.sin(2 * np.pi * 8 * t) + np.cos(300 * t), "g")
    acc = cfc_filter(acc, cfc=60)
    acc.meta["iso_code"] = "10VEHCCG0000ACZD"
    force = Signal("floor_force_z", t, 2e5 * np.exp(-((t - 0.06) / 0.01) ** 2), "N")
    pitch = Signal("pitch_angle", t, 0.3 * t, "rad", cfc=None)
    return [acc, force, pitch]


@pytest.mark.parametrize("fmt, name", [("csv", "rec.csv"), ("hdf5", "rec.h5"),
                                       ("isomme", "TEST01"), ("isomme", "TEST02.zip")])
def test_round_trip_each_format(tmp_path, fmt, name):
    """Oracle: the written signals. Data bit-exact, time exact (ISO-MME: t0 + i dt to a few ulp),
    units, CFC and ISO code preserved; the format is auto-detected on reading."""
    sigs = _signals()
    path = tmp_path / name
    write_recording(path, sigs, format=fmt)
    assert detect_format(path) == fmt
    out = read_recording(path)
    assert sorted(out) == sorted(s.name for s in sigs)
    for s in sigs:
        r = out[s.name]
        np.testing.assert_array_equal(r.data, s.data)
        np.testing.assert_allclose(r.t, s.t, rtol=0, atol=TIME_ATOL)
        assert r.unit == s.unit
        assert r.cfc == s.cfc
    assert out["cg_accel_z"].meta["iso_code"] == "10VEHCCG0000ACZD"
    if fmt == "hdf5":  # the filter method survives in HDF5 metadata
        assert out["cg_accel_z"].meta["filter"]["padding"] == "odd"


def test_format_from_suffix_and_channel_selection(tmp_path):
    """write_recording infers the format from the suffix; channels= selects by name or code."""
    sigs = _signals()
    write_recording(tmp_path / "a.csv", sigs)
    write_recording(tmp_path / "a.h5", sigs)
    write_recording(tmp_path / "A01", sigs)
    assert [detect_format(tmp_path / p) for p in ("a.csv", "a.h5", "A01")] == \
        ["csv", "hdf5", "isomme"]
    assert list(read_recording(tmp_path / "a.h5", channels=["pitch_angle"])) == ["pitch_angle"]
    assert list(read_recording(tmp_path / "A01", channels=["10VEHCCG0000ACZD"])) == ["cg_accel_z"]
    with pytest.raises(RecordingError, match=r"a\.csv: channel 'nope' not found"):
        read_recording(tmp_path / "a.csv", channels=["nope"])


def test_csv_header_variants(tmp_path):
    """Header grammar variants: 'name (unit)', a second unit row, ';' with decimal commas and
    time in ms all read to the same channels (oracle: the numbers typed in the test)."""
    files = {
        "paren.csv": "Time (s),accel_z (g),force (kN)\n0,1.5,2\n0.001,2.5,3\n0.002,3.5,4\n",
        "unitrow.csv": "time,accel_z,force\n[s],[g],kN\n0,1.5,2\n0.001,2.5,3\n0.002,3.5,4\n",
        "semicolon.csv": "time [ms];accel_z [g];force [kN]\n0;1,5;2\n1;2,5;3\n2;3,5;4\n",
        "tab.txt": "# exported by a DAQ\ntime [s]\taccel_z [g]\tforce [kN]\n0\t1.5\t2\n"
                   "0.001\t2.5\t3\n0.002\t3.5\t4\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text, encoding="utf-8")
        out = read_recording(tmp_path / name)
        np.testing.assert_allclose(out["accel_z"].t, [0, 1e-3, 2e-3], rtol=0, atol=1e-15)
        np.testing.assert_array_equal(out["accel_z"].data, [1.5, 2.5, 3.5])
        assert out["accel_z"].unit == "g" and out["force"].unit == "kN", name
        np.testing.assert_allclose(out["force"].to_si().data, [2e3, 3e3, 4e3])


def test_text_as_other_codes_write_it(tmp_path):
    """Columns as another code or a script writes them read to the same channels (oracle: the
    numbers written here): Yade's ``plot.saveDataTxt`` (header as a '# ' comment, tab-padded,
    no units: given to the reader), ``numpy.savetxt(header=...)`` (whitespace, scientific
    notation), whitespace columns with bracketed units, units as name suffixes, gzip / bzip2."""
    import bz2
    import gzip

    t = np.array([0.0, 1e-4, 2e-4, 3e-4])
    az = np.array([0.5, -1.25, 3.0, 40.0])
    vz = np.array([-16.4, -16.3, -16.1, -15.2])
    yade = "# t\t\tvz\t\taz\n" + "".join(f"{a}\t{b}\t{c}\n" for a, b, c in zip(t, vz, az))
    (tmp_path / "yade.txt").write_text(yade, encoding="utf-8")
    np.savetxt(tmp_path / "np.dat", np.c_[t, vz, az], header="t vz az")
    (tmp_path / "ws.dat").write_text(
        "time [ms]   velocity_z [m/s]   accel_z [m/s^2]\n"
        + "".join(f"{1e3 * a:g}   {b}   {c}\n" for a, b, c in zip(t, vz, az)), encoding="utf-8")
    (tmp_path / "suffix.csv").write_text(
        "time_ms,vz_mps,az_g\n" + "".join(f"{1e3 * a:g},{b},{float(c / 9.80665)!r}\n"
                                            for a, b, c in zip(t, vz, az)), encoding="utf-8")
    (tmp_path / "yade.txt.gz").write_bytes(gzip.compress(yade.encode()))
    (tmp_path / "yade.txt.bz2").write_bytes(bz2.compress(yade.encode()))
    units = {"vz": "m/s", "az": "m/s^2"}
    for name, names in [("yade.txt", ("vz", "az")), ("np.dat", ("vz", "az")),
                        ("ws.dat", ("velocity_z", "accel_z")), ("suffix.csv", ("vz_mps", "az_g")),
                        ("yade.txt.gz", ("vz", "az")), ("yade.txt.bz2", ("vz", "az"))]:
        assert detect_format(tmp_path / name) == "csv"
        out = read_recording(tmp_path / name, strict_fs=False, units=units)
        v, a = out[names[0]].to_si(), out[names[1]].to_si()
        np.testing.assert_allclose(v.t, t, rtol=0, atol=1e-15)
        np.testing.assert_allclose(v.data, vz, rtol=1e-15)
        np.testing.assert_allclose(a.data, az, rtol=1e-15)
        assert (v.unit, a.unit) == ("m/s", "m/s^2"), name


def test_text_without_names_and_suffix_limits(tmp_path):
    """Data with no header line and no comment naming every column is refused by line; a time
    suffix is read on the time column only (``vel_ms`` has no unit); a unit the header gives
    wins over a suffix."""
    (tmp_path / "bare.txt").write_text("# run 3\n0 1 2\n0.001 2 3\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"bare\.txt: line 2 is data, and no header names "
                                             r"its 3 columns"):
        read_recording(tmp_path / "bare.txt", strict_fs=False)
    (tmp_path / "ms.csv").write_text("time_ms,vel_ms\n0,1\n1,2\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"channel 'vel_ms': no unit"):
        read_recording(tmp_path / "ms.csv", strict_fs=False)
    (tmp_path / "win.csv").write_text("time_ms,acc_g [m/s^2]\n0,1\n1,2\n", encoding="utf-8")
    r = read_recording(tmp_path / "win.csv", strict_fs=False)["acc_g"]
    assert r.unit == "m/s^2" and r.t[1] == pytest.approx(1e-3)


def test_csv_channel_comment_metadata(tmp_path):
    """'# channel: name; cfc=..; iso_code=..' lines set the filter class and ISO code."""
    (tmp_path / "m.csv").write_text(
        "# channel: a; cfc=180; iso_code=10VEHCCG0000ACXC\ntime [s],a [m/s^2]\n0,1\n1e-4,2\n"
        "2e-4,3\n", encoding="utf-8")
    s = read_recording(tmp_path / "m.csv")["a"]
    assert s.cfc == 180.0 and s.meta["iso_code"] == "10VEHCCG0000ACXC"


def test_read_with_cfc_filters_raw_channels(tmp_path):
    """read_recording(..., cfc=) returns channels filtered at that class (same as cfc_filter on
    the raw channel), with the method recorded in meta['filter']."""
    t = np.arange(2000) / 10_000.0
    raw = Signal("cg_accel_x", t, np.sign(np.sin(2 * np.pi * 30 * t)), "g")
    write_recording(tmp_path / "r.h5", [raw])
    out = read_recording(tmp_path / "r.h5", cfc=60)["cg_accel_x"]
    assert out.cfc == 60.0 and out.meta["filter"]["cfc"] == 60.0
    np.testing.assert_array_equal(out.data, cfc_filter(raw, cfc=60).data)


# --------------------------------------------------------------------------- bad recordings

def test_error_non_monotonic_time(tmp_path):
    (tmp_path / "b.csv").write_text("time [s],acc [g]\n0,1\n0.002,2\n0.001,3\n0.003,4\n",
                                    encoding="utf-8")
    with pytest.raises(RecordingError,
                       match=r"b\.csv: channel 'acc': time is not strictly increasing at "
                             r"sample 2"):
        read_recording(tmp_path / "b.csv")


def test_error_nan_in_data(tmp_path):
    (tmp_path / "b.csv").write_text("time [s],acc [g],f [N]\n0,1,1\n0.001,,2\n0.002,3,3\n",
                                    encoding="utf-8")
    with pytest.raises(RecordingError,
                       match=r"b\.csv: channel 'acc': data contain NaN/inf: 1 samples, first at "
                             r"sample 1 \(t=0\.001 s\)"):
        read_recording(tmp_path / "b.csv")


def test_error_unknown_unit(tmp_path):
    with h5py.File(tmp_path / "b.h5", "w") as f:
        f.attrs["format"] = "crashdem-recording"
        g = f.create_group("acc")
        g.create_dataset("t", data=np.arange(5) * 1e-3)
        g.create_dataset("data", data=np.ones(5))
        g.attrs["unit"] = "parsec/fortnight"
    with pytest.raises(RecordingError,
                       match=r"b\.h5: channel 'acc': unknown unit 'parsec/fortnight'"):
        read_recording(tmp_path / "b.h5")


@pytest.mark.parametrize("spelled, unit", [
    ("m/s²", "m/s^2"), ("m s^-2", "m/s^2"), ("m/s/s", "m/s^2"), ("m.s-1", "m/s"),
    ("m/sec", "m/s"), ("N.m", "N*m"), ("°", "deg"), ("-", "1")])
def test_other_spellings_of_a_unit(tmp_path, spelled, unit):
    """A column in another spelling of a unit crashdem knows is read and stored in crashdem's
    spelling, so that it converts to SI as that unit does (degrees to radians); a time column
    in ``msec`` is read as ms."""
    from crashdem.signal import UNIT_TO_SI

    (tmp_path / "b.csv").write_text(f"time [msec],x [{spelled}]\n0,1.5\n1,2.5\n2,3.5\n",
                                    encoding="utf-8")
    x = read_recording(tmp_path / "b.csv")["x"]
    assert x.unit == unit
    np.testing.assert_allclose(x.t, [0.0, 1e-3, 2e-3])
    np.testing.assert_allclose(x.to_si().data, UNIT_TO_SI[unit][0] * np.array([1.5, 2.5, 3.5]))


def test_unusable_channels_are_left_out_when_the_reader_asks(tmp_path):
    """Another code's output may hold columns no reader here uses (a temperature in degC, a
    gap in a contact count). With ``skipped`` each unusable channel is left out and its error
    kept under its name; the usable ones are read as without it. Without ``skipped`` the first
    unusable channel fails the file, as before."""
    (tmp_path / "b.csv").write_text(
        "time [s],acc [g],temp [degC],n [1]\n0,1,20,5\n0.001,2,20,\n0.002,3,20,7\n",
        encoding="utf-8")
    skipped: dict[str, str] = {}
    sigs = read_recording(tmp_path / "b.csv", skipped=skipped)
    assert list(sigs) == ["acc"] and sigs["acc"].unit == "g"
    np.testing.assert_array_equal(sigs["acc"].data, [1.0, 2.0, 3.0])
    assert set(skipped) == {"temp", "n"}
    assert "unknown unit 'degC'" in skipped["temp"] and "NaN/inf" in skipped["n"]
    with pytest.raises(RecordingError, match=r"channel 'temp': unknown unit 'degC'"):
        read_recording(tmp_path / "b.csv")


def test_error_empty_channel(tmp_path):
    (tmp_path / "b.csv").write_text("time [s],acc [g],f [N]\n0,,1\n0.001,,2\n0.002,,3\n",
                                    encoding="utf-8")
    with pytest.raises(RecordingError, match=r"b\.csv: channel 'acc': empty channel"):
        read_recording(tmp_path / "b.csv")


def test_error_sample_rate_too_low_for_cfc(tmp_path):
    """J211-1: fs >= 10 CFC (anchors.md section 2); 1 kHz cannot carry CFC 180."""
    t = np.arange(500) / 1000.0
    write_recording(tmp_path / "slow.csv", [Signal("acc", t, np.sin(t), "g")])
    with pytest.raises(RecordingError,
                       match=r"slow\.csv: channel 'acc': fs=1000 Hz is below the J211-1 "
                             r"recommendation fs >= 10\*CFC = 1800 Hz for CFC 180"):
        read_recording(tmp_path / "slow.csv", cfc=180)
    with pytest.raises(RecordingError, match=r"'acc': fs=1000 Hz is too low for CFC 600"):
        validate(Signal("acc", t, np.sin(t), "g"), cfc=600)
    assert validate(Signal("acc", t, np.sin(t), "g"), cfc=60).name == "acc"


def test_error_unknown_format_and_missing_unit(tmp_path):
    (tmp_path / "x.bin").write_bytes(b"\x00\x01")
    with pytest.raises(RecordingError, match=r"x\.bin: unknown recording format"):
        read_recording(tmp_path / "x.bin")
    (tmp_path / "nounit.csv").write_text("time [s],acc\n0,1\n0.001,2\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"nounit\.csv: channel 'acc': no unit"):
        read_recording(tmp_path / "nounit.csv")


def test_units_given_outside_the_header(tmp_path):
    """A CSV without units in its header: the unit of a column comes from a '# channel' comment
    or from the reader's ``units`` (never replacing a unit the file gives); an unknown unit is
    refused by name."""
    (tmp_path / "u.csv").write_text("time,acc,vel [m/s]\n0,1,2\n0.001,2,3\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"channel 'acc': no unit .*--unit acc=UNIT"):
        read_recording(tmp_path / "u.csv", strict_fs=False)
    r = read_recording(tmp_path / "u.csv", strict_fs=False, units={"acc": "g", "vel": "km/h"})
    assert r["acc"].unit == "g" and r["vel"].unit == "m/s"
    assert r["acc"].to_si().data[0] == pytest.approx(9.80665)
    (tmp_path / "c.csv").write_text("# channel: acc; unit=m/s^2\ntime,acc\n0,1\n0.001,2\n",
                                    encoding="utf-8")
    assert read_recording(tmp_path / "c.csv", strict_fs=False)["acc"].unit == "m/s^2"
    with pytest.raises(RecordingError, match=r"'acc'.*unit"):
        read_recording(tmp_path / "u.csv", strict_fs=False, units={"acc": "furlong"})


def test_write_csv_needs_common_time(tmp_path):
    a = Signal("a", np.arange(5) * 1e-3, np.ones(5), "g")
    b = Signal("b", np.arange(5) * 2e-3, np.ones(5), "g")
    with pytest.raises(RecordingError, match=r"'b': CSV needs one common time column"):
        write_recording(tmp_path / "c.csv", [a, b])
    write_recording(tmp_path / "c.h5", [a, b])  # HDF5 keeps one time vector per channel
    assert read_recording(tmp_path / "c.h5")["b"].t[-1] == pytest.approx(8e-3)


def test_reads_crashdem_result_layout_without_results_module(tmp_path, monkeypatch):
    """A crashdem result file (/channels/<name>/{time,raw,filtered}) is read directly when
    crashdem.results is unavailable (guarded import); the filtered dataset and its CFC win."""
    monkeypatch.setitem(sys.modules, "crashdem.results", None)  # import -> ImportError
    t = np.arange(100) * 1e-4
    with h5py.File(tmp_path / "res.h5", "w") as f:
        g = f.create_group("channels/cg_accel_z")
        g.create_dataset("time", data=t)
        g.create_dataset("raw", data=np.sin(t)).attrs["unit"] = "m/s^2"
        d = g.create_dataset("filtered", data=np.cos(t))
        d.attrs["unit"] = "m/s^2"
        d.attrs["cfc"] = 60.0
    s = read_recording(tmp_path / "res.h5")["cg_accel_z"]
    np.testing.assert_array_equal(s.data, np.cos(t))
    assert s.unit == "m/s^2" and s.cfc == 60.0


def test_reads_crashdem_result_through_open_result(tmp_path):
    """A result written by crashdem.results.ResultWriter (docs/results_schema.md) is read through
    open_result: the filtered channel at its CFC class, unit and ISO code with filter letter."""
    results = pytest.importorskip("crashdem.results")
    if not hasattr(results, "ResultWriter"):
        pytest.skip("crashdem.results has no ResultWriter")
    t = np.arange(1000) / 1e4
    w = results.ResultWriter(tmp_path / "run.h5")
    w.declare_channel("cg_accel_z", "m/s^2", 10_000.0, cfc_class=60.0,
                      iso_code="10VEHCCG0000ACZ0")
    w.append_channel("cg_accel_z", t, np.sin(50 * t))
    w.close()
    s = read_recording(tmp_path / "run.h5")["cg_accel_z"]
    assert s.unit == "m/s^2" and s.cfc == 60.0
    assert s.meta["iso_code"] == "10VEHCCG0000ACZD"
    raw = Signal("cg_accel_z", t, np.sin(50 * t), "m/s^2")
    np.testing.assert_allclose(s.data, cfc_filter(raw, cfc=60).data, rtol=0, atol=1e-12)
