"""Signal-processing helpers of the diagnosis: CFC filtering, mount dynamics, noise bandwidth.

``cfc`` delegates to :func:`crashdem.filters.cfc_filter` when that module is importable and falls
back to an equivalent scipy implementation otherwise (same J211 design, forward-backward, odd
padding), so the diagnosis never depends on the import order of the package.

Notes
-----
J211 filter: SAE J211-1 Appendix C (anchors.md section 2): ``wd = 2 pi CFC 2.0775``, bilinear
pre-warp, 2-pole Butterworth run forward and backward. Base-excitation transmissibility of a
single-degree-of-freedom mount: Thomson & Dahl, *Theory of Vibration with Applications*, 5th ed.,
section 3.5: ``H(s) = (2 zeta wn s + wn^2) / (s^2 + 2 zeta wn s + wn^2)``.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy import signal as sps

J211_FACTOR = 2.0775
#: padding per end for the fallback filter [s] (anchors.md section 2: >= 10 ms)
FALLBACK_PAD_TIME = 0.010

try:  # the team's J211 implementation (guarded: written in parallel)
    from crashdem.filters import cfc_filter as _team_cfc_filter
except ImportError:  # pragma: no cover - depends on the checkout state
    _team_cfc_filter = None


def _j211_ba(cfc: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """2-pole J211 coefficients as scipy (b, a) (anchors.md section 2, Eq. C1)."""
    wd = 2.0 * math.pi * cfc * J211_FACTOR
    wa = math.tan(wd / (2.0 * fs))
    d = 1.0 + math.sqrt(2.0) * wa + wa * wa
    a0 = wa * wa / d
    b1 = -2.0 * (wa * wa - 1.0) / d
    b2 = (-1.0 + math.sqrt(2.0) * wa - wa * wa) / d
    return np.array([a0, 2.0 * a0, a0]), np.array([1.0, -b1, -b2])


def cfc(x: np.ndarray, fs: float, cfc_class: float) -> np.ndarray:
    """SAE J211 CFC filter of a uniformly sampled array (zero phase, 4 poles).

    Parameters
    ----------
    x : samples (any unit); fs : sample rate [Hz]; cfc_class : channel frequency class [Hz]
    """
    x = np.asarray(x, dtype=float)
    if _team_cfc_filter is not None:
        return np.asarray(_team_cfc_filter(x, fs=fs, cfc=cfc_class))
    b, a = _j211_ba(cfc_class, fs)
    n_pad = min(max(int(round(FALLBACK_PAD_TIME * fs)), 3), x.size - 1)
    return sps.filtfilt(b, a, x, padtype="odd", padlen=n_pad)


def noise_bandwidth(fs: float, cfc_class: float | None) -> float:
    """Equivalent noise bandwidth [Hz] of the forward-backward J211 filter (or fs/2 if raw).

    ``B_eq = integral_0^{fs/2} |H(f)|^2 df`` with ``|H| = |H_2pole|^2`` (forward + backward).

    Notes
    -----
    Definition of the equivalent noise bandwidth: Bendat & Piersol, *Random Data*, 4th ed., eq. 5.98.
    """
    if cfc_class is None:
        return 0.5 * fs
    b, a = _j211_ba(cfc_class, fs)
    f = np.linspace(0.0, 0.5 * fs, 20001)
    _, h = sps.freqz(b, a, worN=f, fs=fs)
    gain = np.abs(h) ** 4  # |H_fb|^2 = |H_2pole|^4
    return float(np.trapezoid(gain, f))


def effective_samples(n: int, fs: float, cfc_class: float | None) -> float:
    """Number of statistically independent samples among ``n`` samples of band-limited noise.

    ``n_eff = n * 2 B_eq / fs`` (at most ``n``).

    Notes
    -----
    Band-limited white noise of bandwidth B has 2 B independent samples per second (Shannon);
    Bendat & Piersol, *Random Data*, 4th ed., section 8.2 (effective record length).
    """
    return float(min(n, n * 2.0 * noise_bandwidth(fs, cfc_class) / fs))


def mount_filter_bilinear(x: np.ndarray, dt: float, fn: float, zeta: float,
                          form: float = 1.0) -> np.ndarray:
    """Accelerometer-mount response, bilinear (Tustin) discretisation pre-warped at fn.

    Parameters
    ----------
    x : base acceleration samples [m/s^2] at step dt [s]; fn : mount natural frequency [Hz];
    zeta : mount damping ratio [-]; form : weight of the damper term in the numerator,
        ``H = (2 form zeta wn s + wn^2) / (s^2 + 2 zeta wn s + wn^2)``: 1 = transmissibility of a
        resonant mount, 0 = seismic transducer low-pass (``crashdem.sensors.MountDynamics``
        models "mount" and "lowpass")

    Notes
    -----
    The filter starts at rest in equilibrium with the first sample (the record starts in
    free fall or at rest), like ``MountDynamics.apply``.
    """
    b, a, zi = _mount_design(float(dt), float(fn), float(zeta), float(form))
    x = np.asarray(x, dtype=float)
    if x.size == 0 or x[0] == 0.0:
        return sps.lfilter(b, a, x)
    return sps.lfilter(b, a, x, zi=zi * x[0])[0]


#: highest mount resonance the bilinear design resolves, as a fraction of the Nyquist
#: frequency 1 / (2 dt) (``_mount_design``)
MOUNT_NYQUIST_FRACTION = 0.9


@functools.lru_cache(maxsize=256)
def _mount_design(dt: float, fn: float, zeta: float, form: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mount filter's (b, a) and its unit steady state (``lfilter_zi``), designed once per
    (dt, fn, zeta, form): a screening fit evaluates its model thousands of times, and the mount
    stays where it is while the fit moves its other parameters (measured on a planar
    diagnosis: ``scipy.signal.bilinear`` took 7.1 s of 27.7 s, 2.2 ms a call). The arrays are
    read-only; the filter is the one designed each time before, bit for bit.

    A resonance at or above ``MOUNT_NYQUIST_FRACTION`` of the Nyquist frequency is designed at
    that frequency: above it the pre-warp runs into tan(pi / 2) (at the Nyquist frequency the
    filter is singular: a 1 kHz recording and a 1 kHz mount), and a resonance the sampling
    cannot resolve acts, within the band it does resolve, like one at its edge."""
    fn = min(fn, MOUNT_NYQUIST_FRACTION * 0.5 / dt)
    wn = 2.0 * math.pi * fn
    # pre-warp: scale so the discrete resonance sits at fn (Oppenheim & Schafer eq. 7.26)
    wp = 2.0 / dt * math.tan(wn * dt / 2.0)
    b, a = sps.bilinear(_numerator(form, zeta, wp), [1.0, 2.0 * zeta * wp, wp * wp], fs=1.0 / dt)
    zi = sps.lfilter_zi(b, a)
    for arr in (b, a, zi):
        arr.flags.writeable = False
    return b, a, zi


def _numerator(form: float, zeta: float, w: float) -> list[float]:
    """``2 form zeta w s + w^2`` (without the s term when form = 0: a zero leading coefficient
    is an ill-conditioned numerator for scipy)."""
    return [2.0 * form * zeta * w, w * w] if form > 0.0 else [w * w]


def mount_filter_exact(x: np.ndarray, dt: float, fn: float, zeta: float,
                       form: float = 1.0) -> np.ndarray:
    """Same response, first-order-hold exact discretisation (for the truth generator)."""
    wn = 2.0 * math.pi * fn
    sysd = sps.cont2discrete((_numerator(form, zeta, wn), [1.0, 2.0 * zeta * wn, wn * wn]), dt,
                             method="foh")
    b = np.ravel(sysd[0])
    a = np.ravel(sysd[1])
    return sps.lfilter(b, a, x)
