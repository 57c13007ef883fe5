"""Tests of pprender.materials: published optical constants at 532 and 1064 nm.

No network: the oracles below are tabulated points copied from the cited datasets
(refractiveindex.info database files, CC0) and published reflectance ranges.
"""

from __future__ import annotations

import cmath
import math

import pytest

import pprender
from pprender import materials

WL = (532e-9, 1064e-9)
ALL = [(name, wl) for name in materials.NAMES for wl in WL]


def r0(eta: complex) -> float:
    """Normal-incidence reflectance |(eta-1)/(eta+1)|^2."""
    return abs((eta - 1) / (eta + 1)) ** 2


def lerp(x: float, p0: tuple, p1: tuple) -> tuple:
    """Linear interpolation in wavelength between two tabulated (wl, n, k) rows."""
    t = (x - p0[0]) / (p1[0] - p0[0])
    return tuple(a + t * (b - a) for a, b in zip(p0[1:], p1[1:]))


# --------------------------------------------------------------------------- names


def test_names_are_the_required_canonical_set():
    assert materials.NAMES == (
        "aluminium",
        "gold",
        "silver",
        "copper",
        "titanium",
        "fused_silica",
        "kapton",
        "white_paint",
        "black_paint",
    )
    assert isinstance(materials.NAMES, tuple)


@pytest.mark.parametrize("wl", WL)
def test_aluminum_alias(wl):
    assert materials.optical_constants("aluminum", wl) == materials.optical_constants("aluminium", wl)
    assert materials.diffuse_albedo("aluminum", wl) == materials.diffuse_albedo("aluminium", wl)
    assert materials.material_kwargs("aluminum", wl)["name"] == "aluminium"


def test_default_wavelength_is_1064nm():
    for name in materials.NAMES:
        assert materials.optical_constants(name) == materials.optical_constants(name, 1064e-9)
        assert materials.diffuse_albedo(name) == materials.diffuse_albedo(name, 1064e-9)


@pytest.mark.parametrize("wl", [532e-9 + 0.9e-9, 532e-9 - 1e-9, 1064e-9 + 1e-9, 1064.4e-9])
def test_wavelength_within_1nm_is_accepted(wl):
    ref = 532e-9 if wl < 800e-9 else 1064e-9
    assert materials.optical_constants("gold", wl) == materials.optical_constants("gold", ref)


# --------------------------------------------------------------------------- validity


@pytest.mark.parametrize("name,wl", ALL)
def test_eta_finite_physical(name, wl):
    eta = materials.optical_constants(name, wl)
    assert isinstance(eta, complex)
    assert math.isfinite(eta.real) and math.isfinite(eta.imag)
    assert eta.real > 0.0
    assert eta.imag >= 0.0


@pytest.mark.parametrize("name,wl", ALL)
def test_diffuse_albedo_range(name, wl):
    a = materials.diffuse_albedo(name, wl)
    assert isinstance(a, float)
    assert 0.0 <= a <= 1.0
    if name in ("white_paint", "black_paint"):
        assert a > 0.0
    else:
        assert a == 0.0  # metals and clear dielectrics


# ------------------------------------------------------- oracle: the cited datasets

# Bracketing rows (wavelength um, n, k) copied from the refractiveindex.info database
# files of the cited datasets; the module must equal their linear interpolation
# (4 decimals stored, so 1e-4 absolute; Kapton k relative).
BRACKETS = {
    # Rakic 1995, Appl. Opt. 34, 4755 -- database/data/main/Al/nk/Rakic.yml
    ("aluminium", 532e-9): ((0.5166, 0.8734, 6.2418), (0.56357, 1.0728, 6.7839)),
    ("aluminium", 1064e-9): ((1.0332, 1.3998, 9.8914), (1.1271, 1.3281, 10.969)),
    # Johnson & Christy 1972, PRB 6, 4370 -- main/{Au,Ag,Cu}/nk/Johnson.yml
    ("gold", 532e-9): ((0.5209, 0.62, 2.081), (0.5486, 0.43, 2.455)),
    ("gold", 1064e-9): ((0.984, 0.22, 6.35), (1.088, 0.27, 7.15)),
    ("silver", 532e-9): ((0.5209, 0.05, 3.324), (0.5486, 0.06, 3.586)),
    ("silver", 1064e-9): ((0.984, 0.04, 6.992), (1.088, 0.04, 7.795)),
    ("copper", 532e-9): ((0.5209, 1.18, 2.608), (0.5486, 1.02, 2.577)),
    ("copper", 1064e-9): ((0.984, 0.32, 6.421), (1.088, 0.36, 7.217)),
    # Johnson & Christy 1974, PRB 9, 5056 -- main/Ti/nk/Johnson.yml
    ("titanium", 532e-9): ((0.521, 2.44, 3.30), (0.549, 2.54, 3.43)),
    ("titanium", 1064e-9): ((0.984, 3.35, 3.97), (1.088, 3.50, 4.02)),
    # French et al. 2009 (Kapton HN) -- other/commercial polymers/Kapton/nk/French.yml
    ("kapton", 532e-9): ((0.53, 1.83685, 0.00034601), (0.54, 1.83256, 0.000258291)),
    ("kapton", 1064e-9): ((1.06, 1.76937, 4.16168e-05), (1.07, 1.76633, 4.23808e-05)),
}


@pytest.mark.parametrize("key", sorted(BRACKETS))
def test_matches_linear_interpolation_of_cited_table(key):
    name, wl = key
    n, k = lerp(wl * 1e6, *BRACKETS[key])
    eta = materials.optical_constants(name, wl)
    assert eta.real == pytest.approx(n, abs=1e-4)
    assert eta.imag == pytest.approx(k, rel=2e-3, abs=1e-4 if k > 1e-2 else 1e-7)


def malitson(wl_um: float) -> float:
    """Malitson 1965 Sellmeier formula for fused silica (JOSA 55, 1205)."""
    l2 = wl_um**2
    terms = ((0.6961663, 0.0684043), (0.4079426, 0.1162414), (0.8974794, 9.896161))
    return math.sqrt(1.0 + sum(b * l2 / (l2 - c * c) for b, c in terms))


@pytest.mark.parametrize("wl", WL)
def test_fused_silica_is_malitson(wl):
    eta = materials.optical_constants("fused_silica", wl)
    assert eta.real == pytest.approx(malitson(wl * 1e6), abs=1e-4)
    assert eta.imag == 0.0
    # Textbook check values of the same formula: 1.4607 at 532 nm, 1.4496 at 1064 nm.
    assert eta.real == pytest.approx({532e-9: 1.4607, 1064e-9: 1.4496}[wl], abs=1e-4)


# ------------------------------------------- normal-incidence reflectance, published

# (low, high) bounds on R0 = |(eta-1)/(eta+1)|^2. Each range is the spread of the
# bulk-like datasets in the refractiveindex.info database (computed from their n, k),
# widened by about 0.01; the chosen dataset lies inside it.
R0_RANGES = {
    # Al: 7 datasets (Rakic 1995, Rakic 1998 BB/LD, Hagemann, Mathewson, McPeak, Cheng)
    # give 0.915-0.923 at 532 nm; at 1064 nm 0.947-0.963 (incl. Ordal). "Al ~0.92 at 532".
    ("aluminium", 532e-9): (0.90, 0.935),
    ("aluminium", 1064e-9): (0.935, 0.975),
    # Au: bulk-like datasets (J&C, Hagemann, McPeak, Olmon, Babar, Magnozzi, Yakubovsky
    # 117 nm, Rakic 1998) 0.61-0.77 at 532 nm; 0.969-0.991 at 1064 nm ("Au ~0.98").
    ("gold", 532e-9): (0.60, 0.80),
    ("gold", 1064e-9): (0.96, 0.995),
    # Ag: 0.95-0.99 at 532 nm (J&C, McPeak, Babar, Yang, Jiang, Rakic 1998; Hagemann
    # 0.925); 0.979-0.997 at 1064 nm in all bulk-like datasets ("Ag > 0.98").
    ("silver", 532e-9): (0.94, 0.995),
    ("silver", 1064e-9): (0.98, 0.999),
    # Cu: 0.56-0.66 at 532 nm (J&C, Hagemann, McPeak, Ordal, Querry, Babar, Rakic BB;
    # Rakic LD 0.73); 0.957-0.993 at 1064 nm.
    ("copper", 532e-9): (0.55, 0.75),
    ("copper", 1064e-9): (0.95, 0.995),
    # Ti: 0.53-0.60 at 532 nm (J&C 1974, Mash, Rakic 1998 BB/LD); 0.55-0.62 at 1064 nm
    # (+ Ordal). Palm et al. 2018 (annealed 200 nm film) is lower, 0.40 / 0.49.
    ("titanium", 532e-9): (0.50, 0.62),
    ("titanium", 1064e-9): (0.54, 0.65),
    # Fused silica: n = 1.45-1.46 (Malitson, Arosa, Franta) gives R0 = 0.034-0.035.
    ("fused_silica", 532e-9): (0.033, 0.037),
    ("fused_silica", 1064e-9): (0.032, 0.036),
    # Kapton: Arakawa 1981 n = 1.760/1.725 -> 0.076/0.071; French 2009 1.836/1.768 ->
    # 0.087/0.077.
    ("kapton", 532e-9): (0.07, 0.09),
    ("kapton", 1064e-9): (0.065, 0.085),
    # Paint binders are clear polymers/silicates, n = 1.40-1.55 -> R0 = 0.028-0.047.
    ("white_paint", 532e-9): (0.028, 0.047),
    ("white_paint", 1064e-9): (0.028, 0.047),
    ("black_paint", 532e-9): (0.028, 0.047),
    ("black_paint", 1064e-9): (0.028, 0.047),
}


def test_every_name_has_a_reflectance_range():
    assert set(R0_RANGES) == set(ALL)


@pytest.mark.parametrize("key", sorted(R0_RANGES))
def test_normal_incidence_reflectance_in_published_range(key):
    lo, hi = R0_RANGES[key]
    r = r0(materials.optical_constants(*key))
    assert lo <= r <= hi, f"{key}: R0 = {r:.4f} not in [{lo}, {hi}]"


def test_reflectance_spot_values():
    # The values quoted in the brief and in the docs, to their stated precision.
    assert r0(materials.optical_constants("aluminium", 532e-9)) == pytest.approx(0.92, abs=0.01)
    assert r0(materials.optical_constants("gold", 1064e-9)) == pytest.approx(0.98, abs=0.01)
    assert r0(materials.optical_constants("silver", 1064e-9)) > 0.98
    assert r0(materials.optical_constants("fused_silica", 532e-9)) == pytest.approx(0.035, abs=0.001)


@pytest.mark.parametrize("name", ["aluminium", "gold", "silver", "copper"])
def test_free_electron_metals_reflect_more_in_the_near_ir(name):
    # Drude-like metals: R0 rises from 532 to 1064 nm (all datasets agree).
    assert r0(materials.optical_constants(name, 1064e-9)) > r0(materials.optical_constants(name, 532e-9))


@pytest.mark.parametrize("name", ["fused_silica", "kapton"])
def test_normal_dispersion(name):
    # Transparent region: n decreases with wavelength.
    assert materials.optical_constants(name, 532e-9).real > materials.optical_constants(name, 1064e-9).real


# ---------------------------------------------------------------- paint albedos

# Solar absorptance alpha_s: silicate white paint 0.12, AZ-93 0.15 (AZ Technology data
# sheet), polyurethane black paint 0.95 (Fortescue, Swinerd & Stark 2011, Table 11.3).
# With pprender's diffuse term the directional-hemispherical reflectance at normal
# incidence is about R0 + (1 - R0) rho_d; it must be consistent with 1 - alpha_s over
# the 0.4-2.5 um band (white: ZnO absorbs the ~8% of sunlight below 385 nm, so the
# in-band reflectance is above 1 - alpha_s).


@pytest.mark.parametrize("wl", WL)
def test_white_paint_albedo_consistent_with_solar_absorptance(wl):
    eta = materials.optical_constants("white_paint", wl)
    rho = materials.diffuse_albedo("white_paint", wl)
    r_dh = r0(eta) + (1 - r0(eta)) * rho
    assert 0.85 <= r_dh <= 0.95


@pytest.mark.parametrize("wl", WL)
def test_black_paint_albedo_consistent_with_solar_absorptance(wl):
    eta = materials.optical_constants("black_paint", wl)
    rho = materials.diffuse_albedo("black_paint", wl)
    r_dh = r0(eta) + (1 - r0(eta)) * rho
    assert 0.04 <= r_dh <= 0.08  # alpha_s = 0.92-0.95


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "wl", [633e-9, 1550e-9, 530e-9, 0.0, -532e-9, 532.0, 1064.0, math.nan, math.inf, -math.inf]
)
def test_unsupported_wavelength_raises(wl):
    with pytest.raises(pprender.Error, match="wavelength"):
        materials.optical_constants("gold", wl)
    with pytest.raises(pprender.Error, match="wavelength"):
        materials.diffuse_albedo("gold", wl)
    with pytest.raises(pprender.Error, match="wavelength"):
        materials.material_kwargs("gold", wl)


def test_wavelength_error_lists_available_values():
    with pytest.raises(pprender.Error, match="wavelength") as info:
        materials.optical_constants("silver", 633e-9)
    msg = str(info.value)
    assert "532e-9" in msg and "1064e-9" in msg


@pytest.mark.parametrize("wl", ["532e-9", None, 1j, object()])
def test_non_numeric_wavelength_raises(wl):
    with pytest.raises(pprender.Error, match="wavelength"):
        materials.optical_constants("gold", wl)


@pytest.mark.parametrize("name", ["plutonium", "", "gold ", None, 3, "alu"])
def test_unknown_name_raises(name):
    if name == "gold ":  # surrounding whitespace and case are forgiven
        assert materials.optical_constants(name) == materials.optical_constants("gold")
        return
    with pytest.raises(pprender.Error, match="name") as info:
        materials.optical_constants(name)
    for n in materials.NAMES:
        assert n in str(info.value)
    with pytest.raises(pprender.Error, match="name"):
        materials.diffuse_albedo(name)
    with pytest.raises(pprender.Error, match="name"):
        materials.get(name)


def test_error_is_a_value_error():
    with pytest.raises(ValueError):
        materials.optical_constants("unobtainium")


# ------------------------------------------------------------- Material kwargs


@pytest.mark.parametrize("name,wl", ALL)
def test_material_kwargs_defaults(name, wl):
    kw = materials.material_kwargs(name, wl)
    assert kw["eta"] == materials.optical_constants(name, wl)
    assert kw["diffuse_albedo"] == materials.diffuse_albedo(name, wl)
    assert kw["name"] == name
    assert kw["distribution"] in ("blinn_phong", "beckmann", "ggx")
    assert ("alpha" in kw) != ("m" in kw)
    if kw["diffuse_albedo"] > 0:
        assert kw["terms"] == ("single", "multiple", "diffuse")
    else:
        assert kw["terms"] == ("single", "multiple")


def test_paints_get_the_diffuse_term():
    for name in ("white_paint", "black_paint"):
        assert "diffuse" in materials.material_kwargs(name)["terms"]


def test_material_kwargs_overrides():
    kw = materials.material_kwargs("gold", 532e-9, alpha=0.3, shadowing="smith")
    assert kw["alpha"] == 0.3 and kw["shadowing"] == "smith"
    assert kw["distribution"] == "beckmann"
    # m replaces the default alpha (Material refuses both).
    kw = materials.material_kwargs("gold", distribution="blinn_phong", m=200.0)
    assert kw["m"] == 200.0 and "alpha" not in kw and kw["distribution"] == "blinn_phong"
    # Caller's terms win; a caller's zero albedo drops the default diffuse term.
    kw = materials.material_kwargs("white_paint", terms=("single",))
    assert kw["terms"] == ("single",)
    kw = materials.material_kwargs("white_paint", diffuse_albedo=0.0)
    assert kw["terms"] == ("single", "multiple")
    # A caller's positive albedo on a metal turns the diffuse term on.
    kw = materials.material_kwargs("aluminium", diffuse_albedo=0.1)
    assert kw["terms"] == ("single", "multiple", "diffuse")
    # eta can be overridden too.
    kw = materials.material_kwargs("kapton", eta=1.7 + 0j)
    assert kw["eta"] == 1.7 and kw["name"] == "kapton"


# Which orders >= 2 each material gets (module docstring): "surface" for a Beckmann
# material with alpha in SURFACE_ALPHA, "seed" otherwise, decided from the parameters.
SURFACE_BY_DEFAULT = ("aluminium", "gold", "silver", "copper", "titanium", "kapton")


@pytest.mark.parametrize("name", materials.NAMES)
def test_default_orders(name):
    kw = materials.material_kwargs(name)
    assert kw["orders"] == ("surface" if name in SURFACE_BY_DEFAULT else "seed")


def test_default_orders_follow_the_parameters():
    lo, hi = materials.SURFACE_ALPHA
    kw = materials.material_kwargs
    assert kw("aluminium", alpha=lo)["orders"] == "surface"
    assert kw("aluminium", alpha=hi)["orders"] == "surface"
    assert kw("aluminium", alpha=lo * 0.999)["orders"] == "seed"
    assert kw("aluminium", alpha=hi * 1.001)["orders"] == "seed"
    # fused silica's own 0.02 is below the banks; at 0.1 it gets them
    assert kw("fused_silica", alpha=0.1)["orders"] == "surface"
    # another distribution keeps the seed's; a GGX paint made Beckmann gets the banks
    assert kw("gold", distribution="ggx")["orders"] == "seed"
    assert kw("gold", distribution="blinn_phong", m=100.0)["orders"] == "seed"
    assert kw("white_paint", distribution="beckmann")["orders"] == "surface"
    # a Beckmann m maps to alpha = sqrt(2 / (m + 2)): m = 20 -> 0.30, m = 1e4 -> 0.014
    assert kw("gold", m=20.0)["orders"] == "surface"
    assert kw("gold", m=1e4)["orders"] == "seed"
    # the caller's orders win, and a bad value is left for Material to refuse
    assert kw("gold", orders="seed")["orders"] == "seed"
    assert kw("gold", alpha="rough")["orders"] == "seed"


def test_surface_alpha_is_the_banks_range():
    """SURFACE_ALPHA is a copy of the banks' node range: Material must accept its lower end
    and refuse just outside both ends (else get() would build materials that fail, or
    give the seed's orders where the banks exist)."""
    lo, hi = materials.SURFACE_ALPHA
    for alpha in (lo * (1 - 1e-9), hi * (1 + 1e-9)):
        with pytest.raises(pprender.Error, match=r"alpha.*\[0\.05, 1\]"):
            pprender.Material("beckmann", alpha=alpha, eta=1.5, orders="surface")
    m = materials.get("gold", alpha=lo)
    assert m.orders == "surface" and m.alpha == lo


def test_material_kwargs_does_not_share_state():
    a = materials.material_kwargs("gold")
    a["alpha"] = 99.0
    assert materials.material_kwargs("gold")["alpha"] == 0.05


# ------------------------------------------- get (needs pprender.Material)


@pytest.mark.parametrize("name,wl", ALL)
def test_get_builds_a_material(name, wl):
    mat = materials.get(name, wl)
    assert isinstance(mat, pprender.Material)
    kw = materials.material_kwargs(name, wl)
    assert mat.eta == kw["eta"] == materials.optical_constants(name, wl)
    assert mat.diffuse_albedo == materials.diffuse_albedo(name, wl)
    assert mat.name == name
    assert mat.distribution == kw["distribution"]
    assert mat.alpha == pytest.approx(kw["alpha"])
    assert tuple(mat.terms) == kw["terms"]
    assert ("diffuse" in tuple(mat.terms)) == (name in ("white_paint", "black_paint"))
    assert mat.orders == kw["orders"]
    assert ('orders="surface"' in repr(mat)) == (name in SURFACE_BY_DEFAULT)


def test_get_alias_and_overrides():
    al = materials.get("aluminum", 532e-9)
    assert isinstance(al, pprender.Material) and al.name == "aluminium"
    assert materials.get("gold", alpha=0.3).alpha == pytest.approx(0.3)
    bp = materials.get("gold", distribution="blinn_phong", m=100.0)
    assert bp.distribution == "blinn_phong" and bp.m == pytest.approx(100.0)
    assert isinstance(materials.get("titanium", distribution="ggx"), pprender.Material)
    assert isinstance(materials.get("white_paint", diffuse_albedo=0.0), pprender.Material)
    assert isinstance(materials.get("black_paint", 532e-9, terms=("single", "diffuse")), pprender.Material)


def test_get_validates_through_material():
    # Bad overrides are refused by Material with pprender.Error naming the parameter.
    with pytest.raises(pprender.Error, match="alpha"):
        materials.get("gold", alpha=-1.0)
    with pytest.raises(pprender.Error, match="wavelength"):
        materials.get("gold", 633e-9)


def test_module_docstring_has_the_table():
    doc = materials.__doc__ or ""
    for name in materials.NAMES:
        assert name in doc
    for s in ("Rakic", "Johnson", "Malitson", "French", "ENGINEERING ESTIMATE"):
        assert s in doc


def test_docstring_table_matches_values():
    # Every eta in the docstring table is the value returned (guards against drift).
    doc = materials.__doc__ or ""
    for name in materials.NAMES:
        line = next(l for l in doc.splitlines() if l.startswith(name + " "))
        for wl in WL:
            eta = materials.optical_constants(name, wl)
            assert f"{eta.real:.4f}".rstrip("0").rstrip(".") in line or f"{eta.real:.2f}" in line
    assert cmath.isclose(materials.optical_constants("kapton", 532e-9), 1.8360 + 3.285e-4j)
