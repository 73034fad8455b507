"""Tests of ISO/TS 13499 channel codes and ISO-MME folders (crashdem.isomme).

Oracle for the format: anchors.md section 3 [V] (pyisomme fixtures: 28-character keys, ':Value',
NOVALUE, implicit time t_i = t0 + i*dt, filter letters A/B/C/D = CFC 1000/600/180/60). The
fixture text below is written in the test in that layout, not produced by crashdem.
"""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

from crashdem.isomme import (
    CRASHDEM_CODES,
    ChannelCode,
    cfc_to_letter,
    code_for,
    name_for,
    read_isomme,
    write_isomme,
)
from crashdem.signal import Signal

#: ISO-MME values are written with 17 significant digits (exact float64 round trip); the time
#: vector is rebuilt as t0 + i*dt, so it matches the original to a few ulp of t_end
TIME_ATOL = 1e-15


def test_code_parse_and_format_round_trip():
    """A code splits into the 9 fields of ISO/TS 13499 (anchors.md section 3) and back."""
    c = ChannelCode.parse("10VEHCCG0000ACXD")
    assert (c.test_object, c.position, c.main_location, c.fine1, c.fine2, c.fine3,
            c.dimension, c.direction, c.filter_class) == ("1", "0", "VEHC", "CG", "00", "00",
                                                          "AC", "X", "D")
    assert str(c) == "10VEHCCG0000ACXD"
    assert c.cfc == 60.0 and c.si_unit == "m/s^2"
    assert str(c.with_cfc(None)) == "10VEHCCG0000ACX0"
    assert str(c.with_cfc(1000)) == "10VEHCCG0000ACXA"


@pytest.mark.parametrize("code, field", [
    ("X0VEHCCG0000ACXD", "test_object"),
    ("1_VEHCCG0000ACXD", "position"),
    ("10VE-CCG0000ACXD", "main_location"),
    ("10VEHCC-0000ACXD", "fine1"),
    ("10VEHCCG0-00ACXD", "fine2"),
    ("10VEHCCG00-0ACXD", "fine3"),
    ("10VEHCCG0000ZZXD", "dimension"),
    ("10VEHCCG0000ACWD", "direction"),
    ("10VEHCCG0000ACXK", "filter_class"),
])
def test_code_field_validation_names_field(code, field):
    """Each field is validated and the error names the field and the bad value."""
    with pytest.raises(ValueError, match=rf"ChannelCode\.{field}="):
        ChannelCode.parse(code)


def test_code_length_error():
    with pytest.raises(ValueError, match="16-character"):
        ChannelCode.parse("10VEHCCG0000ACX")


def test_filter_letters_and_cfc():
    """A/B/C/D <-> CFC 1000/600/180/60, L = CFC 20, 0 = raw; E-H old editions read as the same
    classes (anchors.md section 3 [V])."""
    for letter, cfc in zip("ABCD", (1000, 600, 180, 60)):
        assert cfc_to_letter(cfc) == letter
        assert ChannelCode.parse(f"10VEHCCG0000ACX{letter}").cfc == cfc
    for letter, cfc in zip("EFGH", (1000, 600, 180, 60)):
        assert ChannelCode.parse(f"10VEHCCG0000ACX{letter}").cfc == cfc
    assert cfc_to_letter(None) == "0" and cfc_to_letter(20) == "L" and cfc_to_letter(300) == "S"


def test_crashdem_name_table_is_valid_and_invertible():
    """Every entry of the crashdem name table is a valid code and maps back to its name."""
    bases = set()
    for name, code in CRASHDEM_CODES.items():
        cc = ChannelCode.parse(code)
        assert cc.base() not in bases, name
        bases.add(cc.base())
        assert name_for(code_for(name, 180)) == name
    assert code_for("cg_accel_z", 60) == "10VEHCCG0000ACZD"
    assert code_for("impactor_accel_z").startswith("H0")
    assert code_for("floor_force_z").startswith("T0")
    with pytest.raises(ValueError, match="'mystery'.*no ISO/TS 13499 code"):
        code_for("mystery")


def _signals():
    t = -0.01 + np.arange(1500) / 10_000.0
    a = Signal("cg_accel_z", t, 30 * np.sin(60 * t), "g", cfc=60.0)
    f = Signal("floor_force_z", t, 1e5 * np.exp(-((t - 0.05) / 0.01) ** 2), "kN", cfc=None)
    p = Signal("pitch_rate", t, np.cos(20 * t), "deg/s", cfc=180.0,
               meta={"iso_code": "10VEHCCG0000AVY0"})
    return [a, f, p]


@pytest.mark.parametrize("encoding", ["ascii", "latin-1", "windows-1252", "utf-8"])
def test_folder_round_trip_each_encoding(tmp_path, encoding):
    """Write -> read returns the same data, units, CFC and codes, for each encoding of the
    pyisomme fixtures; a non-ASCII laboratory name survives in the 8-bit and UTF-8 encodings."""
    lab = "Laboratorio" if encoding == "ascii" else "Laboratório de Ensaios"
    sigs = _signals()
    write_isomme(tmp_path / "T001", sigs, encoding=encoding, test_header={"Laboratory name": lab})
    assert (tmp_path / "T001" / "T001.mme").is_file()
    assert (tmp_path / "T001" / "Channel" / "T001.chn").is_file()
    assert (tmp_path / "T001" / "Channel" / "T001.003").is_file()
    out, head = read_isomme(tmp_path / "T001")
    assert head["laboratory name"] == [lab]
    assert head["data format"] == ["ISO-MME"]
    for s in sigs:
        r = out[s.name]
        np.testing.assert_array_equal(r.data, s.data)
        np.testing.assert_allclose(r.t, s.t, rtol=0, atol=TIME_ATOL)
        assert r.unit == s.unit and r.cfc == s.cfc
    assert out["cg_accel_z"].meta["iso_code"] == "10VEHCCG0000ACZD"
    assert out["floor_force_z"].meta["iso_code"] == "T0GRNDBO0000FOZ0"
    assert out["pitch_rate"].meta["iso_code"] == "10VEHCCG0000AVYC"


def test_zip_round_trip_and_channel_selection(tmp_path):
    """A .zip of the folder reads like the folder; channels can be picked by name or code."""
    sigs = _signals()
    write_isomme(tmp_path / "T002.zip", sigs)
    with zipfile.ZipFile(tmp_path / "T002.zip") as z:
        assert "T002/T002.mme" in z.namelist() and "T002/Channel/T002.001" in z.namelist()
    out, _ = read_isomme(tmp_path / "T002.zip", channels=["cg_accel_z", "10VEHCCG0000AVYC"])
    assert sorted(out) == ["cg_accel_z", "pitch_rate"]
    with pytest.raises(ValueError, match="not found.*nope"):
        read_isomme(tmp_path / "T002.zip", channels=["nope"])


def _fixture_channel(code="24NECKUP00P2MOZP", unit="Nm", dt="0.0001", t0="-0.1", n="5",
                     cfc="NOVALUE", values=("1.0E-1", "2.0E-1", "-3.5E-1", "0.0E+0", "4.0E0")):
    """A channel file in the layout of pyisomme's data/tests/ascii/Channel/test.001."""
    keys = [("Channel code", code), ("Name of the channel", "Neck Upper Moment Z"),
            ("Channel frequency class", cfc), ("Cut off frequency", "NOVALUE"),
            ("Sampling interval", dt), ("Unit", unit), ("Time of first sample", t0),
            ("Number of samples", n), ("Dimension", code[12:14]), ("Data status", "ok")]
    head = "\n".join(f"{k:<28}:{v}" for k, v in keys)
    return head + "\n" + "\n".join(values) + "\n"


def _fixture_folder(root, channel_text, encoding="latin-1"):
    (root / "Channel").mkdir(parents=True)
    (root / "test.mme").write_bytes(
        "Data format                 :ISO-MME\nVersion                     :1.6\n"
        "Test number                 :test\nComments                    :a\n"
        "Comments                    :b\n".encode(encoding))
    (root / "Channel" / "test.chn").write_bytes(
        "Number of channels          :1\n".encode(encoding))
    (root / "Channel" / "test.001").write_bytes(channel_text.encode(encoding))


def test_read_external_fixture_layout(tmp_path):
    """Oracle: the pyisomme fixture layout (anchors.md section 3): implicit time from t0 = -0.1 s
    and dt = 1e-4 s, NOVALUE keys, unit 'Nm', repeated keys, an unknown code stays the name."""
    _fixture_folder(tmp_path / "test", _fixture_channel())
    out, head = read_isomme(tmp_path / "test" / "test.mme")
    s = out["24NECKUP00P2MOZP"]
    np.testing.assert_allclose(s.t, -0.1 + 1e-4 * np.arange(5), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(s.data, [0.1, 0.2, -0.35, 0.0, 4.0])
    assert s.unit == "N*m" and s.cfc is None  # filter letter P: prefiltered, not a CFC
    assert head["comments"] == ["a", "b"]


@pytest.mark.parametrize("kw, message", [
    ({"dt": "NOVALUE"}, r"test\.001.*24NECKUP00P2MOZP.*'Sampling interval' is missing"),
    ({"t0": "NOVALUE"}, r"test\.001.*'Time of first sample' is missing"),
    ({"n": "7"}, r"test\.001.*'Number of samples' = 7 but 5 values"),
    ({"unit": "furlong"}, r"test\.001.*unknown unit 'furlong'"),
    ({"code": "10VEHCCG0000ACXD", "unit": "g", "cfc": "180"},
     r"'Channel frequency class' = 180 contradicts.*'D'"),
    ({"values": ("1.0", "oops", "2", "3", "4")}, r"test\.001.*'oops' is not a number"),
])
def test_bad_channel_file_errors(tmp_path, kw, message):
    """Bad channel files give errors naming the file, the channel and the problem."""
    _fixture_folder(tmp_path / "test", _fixture_channel(**kw))
    with pytest.raises(ValueError, match=message):
        read_isomme(tmp_path / "test")


def test_write_rejects_unit_dimension_mismatch_and_unknown_name(tmp_path):
    t = np.arange(10) / 1e4
    with pytest.raises(ValueError, match="'cg_accel_z'.*does not match the ISO dimension AC"):
        write_isomme(tmp_path / "A", [Signal("cg_accel_z", t, t, "deg")])
    with pytest.raises(ValueError, match="'foo'.*no ISO/TS 13499 code"):
        write_isomme(tmp_path / "B", [Signal("foo", t, t, "g")])
    with pytest.raises(ValueError, match="cannot encode"):
        write_isomme(tmp_path / "C", [Signal("cg_accel_z", t, t, "g")], encoding="ascii",
                     test_header={"Laboratory name": "Laboratório"})


def test_rewrite_with_fewer_channels_leaves_no_stale_files(tmp_path):
    """Writing the same test again with fewer channels must not leave old channel files that
    would be read back."""
    sigs = _signals()
    write_isomme(tmp_path / "T003", sigs)
    write_isomme(tmp_path / "T003", sigs[:1])
    out, _ = read_isomme(tmp_path / "T003")
    assert list(out) == ["cg_accel_z"]
