"""The Yade truth's contact laws (``validation/diagnosis_yade``, ``--contact-law``), checked on
Yade's own runs against the analytic impact of an elastic contact (needs ``yade``).

The drop mass falls at speed v on a single grain resting on the floor, without gravity: two
contacts in series, drop mass-grain and grain-floor, both linear or both Hertzian. For a
linear spring the contact lasts half a period, pi sqrt(m / k), whatever the speed. For a
Hertzian contact F = K delta^1.5 (two in series are one of the same exponent) the duration
scales as v^(-1/5) (Johnson, Contact Mechanics, 1985, section 11.4): four times the speed
lasts 4^(-1/5) = 0.758 times as long. Both are elastic: the drop mass leaves at its impact
speed."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tests.validation.test_diagnosis_yade_fixed import _cfg  # noqa: E402
from validation.diagnosis_yade import cases  # noqa: E402

pytestmark = pytest.mark.skipif(not cases.yade_available(), reason="yade is not installed")

#: impact speeds [m/s]: slow enough that the grain (11 kg against 850 kg) follows quasi-statically
SPEEDS = (0.1, 0.4)


def _durations(cfg: dict, cache: Path, bed: Path) -> list[tuple[float, float, float]]:
    """(contact duration [s], rebound speed [m/s], peak force [N]) of the drop mass at each of
    ``SPEEDS``."""
    out = []
    for v in SPEEDS:
        hist, _ = cases.run_yade(dict(cfg, impact_speed=v, t_end=0.4, gap=0.0, gravity=0.0),
                                 cache, packing_npz=bed)
        t, vz, fz = hist[:, 0], hist[:, 2], hist[:, 3]
        on = fz > 0.0
        first = int(np.argmax(on))
        assert not on[-1], "still in contact at the end of the run"
        last = first + int(np.argmax(~on[first:]))
        assert on[first:last].all()  # one contact, no chatter
        out.append((float(t[last] - t[first]), float(vz[-1]), float(fz.max())))
    return out


def test_the_truths_contact_laws_impact_as_their_analytic_contacts(monkeypatch, tmp_path):
    r = 0.1
    bed = tmp_path / "one_grain.npz"
    np.savez(bed, x=np.array([[0.0, 0.0, r]]), radius=np.array([r]))
    # the configurations the null case of seed 21 hands Yade under each law, then Yade itself
    lin_cfg = _cfg(monkeypatch, tmp_path, 21, None, contact_law="linear")
    hm_cfg = _cfg(monkeypatch, tmp_path, 21, None, contact_law="hertz_mindlin")
    monkeypatch.undo()
    lin = _durations(lin_cfg, tmp_path, bed)
    hm = _durations(hm_cfg, tmp_path, bed)
    # linear: the duration does not depend on the speed; the peak force grows with it
    assert lin[1][0] / lin[0][0] == pytest.approx(1.0, abs=0.01)
    assert lin[1][2] / lin[0][2] == pytest.approx(4.0, rel=0.02)
    # and it is half the period of the drop mass on the two springs in series (Yade's
    # k = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2); the wall side takes the grain's radius), within
    # the grain's own mass (11 kg under 850 kg)
    e, e_imp, big_r = lin_cfg["young"], lin_cfg["impactor_young"], lin_cfg["drop_radius"]
    k_top = 2.0 * e * r * e_imp * big_r / (e * r + e_imp * big_r)
    k = 1.0 / (1.0 / k_top + 1.0 / (e * r))
    assert lin[0][0] == pytest.approx(np.pi * np.sqrt(lin_cfg["drop_mass"] / k), rel=0.03)
    # Hertz: four times the speed lasts 4^(-1/5) times as long
    assert hm[1][0] / hm[0][0] == pytest.approx(4.0 ** -0.2, abs=0.01)
    assert hm[1][2] / hm[0][2] == pytest.approx(4.0 ** 1.2, rel=0.03)  # F_max ~ v^(6/5)
    for (_, v_out, _), v in zip(lin + hm, SPEEDS * 2):
        assert v_out == pytest.approx(v, rel=0.01)  # elastic: no damping in either law


def test_the_truths_contact_damping_rebounds_at_its_restitution_under_either_law(monkeypatch,
                                                                                 tmp_path):
    """The contact damping truth (``restitution``) under each law, on Yade's own runs: the drop
    mass (850 kg) hits a free grain (11 kg, no floor under it before it leaves, no gravity)
    head-on, and the grain's rebound ratio follows from the drop mass's velocity change,
    dv = m (1 + e) v / (M + m). The linear law's dashpot (its damping ratio exact for a contact
    that may pull) and the Hertz-Mindlin law's own restitution dashpots (Thornton et al. 2013's
    damping ratio for a Hertzian contact cut at zero force) both return the drawn restitution;
    the linear contact pulls as it opens, the Hertz-Mindlin one never does."""
    r = 0.1
    bed = tmp_path / "free_grain.npz"
    np.savez(bed, x=np.array([[0.0, 0.0, 1.0]]), radius=np.array([r]))
    v = 0.4
    for law, tol in (("linear", 0.01), ("hertz_mindlin", 0.002)):
        cfg = _cfg(monkeypatch, tmp_path, 11, "contact_damping", contact_law=law)
        monkeypatch.undo()
        m = cfg["density"] * 4.0 / 3.0 * np.pi * r ** 3
        for e in (0.1, 0.3):
            hist, info = cases.run_yade(dict(cfg, restitution=e, impact_speed=v, t_end=0.05,
                                             gap=0.0, gravity=0.0), tmp_path, packing_npz=bed)
            big_m = info["mass"]
            e_run = (v + hist[-1, 2]) * (big_m + m) / (m * v) - 1.0
            assert e_run == pytest.approx(e, abs=tol), (law, e)
            if law == "linear":
                assert hist[:, 3].min() < 0.0  # the dashpot pulls as the contact opens
            else:
                assert hist[:, 3].min() == 0.0  # cut at zero force
