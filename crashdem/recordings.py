"""Test recordings: read and write CSV, crashdem recording HDF5 and ISO-MME, with validation.

``read_recording(path)`` detects the format (see ``detect_format``) and returns
``{name: Signal}``; every channel is validated (``validate``) and an error names the file, the
channel and the problem. ``write_recording(path, signals, format=...)`` writes any of the three.
Grammars and layouts are documented in ``docs/recordings.md``.

CSV grammar (summary)::

    # crashdem-recording: 1                          optional comment lines ('#')
    # channel: accel_z; cfc=60; iso_code=10VEHCCG0000ACZD
    time [s],accel_z [g],pitch_angle [deg]           header: name [unit] | name (unit) | name
    [s],[g],[deg]                                    optional unit row (if the header has none)
    0.0,0.01,0.0                                     data; ',' ';' or tab; ';' allows decimal ','

The first column is time in s, ms or us. Empty cells are NaN (and rejected by validation).
Also read, as other codes write them: whitespace-separated columns; the header as the last
comment line right above the data when no header line precedes it (``# t  vz  az``: Yade's
``plot.saveDataTxt``, ``numpy.savetxt(header=...)``); a unit as the name's suffix
(``time_ms``, ``accel_g``, ``force_kN``: ``_SUFFIX_UNITS``) when nothing else gives one; files
compressed with gzip or bzip2 (``.gz`` / ``.bz2``); other spellings of the units (``m/s²``,
``m s^-2``, ``m/sec``, ``N.m``, ``°``, ``-``, time in ``sec``: ``UNIT_SPELLINGS``), stored in
crashdem's.

HDF5 recording layout::

    /            attrs: format="crashdem-recording", version=1
    /<name>/t    float64 (n,)  attrs: unit="s"
    /<name>/data float64 (n,)  attrs: unit
    /<name>      attrs: unit, cfc (absent = raw), iso_code (optional), meta_json (optional)

A crashdem result file (``/channels/<name>/{time,raw,filtered}``) is read through
``crashdem.results.open_result`` when that module exists (guarded import), else directly.

Notes
-----
ISO-MME: ISO/TS 13499 (anchors.md section 3 [V]), implemented in ``crashdem.isomme``.
Sample-rate rule for a requested CFC: SAE J211-1 fs >= 10 CFC (anchors.md section 2 [V]).
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path
from typing import Any, Iterable, Mapping

import h5py
import numpy as np

from crashdem import isomme
from crashdem.filters import cfc_filter, check_sample_rate
from crashdem.signal import UNIT_TO_SI, Signal

FORMATS = ("csv", "hdf5", "isomme")
HDF5_FORMAT_TAG = "crashdem-recording"
HDF5_VERSION = 1
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "sec": 1.0, "msec": 1e-3}
#: other spellings of units crashdem knows (``signal.UNIT_TO_SI``), as other codes and
#: spreadsheets write them -> crashdem's spelling; a channel read with one is stored with
#: crashdem's, so that it converts to SI
UNIT_SPELLINGS = {
    **dict.fromkeys(("m/s²", "m/s/s", "m/s**2", "m s^-2", "m s-2", "m*s^-2", "m.s^-2", "m.s-2",
                     "ms^-2", "ms-2", "m/sec^2", "m/sec2", "m/sec²", "m s⁻²", "m·s⁻²",
                     "m·s^-2"), "m/s^2"),
    **dict.fromkeys(("m s^-1", "m s-1", "m*s^-1", "m.s^-1", "m.s-1", "ms^-1", "ms-1", "m/sec",
                     "m s⁻¹", "m·s⁻¹", "m·s^-1"), "m/s"),
    **dict.fromkeys(("N.m", "N·m", "N m"), "N*m"),
    **dict.fromkeys(("rad.s^-1", "rad s^-1", "rad s-1", "rad/sec"), "rad/s"),
    **dict.fromkeys(("°/s", "deg/sec"), "deg/s"),
    "°": "deg", "-": "1", "sec": "s"}
_TIME_NAMES = {"time", "t", "zeit", "temps", "tempo"}
#: a unit written as the last ``_``-separated part of a column name (lower-cased) -> the unit;
#: time units only for the time column (``vel_ms`` is not read as milliseconds)
_SUFFIX_UNITS = {"g": "g", "mps2": "m/s^2", "ms2": "m/s^2", "mps": "m/s", "kmh": "km/h",
                 "m": "m", "mm": "mm", "n": "N", "kn": "kN", "nm": "N*m", "rads": "rad/s",
                 "degs": "deg/s", "rad": "rad", "deg": "deg"}
_SUFFIX_TIME_UNITS = {"s": "s", "ms": "ms", "us": "us"}
#: whitespace-separated header cells, a bracketed unit kept with its name (``time [s]``)
_WS_HEADER_CELL = re.compile(r"[^\s\[(]+(?:\s*(?:\[[^\]]*\]|\([^)]*\)))?")
_COMPRESSED = {".gz": "gzip", ".bz2": "bz2"}
_HEADER_CELL = re.compile(r"^\s*(?P<name>.*?)\s*(?:\[(?P<u1>[^\]]*)\]|\((?P<u2>[^)]*)\))\s*$")
#: relative tolerance on a common time vector when writing CSV
CSV_TIME_RTOL = 1e-12

__all__ = ["FORMATS", "RecordingError", "detect_format", "read_recording", "validate",
           "write_recording"]


class RecordingError(ValueError):
    """A recording (file or channel) is unusable; the message names file, channel and problem."""


# --------------------------------------------------------------------------- validation

def validate(signal: Signal, cfc: float | None = None, *, source: str | Path | None = None,
             strict_fs: bool = True) -> Signal:
    """Check that a channel is usable; return it unchanged.

    Parameters
    ----------
    signal : the channel
    cfc : if given, the channel must be sampled fast enough for this CFC [Hz]
    source : file name used in messages
    strict_fs : if True (default) a sample rate below J211-1's 10 x CFC is an error; otherwise it
        only warns (``crashdem.filters.SampleRateWarning``) and only fs <= 2*2.0775*CFC is an error

    Raises
    ------
    RecordingError
        empty channel, unknown unit, NaN/inf in time or data, time not strictly increasing,
        fewer than 2 samples or too low a sample rate for ``cfc``.

    Notes
    -----
    Sample-rate thresholds: SAE J211-1 (anchors.md section 2); see docs/filtering.md.
    """
    where = f"{source}: " if source is not None else ""
    pre = f"{where}channel {signal.name!r}: "
    if signal.t.size == 0 or (signal.data.size and np.all(np.isnan(signal.data))):
        raise RecordingError(pre + "empty channel (no samples)")
    if signal.unit not in UNIT_TO_SI:
        raise RecordingError(pre + f"unknown unit {signal.unit!r}; known units are "
                             f"{sorted(UNIT_TO_SI)}")
    bad_t = ~np.isfinite(signal.t)
    if bad_t.any():
        i = int(np.flatnonzero(bad_t)[0])
        raise RecordingError(pre + f"time contains NaN/inf at sample {i}")
    bad = ~np.isfinite(signal.data)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise RecordingError(pre + f"data contain NaN/inf: {int(bad.sum())} samples, first at "
                             f"sample {i} (t={signal.t[i]:.6g} s)")
    dt = np.diff(signal.t)
    if (dt <= 0).any():
        i = int(np.flatnonzero(dt <= 0)[0])
        raise RecordingError(pre + f"time is not strictly increasing at sample {i + 1} "
                             f"(t={signal.t[i]:.9g} s -> {signal.t[i + 1]:.9g} s)")
    if cfc is not None:
        if signal.t.size < 2:
            raise RecordingError(pre + "fewer than 2 samples: no sample rate for the CFC check")
        try:
            check_sample_rate(signal.fs, cfc, signal.name, strict=strict_fs)
        except ValueError as e:
            raise RecordingError(f"{where}{e}") from None
    return signal


# --------------------------------------------------------------------------- dispatch

def detect_format(path: str | Path) -> str:
    """'isomme' (folder, .mme or zip with a .mme), 'hdf5' (HDF5 signature) or 'csv'."""
    p = Path(path)
    if not p.exists():
        raise RecordingError(f"{p}: no such file or folder")
    if isomme.is_isomme(p):
        return "isomme"
    if p.is_file():
        with open(p, "rb") as f:
            if f.read(8) == b"\x89HDF\r\n\x1a\n":
                return "hdf5"
        suffix = p.suffix.lower()
        if suffix in _COMPRESSED:
            suffix = Path(p.stem).suffix.lower()
        if suffix in (".csv", ".txt", ".dat", ".tsv", ""):
            return "csv"
    raise RecordingError(f"{p}: unknown recording format (expected CSV, HDF5 or an ISO-MME "
                         "folder/.mme/.zip)")


def read_recording(path: str | Path, channels: Iterable[str] | None = None, *,
                   format: str | None = None, cfc: float | None = None,
                   strict_fs: bool = True,
                   units: Mapping[str, str] | None = None,
                   skipped: dict[str, str] | None = None) -> dict[str, Signal]:
    """Read a recording and validate every channel.

    Parameters
    ----------
    path : CSV file, HDF5 file (crashdem recording or result), ISO-MME folder / .mme / .zip
    channels : names to keep (ISO codes also accepted for ISO-MME); None = all
    format : force "csv", "hdf5" or "isomme" (default: ``detect_format``)
    cfc : if given, check the sample rate of every channel against this CFC [Hz] and return the
        channels filtered with it (``crashdem.filters.cfc_filter``; method in ``meta['filter']``)
    strict_fs : see ``validate``
    units : CSV only: unit of each named column whose header (and ``# channel: NAME; unit=U``
        comment) gives none, e.g. ``{"accel_z": "g"}``; a unit the file gives is never replaced
    skipped : when given (a dict, filled in), a channel that fails ``validate`` is left out
        and its error message stored under its name, instead of failing the whole file: a
        reader that uses some channels of another code's output (which may hold a temperature
        in degC or a contact count in ``-`` beside them) decides itself whether what it needs
        was among them

    Returns
    -------
    dict name -> Signal (units as stored in the file; use ``Signal.to_si()`` for SI)

    Raises
    ------
    RecordingError
        naming the file, the channel and the problem.
    """
    path = Path(path)
    fmt = format or detect_format(path)
    if fmt not in FORMATS:
        raise RecordingError(f"format={fmt!r}: must be one of {FORMATS}")
    try:
        if fmt == "csv":
            sigs = _read_csv(path, units)
        elif fmt == "hdf5":
            sigs = _read_hdf5(path)
        else:
            sigs, _ = isomme.read_isomme(path)
    except RecordingError:
        raise
    except (ValueError, OSError, KeyError) as e:
        msg = str(e)
        raise RecordingError(msg if str(path) in msg else f"{path}: {msg}") from None
    if channels is not None:
        wanted = list(channels)
        out = {}
        for w in wanted:
            hit = [s for s in sigs.values() if w in (s.name, s.meta.get("iso_code"))]
            if not hit:
                raise RecordingError(f"{path}: channel {w!r} not found; available: "
                                     f"{sorted(sigs)}")
            out[hit[0].name] = hit[0]
        sigs = out
    for name, s in list(sigs.items()):
        try:
            validate(s, cfc, source=path, strict_fs=strict_fs)
        except RecordingError as e:
            if skipped is None:
                raise
            skipped[name] = str(e)
            del sigs[name]
    if cfc is not None:
        sigs = {k: (s if s.cfc == cfc else cfc_filter(s, cfc=cfc)) for k, s in sigs.items()}
    return sigs


def write_recording(path: str | Path, signals: Mapping[str, Signal] | Iterable[Signal],
                    format: str | None = None, **kwargs: Any) -> Path:
    """Write signals as a recording.

    Parameters
    ----------
    path : target file (CSV, HDF5) or folder / .zip (ISO-MME)
    signals : dict name -> Signal or an iterable of Signals
    format : "csv", "hdf5" or "isomme"; default from the suffix (.csv/.txt -> csv, .h5/.hdf5 ->
        hdf5, .zip or no suffix -> isomme)
    **kwargs : passed to the writer (ISO-MME: ``test_number``, ``encoding``, ``test_header``)

    Returns
    -------
    the path written
    """
    path = Path(path)
    sigs = list(signals.values()) if isinstance(signals, Mapping) else list(signals)
    if not sigs:
        raise RecordingError(f"{path}: no channels to write")
    names = [s.name for s in sigs]
    if len(set(names)) != len(names):
        raise RecordingError(f"{path}: duplicate channel names {names}")
    for s in sigs:
        validate(s, source=path)
    if format is None:
        suf = path.suffix.lower()
        format = ("csv" if suf in (".csv", ".txt") else "hdf5" if suf in (".h5", ".hdf5")
                  else "isomme" if suf in (".zip", "") else None)
        if format is None:
            raise RecordingError(f"{path}: cannot infer the format from the suffix; give format=")
    if format == "csv":
        _write_csv(path, sigs, **kwargs)
    elif format == "hdf5":
        _write_hdf5(path, sigs, **kwargs)
    elif format == "isomme":
        try:
            isomme.write_isomme(path, sigs, **kwargs)
        except ValueError as e:
            raise RecordingError(f"{path}: {e}") from None
    else:
        raise RecordingError(f"format={format!r}: must be one of {FORMATS}")
    return path


# --------------------------------------------------------------------------- CSV

def _decode_text(raw: bytes) -> str:
    for enc in ("utf-8-sig", "windows-1252", "latin-1"):
        try:
            return raw.decode(enc)
        except UnicodeDecodeError:
            continue
    raise AssertionError("latin-1 decodes everything")  # pragma: no cover


def _parse_meta_comment(line: str, meta: dict[str, dict[str, str]]) -> None:
    body = line.lstrip("#").strip()
    if not body.lower().startswith("channel:"):
        return
    parts = [p.strip() for p in body.split(":", 1)[1].split(";")]
    name = parts[0]
    kv = {}
    for p in parts[1:]:
        if "=" in p:
            k, v = p.split("=", 1)
            kv[k.strip()] = v.strip()
    meta[name] = kv


def _suffix_unit(name: str, time: bool = False) -> str | None:
    """The unit a column name carries as its last ``_``-separated part (``time_ms``,
    ``accel_g``), or None."""
    head, sep, tail = name.strip().rpartition("_")
    if not sep or not head:
        return None
    table = _SUFFIX_TIME_UNITS if time else _SUFFIX_UNITS
    return table.get(tail.lower())


def _header_cells(line: str, delim: str | None) -> list[str]:
    """A header line cut into cells: by ``delim``, or (None) at whitespace keeping a bracketed
    unit with its name; tab-separated headers lose their empty cells (Yade pads with tabs)."""
    if delim is None:
        return _WS_HEADER_CELL.findall(line)
    cells = next(csv.reader([line], delimiter=delim))
    return [c for c in cells if c.strip()] if delim == "\t" else cells


def _read_text(path: Path) -> bytes:
    raw = path.read_bytes()
    how = _COMPRESSED.get(path.suffix.lower())
    if how == "gzip":
        import gzip

        return gzip.decompress(raw)
    if how == "bz2":
        import bz2

        return bz2.decompress(raw)
    return raw


def _split_header(cell: str) -> tuple[str, str | None]:
    m = _HEADER_CELL.match(cell)
    if m:
        unit = m.group("u1") if m.group("u1") is not None else m.group("u2")
        return m.group("name").strip(), unit.strip()
    return cell.strip(), None


def _to_float(cell: str, decimal_comma: bool) -> float:
    c = cell.strip()
    if c == "" or c.lower() in ("nan", "novalue"):
        return math.nan
    if decimal_comma:
        c = c.replace(",", ".")
    return float(c)


def _read_csv(path: Path, units: Mapping[str, str] | None = None) -> dict[str, Signal]:
    try:
        text = _decode_text(_read_text(path))
    except (OSError, EOFError) as e:
        raise RecordingError(f"{path}: cannot decompress ({e})") from None
    lines = text.splitlines()
    meta: dict[str, dict[str, str]] = {}
    body: list[tuple[int, str]] = []
    last_comment: str | None = None  # the last comment line above the first body line
    for k, line in enumerate(lines, start=1):
        if line.lstrip().startswith("#"):
            _parse_meta_comment(line, meta)
            if not body:
                last_comment = line.lstrip().lstrip("#").strip()
        elif line.strip():
            body.append((k, line))
    if not body:
        raise RecordingError(f"{path}: no header line")
    head_line = body[0][1]
    delim: str | None = ("\t" if "\t" in head_line else
                         ";" if (";" in head_line and "," not in head_line) else
                         "," if "," in head_line else None)
    decimal_comma = delim == ";"
    if delim is None:  # whitespace-separated columns
        rows = [l.split() for _, l in body]
    else:
        rows = list(csv.reader(io.StringIO("\n".join(l for _, l in body)), delimiter=delim))
    cells = _header_cells(head_line, delim)
    first_data = 1
    if cells and all(_is_num(c, decimal_comma) for c in rows[0] if c.strip()):
        # no header line: the names are in the comment line above the data (Yade's
        # plot.saveDataTxt, numpy.savetxt(header=...)), when it has one per column
        ncells = len([c for c in rows[0] if c.strip()])
        names = _header_cells(last_comment or "", delim if delim is not None
                              and delim in (last_comment or "") else None)
        if last_comment is None or len(names) != ncells:
            raise RecordingError(
                f"{path}: line {body[0][0]} is data, and no header names its {ncells} columns "
                f"(write a header line such as 'time [s],accel_z [g]', or a '# ' comment line "
                f"right above the data with one name per column)")
        cells = names
        first_data = 0
    header = [_split_header(c) for c in cells]
    ncol = len(header)
    if ncol < 2:
        raise RecordingError(f"{path}: header {head_line!r} has fewer than 2 columns "
                             "(time + channels)")
    if first_data == 1:
        rows = [cells] + rows[1:]
    if first_data == 1 and len(rows) > 1 and any(not _is_num(c, decimal_comma)
                                                 for c in rows[1] if c.strip()):
        units_row = rows[1] if delim is not None else _header_cells(body[1][1], None)
        if len(units_row) != ncol:
            raise RecordingError(f"{path}: line {body[1][0]}: unit row has {len(units_row)} "
                                 f"cells, header has {ncol}")
        header = [(n, (u if u is not None else units_row[i].strip().strip("[]()")))
                  for i, (n, u) in enumerate(header)]
        first_data = 2
    names = [n for n, _ in header]
    if len(set(names)) != len(names):
        raise RecordingError(f"{path}: duplicate column names in the header {names}")
    t_name, t_unit = header[0]
    if t_unit is None:
        t_unit = ("s" if t_name.lower() in _TIME_NAMES else
                  _suffix_unit(t_name, time=True) if t_name.lower().rpartition("_")[0]
                  in _TIME_NAMES else None)
    if t_unit not in TIME_UNITS:
        raise RecordingError(f"{path}: first column {t_name!r} must be time in "
                             f"{sorted(TIME_UNITS)}, got unit {t_unit!r}")
    data = np.full((len(rows) - first_data, ncol), np.nan)
    for r, row in enumerate(rows[first_data:]):
        line_no = body[first_data + r][0]
        if delim == "\t" and len(row) > ncol:  # tab-padded like its header
            row = [c for c in row if c.strip()] if len([c for c in row if c.strip()]) == ncol \
                else row
        if len(row) > ncol or (len(row) < ncol and any(c.strip() for c in row[ncol:])):
            raise RecordingError(f"{path}: line {line_no}: {len(row)} cells, header has {ncol}")
        for c, cell in enumerate(row[:ncol]):
            try:
                data[r, c] = _to_float(cell, decimal_comma)
            except ValueError:
                col = names[c]
                raise RecordingError(f"{path}: channel {col!r}: line {line_no}: {cell!r} is not "
                                     "a number") from None
    t = data[:, 0] * TIME_UNITS[t_unit]
    out: dict[str, Signal] = {}
    for c in range(1, ncol):
        name, unit = header[c]
        m = dict(meta.get(name, {}))
        if unit is None:
            unit = m.pop("unit", None) or (units or {}).get(name) or _suffix_unit(name)
        if unit is None:
            raise RecordingError(f"{path}: channel {name!r}: no unit in the header (write "
                                 f"'{name} [unit]', a '# channel: {name}; unit=UNIT' line, or "
                                 f"give it to the reader: units={{{name!r}: UNIT}}, "
                                 f"crashdem diagnose --unit {name}=UNIT)")

        cfc = None
        if "cfc" in m:
            v = m.pop("cfc")
            if v.lower() not in ("", "none", "raw"):
                try:
                    cfc = float(v)
                except ValueError:
                    raise RecordingError(f"{path}: channel {name!r}: cfc={v!r} is not a "
                                         "number") from None
        col = data[:, c]
        if col.size and np.all(np.isnan(col)):
            raise RecordingError(f"{path}: channel {name!r}: empty channel (no values)")
        out[name] = Signal(name, t.copy(), col.copy(), UNIT_SPELLINGS.get(unit, unit), cfc, m)
    return out


def _is_num(cell: str, decimal_comma: bool) -> bool:
    try:
        _to_float(cell, decimal_comma)
        return True
    except ValueError:
        return False


def _write_csv(path: Path, sigs: list[Signal], delimiter: str = ",") -> None:
    t = sigs[0].t
    for s in sigs[1:]:
        if s.t.shape != t.shape or np.max(np.abs(s.t - t)) > CSV_TIME_RTOL * max(
                1.0, float(np.max(np.abs(t)))):
            raise RecordingError(f"{path}: channel {s.name!r}: CSV needs one common time column; "
                                 f"its time vector differs from {sigs[0].name!r} (resample "
                                 "first or write HDF5/ISO-MME)")
    for s in sigs:
        if any(ch in s.name for ch in "[]()#" + delimiter) or s.name != s.name.strip():
            raise RecordingError(f"{path}: channel {s.name!r}: name not allowed in a CSV header")
    buf = io.StringIO()
    buf.write(f"# crashdem-recording: {HDF5_VERSION}\n")
    for s in sigs:
        parts = [f"cfc={s.cfc:g}" if s.cfc is not None else "cfc=raw"]
        if s.meta.get("iso_code"):
            parts.append(f"iso_code={s.meta['iso_code']}")
        buf.write(f"# channel: {s.name}; " + "; ".join(parts) + "\n")
    buf.write(delimiter.join(["time [s]"] + [f"{s.name} [{s.unit}]" for s in sigs]) + "\n")
    cols = np.column_stack([t] + [s.data for s in sigs])
    for row in cols:
        buf.write(delimiter.join(repr(float(v)) for v in row) + "\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(buf.getvalue(), encoding="utf-8")


# --------------------------------------------------------------------------- HDF5

def _json_meta(meta: Mapping[str, Any]) -> str:
    def default(o: Any) -> Any:
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, (np.floating, np.integer)):
            return o.item()
        return repr(o)
    return json.dumps(dict(meta), default=default)


def _write_hdf5(path: Path, sigs: list[Signal]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = HDF5_FORMAT_TAG
        f.attrs["version"] = HDF5_VERSION
        for s in sigs:
            if "/" in s.name or s.name in ("", ".", ".."):
                raise RecordingError(f"{path}: channel {s.name!r}: not a valid HDF5 group name")
            g = f.create_group(s.name)
            dt = g.create_dataset("t", data=s.t)
            dt.attrs["unit"] = "s"
            dd = g.create_dataset("data", data=s.data)
            dd.attrs["unit"] = s.unit
            g.attrs["unit"] = s.unit
            if s.cfc is not None:
                g.attrs["cfc"] = float(s.cfc)
            if s.meta.get("iso_code"):
                g.attrs["iso_code"] = str(s.meta["iso_code"])
            if s.meta:
                g.attrs["meta_json"] = _json_meta(s.meta)


def _attr_str(v: Any) -> str:
    return v.decode() if isinstance(v, bytes) else str(v)


def _read_hdf5(path: Path) -> dict[str, Signal]:
    with h5py.File(path, "r") as f:
        tag = _attr_str(f.attrs.get("format", ""))
        if tag != HDF5_FORMAT_TAG and "channels" in f:
            return _read_result(path)
        if tag != HDF5_FORMAT_TAG:
            raise RecordingError(f"{path}: HDF5 file is neither a crashdem recording "
                                 f"(format={HDF5_FORMAT_TAG!r}) nor a crashdem result "
                                 "(/channels)")
        out: dict[str, Signal] = {}
        for name, g in f.items():
            if not isinstance(g, h5py.Group):
                continue
            for ds in ("t", "data"):
                if ds not in g:
                    raise RecordingError(f"{path}: channel {name!r}: dataset {ds!r} missing")
            t, d = g["t"][()], g["data"][()]
            if t.shape != d.shape or t.ndim != 1:
                raise RecordingError(f"{path}: channel {name!r}: t {t.shape} and data "
                                     f"{d.shape} must be 1-D of equal length")
            t_unit = _attr_str(g["t"].attrs.get("unit", "s"))
            if t_unit not in TIME_UNITS:
                raise RecordingError(f"{path}: channel {name!r}: time unit {t_unit!r} not in "
                                     f"{sorted(TIME_UNITS)}")
            if "unit" not in g.attrs and "unit" not in g["data"].attrs:
                raise RecordingError(f"{path}: channel {name!r}: no 'unit' attribute")
            unit = _attr_str(g.attrs.get("unit", g["data"].attrs.get("unit")))
            meta: dict[str, Any] = {}
            if "meta_json" in g.attrs:
                meta = json.loads(_attr_str(g.attrs["meta_json"]))
            if "iso_code" in g.attrs:
                meta["iso_code"] = _attr_str(g.attrs["iso_code"])
            cfc = float(g.attrs["cfc"]) if "cfc" in g.attrs else None
            if cfc is not None and not np.isfinite(cfc):
                cfc = None
            out[name] = Signal(name, t * TIME_UNITS[t_unit], d, UNIT_SPELLINGS.get(unit, unit),
                               cfc, meta)
        return out


def _until_failure(s: Signal) -> Signal:
    """A result channel whose sensor failed (``failed_at`` in its meta: e.g. an accelerometer
    past its failure scale, whose tail the result stores as NaN) ends at the failure, as the
    lab channel of a broken transducer does; ``meta['truncated_at_failure']`` says so. Other
    channels, and NaN anywhere else, are left to ``validate``."""
    if s.meta.get("failed_at") is None or np.all(np.isfinite(s.data)):
        return s
    finite = np.isfinite(s.data)
    n_ok = int(np.argmin(finite))
    if finite[n_ok:].any() or n_ok == 0:
        return s
    meta = dict(s.meta, truncated_at_failure=float(s.t[n_ok]))
    return Signal(s.name, s.t[:n_ok].copy(), s.data[:n_ok].copy(), s.unit, s.cfc, meta)


def _read_result(path: Path) -> dict[str, Signal]:
    """A crashdem result file: via ``crashdem.results.open_result`` if available, else direct.
    A failed sensor's channel ends at its failure (``_until_failure``)."""
    try:
        from crashdem.results import open_result  # type: ignore[attr-defined]
    except ImportError:
        open_result = None
    if open_result is not None:
        res = open_result(path)
        try:
            chans = getattr(res, "channels", None)
            names = (list(chans()) if callable(chans) else list(chans) if chans is not None
                     else list(res.keys()))
            out = {}
            for n in names:
                s = res[n]
                if isinstance(s, Signal):
                    out[s.name] = _until_failure(s)
            if out:
                return out
        finally:
            if hasattr(res, "close"):
                res.close()
    out = {}
    with h5py.File(path, "r") as f:
        for name, g in f["channels"].items():
            t_key = "time" if "time" in g else "t"
            if t_key not in g:
                raise RecordingError(f"{path}: channel {name!r}: no time dataset")
            d_key = "filtered" if "filtered" in g else "raw" if "raw" in g else "data"
            if d_key not in g:
                raise RecordingError(f"{path}: channel {name!r}: no raw/filtered dataset")
            ds = g[d_key]
            unit = _attr_str(ds.attrs.get("unit", g.attrs.get("unit", "")))
            cfc_attr = ds.attrs.get("cfc", g.attrs.get("cfc")) if d_key == "filtered" else None
            cfc = float(cfc_attr) if cfc_attr is not None and np.isfinite(cfc_attr) else None
            out[name] = Signal(name, g[t_key][()], ds[()], unit, cfc,
                               {"source": "crashdem result", "dataset": d_key})
    return out
