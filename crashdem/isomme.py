"""ISO/TS 13499 (ISO-MME) channel codes and test folders.

Channel code (16 characters, ISO/TS 13499 RED B 1.6.2 as encoded in pyisomme ``channel_codes.xml``;
anchors.md section 3 [V])::

    [0]      test object       0 undefined, 1-9 vehicle, B fixed barrier, C component, D dummy,
                               H linear impactor, M mobile barrier, P pendulum, S sled, T test rig
    [1]      position          0-9, A-Z
    [2:6]    main location     4 characters (VEHC, TAIL, GRND, IMPA, SEAT, ...)
    [6:8]    fine location 1   2 characters (CG, FR, RE, BO, TP, 00, 01-99, ...)
    [8:10]   fine location 2
    [10:12]  fine location 3
    [12:14]  physical dimension (AC, AV, AN, FO, ...)
    [14]     direction         X, Y, Z, R (resultant), 0 (other), 1/2/3 (non-J211 sign convention)
    [15]     filter class      0 raw, A/B/C/D = CFC 1000/600/180/60, E-H the same classes under the
                               1987/1988 editions, L CFC 20, P/Q/S/V/X special

Folder layout written and read::

    <Test>/<Test>.mme                 test header (``Key`` padded to 28 chars, ``:Value``)
    <Test>/Channel/<Test>.chn         channel list
    <Test>/Channel/<Test>.001 ...     one file per channel: header, then one value per line

Time is implicit: ``t_i = t0 + i*dt`` from ``Time of first sample`` and ``Sampling interval``.

Notes
-----
Format and code tables: anchors.md section 3 [V] (pyisomme, jonaskeller14/pyisomme, fixtures
``data/tests/<encoding>/``; ``channel_codes.xml`` v1.6.2). The crashdem name <-> code table
(``CRASHDEM_CODES``) is a crashdem choice documented in docs/recordings.md.
"""
from __future__ import annotations

import io
import math
import re
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from crashdem.signal import UNIT_TO_SI, Signal

KEY_WIDTH = 28
NOVALUE = "NOVALUE"
ENCODINGS = ("utf-8-sig", "windows-1252", "latin-1")  # read attempts, in this order

#: test object letter -> meaning (ISO/TS 13499 RED B 1.6.2)
TEST_OBJECTS: dict[str, str] = {
    "0": "undefined", **{str(i): f"vehicle {i}" for i in range(1, 10)}, "B": "fixed barrier",
    "C": "component", "D": "dummy", "H": "linear impactor", "M": "mobile barrier",
    "P": "pendulum", "S": "sled", "T": "test rig",
}
#: filter class letter -> CFC [Hz] (None: unfiltered or not a CFC class)
FILTER_CLASSES: dict[str, float | None] = {
    "0": None, "A": 1000.0, "B": 600.0, "C": 180.0, "D": 60.0,
    "E": 1000.0, "F": 600.0, "G": 180.0, "H": 60.0, "L": 20.0,
    "P": None, "Q": None, "S": None, "V": None, "X": None,
}
#: physical dimension -> SI unit in crashdem notation (None: no unit check)
DIMENSIONS: dict[str, str | None] = {
    "AC": "m/s^2", "AV": "rad/s", "AA": None, "AN": "rad", "DS": "m", "DC": "m", "VE": "m/s",
    "VA": "m/s", "FO": "N", "MO": "N*m", "PR": "Pa", "EN": "J", "TI": "s", "QU": "1",
}
DIRECTIONS = "XYZR0123"
_CFC_TO_LETTER = {1000.0: "A", 600.0: "B", 180.0: "C", 60.0: "D", 20.0: "L"}

#: ISO-MME unit spellings -> crashdem unit strings (see crashdem.signal.UNIT_TO_SI)
ISO_UNITS: dict[str, str] = {
    "m/s**2": "m/s^2", "m/s^2": "m/s^2", "m/s2": "m/s^2", "m/(s*s)": "m/s^2", "g": "g", "G": "g",
    "m/s": "m/s", "km/h": "km/h", "m": "m", "mm": "mm", "N": "N", "kN": "kN", "Nm": "N*m",
    "N*m": "N*m", "N.m": "N*m", "rad/s": "rad/s", "deg/s": "deg/s", "°/s": "deg/s",
    "rad": "rad", "deg": "deg", "°": "deg", "s": "s", "J": "J", "Pa": "Pa", "kg": "kg", "1": "1",
    "-": "1",
}
#: crashdem unit -> spelling written to ISO-MME files
_UNIT_OUT = {"m/s^2": "m/s**2", "N*m": "Nm"}

#: crashdem channel name -> channel code with the filter letter '0' (replaced from Signal.cfc)
CRASHDEM_CODES: dict[str, str] = {
    # glider / vehicle 1 rigid body at its CG
    "cg_accel_x": "10VEHCCG0000ACX0", "cg_accel_y": "10VEHCCG0000ACY0",
    "cg_accel_z": "10VEHCCG0000ACZ0", "cg_accel_r": "10VEHCCG0000ACR0",
    "pitch_rate": "10VEHCCG0000AVY0", "roll_rate": "10VEHCCG0000AVX0",
    "yaw_rate": "10VEHCCG0000AVZ0", "pitch_angle": "10VEHCCG0000ANY0",
    "cg_velocity_x": "10VEHCCG0000VEX0", "cg_velocity_z": "10VEHCCG0000VEZ0",
    "cg_displacement_x": "10VEHCCG0000DSX0", "cg_displacement_z": "10VEHCCG0000DSZ0",
    # glider nose (front) and tail accelerometers
    "nose_accel_x": "10VEHCFR0000ACX0", "nose_accel_z": "10VEHCFR0000ACZ0",
    "rear_accel_x": "10VEHCRE0000ACX0", "rear_accel_z": "10VEHCRE0000ACZ0",
    "tail_accel_z": "10TAIL000000ACZ0",
    # pilot seat (position 1 = front left, single seat)
    "seat_accel_z": "11SEAT000000ACZ0", "seat_accel_x": "11SEAT000000ACX0",
    # drop mass = linear impactor H
    "impactor_accel_z": "H0IMPACG0000ACZ0", "impactor_velocity_z": "H0IMPACG0000VEZ0",
    "impactor_displacement_z": "H0IMPACG0000DSZ0", "penetration": "H0IMPACG0000DCZ0",
    "impactor_force_z": "H0IMPACG0000FOZ0",
    # soil container = test rig T: floor load cells under the sand bed, wall load cells
    "floor_force_z": "T0GRNDBO0000FOZ0", "wall_force_x": "T0GRNDLE0000FOX0",
    # time reference
    "time_zero": "T0ZERO000000TI00",
}


@dataclass(frozen=True)
class ChannelCode:
    """A 16-character ISO/TS 13499 channel code, validated field by field.

    Parameters
    ----------
    test_object : one of ``TEST_OBJECTS``
    position : ``0-9`` or ``A-Z``
    main_location : 4 characters ``[A-Z0-9]``
    fine1, fine2, fine3 : 2 characters ``[A-Z0-9]`` each
    dimension : one of ``DIMENSIONS``
    direction : one of ``X Y Z R 0 1 2 3``
    filter_class : one of ``FILTER_CLASSES``

    Notes
    -----
    ISO/TS 13499 RED B 1.6.2 code structure (anchors.md section 3 [V]).
    """

    test_object: str
    position: str
    main_location: str
    fine1: str
    fine2: str
    fine3: str
    dimension: str
    direction: str
    filter_class: str

    def __post_init__(self) -> None:
        def bad(field: str, value: str, allowed: str) -> ValueError:
            return ValueError(f"ChannelCode.{field}={value!r}: must be {allowed}")

        if self.test_object not in TEST_OBJECTS:
            raise bad("test_object", self.test_object, f"one of {''.join(TEST_OBJECTS)}")
        if not re.fullmatch(r"[0-9A-Z]", self.position):
            raise bad("position", self.position, "one character 0-9 or A-Z")
        if not re.fullmatch(r"[0-9A-Z]{4}", self.main_location):
            raise bad("main_location", self.main_location, "4 characters A-Z/0-9")
        for name in ("fine1", "fine2", "fine3"):
            v = getattr(self, name)
            if not re.fullmatch(r"[0-9A-Z]{2}", v):
                raise bad(name, v, "2 characters A-Z/0-9")
        if self.dimension not in DIMENSIONS:
            raise bad("dimension", self.dimension, f"one of {sorted(DIMENSIONS)}")
        if self.direction not in DIRECTIONS:
            raise bad("direction", self.direction, f"one of {' '.join(DIRECTIONS)}")
        if self.filter_class not in FILTER_CLASSES:
            raise bad("filter_class", self.filter_class, f"one of {''.join(FILTER_CLASSES)}")

    @classmethod
    def parse(cls, code: str) -> "ChannelCode":
        """Parse a 16-character code (``ValueError`` naming the bad field)."""
        if not isinstance(code, str) or len(code) != 16:
            raise ValueError(f"channel code {code!r}: must be a 16-character string")
        c = code.upper()
        return cls(c[0], c[1], c[2:6], c[6:8], c[8:10], c[10:12], c[12:14], c[14], c[15])

    def __str__(self) -> str:
        return (self.test_object + self.position + self.main_location + self.fine1 + self.fine2
                + self.fine3 + self.dimension + self.direction + self.filter_class)

    @property
    def cfc(self) -> float | None:
        """CFC [Hz] of the filter-class letter, or None."""
        return FILTER_CLASSES[self.filter_class]

    @property
    def si_unit(self) -> str | None:
        """SI unit implied by the physical dimension (crashdem notation), or None."""
        return DIMENSIONS[self.dimension]

    def with_cfc(self, cfc: float | None) -> "ChannelCode":
        """Same code with the filter letter of ``cfc`` (see ``cfc_to_letter``)."""
        return replace(self, filter_class=cfc_to_letter(cfc))

    def base(self) -> str:
        """First 15 characters (everything but the filter class)."""
        return str(self)[:15]


def cfc_to_letter(cfc: float | None) -> str:
    """Filter-class letter for a CFC: None -> '0', 1000/600/180/60 -> A/B/C/D, 20 -> L, else 'S'.

    Notes
    -----
    ISO/TS 13499 filter classes (anchors.md section 3 [V]); the current-edition letters A-D are
    written, E-H (older editions) are only read.
    """
    if cfc is None:
        return "0"
    if not (np.isfinite(cfc) and cfc > 0):
        raise ValueError(f"cfc={cfc!r}: must be None or > 0 [Hz]")
    return _CFC_TO_LETTER.get(float(cfc), "S")


def code_for(name: str, cfc: float | None = None, code: str | None = None) -> str:
    """ISO code of a crashdem channel: ``code`` (validated) or ``CRASHDEM_CODES[name]``, with the
    filter letter set from ``cfc``.

    Raises
    ------
    ValueError
        the name has no code in ``CRASHDEM_CODES`` and none was given, or the code is invalid.
    """
    if code is None:
        try:
            code = CRASHDEM_CODES[name]
        except KeyError:
            raise ValueError(
                f"channel {name!r}: no ISO/TS 13499 code known; set Signal.meta['iso_code'] or "
                f"use one of {sorted(CRASHDEM_CODES)}") from None
    cc = ChannelCode.parse(code)
    if cfc is not None or cc.filter_class in "0ABCDL":
        cc = cc.with_cfc(cfc)
    return str(cc)


def name_for(code: str) -> str | None:
    """crashdem name of an ISO code (filter letter ignored), or None if not in the table."""
    base = ChannelCode.parse(code).base()
    for name, c in CRASHDEM_CODES.items():
        if c[:15] == base:
            return name
    return None


# --------------------------------------------------------------------------- file I/O

def _fmt_line(key: str, value: object) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        value = NOVALUE
    return f"{key:<{KEY_WIDTH}}:{value}"


def _parse_header_line(line: str) -> tuple[str, str] | None:
    """``Key<pad>:Value`` -> (key, value); None if the line is not a header line."""
    if ":" not in line:
        return None
    if len(line) > KEY_WIDTH and line[KEY_WIDTH] == ":":
        key, value = line[:KEY_WIDTH], line[KEY_WIDTH + 1:]
    else:
        key, value = line.split(":", 1)
    key = key.strip()
    if not key:
        return None
    return key, value.strip()


def _decode(raw: bytes, where: str) -> str:
    for enc in ENCODINGS:
        try:
            return raw.decode(enc)
        except UnicodeDecodeError:
            continue
    raise ValueError(f"{where}: cannot decode with {ENCODINGS}")  # pragma: no cover (latin-1)


def _header(text: str) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for line in text.splitlines():
        kv = _parse_header_line(line)
        if kv:
            out.setdefault(kv[0].lower(), []).append(kv[1])
    return out


def _get(h: Mapping[str, list[str]], key: str) -> str | None:
    v = h.get(key.lower())
    if not v or v[0] == "" or v[0].upper() == NOVALUE:
        return None
    return v[0]


def _float(h: Mapping[str, list[str]], key: str, where: str, required: bool = True
           ) -> float | None:
    v = _get(h, key)
    if v is None:
        if required:
            raise ValueError(f"{where}: '{key}' is missing or NOVALUE; cannot build the time "
                             "vector / data")
        return None
    try:
        return float(v.replace(",", ".") if v.count(",") == 1 and "." not in v else v)
    except ValueError:
        raise ValueError(f"{where}: '{key}' = {v!r} is not a number") from None


class _Source:
    """Read access to a test folder or a .zip of it (paths relative to the folder root)."""

    def __init__(self, path: Path):
        self.path = path
        self.zip: zipfile.ZipFile | None = None
        if path.is_file() and zipfile.is_zipfile(path):
            self.zip = zipfile.ZipFile(path)
            mmes = [n for n in self.zip.namelist() if n.lower().endswith(".mme")]
            if not mmes:
                raise ValueError(f"{path}: zip archive contains no .mme file")
            mme = sorted(mmes, key=lambda n: n.count("/"))[0]
            self.root = mme.rsplit("/", 1)[0] + "/" if "/" in mme else ""
            self.mme = mme[len(self.root):]
            self.names = {n[len(self.root):].lower(): (n[len(self.root):], n)
                          for n in self.zip.namelist() if n.startswith(self.root)}
        else:
            if path.is_file() and path.suffix.lower() == ".mme":
                path = path.parent
            mmes = sorted(path.glob("*.mme")) + sorted(path.glob("*.MME"))
            if not mmes:
                raise ValueError(f"{path}: not an ISO-MME test folder (no <Test>.mme)")
            self.root_dir = path
            self.mme = mmes[0].name
            self.names = {}
            for p in path.rglob("*"):
                if p.is_file():
                    rel = p.relative_to(path).as_posix()
                    self.names[rel.lower()] = (rel, rel)

    def exists(self, rel: str) -> bool:
        return rel.lower() in self.names

    def read(self, rel: str) -> bytes:
        real = self.names.get(rel.lower(), (None, None))[1]
        if real is None:
            raise ValueError(f"{self.path}: missing file {rel!r} in the test folder")
        if self.zip is not None:
            return self.zip.read(real)
        return (self.root_dir / real).read_bytes()

    def list(self, folder: str) -> list[str]:
        pre = folder.lower().rstrip("/") + "/"
        return sorted(v[0] for k, v in self.names.items() if k.startswith(pre))

    def close(self) -> None:
        if self.zip is not None:
            self.zip.close()


def is_isomme(path: str | Path) -> bool:
    """True if ``path`` is an ISO-MME test folder, its .mme file or a zip containing one."""
    p = Path(path)
    if p.is_dir():
        return any(p.glob("*.mme")) or any(p.glob("*.MME"))
    if p.is_file() and p.suffix.lower() == ".mme":
        return True
    if p.is_file() and zipfile.is_zipfile(p):
        with zipfile.ZipFile(p) as z:
            return any(n.lower().endswith(".mme") for n in z.namelist())
    return False


def read_isomme(path: str | Path, channels: Iterable[str] | None = None
                ) -> tuple[dict[str, Signal], dict[str, list[str]]]:
    """Read an ISO-MME test (folder, .mme file or .zip).

    Parameters
    ----------
    path : test folder, its ``.mme`` file, or a ``.zip`` of the folder
    channels : keep only these channels (crashdem names or ISO codes); None = all

    Returns
    -------
    signals : crashdem name (``name_for(code)``, else the channel code) -> Signal in the file's
        unit, with ``cfc`` from ``Channel frequency class`` or the code's filter letter, and
        ``meta`` = {"iso_code", "description", "header"}
    test_header : the .mme keys (lower case) -> list of values

    Raises
    ------
    ValueError
        naming the file and channel: missing time metadata, wrong number of samples, a value that
        is not a number, an unknown unit, a CFC that contradicts the code's filter letter.

    Notes
    -----
    ISO/TS 13499 layout and header syntax (anchors.md section 3 [V]).
    """
    src = _Source(Path(path))
    try:
        mme_h = _header(_decode(src.read(src.mme), f"{path}/{src.mme}"))
        files = [f for f in src.list("Channel")
                 if re.fullmatch(r"\d{3,}", f.rsplit(".", 1)[-1])]
        wanted = None if channels is None else set(channels)
        out: dict[str, Signal] = {}
        for rel in files:
            where = f"{path}:{rel}"
            sig = _read_channel_file(_decode(src.read(rel), where), where)
            if wanted is not None and not ({sig.name, sig.meta["iso_code"]} & wanted):
                continue
            if sig.name in out:
                raise ValueError(f"{where}: duplicate channel {sig.name!r}")
            out[sig.name] = sig
        if wanted is not None:
            missing = wanted - {s.name for s in out.values()} - {
                s.meta["iso_code"] for s in out.values()}
            if missing:
                raise ValueError(f"{path}: channels not found: {sorted(missing)}")
        return out, mme_h
    finally:
        src.close()


def _read_channel_file(text: str, where: str) -> Signal:
    lines = text.splitlines()
    header_lines: list[str] = []
    i = 0
    for i, line in enumerate(lines):  # noqa: B007
        s = line.strip()
        if not s:
            continue
        if _parse_header_line(s) is not None and not _is_number(s):
            header_lines.append(line)
        else:
            break
    else:
        i = len(lines)
    h = _header("\n".join(header_lines))
    code_s = _get(h, "Channel code")
    if code_s is None:
        raise ValueError(f"{where}: 'Channel code' is missing")
    try:
        code = ChannelCode.parse(code_s)
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    label = f"{where} (channel {code_s})"
    dt = _float(h, "Sampling interval", label)
    t0 = _float(h, "Time of first sample", label)
    n_decl = _float(h, "Number of samples", label, required=False)
    if not (dt and dt > 0):
        raise ValueError(f"{label}: 'Sampling interval' = {dt!r} must be > 0 [s]")
    vals: list[float] = []
    for k, line in enumerate(lines[i:], start=i + 1):
        s = line.strip()
        if not s:
            continue
        try:
            vals.append(float(s))
        except ValueError:
            if s.upper() == NOVALUE:
                vals.append(math.nan)
                continue
            raise ValueError(f"{label}: line {k}: {s!r} is not a number") from None
    data = np.asarray(vals, dtype=float)
    if n_decl is not None and int(n_decl) != data.size:
        raise ValueError(f"{label}: 'Number of samples' = {int(n_decl)} but {data.size} values "
                         "follow the header")
    unit_raw = _get(h, "Unit") or "1"
    unit = ISO_UNITS.get(unit_raw, unit_raw if unit_raw in UNIT_TO_SI else None)
    if unit is None:
        raise ValueError(f"{label}: unknown unit {unit_raw!r}; known: {sorted(ISO_UNITS)}")
    cfc_key = _get(h, "Channel frequency class")
    cfc: float | None = code.cfc
    if cfc_key is not None:
        try:
            cfc_val = float(re.sub(r"(?i)^\s*cfc\s*", "", cfc_key))  # "180", "CFC180", "CFC 180"
        except ValueError:
            raise ValueError(f"{label}: 'Channel frequency class' = {cfc_key!r} is not a "
                             "number") from None
        if code.cfc is not None and abs(cfc_val - code.cfc) > 1e-9:
            raise ValueError(f"{label}: 'Channel frequency class' = {cfc_val:g} contradicts "
                             f"the code's filter letter {code.filter_class!r} (CFC {code.cfc:g})")
        cfc = cfc_val
    t = t0 + dt * np.arange(data.size)
    name = name_for(str(code)) or str(code)
    meta = {"iso_code": str(code), "description": _get(h, "Name of the channel"),
            "header": {k: v[0] for k, v in h.items()}}
    return Signal(name, t, data, unit, cfc, meta)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def write_isomme(path: str | Path, signals: Mapping[str, Signal] | Iterable[Signal],
                 test_number: str | None = None, *, encoding: str = "latin-1",
                 test_header: Mapping[str, object] | None = None, zip_file: bool | None = None,
                 rtol_dt: float = 1e-6) -> Path:
    """Write signals as an ISO-MME test folder (or a .zip of it).

    Parameters
    ----------
    path : target folder ``.../<Test>`` (created), or ``.../<Test>.zip``
    signals : Signals (uniformly sampled); each needs ``meta['iso_code']`` or a name in
        ``CRASHDEM_CODES``; the filter letter is set from ``Signal.cfc``
    test_number : test number (default: the folder / zip stem)
    encoding : text encoding of all files (ascii, latin-1, windows-1252, utf-8)
    test_header : extra .mme keys (e.g. {"Impact velocity": 18.33, "Test object": "glider"})
    zip_file : write a zip (default: True if ``path`` ends in .zip)
    rtol_dt : allowed relative spread of the sample interval

    Returns
    -------
    the written folder or zip path

    Notes
    -----
    ISO/TS 13499 layout, 28-character keys, implicit time (anchors.md section 3 [V]).
    """
    path = Path(path)
    sigs = list(signals.values()) if isinstance(signals, Mapping) else list(signals)
    if zip_file is None:
        zip_file = path.suffix.lower() == ".zip"
    stem = test_number or (path.stem if zip_file else path.name)
    files: dict[str, str] = {}
    mme = [_fmt_line("Data format", "ISO-MME"), _fmt_line("Version", "1.6"),
           _fmt_line("Test number", stem)]
    extra = dict(test_header or {})
    for key in ("Test date", "Time of test", "Test type", "Laboratory name", "Customer name",
                "Test object", "Number of test objects", "Impact velocity", "Regulation"):
        mme.append(_fmt_line(key, extra.pop(key, None)))
    for key, v in extra.items():
        mme.append(_fmt_line(key, v))
    mme.append(_fmt_line("Comments", "written by crashdem (SI units unless stated)"))
    files[f"{stem}.mme"] = "\n".join(mme) + "\n"
    chn = [_fmt_line("Instrumentation standard", "SAEJ211-1"),
           _fmt_line("Number of channels", len(sigs))]
    seen: set[str] = set()
    for k, s in enumerate(sigs, start=1):
        code = code_for(s.name, s.cfc, s.meta.get("iso_code"))
        if code in seen:
            raise ValueError(f"channel {s.name!r}: duplicate ISO code {code}")
        seen.add(code)
        cc = ChannelCode.parse(code)
        _check_unit(s, cc)
        chn.append(_fmt_line(f"Name of channel {k:03d}", f"{code} / {s.name}"))
        files[f"Channel/{stem}.{k:03d}"] = _channel_text(s, cc, rtol_dt)
    files[f"Channel/{stem}.chn"] = "\n".join(chn) + "\n"
    encoded = {}
    for rel, text in files.items():
        try:
            encoded[rel] = text.encode(encoding)
        except UnicodeEncodeError as e:
            raise ValueError(f"{path}/{rel}: cannot encode {e.object[e.start:e.end]!r} as "
                             f"{encoding}") from None
    if zip_file:
        path.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as z:
            for rel, raw in encoded.items():
                z.writestr(f"{stem}/{rel}", raw)
    else:
        (path / "Channel").mkdir(parents=True, exist_ok=True)
        # an earlier write of the same test may have had more channels: remove its channel
        # files (only <stem>.NNN, which this writer owns by name) so they are not read back
        for old in (path / "Channel").glob(f"{stem}.*"):
            if re.fullmatch(r"\d{3,}", old.suffix[1:]) and old.is_file():
                old.unlink()
        for rel, raw in encoded.items():
            (path / rel).write_bytes(raw)
    return path


def _check_unit(s: Signal, cc: ChannelCode) -> None:
    if s.unit not in UNIT_TO_SI:
        raise ValueError(f"channel {s.name!r}: unknown unit {s.unit!r}")
    si = UNIT_TO_SI[s.unit][1]
    if cc.si_unit is not None and si != cc.si_unit:
        raise ValueError(f"channel {s.name!r}: unit {s.unit!r} ({si}) does not match the ISO "
                         f"dimension {cc.dimension} of code {cc} ({cc.si_unit})")


def _channel_text(s: Signal, cc: ChannelCode, rtol_dt: float) -> str:
    n = s.t.size
    if n < 2:
        raise ValueError(f"channel {s.name!r}: needs at least 2 samples for ISO-MME, got {n}")
    dt = (s.t[-1] - s.t[0]) / (n - 1)
    if np.max(np.abs(np.diff(s.t) - dt)) > rtol_dt * dt:
        raise ValueError(f"channel {s.name!r}: ISO-MME needs uniform sampling (implicit time); "
                         "resample first")
    i_max, i_min = int(np.argmax(s.data)), int(np.argmin(s.data))
    unit = _UNIT_OUT.get(s.unit, s.unit)
    head = [
        ("Channel code", str(cc)), ("Laboratory channel code", str(cc)),
        ("Customer channel code", NOVALUE), ("Reference channel", "implicit"),
        ("Reference channel name", NOVALUE), ("Data source", s.meta.get("data_source",
                                                                        "calculation")),
        ("Test object number", cc.test_object if cc.test_object.isdigit() else NOVALUE),
        ("Name of the channel", s.name), ("Location", NOVALUE), ("Direction", cc.direction),
        ("Pre-filter type", NOVALUE),
        ("Channel frequency class", f"{s.cfc:g}" if s.cfc is not None else NOVALUE),
        ("Cut off frequency", NOVALUE), ("Reference system", NOVALUE),
        ("Transducer type", NOVALUE), ("Transducer id", NOVALUE),
        ("Transducer natural frequency", NOVALUE), ("Transducer damping ratio", NOVALUE),
        ("Offset post test", NOVALUE), ("Channel amplitude class", NOVALUE),
        ("Sampling interval", repr(float(dt))), ("Unit", unit),
        ("Time of first sample", repr(float(s.t[0]))), ("Number of samples", n),
        ("First global maximum value", f"{s.data[i_max]:.6E}"),
        ("Time of maximum value", f"{s.t[i_max]:.6E}"),
        ("First global minimum value", f"{s.data[i_min]:.6E}"),
        ("Time of minimum value", f"{s.t[i_min]:.6E}"),
        ("Dimension", cc.dimension), ("Bit resolution", NOVALUE),
        ("Start offset interval", NOVALUE), ("End offset interval", NOVALUE),
        ("Data status", "ok"),
    ]
    buf = io.StringIO()
    for k, v in head:
        buf.write(_fmt_line(k, v) + "\n")
    for v in s.data:
        buf.write(f"{v:.16E}\n" if math.isfinite(v) else f"{NOVALUE}\n")
    return buf.getvalue()
