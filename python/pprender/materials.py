"""Named spacecraft materials: complex refractive index, diffuse albedo, default roughness.

``eta = n + i k`` (physics convention, ``k >= 0`` absorbing) at the two Nd:YAG laser
lines, 532 nm and 1064 nm, in vacuum. Wavelengths are in metres. Only these two
wavelengths are tabulated: any other value (more than 1 nm away) raises
:class:`pprender.Error`.

Metals and clear dielectrics come from one published dataset each, read from the
refractiveindex.info database (CC0; https://refractiveindex.info, page named per row).
Tabulated datasets are interpolated linearly in wavelength between the two tabulated
points that bracket 532 nm or 1064 nm; Malitson's Sellmeier formula is evaluated
exactly. ``R0`` is the normal-incidence reflectance ``|(eta-1)/(eta+1)|^2``.

==============  =====================  =====================  ======  =======  ==================================
name            eta at 532 nm          eta at 1064 nm         R0 532  R0 1064  source
==============  =====================  =====================  ======  =======  ==================================
aluminium       0.9388 + 6.4195i       1.3763 + 10.2449i      0.917   0.950    Rakic 1995, Appl. Opt. 34, 4755
gold            0.5439 + 2.2309i       0.2585 + 6.9654i       0.704   0.979    Johnson & Christy 1972, PRB 6, 4370
silver          0.0540 + 3.4290i       0.0400 + 7.6097i       0.983   0.997    Johnson & Christy 1972, PRB 6, 4370
copper          1.1159 + 2.5956i       0.3508 + 7.0333i       0.602   0.973    Johnson & Christy 1972, PRB 6, 4370
titanium        2.4793 + 3.3511i       3.4654 + 4.0085i       0.575   0.615    Johnson & Christy 1974, PRB 9, 5056
fused_silica    1.4607                 1.4496                 0.035   0.034    Malitson 1965, JOSA 55, 1205
kapton          1.8360 + 3.28e-4i      1.7682 + 4.19e-5i      0.087   0.077    French et al. 2009, IEEE PVSC 34
white_paint     1.4607 (binder)        1.4496 (binder)        0.035   0.034    binder: ESTIMATE (silica proxy)
black_paint     1.50 (binder)          1.50 (binder)          0.040   0.040    binder: ESTIMATE (PU ~1.5)
==============  =====================  =====================  ======  =======  ==================================

Diffuse (Lambertian) albedo ``rho_d``: 0 for metals, fused silica and Kapton; white
paint 0.90 and black paint 0.02 at both wavelengths. Both paint albedos are ENGINEERING
ESTIMATES derived from published solar absorptances (no spectral reflectance at
532/1064 nm was found in the sources available); see the ``white_paint`` and
``black_paint`` notes below and docs/materials.md for the reasoning.

``rho_d`` is the albedo of the body under the binder's specular surface: pprender's
diffuse term is ``rho_d (1 - E_s(wi)) (1 - E_s(wo)) / (pi (1 - E_s,avg))`` with ``E_s``
the specular layer's albedo, so a measured directional-hemispherical reflectance
``R_dh`` corresponds to ``rho_d ~ (R_dh - R0) / (1 - R0)``.

Per-material notes and sources (full references, spreads between datasets, and the
interpolation brackets are in docs/materials.md):

- aluminium: A. D. Rakic, "Algorithm for the determination of intrinsic optical
  constants of metal films: application to aluminum", Appl. Opt. 34, 4755-4767 (1995),
  doi:10.1364/AO.34.004755; refractiveindex.info/?shelf=main&book=Al&page=Rakic.
  Spread over 7 datasets in the database: R0 0.915-0.923 at 532 nm, 0.947-0.963 at
  1064 nm (Rakic lies inside both).
- gold, silver, copper: P. B. Johnson and R. W. Christy, "Optical constants of the
  noble metals", Phys. Rev. B 6, 4370-4379 (1972), doi:10.1103/PhysRevB.6.4370;
  refractiveindex.info/?shelf=main&book=Au|Ag|Cu&page=Johnson. J&C tabulate n to two
  decimals; their silver n in the near IR is at the low end of later work (R0 at
  1064 nm from other bulk-like datasets 0.979-0.995).
- titanium: P. B. Johnson and R. W. Christy, "Optical constants of transition metals",
  Phys. Rev. B 9, 5056-5070 (1974), doi:10.1103/PhysRevB.9.5056;
  refractiveindex.info/?shelf=main&book=Ti&page=Johnson. Palm et al. 2018 (annealed
  thin film) give a much lower R0 (0.40 / 0.49); Rakic 1998 and Mash agree with J&C.
- fused_silica (stand-in for solar-cell cover glass): I. H. Malitson, "Interspecimen
  comparison of the refractive index of fused silica", J. Opt. Soc. Am. 55, 1205-1208
  (1965), doi:10.1364/JOSA.55.001205; refractiveindex.info/?shelf=main&book=SiO2&page=Malitson.
  k = 0: Malitson gives n only, and bulk absorption of fused silica at these wavelengths
  is negligible for a surface reflection (modelling choice). Real cover glasses
  (Ce-doped borosilicate, often AR-coated) differ by a few 0.01 in n.
- kapton: R. H. French et al., "Optical properties of materials for concentrator
  photovoltaic systems", 34th IEEE PVSC, pp. 394-399 (2009),
  doi:10.1109/PVSC.2009.5411657 (Kapton HN, the MLI grade);
  refractiveindex.info/?shelf=other&book=Kapton&page=French. Arakawa et al. 1981
  (J. Appl. Phys. 52, 3579; Kapton H) give n = 1.760 / 1.725, i.e. R0 0.076 / 0.071.
- white_paint: a ZnO-pigmented potassium-silicate paint (Z-93 / AZ-93 class).
  Binder n: ENGINEERING ESTIMATE, fused silica (Malitson 1965) as a proxy for the
  cured silicate network (true value probably 1.45-1.50). rho_d = 0.90: ENGINEERING
  ESTIMATE from the published solar absorptance alpha_s = 0.15 (AZ-93 data sheet,
  AZ Technology) and 0.12 for silicate white paint (Fortescue, Swinerd & Stark,
  Spacecraft Systems Engineering, 4th ed., Wiley 2011, Table 11.3): ZnO absorbs
  below ~385 nm (8-10% of the solar spectrum), which leaves 0.03-0.07 absorbed over
  0.4-2.5 um, i.e. R_dh ~ 0.91-0.95 there; taking the low end (margin for ageing), rho_d =
  (0.91 - 0.035)/0.965 ~ 0.90; uncertainty about +/-0.04, and it falls with
  UV/particle ageing in orbit.
- black_paint: a carbon-pigmented polyurethane paint (Aeroglaze/Chemglaze Z306 class).
  Binder n = 1.50: ENGINEERING ESTIMATE (cured polyurethanes are ~1.5; PMMA, a
  similar clear polymer, is 1.494 / 1.482). rho_d = 0.02: ENGINEERING ESTIMATE from
  alpha_s = 0.95 for polyurethane black paint (Fortescue et al. 2011, Table 11.3):
  R_dh ~ 0.05, of which ~0.04 is the binder's surface reflection, leaving
  rho_d ~ 0.01-0.03; carbon black absorbs nearly flat from 0.4 to 2.5 um, so the same
  value is used at both wavelengths.

Default roughness (:func:`get`, overridable; engineering choices, Beckmann
``alpha = sqrt(2) * rms slope``):

- aluminium: beckmann 0.10 -- machined/brushed alloy panel, rms slope ~4 deg.
- gold: beckmann 0.05 -- plated or vapour-deposited gold on a smooth substrate, near-mirror.
- silver: beckmann 0.05 -- vapour-deposited silver (OSR / silvered-film backing), near-mirror.
- copper: beckmann 0.10 -- machined or plated finish, like aluminium.
- titanium: beckmann 0.20 -- machined or bead-blasted Ti-alloy fittings are dull.
- fused_silica: beckmann 0.02 -- optically polished cover glass; width covers panel waviness.
- kapton: beckmann 0.15 -- the film is smooth but MLI blankets crinkle below mesh scale.
- white_paint: ggx 0.50 -- matte ceramic paint; GGX's long tail fits rough-surface glints.
- black_paint: ggx 0.50 -- flat (matte) polyurethane paint, same reasoning.

Orders >= 2: every Beckmann material with alpha in :data:`SURFACE_ALPHA` (0.05-1: the
defaults of aluminium, gold, silver, copper, titanium and kapton, and any of them at another
alpha there) takes them from paths traced on explicit Gaussian surfaces
(``pprender.Material``'s ``orders="surface"``: order 2 and orders 3-8 polarized, with the
surface's slope correlation; path banks traced once per machine and cached, 30-52 s per
roughness node up to 0.3 on 2 cores, longer above; ``get(name, autocorrelation="matern")``
takes banks of Matern-correlated surfaces instead, with the same slopes). The others keep the seed paper's
(``terms`` ``("single", "multiple")``: a fully depolarizing multiple term): fused_silica
(alpha 0.02, below the banks: there orders >= 2 exist only within a few degrees of grazing),
the GGX paints (the banks' surfaces are Gaussian, so Beckmann; the paints' return is mostly
their diffuse layer), and any material given ``alpha`` outside 0.05-1 or another
distribution. ``get(name, orders="seed")`` selects the seed's terms for any of them.

What the choice changes is measured in docs/grazing-backscatter.md: at 80 deg backscatter
the seed's aluminium returns 0.23 /sr from its multiple term and the surface orders
7.6e-5 /sr (gold 0.011 against 0; titanium 0.050 against 8.9e-6), and an explicit aluminium
surface of alpha 0.12 sent no ray of 1e6 back into a 0.1 rad cone at 70-80 deg
(docs/double-bounce.md section 6). Scored against explicit surfaces at alpha 0.3-1
(docs/surface-orders-reference.md), the surface orders' order 2 is within 10% in 141 of 167
rows (the seed's 58), their orders 3+ within 25% in 86 of 110 (the seed's 4), and the whole
return's depolarization index at backscatter within 0.03 in 64 of 66 (the seed's 42).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Tuple

from pprender import Error

__all__ = [
    "NAMES",
    "ALIASES",
    "WAVELENGTHS",
    "optical_constants",
    "diffuse_albedo",
    "material_kwargs",
    "get",
    "SURFACE_ALPHA",
]

#: The tabulated wavelengths in metres; a request must lie within ``_TOLERANCE`` of one.
WAVELENGTHS: Tuple[float, ...] = (532e-9, 1064e-9)
_TOLERANCE = 1e-9  # 1 nm

#: The Beckmann roughness over which :func:`get` takes orders >= 2 from the path banks
#: (``orders="surface"``: the banks' alpha nodes span it; tests/test_materials.py checks
#: that ``pprender.Material`` accepts its lower end and refuses just outside both).
SURFACE_ALPHA: Tuple[float, float] = (0.05, 1.0)

_SINGLE_MULTIPLE = ("single", "multiple")
_WITH_DIFFUSE = ("single", "multiple", "diffuse")


@dataclass(frozen=True)
class _Entry:
    # (n, k) per wavelength, same order as WAVELENGTHS.
    nk: Tuple[Tuple[float, float], Tuple[float, float]]
    albedo: Tuple[float, float]
    roughness: Mapping[str, Any]
    source: str
    notes: str = field(default="")


_TABLE: Dict[str, _Entry] = {
    # Rakic 1995, Appl. Opt. 34, 4755; linear interpolation between 516.6/563.6 nm and
    # 1033.2/1127.1 nm of refractiveindex.info main/Al/Rakic.
    "aluminium": _Entry(
        nk=((0.9388, 6.4195), (1.3763, 10.2449)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.10},
        source="Rakic 1995, Appl. Opt. 34, 4755 (refractiveindex.info main/Al/Rakic)",
    ),
    # Johnson & Christy 1972, PRB 6, 4370; interpolated between 520.9/548.6 nm and
    # 984/1088 nm (refractiveindex.info main/Au/Johnson).
    "gold": _Entry(
        nk=((0.5439, 2.2309), (0.2585, 6.9654)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.05},
        source="Johnson & Christy 1972, Phys. Rev. B 6, 4370 (refractiveindex.info main/Au/Johnson)",
    ),
    "silver": _Entry(
        nk=((0.0540, 3.4290), (0.0400, 7.6097)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.05},
        source="Johnson & Christy 1972, Phys. Rev. B 6, 4370 (refractiveindex.info main/Ag/Johnson)",
    ),
    "copper": _Entry(
        nk=((1.1159, 2.5956), (0.3508, 7.0333)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.10},
        source="Johnson & Christy 1972, Phys. Rev. B 6, 4370 (refractiveindex.info main/Cu/Johnson)",
    ),
    # Johnson & Christy 1974, PRB 9, 5056; interpolated between 521/549 nm and 984/1088 nm.
    "titanium": _Entry(
        nk=((2.4793, 3.3511), (3.4654, 4.0085)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.20},
        source="Johnson & Christy 1974, Phys. Rev. B 9, 5056 (refractiveindex.info main/Ti/Johnson)",
    ),
    # Malitson 1965 Sellmeier, evaluated at 0.532 and 1.064 um (n = 1.460706, 1.449631).
    "fused_silica": _Entry(
        nk=((1.4607, 0.0), (1.4496, 0.0)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.02},
        source="Malitson 1965, J. Opt. Soc. Am. 55, 1205 (refractiveindex.info main/SiO2/Malitson); k = 0 by choice",
    ),
    # French et al. 2009 (Kapton HN), 10 nm table, interpolated between 530/540 nm and
    # 1060/1070 nm.
    "kapton": _Entry(
        nk=((1.8360, 3.285e-4), (1.7682, 4.19e-5)),
        albedo=(0.0, 0.0),
        roughness={"distribution": "beckmann", "alpha": 0.15},
        source="French et al. 2009, 34th IEEE PVSC, 394 (refractiveindex.info other/Kapton/French)",
    ),
    "white_paint": _Entry(
        nk=((1.4607, 0.0), (1.4496, 0.0)),
        albedo=(0.90, 0.90),
        roughness={"distribution": "ggx", "alpha": 0.50},
        source="ENGINEERING ESTIMATE: binder n from fused silica (Malitson 1965) as a silicate proxy; "
        "albedo from alpha_s = 0.12-0.15 (AZ-93 data sheet; Fortescue et al. 2011, Table 11.3)",
        notes="ZnO / potassium-silicate paint (Z-93, AZ-93 class)",
    ),
    "black_paint": _Entry(
        nk=((1.50, 0.0), (1.50, 0.0)),
        albedo=(0.02, 0.02),
        roughness={"distribution": "ggx", "alpha": 0.50},
        source="ENGINEERING ESTIMATE: binder n = 1.50 (polyurethane ~1.5); "
        "albedo from alpha_s = 0.95 (Fortescue et al. 2011, Table 11.3)",
        notes="carbon-black / polyurethane paint (Aeroglaze or Chemglaze Z306 class)",
    ),
}

#: Canonical material names, in table order.
NAMES: Tuple[str, ...] = tuple(_TABLE)

#: Accepted alternative spellings, mapped to canonical names.
ALIASES: Mapping[str, str] = {"aluminum": "aluminium"}


def _canonical(name: object) -> str:
    if isinstance(name, str):
        key = name.strip().lower()
        key = ALIASES.get(key, key)
        if key in _TABLE:
            return key
    raise Error(
        f"invalid name = {name!r}: expected one of {', '.join(NAMES)}"
        f" (aliases: {', '.join(f'{a} -> {c}' for a, c in ALIASES.items())})"
    )


def _index(wavelength: object) -> int:
    wl = math.nan
    if not isinstance(wavelength, (str, bytes, bool)):
        try:
            wl = float(wavelength)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            pass
    if math.isfinite(wl):
        for i, w in enumerate(WAVELENGTHS):
            if abs(wl - w) <= _TOLERANCE * (1.0 + 1e-9):
                return i
    raise Error(
        f"invalid wavelength = {wavelength!r}: expected one of "
        f"{', '.join(f'{w * 1e9:.0f}e-9' for w in WAVELENGTHS)} (metres, within 1 nm)"
    )


def optical_constants(name: str, wavelength: float = 1064e-9) -> complex:
    """Complex refractive index ``eta = n + 1j*k`` (``k >= 0``) of a named material.

    For the paints this is the binder's index (the specular surface); the pigment enters
    through :func:`diffuse_albedo`. Sources per material: see the module docstring.

    Parameters
    ----------
    name : str
        A material name (:data:`NAMES`, or an alias in :data:`ALIASES`).
    wavelength : float, optional
        In metres, within 1 nm of 532e-9 or 1064e-9. Default 1064e-9.

    Returns
    -------
    complex
        ``eta``.

    Raises
    ------
    pprender.Error
        For an unknown ``name`` or an unsupported or non-finite ``wavelength``.
    """
    entry = _TABLE[_canonical(name)]
    n, k = entry.nk[_index(wavelength)]
    return complex(n, k)


def diffuse_albedo(name: str, wavelength: float = 1064e-9) -> float:
    """Lambertian albedo of the body under the specular surface.

    0 for metals and clear dielectrics. The paint values are engineering estimates (module
    docstring).

    Parameters
    ----------
    name : str
        A material name (:data:`NAMES`, or an alias in :data:`ALIASES`).
    wavelength : float, optional
        In metres, within 1 nm of 532e-9 or 1064e-9. Default 1064e-9.

    Returns
    -------
    float
        The albedo ``rho_d``.

    Raises
    ------
    pprender.Error
        For an unknown ``name`` or an unsupported ``wavelength``.
    """
    entry = _TABLE[_canonical(name)]
    return float(entry.albedo[_index(wavelength)])


def material_kwargs(name: str, wavelength: float = 1064e-9, **kwargs: Any) -> Dict[str, Any]:
    """The keyword arguments :func:`get` passes to ``pprender.Material``.

    Starts from ``eta``, ``diffuse_albedo``, ``name`` (canonical, so "aluminum" gives
    "aluminium"), ``wavelength`` (the one given, which the constants are for) and the
    material's default roughness, then applies ``kwargs`` (which win; ``name`` itself cannot
    be overridden here). A caller's ``m`` replaces the default ``alpha`` and vice versa.
    Unless the caller gives ``terms``, they are ``("single", "multiple", "diffuse")`` when the
    resulting ``diffuse_albedo`` is positive and ``("single", "multiple")`` otherwise. Unless
    the caller gives ``orders``, it is ``"surface"`` when the resulting material is Beckmann
    with ``alpha`` (or the ``alpha`` its ``m`` maps to) in :data:`SURFACE_ALPHA`, and
    ``"seed"`` otherwise (module docstring): decided once per material, from its parameters.

    Parameters
    ----------
    name : str
        A material name (:data:`NAMES`, or an alias in :data:`ALIASES`).
    wavelength : float, optional
        In metres, within 1 nm of 532e-9 or 1064e-9. Default 1064e-9.
    **kwargs
        Overrides of the keyword arguments.

    Returns
    -------
    dict
        Keyword arguments of ``pprender.Material``.

    Raises
    ------
    pprender.Error
        For an unknown ``name`` or an unsupported ``wavelength``.
    """
    key = _canonical(name)
    i = _index(wavelength)
    entry = _TABLE[key]
    params: Dict[str, Any] = {
        "eta": complex(*entry.nk[i]),
        "diffuse_albedo": float(entry.albedo[i]),
        "name": key,
        # The material is labelled with the wavelength its constants are for, so that a
        # sensor at another wavelength is refused by pprender.render.
        "wavelength": float(wavelength),  # type: ignore[arg-type]
    }
    defaults = dict(entry.roughness)
    if "m" in kwargs:
        defaults.pop("alpha", None)
    if "alpha" in kwargs:
        defaults.pop("m", None)
    params.update(defaults)
    params.update(kwargs)
    if "terms" not in kwargs:
        albedo = params.get("diffuse_albedo")
        positive = isinstance(albedo, (int, float)) and albedo > 0.0
        params["terms"] = _WITH_DIFFUSE if positive else _SINGLE_MULTIPLE
    if "orders" not in kwargs:
        params["orders"] = _default_orders(params)
    return params


def _default_orders(params: Mapping[str, Any]) -> str:
    """``"surface"`` for a Beckmann material with alpha in :data:`SURFACE_ALPHA`, else
    ``"seed"`` (module docstring). Values that are not numbers are left for
    ``pprender.Material`` to refuse, naming them."""
    if params.get("distribution", "blinn_phong") != "beckmann":
        return "seed"
    alpha, m = params.get("alpha"), params.get("m")
    number = (int, float)
    if isinstance(m, number) and not isinstance(m, bool) and alpha is None:
        from pprender import Material  # lazy: Material is optional at import time

        try:  # the core's map of m to alpha (a single-term material builds in microseconds)
            alpha = Material("beckmann", m=m, terms=("single",)).alpha
        except Error:
            return "seed"
    if isinstance(alpha, number) and not isinstance(alpha, bool):
        lo, hi = SURFACE_ALPHA
        if lo <= alpha <= hi:
            return "surface"
    return "seed"


def get(name: str, wavelength: float = 1064e-9, **kwargs: Any) -> Any:
    """Build a ``pprender.Material`` for a named material at a laser wavelength.

    ``eta`` and ``diffuse_albedo`` come from :func:`optical_constants` and
    :func:`diffuse_albedo`; the default roughness (module docstring) and ``terms`` are
    overridden by ``kwargs`` (see :func:`material_kwargs`), e.g.
    ``get("gold", 532e-9, alpha=0.2)`` or ``get("white_paint", distribution="beckmann")``.

    Parameters
    ----------
    name : str
        A material name (:data:`NAMES`, or an alias in :data:`ALIASES`).
    wavelength : float, optional
        In metres, within 1 nm of 532e-9 or 1064e-9. Default 1064e-9.
    **kwargs
        Keyword arguments of ``pprender.Material`` overriding the defaults.

    Returns
    -------
    pprender.Material
        The material, named and labelled with ``wavelength``.

    Raises
    ------
    pprender.Error
        For an unknown ``name`` or an unsupported ``wavelength``.
    """
    from pprender import Material  # lazy: Material is optional at import time

    return Material(**material_kwargs(name, wavelength, **kwargs))
