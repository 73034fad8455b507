"""Tests of crashdem.plotting: files written, and plotted data equal the channel data."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crashdem.plotting import overlay_figure, plot_overlay, plot_result, result_figures
from crashdem.results import ResultWriter, open_result
from crashdem.signal import G0, Signal

FS = 12500.0
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def result_path(tmp_path_factory):
    """A result with one channel of each group, written from analytic signals."""
    path = tmp_path_factory.mktemp("plot") / "run.h5"
    t = np.arange(0, 0.05, 1 / FS)
    chans = {
        "accel_x": ("m/s^2", 60.0, 150.0 * np.sin(math.pi * t / 0.05) ** 2),
        "vel_z": ("m/s", None, -5.0 + 100 * t),
        "penetration": ("m", None, 2.0 * t ** 2),
        "floor_1": ("N", None, 1e4 * np.sin(80 * t)),
        "pitch_rate": ("rad/s", 20.0, 0.3 * np.cos(60 * t)),
        "pitch": ("rad", None, 0.005 * np.sin(60 * t)),
    }
    with ResultWriter(path) as w:
        for name, (unit, cfc, _) in chans.items():
            meta = {"cfc_class": cfc} if cfc else {}
            w.declare_channel(name, unit, FS, **meta)
        w.declare_energy(["kinetic", "dissipated"])
        for name, (_, _, data) in chans.items():
            w.append_channel(name, t, data)
        for tt in t[::25]:
            w.append_energy(tt, {"kinetic": 1e4 * (1 - tt), "dissipated": 1e4 * tt})
    return path


def _line(ax, label):
    for line in ax.get_lines():
        if line.get_label() == label or line.get_gid() == label and "(raw)" not in label:
            return line
    raise AssertionError(f"no line {label!r} in {[ln.get_label() for ln in ax.get_lines()]}")


def test_plot_result_writes_one_nonempty_png_per_group(result_path, tmp_path):
    """Oracle: file contract -- one PNG per group present (7 groups here), each a valid,
    non-trivial PNG file."""
    paths = plot_result(result_path, tmp_path / "plots")
    names = sorted(p.name for p in paths)
    assert names == sorted(["accelerations.png", "velocities.png", "displacements.png",
                            "forces.png", "angular.png", "energy.png"])
    for p in paths:
        data = p.read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 5000
    # channel selection restricts the groups; Result.plot is the same call
    with open_result(result_path) as res:
        only = res.plot(tmp_path / "sel", channels=["floor_1"])
    assert [p.name for p in only] == ["forces.png", "energy.png"]
    assert all(p.parent == tmp_path / "sel" for p in only)


def test_plotted_lines_equal_channel_data(result_path):
    """Oracle: identity -- the Line2D data are the channel data (time in ms; acceleration in g
    via G0, or in m/s^2 with in_g=False; angles in degrees), filtered and raw traces alike."""
    with open_result(result_path) as res:
        figs = result_figures(res)
        acc = res["accel_x"]
        ax = figs["accelerations"].axes[0]
        line = next(ln for ln in ax.get_lines() if ln.get_gid() == "accel_x")
        assert np.array_equal(line.get_xdata(), acc.t * 1e3)
        assert np.array_equal(line.get_ydata(), acc.data / G0)
        raw_line = _line(ax, "accel_x (raw)")
        assert np.array_equal(raw_line.get_ydata(), res.channel("accel_x", False).data / G0)
        figs_si = result_figures(res, in_g=False)
        line = next(ln for ln in figs_si["accelerations"].axes[0].get_lines()
                    if ln.get_gid() == "accel_x")
        assert np.array_equal(line.get_ydata(), acc.data)
        rate_ax, angle_ax = figs["angular"].axes
        rl = next(ln for ln in rate_ax.get_lines() if ln.get_gid() == "pitch_rate")
        assert np.array_equal(rl.get_ydata(), np.degrees(res["pitch_rate"].data))
        al = next(ln for ln in angle_ax.get_lines() if ln.get_gid() == "pitch")
        assert np.array_equal(al.get_ydata(), np.degrees(res["pitch"].data))
        en = res.energy()["kinetic"]
        el = next(ln for ln in figs["energy"].axes[0].get_lines() if ln.get_gid() == "kinetic")
        assert np.array_equal(el.get_ydata(), en.data)
        fl = next(ln for ln in figs["forces"].axes[0].get_lines() if ln.get_gid() == "floor_1")
        assert np.array_equal(fl.get_ydata(), res["floor_1"].data)


def test_overlay_with_shaded_windows(tmp_path):
    """Oracle: identity -- overlay lines equal the signals converted to one display unit (a
    recording in g and a simulation in m/s^2 both shown in g); each window is a shaded span
    with the requested bounds in ms; incompatible units are refused."""
    t = np.linspace(0, 0.1, 501)
    rec = Signal("rec", t, 20 * np.sin(30 * t), "g")
    sim = Signal("sim", t, 19 * G0 * np.sin(30 * t + 0.1), "m/s^2")
    windows = [(0.01, 0.03, "impact"), (0.06, 0.08)]
    fig = overlay_figure({"recording": rec, "baseline": sim}, windows)
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    assert np.array_equal(lines["recording"].get_ydata(), rec.data)
    assert np.allclose(lines["baseline"].get_ydata(), sim.data / G0, rtol=1e-15, atol=0)
    assert np.array_equal(lines["recording"].get_xdata(), t * 1e3)
    spans = [p for p in ax.patches]
    assert len(spans) == 2
    xs = sorted((round(p.get_x(), 9), round(p.get_x() + p.get_width(), 9)) for p in spans)
    assert xs == [(10.0, 30.0), (60.0, 80.0)]
    out = plot_overlay({"recording": rec}, tmp_path / "o" / "overlay.png",
                       shade_windows={"impact": (0.01, 0.03)}, title="x")
    assert out.read_bytes()[:8] == PNG_MAGIC
    with pytest.raises(ValueError, match="incompatible units"):
        overlay_figure({"a": rec, "b": Signal("f", t, t, "N")})
    with pytest.raises(ValueError, match="end must be > start"):
        overlay_figure({"a": rec}, [(0.03, 0.01)])
