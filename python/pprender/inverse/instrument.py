"""Synthetic PPR measurements: what a photon-counting polarimetric lidar records.

Conventions (written once here; every function in this module follows them):

* SI units: metres, seconds, joules, radians; cross-sections in m^2; counts are detected
  photo-electrons (dimensionless).
* Profiles are the renderer's (:func:`pprender.render`): ``(..., B, 4, 4)`` Mueller or
  ``(..., B, 4)`` Stokes lidar cross-sections in m^2 per range bin, with range bin edges
  ``(B + 1,)`` in metres. Stokes bases are the renderer's (``pprender.lidar``): the
  transmitted beam's ``x`` is the telescope ``X`` axis (monostatic), the received beam's
  basis is ``(X, Y)``. ``V = 2 Im(Ex Ey*)``; "R" below means ``S3 = V = +1`` in this
  convention and "L" ``V = -1``. A mirror facing the sensor is ``diag(1, 1, -1, -1)``.
* Counts arrays are ``(..., B, C)``: range bins, then polarization channels ``C``.

Link budget (the lidar equation for a target smaller than the beam)::

    N_sig[b, c] = N_tx * (1 / A_beam) * sigma_c[b] * A_rx / (4 pi R^2) * eta * T^2

with

* ``N_tx = n_pulses * E lambda / (h c)``: transmitted photons (``E`` pulse energy, J);
* ``A_beam`` (m^2): the beam's effective area at the target, ``1 / A_beam`` being the
  fraction of the transmitted photons per m^2 at the beam centre (the target is assumed on
  the beam axis and much smaller than the footprint). ``beam="gaussian"``: ``divergence``
  is the full angle at the 1/e^2 irradiance points, the 1/e^2 radius on target is
  ``w = R tan(divergence / 2)`` (``~ R divergence / 2``) and the peak irradiance is
  ``2 P / (pi w^2)``, so ``A_beam = pi w^2 / 2``. ``beam="tophat"``: uniform irradiance over the disc of radius
  ``w``, ``A_beam = pi w^2``;
* ``sigma_c[b] = a_c^T M[b] g_c`` (m^2): the lidar (backscatter) cross-section in bin ``b``
  seen by channel ``c`` with analyzer row ``a_c`` (split factors included) and transmitted
  Stokes state ``g_c`` (unit intensity, its share of the pulses included); the renderer's
  pixel values are ``4 pi f cos(theta_i) delta^2``, so the received power is
  ``I_inc sigma / (4 pi R^2) A_rx``: the standard form;
* ``A_rx = pi D^2 / 4`` (m^2), ``D`` the receiver aperture diameter;
* ``eta``: system efficiency (receiver optics x detector quantum efficiency);
* ``T``: one-way atmospheric transmission (``T^2`` for the round trip): ``transmission``,
  or an :class:`~pprender.inverse.atmosphere.Atmosphere`'s
  :meth:`~pprender.inverse.atmosphere.Atmosphere.transmission` by elevation (one of the two;
  :attr:`Instrument.one_way_transmission`); ``R``: range (m).

Detector timing jitter (Gaussian, ``jitter`` s RMS, i.e. ``c jitter / 2`` m of range)
blurs the signal: each rendered bin's content is spread uniformly over its bin, convolved
with the Gaussian and integrated over every output bin in closed form (erf / Gaussian
terms, :func:`jitter_matrix`); the total is kept when the bins cover the blurred profile.
Counts blurred outside the bins are lost, as behind a range gate.

Background (sky, detector dark counts): ``background_rate`` counts/s in each channel
while its range gate is open, i.e. ``rate * (2 * bin width / c)`` per bin and pulse.

Shot noise: counts are Poisson with mean ``signal + background`` (a photon-counting
detector without dead time or pile-up: valid while the expected counts per bin and
pulse are well below 1) by default. ``Instrument(detector=...)`` replaces them with what
a :class:`~pprender.inverse.detector.Detector` records (dead time: Coates' first-photon
counts; a linear-mode APD: float photo-electron estimates with excess noise), and
``Instrument(atmosphere=...)`` adds an :class:`~pprender.inverse.atmosphere.Atmosphere`'s
per-pulse scintillation (:func:`pprender.inverse.detector.record`; with neither, the
counts are today's ``rng.poisson`` draws, bit for bit). Both act pulse by pulse, so with
a dead time or scintillation every channel needs a whole number of pulses,
``n_pulses * pulse_share``. Without a detector (or with a photon counter without dead time)
:func:`measure` warns (:class:`PileUpWarning`, never refuses) where the expected counts
per bin and per pulse of a channel exceed :data:`PILE_UP_THRESHOLD` = 0.1. Why 0.1: a
single-photon detector whose dead time spans at least a bin records at most one event
per bin and pulse, on average ``1 - exp(-lam)`` of the ``lam`` expected, a loss of
``1 - (1 - exp(-lam)) / lam ~ lam / 2``: 5 % at ``lam = 0.1`` (and the counts are then
no longer Poisson). This is a lower bound on the distortion: a detector whose dead time
spans many bins (or the whole range gate, one event per pulse) loses counts in later
bins at lower per-bin rates, governed by the counts per pulse within a dead time. "Per
pulse" counts the pulses a channel sees: ``n_pulses * pulse_share``. A detector with a
dead time models pile-up instead (no warning); a linear-mode APD warns above its
saturation level (:class:`~pprender.inverse.detector.SaturationWarning`).

Wavelength: a :class:`pprender.RenderResult` records the wavelength it was rendered at
(its materials' wavelength); :func:`expected_counts`, :func:`measure`,
:meth:`Instrument.signal_counts` and :meth:`Instrument.scaled_to` refuse one that
differs from ``instrument.wavelength`` by more than 1e-6 relative (the photon number
scales with the wavelength, the materials' response too). Raw profile arrays, and
results assembled by hand (``wavelength=None``), carry no wavelength and cannot be
checked: render them at the instrument's wavelength.

Numbers are numbers: text (``"1e-3"``), None or a complex value where a real number or
an array of them is expected raises :class:`pprender.Error` naming the parameter
(scalar parameters refuse booleans too); nothing is converted from text.

SNR (:func:`snr`): ``S / sqrt(S + B)`` with ``S`` and ``B`` the expected signal and
background counts summed over all bins and channels.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from scipy.special import erfc

from .. import _io
from .._core import Error
from ..lidar import SPEED_OF_LIGHT, RenderResult
from . import speckle as _speckle
from .speckle import Speckle
from .atmosphere import Atmosphere, pulse_groups
from .detector import Detector, record

__all__ = [
    "PLANCK",
    "PILE_UP_THRESHOLD",
    "CHANNEL_PRESETS",
    "Channels",
    "Instrument",
    "Measurement",
    "PileUpWarning",
    "channel_set",
    "expected_counts",
    "jitter_matrix",
    "measure",
    "snr",
]

#: Planck constant (J s), exact in the SI.
PLANCK = 6.62607015e-34

#: Expected counts per bin and per pulse (of one channel) above which :func:`measure`
#: warns that the Poisson photon-counting model no longer holds (module docstring:
#: a pile-up loss of about half of it, 5 %).
PILE_UP_THRESHOLD = 0.1


class PileUpWarning(UserWarning):
    """:func:`measure` was asked for more than :data:`PILE_UP_THRESHOLD` expected counts per bin and pulse.

    Detector dead time, pile-up and saturation, which a Poisson photon counter does not model,
    would distort such a measurement (module docstring): ``Instrument(detector=Detector(
    dead_time=...))`` models them (:mod:`pprender.inverse.detector`).
    """


#: Version of the saved layout (:meth:`Measurement.to_xarray`); files of a newer version
#: are refused. Version 2 adds the instrument's ``speckle``, ``detector`` and
#: ``atmosphere`` and the ``speckle_dof`` variable; a measurement without them is still
#: written as version 1, which earlier pprender versions read.
FORMAT_VERSION = 2

# Largest mean numpy's Poisson sampler accepts (int64 counts; its limit is 9.2234e18).
_POISSON_MAX = 9.2e18

_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)

# Unit-intensity Stokes states (transmit or receive basis).
_STATES = {
    "H": (1.0, 1.0, 0.0, 0.0),
    "V": (1.0, -1.0, 0.0, 0.0),
    "D": (1.0, 0.0, 1.0, 0.0),
    "A": (1.0, 0.0, -1.0, 0.0),
    "R": (1.0, 0.0, 0.0, 1.0),
    "L": (1.0, 0.0, 0.0, -1.0),
}

#: Names accepted by :func:`channel_set` (and ``Instrument(channels=...)``).
CHANNEL_PRESETS = ("co_cross_linear", "co_cross_circular", "stokes", "mueller")


def _analyzer(state: str) -> tuple[float, ...]:
    # ideal polarizer transmitting `state`: the row 1/2 (1, s)
    return tuple(0.5 * x for x in _STATES[state])


@dataclass(frozen=True)
class Channels:
    """The receiver's polarization channels (and, for Mueller polarimeters, the transmitted states).

    Channel ``c`` counts ``split[c] * pulse_share[c] * analyzers[c] @ M @ generators[c]`` per
    unit of the link budget, ``M`` the target's Mueller cross-section. Arrays are stored as
    tuples (hashable); the properties ``*_array`` give NumPy arrays.

    Parameters
    ----------
    names : sequence of str
        (C,) labels, unique.
    analyzers : array_like
        (C, 4) analyzer rows in the received basis; an ideal polarizer passing the unit state
        ``s`` is ``1/2 (1, s1, s2, s3)``. Each row ``(a0, a1, a2, a3)`` needs
        ``0 < a0 <= 1`` and ``|(a1, a2, a3)| <= a0`` (a physical analyzer).
    generators : array_like
        (C, 4) transmitted Stokes states, unit intensity (``g0 = 1``,
        ``|(g1, g2, g3)| <= 1``), in the transmit basis.
    split : array_like
        (C,) fraction of the received light sent to the channel's analyzer, in (0, 1] (beam
        splitters; a polarizing beam splitter's two outputs each count 1).
    pulse_share : array_like
        (C,) fraction of the pulses transmitted with the channel's generator, in (0, 1].
    description : str, optional
        A free-text description (the presets of :func:`channel_set` say what they are).
        Default ``""``.

    Raises
    ------
    pprender.Error
        For no channels, repeated names, arrays of the wrong shape, non-finite values, or
        values outside the ranges above.
    """

    names: tuple[str, ...]
    analyzers: tuple[tuple[float, ...], ...]
    generators: tuple[tuple[float, ...], ...]
    split: tuple[float, ...]
    pulse_share: tuple[float, ...]
    description: str = ""

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        c = len(names)
        if c == 0:
            raise Error("invalid channels: at least one channel is needed")
        if len(set(names)) != c:
            raise Error(f"invalid channels: names must be unique, got {names}")
        arrays = {}
        for fname, shape in (("analyzers", (c, 4)), ("generators", (c, 4)), ("split", (c,)), ("pulse_share", (c,))):
            try:
                a = np.asarray(getattr(self, fname), dtype=np.float64)
            except (TypeError, ValueError):
                raise Error(f"invalid channels.{fname}: not an array of numbers") from None
            if a.shape != shape:
                raise Error(f"invalid channels.{fname}: shape {a.shape}, expected {shape}")
            if not np.all(np.isfinite(a)):
                raise Error(f"invalid channels.{fname}: not finite")
            arrays[fname] = a
        a = arrays["analyzers"]
        if np.any(a[:, 0] <= 0) or np.any(a[:, 0] > 1) or np.any(
            np.linalg.norm(a[:, 1:], axis=1) > a[:, 0] * (1 + 1e-12)
        ):
            raise Error(
                "invalid channels.analyzers: each row (a0, a1, a2, a3) needs 0 < a0 <= 1 and "
                "|(a1, a2, a3)| <= a0 (a physical analyzer)"
            )
        g = arrays["generators"]
        if np.any(np.abs(g[:, 0] - 1) > 1e-12) or np.any(np.linalg.norm(g[:, 1:], axis=1) > 1 + 1e-12):
            raise Error(
                "invalid channels.generators: each row must be a unit-intensity Stokes vector "
                "(g0 = 1, |(g1, g2, g3)| <= 1)"
            )
        for fname in ("split", "pulse_share"):
            v = arrays[fname]
            if np.any(v <= 0) or np.any(v > 1):
                raise Error(f"invalid channels.{fname}: values in (0, 1]")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "analyzers", tuple(tuple(float(x) for x in r) for r in a))
        object.__setattr__(self, "generators", tuple(tuple(float(x) for x in r) for r in g))
        object.__setattr__(self, "split", tuple(float(x) for x in arrays["split"]))
        object.__setattr__(self, "pulse_share", tuple(float(x) for x in arrays["pulse_share"]))

    def __len__(self) -> int:
        return len(self.names)

    @property
    def analyzers_array(self) -> np.ndarray:
        return np.array(self.analyzers, dtype=np.float64)

    @property
    def generators_array(self) -> np.ndarray:
        return np.array(self.generators, dtype=np.float64)

    @property
    def rows(self) -> np.ndarray:
        """(C, 4) effective analyzer rows ``split * pulse_share * analyzer``."""
        w = np.asarray(self.split) * np.asarray(self.pulse_share)
        return w[:, None] * self.analyzers_array

    @property
    def single_generator(self) -> bool:
        """Whether every channel has the same transmitted state (a Stokes profile for that
        state is then enough)."""
        g = self.generators_array
        return bool(np.all(g == g[0]))

    @property
    def transmit(self) -> np.ndarray:
        """The transmitted Stokes state (4,) of a single-generator channel set: render with
        ``Lidar(polarization=channels.transmit)`` for a Stokes profile."""
        if not self.single_generator:
            raise Error(
                "this channel set has several transmitted states (a Mueller polarimeter): "
                "it needs a Mueller profile"
            )
        return self.generators_array[0].copy()


def channel_set(name: str) -> Channels:
    """A named receiver (:data:`CHANNEL_PRESETS`).

    Parameters
    ----------
    name : {"co_cross_linear", "co_cross_circular", "stokes", "mueller"}
        The preset:

        * ``"co_cross_linear"``: transmit H (linear along ``x``); a polarizing beam splitter
          gives ``co`` (analyzer H, parallel) and ``cross`` (V, perpendicular), each with all
          of its polarization (split 1).
        * ``"co_cross_circular"``: transmit R (``V = +1``); ``co`` is the handedness a mirror
          returns (analyzer L, since a mirror flips ``V``) and ``cross`` the other (R); a
          quarter-wave plate and a polarizing beam splitter (split 1).
        * ``"stokes"``: transmit H; a division-of-amplitude six-state polarimeter: a
          non-polarizing 1/3 : 1/3 : 1/3 split into three arms with polarizing beam splitters
          analysing H/V, D/A (behind a half-wave plate) and R/L (behind a quarter-wave plate):
          channels H, V, D, A, R, L, each with split 1/3. The Stokes vector is
          ``3 (H + V, H - V, D - A, R - L)``.
        * ``"mueller"``: a multi-state Mueller polarimeter: the pulses cycle through four
          generator states H, V, D, R (a quarter of the pulses each) and the six-state
          analyzer above records each: 24 channels ``"G->A"`` (generator G, analyzer A),
          weight ``1/4 * 1/3``. Its measurement matrix has rank 16: the full Mueller matrix.

    Returns
    -------
    Channels
        The preset's channels.

    Raises
    ------
    pprender.Error
        For any other name.
    """
    if name == "co_cross_linear":
        return Channels(("co", "cross"), (_analyzer("H"), _analyzer("V")), (_STATES["H"],) * 2,
                        (1.0, 1.0), (1.0, 1.0), "transmit H; PBS analyzers H (co), V (cross)")
    if name == "co_cross_circular":
        return Channels(("co", "cross"), (_analyzer("L"), _analyzer("R")), (_STATES["R"],) * 2,
                        (1.0, 1.0), (1.0, 1.0), "transmit R (V=+1); analyzers L (co), R (cross)")
    six = ("H", "V", "D", "A", "R", "L")
    if name == "stokes":
        return Channels(six, tuple(_analyzer(s) for s in six), (_STATES["H"],) * 6, (1 / 3,) * 6, (1.0,) * 6,
                        "transmit H; six-state division-of-amplitude polarimeter, split 1/3")
    if name == "mueller":
        gens = ("H", "V", "D", "R")
        names = tuple(f"{g}->{a}" for g in gens for a in six)
        return Channels(
            names,
            tuple(_analyzer(a) for _ in gens for a in six),
            tuple(_STATES[g] for g in gens for _ in six),
            (1 / 3,) * 24,
            (0.25,) * 24,
            "generators H, V, D, R (1/4 of the pulses each) x six-state analyzer (split 1/3)",
        )
    raise Error(f"invalid channels = {name!r}: choose one of {CHANNEL_PRESETS} or pass a Channels")


def _check_number(name: str, value: Any, lo: float, hi: float, lo_open: bool, hi_open: bool, unit: str) -> float:
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    v = float(value) if ok else math.nan
    if ok and math.isfinite(v):
        ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    else:
        ok = False
    if not ok:
        rng = ("(" if lo_open else "[") + f"{lo:g}, {hi:g}" + (")" if hi_open else "]")
        raise Error(f"invalid {name} = {value!r}: a finite number in {rng} ({unit})")
    return v


def _numeric_array(value: Any, name: str, what: str = "an array of numbers") -> np.ndarray:
    """``value`` as a float64 array; :class:`Error` naming ``name`` for text, None,
    complex values or anything else that is not made of real numbers (booleans pass as
    0/1, as in NumPy). NumPy would otherwise convert ``"1e-3"`` silently."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):
        raise Error(f"invalid {name}: {what}, got {type(value).__name__}") from None
    ok = raw.dtype.kind in "biuf"
    if raw.dtype.kind == "O":
        ok = all(isinstance(v, (int, float, np.integer, np.floating, np.bool_)) for v in raw.flat)
    if not ok:
        shown = repr(value) if raw.size <= 8 else f"an array of dtype {raw.dtype}"
        raise Error(f"invalid {name} = {shown}: {what} (not text, None or complex)")
    return raw.astype(np.float64)


@dataclass(frozen=True)
class Instrument:
    """A PPR instrument: laser, beam, receiver, detector and polarization channels.

    Parameters
    ----------
    pulse_energy : float
        Transmitted energy per pulse (J), in (0, 1e3].
    target_range : float
        Range to the target (m), in (0, 1e9].
    wavelength : float, optional
        Laser wavelength (m), in (0, 1e-5]; must match the renderer's materials (checked
        against a RenderResult's ``wavelength``, module docstring). Default 1064e-9.
    divergence : float, optional
        Transmit beam divergence, full angle (rad) in (0, pi): at the 1/e^2 irradiance
        points for ``beam="gaussian"``, the edge of the disc for ``"tophat"``. Default 20e-6.
    beam : {"gaussian", "tophat"}, optional
        ``"gaussian"`` (default; peak irradiance at the beam centre) or ``"tophat"``.
    aperture_diameter : float, optional
        Receiver aperture diameter (m), in (0, 100]. Default 1.
    efficiency : float, optional
        System efficiency: receiver optics transmission times detector quantum
        efficiency, in (0, 1]. Default 0.3.
    transmission : float, optional
        One-way atmospheric transmission in (0, 1] (1 in space). Default 1.
    jitter : float, optional
        Detector timing jitter (s RMS, Gaussian), in [0, 1e-6]. Default 0.
    background_rate : float or sequence of float, optional
        Background count rate per channel (counts/s, >= 0): one value for every
        channel or one per channel. Default 0.
    channels : str or Channels, optional
        A preset name (:func:`channel_set`) or a :class:`Channels`. Default
        ``"co_cross_linear"``.
    n_pulses : int, optional
        Number of pulses accumulated, in [1, 1e12]. Default 1.
    speckle : Speckle or None, optional
        Laser speckle (:class:`pprender.inverse.speckle.Speckle`): :func:`measure` draws
        speckled counts and :mod:`pprender.inverse.fit` uses the speckle likelihood. Default
        None: no speckle, Poisson counts (today's model, the same draws bit for bit).
    detector : Detector, optional
        What the detector records (:class:`pprender.inverse.detector.Detector`): a photon
        counter with a dead time (Coates' first-photon counts) or a linear-mode APD (float
        photo-electron estimates). Default None: Poisson counts, as ``Detector()``.
    atmosphere : Atmosphere, optional
        The atmosphere (:class:`pprender.inverse.atmosphere.Atmosphere`): its one-way
        transmission by elevation enters the link budget in place of ``transmission``
        (give one of them: an atmosphere whose transmission is not 1 together with
        ``transmission`` other than 1 is refused), its scintillation the counts. Default
        None (vacuum).

    Raises
    ------
    pprender.Error
        For a value outside its range, or one that is not a number (module docstring); a
        ``detector`` or ``atmosphere`` of another type; both ``transmission`` and an
        atmosphere's transmission other than 1; a dead time or scintillation with a channel
        that sees a fractional number of pulses (``n_pulses * pulse_share``); ``speckle``
        together with a detector other than a Poisson counter or with scintillation (their
        joint statistics are not modelled).
    """

    pulse_energy: float
    target_range: float
    wavelength: float = 1064e-9
    divergence: float = 20e-6
    beam: str = "gaussian"
    aperture_diameter: float = 1.0
    efficiency: float = 0.3
    transmission: float = 1.0
    jitter: float = 0.0
    background_rate: float | Sequence[float] = 0.0
    channels: str | Channels = "co_cross_linear"
    n_pulses: int = 1
    speckle: Speckle | None = None
    detector: Detector | None = None
    atmosphere: Atmosphere | None = None

    def __post_init__(self) -> None:
        _check_number("pulse_energy", self.pulse_energy, 0.0, 1e3, True, False, "J")
        _check_number("target_range", self.target_range, 0.0, 1e9, True, False, "m")
        _check_number("wavelength", self.wavelength, 0.0, 1e-5, True, False, "m")
        _check_number("divergence", self.divergence, 0.0, math.pi, True, True, "rad, full angle")
        if self.beam not in ("gaussian", "tophat"):
            raise Error(f'invalid beam = {self.beam!r}: "gaussian" or "tophat"')
        _check_number("aperture_diameter", self.aperture_diameter, 0.0, 100.0, True, False, "m")
        _check_number("efficiency", self.efficiency, 0.0, 1.0, True, False, "optics x quantum efficiency")
        _check_number("transmission", self.transmission, 0.0, 1.0, True, False, "one-way")
        _check_number("jitter", self.jitter, 0.0, 1e-6, False, False, "s RMS")
        if isinstance(self.n_pulses, (bool, np.bool_)) or not isinstance(self.n_pulses, (int, np.integer)) or not (
            1 <= self.n_pulses <= 10**12
        ):
            raise Error(f"invalid n_pulses = {self.n_pulses!r}: an integer in [1, 1e12]")
        ch = self.channels
        if isinstance(ch, str):
            ch = channel_set(ch)
        elif not isinstance(ch, Channels):
            raise Error(f"invalid channels = {ch!r}: one of {CHANNEL_PRESETS} or a Channels")
        object.__setattr__(self, "channels", ch)
        bg = _numeric_array(self.background_rate, "background_rate", "counts/s >= 0, one value or one per channel")
        if bg.ndim == 0:
            bg = np.full(len(ch), float(bg))
        if bg.shape != (len(ch),) or not np.all(np.isfinite(bg)) or np.any(bg < 0):
            raise Error(
                f"invalid background_rate = {self.background_rate!r}: finite counts/s >= 0, "
                f"one value or one per channel ({len(ch)})"
            )
        object.__setattr__(self, "background_rate", tuple(float(x) for x in bg))
        object.__setattr__(self, "n_pulses", int(self.n_pulses))
        if self.speckle is not None and not isinstance(self.speckle, Speckle):
            raise Error(
                f"invalid speckle of type {type(self.speckle).__name__}: None or a "
                "pprender.inverse.speckle.Speckle (e.g. Speckle(dof=4.0))"
            )
        _check_receiver(self)
        if self.speckle is not None and (
            (self.detector is not None and not self.detector.is_poisson)
            or (self.atmosphere is not None and self.atmosphere.scintillation != "none")
        ):
            raise Error(
                "invalid speckle together with a detector that is not a Poisson photon counter or with "
                "scintillation: their joint statistics are not modelled (speckle, a dead time or an APD, and "
                "scintillation each work alone; an atmosphere's transmission works with all)"
            )

    # ------------------------------------------------------------------ link budget

    @property
    def channel_names(self) -> tuple[str, ...]:
        return self.channels.names  # type: ignore[union-attr]

    @property
    def photons_per_pulse(self) -> float:
        """Transmitted photons per pulse, ``E lambda / (h c)``."""
        return self.pulse_energy * self.wavelength / (PLANCK * SPEED_OF_LIGHT)

    @property
    def beam_radius(self) -> float:
        """Beam radius on target ``w = R tan(divergence / 2)`` (m): the 1/e^2 radius
        (Gaussian) or the disc radius (top-hat)."""
        return self.target_range * math.tan(self.divergence / 2.0)

    @property
    def beam_area(self) -> float:
        """Effective beam area at the target (m^2): ``pi w^2 / 2`` (Gaussian peak) or
        ``pi w^2`` (top-hat)."""
        a = math.pi * self.beam_radius**2
        return a / 2.0 if self.beam == "gaussian" else a

    @property
    def aperture_area(self) -> float:
        """Receiver collecting area ``pi D^2 / 4`` (m^2)."""
        return math.pi * self.aperture_diameter**2 / 4.0

    @property
    def counts_per_cross_section(self) -> float:
        """Detected counts per m^2 of channel cross-section over all pulses:
        ``n_pulses N_tx / A_beam * A_rx / (4 pi R^2) * eta * T^2`` (1/m^2), ``T``
        :attr:`one_way_transmission`."""
        return (
            self.n_pulses
            * self.photons_per_pulse
            / self.beam_area
            * self.aperture_area
            / (4.0 * math.pi * self.target_range**2)
            * self.efficiency
            * self.one_way_transmission**2
        )

    @property
    def one_way_transmission(self) -> float:
        """The one-way atmospheric transmission ``T`` of the link budget: ``transmission``,
        or the atmosphere's :meth:`~pprender.inverse.atmosphere.Atmosphere.transmission`
        (only one of them differs from 1)."""
        if self.atmosphere is None:
            return float(self.transmission)
        return float(self.transmission) * self.atmosphere.transmission()

    @property
    def pulses(self) -> np.ndarray:
        """(C,) pulses each channel sees, ``n_pulses * pulse_share``."""
        return self.n_pulses * np.asarray(self.channels.pulse_share)  # type: ignore[union-attr]

    @property
    def jitter_range(self) -> float:
        """Timing jitter in range units, ``c jitter / 2`` (m)."""
        return SPEED_OF_LIGHT * self.jitter / 2.0

    def background_counts(self, bin_edges: Any) -> np.ndarray:
        """Expected background counts (B, C) per bin and channel:
        ``rate_c * (2 * bin width / c) * n_pulses * pulse_share_c``."""
        e = _check_edges(bin_edges, "bin_edges")
        dt = 2.0 * np.diff(e) / SPEED_OF_LIGHT
        rate = np.asarray(self.background_rate) * np.asarray(self.channels.pulse_share)  # type: ignore[union-attr]
        return self.n_pulses * dt[:, None] * rate[None, :]

    def signal_counts(self, profile: Any, *, bin_edges: Any = None) -> float:
        """Expected signal counts summed over bins and channels (background excluded,
        jitter included), averaged over any leading (attitude) axes of ``profile``."""
        s = expected_counts(profile, self, bin_edges=bin_edges, background=False)
        return float(s.sum(axis=(-2, -1)).mean())

    def scaled_to(self, total_signal_counts: float, for_profile: Any, *, bin_edges: Any = None) -> "Instrument":
        """A copy whose pulse energy gives ``total_signal_counts`` expected signal counts
        (summed over bins and channels, averaged over leading axes) for ``for_profile``
        (a :class:`RenderResult` or an array with ``bin_edges``). The signal is linear in
        the pulse energy, so ``E' = E N / S(E)``."""
        n = _check_number("total_signal_counts", total_signal_counts, 0.0, 1e18, True, False, "counts")
        s = self.signal_counts(for_profile, bin_edges=bin_edges)
        if not s > 0:
            raise Error("invalid for_profile: it gives no signal in any channel (cannot scale)")
        e = self.pulse_energy * n / s
        if not e <= 1e3:
            raise Error(
                f"invalid total_signal_counts = {total_signal_counts!r}: it needs pulse_energy = {e:.3g} J, "
                "beyond (0, 1e3] J; raise n_pulses (or the aperture) first"
            )
        return replace(self, pulse_energy=e)


def _check_receiver(inst: Instrument) -> None:
    """Check ``inst.detector`` and ``inst.atmosphere`` against the rest of the instrument
    (:class:`Instrument`'s Raises)."""
    det, atm = inst.detector, inst.atmosphere
    if det is not None and not isinstance(det, Detector):
        raise Error(f"invalid detector of type {type(det).__name__}: a pprender.inverse.detector.Detector or None")
    if atm is not None and not isinstance(atm, Atmosphere):
        raise Error(
            f"invalid atmosphere of type {type(atm).__name__}: a pprender.inverse.atmosphere.Atmosphere or None"
        )
    if atm is not None and inst.transmission != 1.0 and atm.transmission() != 1.0:
        raise Error(
            f"invalid transmission = {inst.transmission!r} with an atmosphere of transmission "
            f"{atm.transmission():.6g} (elevation {atm.elevation_deg:g} deg): both are the one-way "
            "transmission; give one of them (transmission=1, or Atmosphere(zenith_transmission=1))"
        )
    dead = det is not None and det.kind == "photon_counting" and det.dead_time > 0
    scint = atm is not None and atm.scintillation != "none"
    if dead or scint:
        p = inst.pulses
        r = np.round(p)
        if np.any(np.abs(p - r) > 1e-9 * np.maximum(r, 1.0)) or np.any(r < 1):
            share = np.asarray(inst.channels.pulse_share)  # type: ignore[union-attr]
            raise Error(
                f"invalid n_pulses = {inst.n_pulses} for these channels (pulse_share {sorted(set(share.tolist()))}): "
                f"{'a dead time' if dead else 'scintillation'} acts pulse by pulse, so each channel needs a whole "
                f"number (>= 1) of pulses n_pulses * pulse_share, got {p.tolist()}; choose n_pulses so that "
                "every n_pulses * pulse_share is a whole number"
            )


# ---------------------------------------------------------------------- jitter


def _h(u: np.ndarray, sigma: float) -> np.ndarray:
    # G(u) - max(u, 0) with G(u) = int_{-inf}^u Phi(v / sigma) dv = u Phi + sigma phi:
    # sigma (phi(t) - |t| Phi(-|t|)), t = u / sigma; decays like a Gaussian, no cancellation.
    t = np.abs(u) / sigma
    return sigma * (_INV_SQRT_2PI * np.exp(-0.5 * t * t) - t * 0.5 * erfc(t / _SQRT2))


def jitter_matrix(src_edges: Any, dst_edges: Any, sigma: float) -> np.ndarray:
    """The (B_dst, B_src) matrix taking bin contents on ``src_edges`` to ``dst_edges`` after a Gaussian blur.

    Parameters
    ----------
    src_edges : array_like
        (B_src + 1,) source bin edges (m), strictly increasing.
    dst_edges : array_like
        (B_dst + 1,) destination bin edges (m), strictly increasing.
    sigma : float
        Standard deviation of the Gaussian blur (m, >= 0).

    Returns
    -------
    numpy.ndarray
        (B_dst, B_src) fractions. Columns sum to 1 where the destination bins cover the
        blurred source bin.

    Raises
    ------
    pprender.Error
        For edges that are not finite and strictly increasing, or a negative or non-finite
        ``sigma``.

    Notes
    -----
    Each source bin's content is spread uniformly over its bin ``[a, b]``; the fraction
    landing in ``[c, d]`` is ``int_c^d int_a^b g(x - y) dy dx / (b - a)`` with ``g`` the
    Gaussian, in closed form ``[G(d-a) - G(c-a) - G(d-b) + G(c-b)] / (b - a)``,
    ``G(u) = u Phi(u / sigma) + sigma phi(u / sigma)``. ``sigma = 0`` gives the overlap
    fractions (plain rebinning; the identity for equal edges).
    """
    a = _check_edges(src_edges, "src_edges")
    d = _check_edges(dst_edges, "dst_edges")
    s = _check_number("sigma", sigma, 0.0, math.inf, False, True, "m")
    lo, hi = a[None, :-1], a[None, 1:]
    c0, c1 = d[:-1, None], d[1:, None]
    k = np.clip(np.minimum(hi, c1) - np.maximum(lo, c0), 0.0, None)
    if s > 0:
        k = k + _h(c1 - lo, s) - _h(c0 - lo, s) - _h(c1 - hi, s) + _h(c0 - hi, s)
    k = k / (hi - lo)
    return np.clip(k, 0.0, None)


# ---------------------------------------------------------------------- validation


def _check_edges(edges: Any, name: str) -> np.ndarray:
    e = _numeric_array(edges, name, "an array of bin edges (m)")
    if e.ndim != 1 or len(e) < 2:
        raise Error(f"invalid {name}: shape {e.shape}, expected (B + 1,) with B >= 1")
    if not np.all(np.isfinite(e)):
        raise Error(f"invalid {name}: not finite")
    if not np.all(np.diff(e) > 0):
        raise Error(f"invalid {name}: must be strictly increasing (m of range)")
    return e


def _check_wavelength(result: RenderResult, instrument: Instrument) -> None:
    """Refuse a render made at another wavelength than the instrument's (module
    docstring); results without a wavelength (assembled by hand) pass unchecked."""
    lam = getattr(result, "wavelength", None)
    if lam is None:
        return
    if not abs(float(lam) - instrument.wavelength) <= 1e-6 * instrument.wavelength:
        raise Error(
            f"invalid profile: the RenderResult was rendered at wavelength {float(lam)!r} m but the "
            f"instrument's wavelength is {instrument.wavelength!r} m (they must agree to 1e-6 relative); "
            "render with Lidar(wavelength=instrument.wavelength) or use an Instrument at the render's wavelength"
        )


def _profile_and_edges(
    profile: Any, bin_edges: Any, instrument: Instrument | None = None
) -> tuple[np.ndarray, np.ndarray, bool]:
    """(profile array, edges, is_mueller); with ``instrument``, a RenderResult's
    wavelength is checked against it."""
    if isinstance(profile, RenderResult):
        if instrument is not None:
            _check_wavelength(profile, instrument)
        if profile.profile is None:
            raise Error('invalid profile: the RenderResult has no profile (render with outputs=("profile",))')
        if bin_edges is not None and not np.array_equal(np.asarray(bin_edges, dtype=np.float64), profile.bin_edges):
            raise Error("invalid bin_edges: they differ from the RenderResult's bin_edges (omit them)")
        bin_edges = profile.bin_edges
        profile = profile.profile
    if bin_edges is None:
        raise Error("invalid bin_edges: required with a profile array (the RenderResult's bin_edges)")
    e = _check_edges(bin_edges, "bin_edges")
    b = len(e) - 1
    p = _numeric_array(profile, "profile", "an array of cross-sections (m^2)")
    if p.ndim >= 3 and p.shape[-3:] == (b, 4, 4):
        mueller = True
    elif p.ndim >= 2 and p.shape[-2:] == (b, 4):
        mueller = False
    else:
        raise Error(
            f"invalid profile: shape {p.shape}; expected (..., B, 4, 4) Mueller or (..., B, 4) Stokes "
            f"with B = len(bin_edges) - 1 = {b}"
        )
    if not np.all(np.isfinite(p)):
        raise Error("invalid profile: not finite (NaN or inf)")
    return p, e, mueller


def _channel_cross_sections(p: np.ndarray, mueller: bool, channels: Channels) -> np.ndarray:
    """(..., B, C) cross-section seen by each channel (m^2 per bin)."""
    rows = channels.rows
    if mueller:
        sig = np.einsum("ci,...bij,cj->...bc", rows, p, channels.generators_array)
    else:
        if not channels.single_generator:
            raise Error(
                "invalid profile: a Stokes profile (..., B, 4) is for one transmitted state, but these "
                "channels use several generator states (Mueller polarimeter): pass a Mueller profile "
                "(render with Lidar(polarization=None))"
            )
        sig = np.einsum("ci,...bi->...bc", rows, p)
    # The renderer accumulates in float32: a fully polarized return (a mirror in its
    # cross channel) comes out at -1e-7 of the intensity. 1e-5 of the largest intensity
    # allows that and still catches unphysical input; what passes is clipped to 0.
    scale = float(np.max(np.abs(p[..., 0, 0] if mueller else p[..., 0]), initial=0.0))
    if np.any(sig < -1e-5 * scale):
        raise Error(
            "invalid profile: negative cross-section in a polarization channel (the profile is "
            "not a physical Mueller/Stokes profile)"
        )
    return np.clip(sig, 0.0, None)


def expected_counts(
    profile: Any,
    instrument: Instrument,
    *,
    bin_edges: Any = None,
    out_edges: Any = None,
    background: bool = True,
) -> np.ndarray:
    """Noise-free expected counts (..., B_out, C): signal (link budget, channels, jitter) plus background.

    Parameters
    ----------
    profile : RenderResult or array_like
        ``(..., B, 4, 4)`` Mueller profile (the instrument's generator states are applied)
        or ``(..., B, 4)`` Stokes profile rendered with ``Lidar(polarization=
        instrument.channels.transmit)`` (unit intensity), m^2 per bin. A RenderResult
        supplies its own ``bin_edges``, and its ``wavelength`` must be the instrument's
        (1e-6 relative); an array's wavelength cannot be checked (module docstring).
    instrument : Instrument
        The instrument (link budget, channels, jitter, background).
    bin_edges : array_like, optional
        (B + 1,) range bin edges of ``profile`` (m); required for an array.
    out_edges : array_like, optional
        Output bin edges (m; default ``bin_edges``): the jitter blur maps the profile onto
        them (counts outside are lost).
    background : bool, optional
        Add the background counts (default True).

    Returns
    -------
    numpy.ndarray
        (..., B_out, C) expected counts.

    Raises
    ------
    pprender.Error
        For a RenderResult rendered at another wavelength or without a profile, a missing
        ``bin_edges`` with an array, a profile of the wrong shape or not finite, a Stokes
        profile for channels with several generator states, or a profile giving a negative
        cross-section in a channel (not physical).

    See Also
    --------
    jitter_matrix : The jitter blur.
    """
    if not isinstance(instrument, Instrument):
        raise Error(f"invalid instrument of type {type(instrument).__name__}: expected pprender.instrument.Instrument")
    p, e, mueller = _profile_and_edges(profile, bin_edges, instrument)
    out = e if out_edges is None else _check_edges(out_edges, "out_edges")
    sig = _channel_cross_sections(p, mueller, instrument.channels)  # type: ignore[arg-type]
    sig = sig * instrument.counts_per_cross_section
    if out_edges is not None or instrument.jitter > 0:
        k = jitter_matrix(e, out, instrument.jitter_range)
        sig = np.einsum("ji,...ic->...jc", k, sig)
    if background:
        sig = sig + instrument.background_counts(out)
    return sig


def snr(signal: Any, background: Any) -> float:
    """Signal-to-noise ratio ``S / sqrt(S + B)`` of expected counts; 0 when both are 0.

    Parameters
    ----------
    signal : array_like
        Expected signal counts; ``S = sum(signal)``.
    background : array_like
        Expected background counts; ``B = sum(background)``.

    Returns
    -------
    float
        ``S / sqrt(S + B)``.

    Raises
    ------
    pprender.Error
        Unless both sums are finite and >= 0.
    """
    s = float(np.sum(_numeric_array(signal, "signal", "counts")))
    b = float(np.sum(_numeric_array(background, "background", "counts")))
    if s < 0 or b < 0 or not (math.isfinite(s) and math.isfinite(b)):
        raise Error("invalid signal/background: finite counts >= 0")
    return 0.0 if s + b == 0 else s / math.sqrt(s + b)


@dataclass
class Measurement:
    """What :func:`measure` returns.

    Indexing, ``measurement[i]``, gives the measurement(s) at ``i`` of the leading (attitude)
    axes.

    Attributes
    ----------
    counts : numpy.ndarray
        (..., B, C) int64 counts: Poisson draws, or what the instrument's
        :class:`~pprender.inverse.detector.Detector` records (a dead time: first-photon
        counts); float64 photo-electron estimates for a linear-mode APD
        (``Detector(kind="linear")``).
    expected : numpy.ndarray
        (..., B, C): their means (``signal + background``).
    signal : numpy.ndarray
        (..., B, C): expected signal counts.
    background : numpy.ndarray
        (B, C): expected background counts.
    bin_edges : numpy.ndarray
        (B + 1,) m of range.
    channel_names : tuple of str
        (C,) channel names.
    instrument : Instrument
        The instrument.
    seed : int or None
        The seed given, if any.
    extra : dict
        Free-form additions; empty as :func:`measure` returns it.
    speckle_dof : numpy.ndarray or None
        (..., B, C): each count's marginal speckle degrees of freedom in [1, inf]
        (:func:`~pprender.inverse.speckle.channel_dof`, through the jitter blur:
        :func:`~pprender.inverse.speckle.blurred_dof`), what :mod:`pprender.inverse.fit`'s
        speckle likelihood needs; None without speckle.
    range_axis : numpy.ndarray
        (B,) bin centres (m).
    time_axis : numpy.ndarray
        (B,) round-trip delays ``2 r / c`` (s).
    snr : float or numpy.ndarray
        :func:`snr` of each measurement (a float, or an array over the leading axes).

    Notes
    -----
    :meth:`save` and :meth:`load` keep a measurement, its instrument included, in a Zarr
    v3 store (``.zarr``) or a netCDF file (``.nc``), exactly; :meth:`to_xarray` gives the
    same layout as an :class:`xarray.Dataset`.
    """

    counts: np.ndarray
    expected: np.ndarray
    signal: np.ndarray
    background: np.ndarray
    bin_edges: np.ndarray
    channel_names: tuple[str, ...]
    instrument: Instrument
    seed: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    speckle_dof: np.ndarray | None = None

    @property
    def range_axis(self) -> np.ndarray:
        return 0.5 * (self.bin_edges[1:] + self.bin_edges[:-1])

    @property
    def time_axis(self) -> np.ndarray:
        return 2.0 * self.range_axis / SPEED_OF_LIGHT

    @property
    def snr(self) -> Any:
        """:func:`snr` of each measurement (float, or an array over the leading axes)."""
        s = self.signal.sum(axis=(-2, -1))
        b = float(self.background.sum())
        out = np.where(s + b > 0, s / np.sqrt(np.maximum(s + b, 1e-300)), 0.0)
        return float(out) if out.ndim == 0 else out

    def __getitem__(self, index: Any) -> "Measurement":
        """The measurement(s) at ``index`` of the leading (attitude) axes."""
        if self.counts.ndim == 2:
            raise Error("this Measurement has no leading axes to index")
        return Measurement(
            counts=self.counts[index],
            expected=self.expected[index],
            signal=self.signal[index],
            background=self.background,
            bin_edges=self.bin_edges,
            channel_names=self.channel_names,
            instrument=self.instrument,
            seed=self.seed,
            speckle_dof=None if self.speckle_dof is None else self.speckle_dof[index],
        )

    # ------------------------------------------------------------------ saving

    def to_xarray(self) -> Any:
        """The measurement as an :class:`xarray.Dataset` with named dimensions, units and metadata.

        Layout (``B`` range bins, ``C`` channels):

        * dimensions: the leading (attitude) axes, ``attitude`` for one and
          ``attitude_0``, ``attitude_1``, ... for several, each with an index coordinate;
          ``range`` (bin centres, m, with ``time`` ``2 r / c`` in s); ``range_edge`` (the
          ``bin_edges`` coordinate, ``B + 1``, m); ``channel`` (the channel names);
        * variables: ``counts`` (int64), ``expected`` and ``signal`` (leading axes,
          ``range, channel``), ``background`` (``range, channel``), in counts; with
          speckle only, ``speckle_dof`` (as ``counts``, float64);
        * attributes (a saved file adds ``created``, UTC): ``format``
          (``pprender.Measurement/1``, or ``/2`` with a speckle, detector or atmosphere:
          :data:`FORMAT_VERSION`), ``pprender_version``,
          ``wavelength`` (m, the instrument's), and as JSON text ``instrument`` (every
          :class:`Instrument` field, its :class:`Channels` in full), ``seed`` and
          ``extra``.

        Each variable keeps its NumPy dtype (``pprender_dtype`` attribute), so that
        :meth:`from_xarray` gives back the same arrays bit for bit and an equal
        :class:`Instrument`.

        Returns
        -------
        xarray.Dataset
            The dataset (in memory).

        Raises
        ------
        pprender.Error
            Naming the field, for arrays whose shapes disagree (``counts``, ``expected``
            and ``signal`` alike, ``background`` ``(B, C)``, ``bin_edges`` ``(B + 1,)``,
            ``channel_names`` ``(C,)``), an ``instrument`` that is not an
            :class:`Instrument`, a ``seed`` that is not an int or None, or an ``extra``
            value that cannot be stored as JSON (naming its key).
        """
        xr = _io._xarray()
        k = np.asarray(self.counts)
        if k.ndim < 2:
            raise Error(f"invalid Measurement.counts: shape {k.shape}, expected (..., B, C)")
        b, c = k.shape[-2:]
        for fname, want in (("expected", k.shape), ("signal", k.shape), ("background", (b, c)),
                            ("bin_edges", (b + 1,))) + ((("speckle_dof", k.shape),) if self.speckle_dof is not None else ()):
            a = np.asarray(getattr(self, fname))
            if a.shape != want:
                raise Error(f"invalid Measurement.{fname}: shape {a.shape}, expected {want} (from counts {k.shape})")
        names = tuple(self.channel_names)
        if len(names) != c or not all(isinstance(n, str) for n in names):
            raise Error(f"invalid Measurement.channel_names = {names!r}: {c} str, one per channel")
        if not isinstance(self.instrument, Instrument):
            raise Error(
                f"invalid Measurement.instrument of type {type(self.instrument).__name__}: expected an Instrument"
            )
        seed = self.seed
        if seed is not None and (isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer))):
            raise Error(f"invalid Measurement.seed = {seed!r}: an int or None")
        n_lead = k.ndim - 2
        lead = ("attitude",) if n_lead == 1 else tuple(f"attitude_{i}" for i in range(n_lead))
        dims = lead + ("range", "channel")
        edges = np.asarray(self.bin_edges)
        r = 0.5 * (edges[1:] + edges[:-1])
        coords: dict[str, Any] = {
            "channel": ("channel", np.array(names, dtype=object), {"long_name": "polarization channel"}),
            "bin_edges": _io.variable(("range_edge",), edges, {"units": "m", "long_name": "range bin edges"}),
            "range": ("range", r, {"units": "m", "long_name": "range bin centre relative to the body origin, positive away from the sensor"}),
            "time": ("range", 2.0 * r / SPEED_OF_LIGHT, {"units": "s", "long_name": "round-trip delay of the range bin centre, 2 range / c"}),
        }
        for d, n in zip(lead, k.shape[:-2]):
            coords[d] = (d, np.arange(n), {"long_name": "attitude index"})
        counts_units = {"units": "1"}
        data_vars = {
            "counts": _io.variable(dims, k, {**counts_units, "long_name": _counts_long_name(self.instrument)}),
            "expected": _io.variable(dims, self.expected, {**counts_units, "long_name": "expected counts, signal + background"}),
            "signal": _io.variable(dims, self.signal, {**counts_units, "long_name": "expected signal counts"}),
            "background": _io.variable(("range", "channel"), self.background, {**counts_units, "long_name": "expected background counts"}),
        }
        if self.speckle_dof is not None:  # only with speckle: other files keep their layout
            data_vars["speckle_dof"] = _io.variable(dims, self.speckle_dof, {
                "units": "1", "long_name": "marginal speckle degrees of freedom of each count (inf: none)"})
        inst = self.instrument
        plain = inst.speckle is None and inst.detector is None and inst.atmosphere is None and self.speckle_dof is None
        attrs = _io.base_attrs(
            "Measurement", 1 if plain else FORMAT_VERSION, "pprender measurement",
            "SI units; counts are detected photo-electrons; link budget and channels as in "
            "pprender.instrument (its module docstring)",
        )
        attrs.update(
            wavelength=float(self.instrument.wavelength),
            wavelength_units="m",
            instrument=_io.to_json(_instrument_params(self.instrument), "Measurement.instrument"),
            seed=_io.to_json(None if seed is None else int(seed), "Measurement.seed"),
            extra=_io.extra_json(self.extra, "Measurement"),
        )
        return xr.Dataset(data_vars, coords=coords, attrs=attrs)

    @classmethod
    def from_xarray(cls, ds: Any) -> "Measurement":
        """The measurement a dataset of :meth:`to_xarray` holds (exactly the one saved).

        Parameters
        ----------
        ds : xarray.Dataset
            A dataset made by :meth:`to_xarray` (or read from a file :meth:`save` wrote).

        Returns
        -------
        Measurement
            The measurement, its :class:`Instrument` equal to the original.

        Raises
        ------
        pprender.Error
            For something that is not an :class:`xarray.Dataset` of a pprender
            Measurement, one written by a newer pprender (a newer format version), or one
            missing a variable or attribute of the layout, or whose instrument is invalid.
        """
        xr = _io._xarray()
        if not isinstance(ds, xr.Dataset):
            raise Error(f"invalid ds of type {type(ds).__name__}: expected an xarray.Dataset")
        where = "ds"
        _io.check_format(ds.attrs, "Measurement", FORMAT_VERSION, where)
        if "counts" not in ds.variables:
            raise Error(f"invalid {where}: no variable 'counts'")
        lead = tuple(d for d in ds["counts"].dims if d not in ("range", "channel"))
        dims = lead + ("range", "channel")
        params = _io.from_json(ds.attrs, "instrument", where)
        try:
            instrument = _instrument_from_params(params)
        except (KeyError, TypeError) as e:
            raise Error(f"invalid {where}: attribute 'instrument' is incomplete ({e})") from None
        if "channel" not in ds.variables:
            raise Error(f"invalid {where}: no coordinate 'channel'")
        return cls(
            counts=_io.array(ds, "counts", dims, where),
            expected=_io.array(ds, "expected", dims, where),
            signal=_io.array(ds, "signal", dims, where),
            background=_io.array(ds, "background", ("range", "channel"), where),
            bin_edges=_io.array(ds, "bin_edges", ("range_edge",), where),
            channel_names=tuple(str(n) for n in np.asarray(ds["channel"].values)),
            instrument=instrument,
            seed=_io.from_json(ds.attrs, "seed", where),
            extra=dict(_io.from_json(ds.attrs, "extra", where)),
            speckle_dof=_io.array(ds, "speckle_dof", dims, where) if "speckle_dof" in ds.variables else None,
        )

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
        """Save the measurement to ``path``: a Zarr v3 store (``.zarr``) or a netCDF file (``.nc``).

        The layout is :meth:`to_xarray`'s; :meth:`load` gives back an equal measurement
        (arrays bit for bit, an equal :class:`Instrument`), which :mod:`pprender.fit` uses
        exactly as the original. The file is written beside ``path`` and renamed into
        place. A netCDF file is read back and checked before it is put in place: data the
        installed netCDF engine cannot store exactly (with scipy's netCDF3, counts above
        2**31 - 1) is refused (save as ``.zarr``).

        Parameters
        ----------
        path : str or os.PathLike
            Where to save; its suffix, ``.zarr`` or ``.nc``, picks the format.
        overwrite : bool, optional
            Replace a saved RenderResult or Measurement at ``path`` (default False: an
            existing ``path`` is refused). Anything else at ``path`` (a candidate database
            included) is never replaced.

        Raises
        ------
        pprender.Error
            For another suffix (naming ``path`` and the supported ones), an existing
            ``path`` without ``overwrite=True`` (or one that is not pprender's), a directory
            that does not exist, data the netCDF engine cannot store exactly, or what
            :meth:`to_xarray` refuses.
        """
        _io._suffix(path)
        _io.write(self.to_xarray(), path, overwrite)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Measurement":
        """Load a measurement :meth:`save` wrote (read into memory; the file is closed).

        Parameters
        ----------
        path : str or os.PathLike
            A ``.zarr`` store or ``.nc`` file.

        Returns
        -------
        Measurement
            The measurement, equal to the one saved.

        Raises
        ------
        pprender.Error
            For another suffix, nothing at ``path``, a file that is not a pprender
            Measurement (a RenderResult included), or one written in a newer format.
        """
        return cls.from_xarray(_io.read(path, "Measurement"))


def _counts_long_name(inst: Instrument) -> str:
    det = inst.detector
    if det is None or det.is_poisson:
        return "detected counts (Poisson draws)"
    if det.kind == "linear":
        return "recorded photo-electron estimates (linear-mode APD)"
    return "recorded counts (first photon per pulse: dead time at least the range gate)"


def _receiver_params(inst: Instrument) -> dict[str, Any]:
    """The detector's and the atmosphere's settings as JSON values, only those set (files
    without them load as before)."""
    out: dict[str, Any] = {}
    det = inst.detector
    if det is not None:
        out["detector"] = {
            "kind": str(det.kind), "dead_time": float(det.dead_time), "gain": float(det.gain),
            "ionization_ratio": float(det.ionization_ratio), "amplifier_noise": float(det.amplifier_noise),
            "saturation": float(det.saturation),
        }
    atm = inst.atmosphere
    if atm is not None:
        a: dict[str, Any] = {"zenith_transmission": float(atm.zenith_transmission),
                             "elevation_deg": float(atm.elevation_deg), "scintillation": str(atm.scintillation)}
        if atm.scintillation == "lognormal":
            a["scintillation_index"] = float(atm.scintillation_index)
        elif atm.scintillation == "gamma_gamma":
            if atm.rytov_variance is not None:
                a["rytov_variance"] = float(atm.rytov_variance)
            else:
                a["alpha"], a["beta"] = float(atm.alpha), float(atm.beta)  # type: ignore[arg-type]
        out["atmosphere"] = a
    return out


def _instrument_params(inst: Instrument) -> dict[str, Any]:
    """Every field of ``inst`` as JSON values (``_instrument_from_params`` rebuilds it)."""
    ch = inst.channels
    assert isinstance(ch, Channels)
    return _receiver_params(inst) | {
        "pulse_energy": float(inst.pulse_energy),
        "target_range": float(inst.target_range),
        "wavelength": float(inst.wavelength),
        "divergence": float(inst.divergence),
        "beam": str(inst.beam),
        "aperture_diameter": float(inst.aperture_diameter),
        "efficiency": float(inst.efficiency),
        "transmission": float(inst.transmission),
        "jitter": float(inst.jitter),
        "background_rate": [float(x) for x in inst.background_rate],  # type: ignore[union-attr]
        "channels": {
            "names": list(ch.names),
            "analyzers": [list(r) for r in ch.analyzers],
            "generators": [list(r) for r in ch.generators],
            "split": list(ch.split),
            "pulse_share": list(ch.pulse_share),
            "description": ch.description,
        },
        "n_pulses": int(inst.n_pulses),
        # only when set: files of speckle-free instruments keep their layout
        **({} if inst.speckle is None else {"speckle": inst.speckle.to_params()}),
    }


def _instrument_from_params(d: Any) -> Instrument:
    kw = dict(d)
    kw["channels"] = Channels(**kw["channels"])
    if kw.get("speckle") is not None:
        kw["speckle"] = Speckle.from_params(kw["speckle"])
    if "detector" in kw:
        kw["detector"] = Detector(**kw["detector"])
    if "atmosphere" in kw:
        kw["atmosphere"] = Atmosphere(**kw["atmosphere"])
    return Instrument(**kw)


def _warn_pile_up(lam: np.ndarray, instrument: Instrument) -> None:
    """:class:`PileUpWarning` where ``lam`` (..., B, C) exceeds :data:`PILE_UP_THRESHOLD`
    counts per bin and per pulse of its channel (``n_pulses * pulse_share`` pulses)."""
    pulses = instrument.n_pulses * np.asarray(instrument.channels.pulse_share)  # type: ignore[union-attr]
    per_pulse = lam / pulses
    worst = float(np.max(per_pulse, initial=0.0))
    if not worst > PILE_UP_THRESHOLD:
        return
    b, c = np.unravel_index(int(np.argmax(per_pulse)), per_pulse.shape)[-2:]
    loss = 1.0 - (1.0 - math.exp(-worst)) / worst if worst < 700 else 1.0
    n_over = int(np.sum(per_pulse > PILE_UP_THRESHOLD))
    warnings.warn(
        f"measure: up to {worst:.3g} expected counts per bin per pulse (channel "
        f"{instrument.channel_names[int(c)]!r}, bin {int(b)}; {n_over} bin/channel value(s) above "
        f"{PILE_UP_THRESHOLD:g}): beyond the photon-counting regime. Detector dead time, pile-up and "
        f"saturation are not modelled (Instrument(detector=Detector(dead_time=...)) models a dead time at "
        f"least the range gate): a detector recording one event per bin and pulse would lose "
        f"{100 * loss:.3g} % of these counts and they would not be Poisson. Lower the pulse energy or "
        "aperture, or spread the counts over more pulses (n_pulses).",
        PileUpWarning,
        stacklevel=3,
    )


def _speckle_state(
    p: np.ndarray, mueller: bool, instrument: Instrument, area: Any = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :mod:`pprender.inverse.speckle` needs of a profile (..., B, 4, 4) / (..., B, 4):
    received Stokes vectors in counts per transmitted state (..., B, G, 4), each channel's
    state (C,), and the degrees of freedom accumulated over each state's pulses (..., B, G)."""
    sp = instrument.speckle
    assert sp is not None
    ch = instrument.channels
    assert isinstance(ch, Channels)
    cpcs = instrument.counts_per_cross_section
    if mueller:
        unique, gi = _speckle.generator_groups(ch.generators_array)
        stokes = _speckle.received_stokes(p * cpcs, unique)
    else:
        unique, gi = ch.generators_array[:1], np.zeros(len(ch), dtype=np.intp)
        stokes = (p * cpcs)[..., None, :]
    n_bins = stokes.shape[-3]
    if isinstance(sp.target_area, tuple) and len(sp.target_area) != n_bins:
        raise Error(
            f"invalid speckle: target_area has {len(sp.target_area)} values but the profile has {n_bins} range "
            "bins (one area per bin, or a single value)"
        )
    m_pulse = np.asarray(sp.pulse_dof(instrument.aperture_diameter, instrument.wavelength, instrument.target_range,
                                      area), dtype=np.float64)
    share = np.array([ch.pulse_share[int(np.flatnonzero(gi == g)[0])] for g in range(len(unique))])
    dof = _speckle.accumulated_dof(m_pulse[..., None], instrument.n_pulses * share, sp.correlation)
    return stokes, gi, np.broadcast_to(np.asarray(dof, dtype=np.float64), stokes.shape[:-1])
def _record(lam: np.ndarray, bin_edges: np.ndarray, instrument: Instrument, rng: np.random.Generator) -> np.ndarray:
    """What the instrument records for expected counts ``lam`` (..., B, C): Poisson draws
    (one ``rng.poisson`` call) without a detector and an atmosphere, else
    :func:`pprender.inverse.detector.record`."""
    if instrument.detector is None and instrument.atmosphere is None:
        return rng.poisson(lam).astype(np.int64)
    return record(
        lam, instrument.pulses, rng, detector=instrument.detector, atmosphere=instrument.atmosphere,
        bin_edges=bin_edges, groups=pulse_groups(instrument.channels.generators_array),  # type: ignore[union-attr]
    )


def measure(
    profile: Any,
    instrument: Instrument,
    *,
    bin_edges: Any = None,
    seed: int | None = None,
    rng: np.random.Generator | None = None,
) -> Measurement:
    """Simulate a measurement: expected counts (:func:`expected_counts`) and Poisson shot noise.

    The noise is drawn with ``numpy.random.default_rng(seed)`` (or ``rng``; not both). With
    an ``instrument.detector`` or ``instrument.atmosphere`` the counts are what that
    receiver records (:func:`pprender.inverse.detector.record`: a dead time's first-photon
    counts, a linear APD's float photo-electron estimates, scintillation per pulse, the
    channels seeing the same transmitted pulses correlated through it); without them, the
    Poisson draws of earlier versions, bit for bit.

    With ``instrument.speckle`` (a :class:`~pprender.inverse.speckle.Speckle`): per range
    bin and transmitted state, a speckle coherency with the degrees of freedom of the
    ``Speckle`` accumulated over that state's pulses
    (:func:`~pprender.inverse.speckle.sample_intensity`; channels of one state see one
    field), the drawn intensities blurred by the jitter (:func:`jitter_matrix`), then
    Poisson counts with mean intensity plus background. The measurement's ``speckle_dof``
    records each count's marginal degrees of freedom (what the fits' likelihood needs).
    Without speckle (None) the draws are today's, bit for bit.

    Parameters
    ----------
    profile : RenderResult or array_like
        A :class:`pprender.RenderResult` (with a profile, rendered at the instrument's
        wavelength) or an array ``(..., B, 4, 4)`` / ``(..., B, 4)`` with ``bin_edges``
        (module docstring).
    instrument : Instrument
        The instrument.
    bin_edges : array_like, optional
        (B + 1,) range bin edges of an array ``profile`` (m).
    seed : int, optional
        Seed of ``numpy.random.default_rng``, an integer >= 0.
    rng : numpy.random.Generator, optional
        The generator to draw with, instead of ``seed``.

    Returns
    -------
    Measurement
        On the profile's bins.

    Raises
    ------
    pprender.Error
        For both ``seed`` and ``rng``, an invalid profile (as :func:`expected_counts`),
        expected counts beyond the largest Poisson mean that can be drawn (9.2e18, int64
        counts), a detector dead time shorter than the range gate of the bins (not
        modelled: :meth:`pprender.inverse.detector.Detector.regime`), or, with a
        ``Speckle`` that takes the illuminated area from the render, a profile without it
        (an array, or a RenderResult rendered without ``"illuminated_area"`` or
        ``("mueller", "range")``: render with ``outputs=("profile", "illuminated_area")``
        or ``("profile", "mueller", "range")`` or give ``Speckle(target_area=...)`` or
        ``Speckle(dof=...)``), or a per-bin ``target_area`` whose length is not the number
        of bins.

    Warns
    -----
    PileUpWarning
        Without a detector, or with a photon counter without dead time: where a channel
        expects more than :data:`PILE_UP_THRESHOLD` counts per bin and per pulse (signal
        plus background): the Poisson model ignores the dead time and pile-up that distort
        such counts (module docstring). The measurement is still returned.
    SaturationWarning
        A linear-mode APD asked for more photo-electrons per bin and pulse than its
        saturation level (:class:`pprender.inverse.detector.SaturationWarning`).
    """
    if seed is not None and rng is not None:
        raise Error("invalid seed/rng: give one of them, not both")
    if rng is None:
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
            raise Error(f"invalid seed = {seed!r}: an integer >= 0")
        rng = np.random.default_rng(seed)
    elif not isinstance(rng, np.random.Generator):
        raise Error(f"invalid rng of type {type(rng).__name__}: expected numpy.random.Generator")
    if not isinstance(instrument, Instrument):
        raise Error(f"invalid instrument of type {type(instrument).__name__}: expected pprender.instrument.Instrument")
    p, e, mueller = _profile_and_edges(profile, bin_edges, instrument)
    result = profile if isinstance(profile, RenderResult) else None
    if isinstance(profile, RenderResult):
        profile = p
    sig = expected_counts(profile, instrument, bin_edges=e, background=False)
    bg = instrument.background_counts(e)
    lam = sig + bg
    top = float(np.max(lam, initial=0.0))
    if not top <= _POISSON_MAX:
        raise Error(
            f"invalid profile/instrument: up to {top:.3g} expected counts in a bin, more than the largest "
            f"Poisson mean that can be drawn ({_POISSON_MAX:.3g}, int64 counts); lower the pulse energy"
        )
    if instrument.detector is None or instrument.detector.is_poisson:
        _warn_pile_up(lam, instrument)
    dof_c = None
    if instrument.speckle is None:
        counts = _record(lam, e, instrument, rng)
    else:
        area = None
        sp = instrument.speckle
        if sp.source == "render" and result is not None and (
            getattr(result, "illuminated_area", None) is not None
            or result.range is not None
            and (result.mueller is not None or result.stokes is not None or result.intensity is not None)
        ):
            # the render's own per-bin area (outputs with "illuminated_area"; a profile-only
            # render can give it), else the one derived from its images
            area = _speckle.illuminated_area(result, sp.pulse_fwhm)
        stokes, gi, dof = _speckle_state(p, mueller, instrument, area)
        rows = instrument.channels.rows  # type: ignore[union-attr]
        inten = _speckle.sample_intensity(stokes, rows, gi, dof, rng)
        dof_c = _speckle.channel_dof(stokes, rows, gi, dof)
        if instrument.jitter > 0:
            # the blur moves detected photons between bins: blur the drawn intensities
            k = jitter_matrix(e, e, instrument.jitter_range)
            s_src = np.clip(np.einsum("ci,...ci->...c", rows, stokes[..., gi, :]), 0.0, None)
            dof_c = _speckle.blurred_dof(k, s_src, dof_c)
            inten = np.einsum("ji,...ic->...jc", k, inten)
        top = float(np.max(inten + bg, initial=0.0))
        if not top <= _POISSON_MAX:
            raise Error(
                f"invalid profile/instrument: a speckle intensity of {top:.3g} counts in a bin, more than the largest "
                f"Poisson mean that can be drawn ({_POISSON_MAX:.3g}, int64 counts); lower the pulse energy"
            )
        counts = rng.poisson(inten + bg).astype(np.int64)
    return Measurement(
        counts=counts,
        expected=lam,
        signal=sig,
        background=bg,
        bin_edges=e.copy(),
        channel_names=instrument.channel_names,
        instrument=instrument,
        seed=None if seed is None else int(seed),
        speckle_dof=dof_c,
    )
