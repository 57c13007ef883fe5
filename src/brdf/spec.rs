//! What a user specifies: the BRDF's terms ([`Term`], the set [`Terms`]) and the
//! [`MaterialSpec`]. The lowest layer of the BRDF: the terms ([`super::single`],
//! [`super::double`], [`super::albedo`](mod@super::albedo)) read it through [`super::surface::Surface`], and
//! [`super::material::Material`] validates it.

use crate::microfacet::{Correlation, Distribution, MaskingEval, Shadowing, SmithG1};
use crate::optics::fresnel::Eta;
pub use crate::reference::microsurface::Autocorrelation;
use crate::{Error, Result};

/// One term of the BRDF. The BRDF is the sum of the enabled ones ([`Terms`]) in the order of
/// [`Term::ALL`], each evaluated by a `match` on this enum (pbrt's BxDF dispatch:
/// [`super::terms::sum_terms`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Term {
    /// The single bounce ([`super::single`]).
    Single,
    /// The double bounce with its coherent backscatter ([`super::double`]).
    Double,
    /// The multiple-scattering term (Kulla-Conty; depolarizing, `M00` only).
    Multiple,
    /// The diffuse (paint) layer under the specular one (depolarizing, `M00` only).
    Diffuse,
}

impl Term {
    /// Every term, in the order the BRDF sums them.
    pub const ALL: [Term; 4] = [Term::Single, Term::Double, Term::Multiple, Term::Diffuse];

    /// The name the user gives (`"single"`, `"double"`, `"multiple"`, `"diffuse"`).
    pub fn name(self) -> &'static str {
        match self {
            Term::Single => "single",
            Term::Double => "double",
            Term::Multiple => "multiple",
            Term::Diffuse => "diffuse",
        }
    }

    /// The term named `name` ([`Term::name`]).
    pub fn from_name(name: &str) -> Option<Term> {
        Term::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// Which BRDF terms are summed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Terms {
    pub single: bool,
    pub double: bool,
    pub multiple: bool,
    pub diffuse: bool,
}

impl Terms {
    /// Parse term names: "single", "double", "multiple", "diffuse".
    pub fn parse<S: AsRef<str>>(names: &[S]) -> Result<Self> {
        let mut t = Terms {
            single: false,
            double: false,
            multiple: false,
            diffuse: false,
        };
        for n in names {
            match Term::from_name(n.as_ref()) {
                Some(term) => t.set(term, true),
                None => return Err(Error::param(
                    "terms",
                    format!("{:?}", n.as_ref()),
                    "each term must be one of \"single\", \"double\", \"multiple\", \"diffuse\"",
                )),
            }
        }
        if t.iter().next().is_none() {
            return Err(Error::param("terms", "()", "enable at least one term"));
        }
        Ok(t)
    }

    pub fn names(&self) -> Vec<&'static str> {
        self.iter().map(Term::name).collect()
    }

    /// Whether `term` is enabled.
    #[inline]
    pub fn contains(&self, term: Term) -> bool {
        match term {
            Term::Single => self.single,
            Term::Double => self.double,
            Term::Multiple => self.multiple,
            Term::Diffuse => self.diffuse,
        }
    }

    /// Enable or disable `term`.
    pub fn set(&mut self, term: Term, on: bool) {
        match term {
            Term::Single => self.single = on,
            Term::Double => self.double = on,
            Term::Multiple => self.multiple = on,
            Term::Diffuse => self.diffuse = on,
        }
    }

    /// The enabled terms, in the order the BRDF sums them ([`Term::ALL`]).
    #[inline]
    pub fn iter(&self) -> impl Iterator<Item = Term> + '_ {
        Term::ALL.into_iter().filter(|&t| self.contains(t))
    }
}

/// Where the orders >= 2 of a material come from (decided once per material, never per
/// direction).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Orders {
    /// The seed's formulation: the double term's quadrature with uncorrelated second facets
    /// ([`super::double`]) and the depolarizing multiple term standing for orders 3+.
    Seed,
    /// The paths of a Beckmann surface with a Gaussian (or Matern,
    /// [`MaterialSpec::autocorrelation`]) height autocorrelation ([`super::bank`]): order 2 and,
    /// under "multiple", the orders beyond the enabled ones, polarized, plus a depolarizing
    /// remainder that closes the energy balance.
    Surface,
}

impl Orders {
    pub fn name(self) -> &'static str {
        match self {
            Orders::Seed => "seed",
            Orders::Surface => "surface",
        }
    }

    pub fn from_name(name: &str) -> Result<Orders> {
        match name {
            "seed" => Ok(Orders::Seed),
            "surface" => Ok(Orders::Surface),
            other => Err(Error::param(
                "orders",
                format!("{other:?}"),
                "expected \"seed\" (the double term and the depolarizing multiple term) or \
                 \"surface\" (the path banks of Gaussian random Beckmann surfaces)",
            )),
        }
    }
}

/// Everything a user specifies; [`Material::new`](super::material::Material::new) validates it and builds the tables.
#[derive(Debug, Clone, PartialEq)]
pub struct MaterialSpec {
    pub distribution: Distribution,
    pub eta: Eta,
    pub shadowing: Shadowing,
    /// `None`: the default for the shadowing model ("seed" for APS, "none" for Smith).
    pub correlation: Option<Correlation>,
    pub smith_g1: SmithG1,
    pub masking: MaskingEval,
    pub terms: Terms,
    pub diffuse_albedo: f64,
    /// Quadrature order of the double-bounce integral (per dimension).
    pub double_order: usize,
    /// Add the coherent-backscatter enhancement to the double bounce.
    pub coherent_backscatter: bool,
    /// The double bounce's hit/escape probabilities use the material's correlated masking
    /// (the seed's eq. 17, made reciprocal; default) or uncorrelated masking.
    pub double_correlated: bool,
    /// Wavelength (m), for the coherent-backscatter width.
    pub wavelength: f64,
    /// Surface correlation length (m): with [`Orders::Seed`] the rms lateral separation of
    /// the double bounce's two facets; with [`Orders::Surface`] the height correlation
    /// length `l` of the banked surfaces (`C(r) ~ exp(-r^2 / l^2)`), which scales the
    /// banked separations ([`crate::brdf::bank::coherent`]).
    pub correlation_length: f64,
    /// Where orders >= 2 come from.
    pub orders: Orders,
    /// With [`Orders::Surface`]: primary rays per incidence node of each path bank.
    pub bank_rays: u64,
    /// With [`Orders::Surface`]: the shape of the banked surfaces' height autocorrelation
    /// (Gaussian, the default, or Matern; the same slope statistics, so the same single
    /// term, but other orders >= 2: `docs/surface-orders-reference.md` measures by how
    /// much). Anything but Gaussian needs [`Orders::Surface`].
    pub autocorrelation: Autocorrelation,
    /// `Some(h)`: the material's albedo and escape tables are the Catmull-Rom interpolation
    /// in `ln alpha` of those of the materials at the four nodes `alpha = exp(j h)` about
    /// it, built once per process and kept ([`Material::new`](super::material::Material::new)
    /// says what that costs and changes); `None`: built at `alpha` itself (exact). With
    /// path banks ([`Self::uses_banks`]) the nodes also give the single term's calibration
    /// and lie within the banks' alpha interval that holds `alpha`
    /// (`material::bank_alpha_nodes`).
    pub alpha_step: Option<f64>,
}

impl MaterialSpec {
    /// A spec with the Python defaults: APS masking (tabulated, seed correlation), single +
    /// multiple terms, no diffuse layer, double-bounce parameters at their defaults.
    pub fn new(distribution: Distribution, eta: Eta) -> Self {
        MaterialSpec {
            distribution,
            eta,
            shadowing: Shadowing::Aps,
            correlation: None,
            smith_g1: SmithG1::Exact,
            masking: MaskingEval::Table,
            terms: Terms {
                single: true,
                double: false,
                multiple: true,
                diffuse: false,
            },
            diffuse_albedo: 0.0,
            double_order: Self::DOUBLE_ORDER,
            coherent_backscatter: true,
            double_correlated: true,
            wavelength: Self::WAVELENGTH,
            correlation_length: Self::CORRELATION_LENGTH,
            orders: Orders::Seed,
            bank_rays: Self::BANK_RAYS,
            autocorrelation: Autocorrelation::Gaussian,
            alpha_step: None,
        }
    }

    /// Whether the orders >= 2 come from the path banks: `orders = Surface` with the
    /// double or multiple term (with the single term alone `orders` has nothing to do).
    pub fn uses_banks(&self) -> bool {
        self.orders == Orders::Surface && (self.terms.double || self.terms.multiple)
    }

    /// Defaults for the double-bounce parameters. `DOUBLE_ORDER`: the quadrature of
    /// `double::eval_double` stays within 1e-4 of the term's M00 against order 384 (max
    /// over the significant pairs of `python benchmarks/bench_double.py`: 1.3e-5, and at most
    /// 1.5e-5 on its pair construction with two other seeds, where order 128 reaches 1.7e-4
    /// on a near-grazing GGX pair; docs/double-bounce.md section 3).
    pub const DOUBLE_ORDER: usize = 160;
    pub const WAVELENGTH: f64 = 1064e-9;
    pub const CORRELATION_LENGTH: f64 = 10e-6;
    /// Primary rays per incidence node of a path bank (`scripts/bank_vs_surface.py`: 4e6
    /// gives the order-2 values within the reference's noise at alpha 0.5 and 0.8).
    pub const BANK_RAYS: u64 = 4_000_000;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Names round-trip through [`Term`]; [`Terms::iter`] follows [`Term::ALL`], the order
    /// the BRDF sums the terms in; bad or no names are refused.
    #[test]
    fn terms_parse_names_and_order() {
        let t = Terms::parse(&["diffuse", "single", "multiple"]).unwrap();
        assert_eq!(t.names(), ["single", "multiple", "diffuse"]);
        assert_eq!(
            t.iter().collect::<Vec<_>>(),
            [Term::Single, Term::Multiple, Term::Diffuse]
        );
        assert!(!t.contains(Term::Double) && t.contains(Term::Diffuse));
        for term in Term::ALL {
            assert_eq!(Term::from_name(term.name()), Some(term));
        }
        let all = Terms::parse(&Term::ALL.map(Term::name)).unwrap();
        assert_eq!(all.iter().collect::<Vec<_>>(), Term::ALL);
        let e = Terms::parse(&["single", "triple"]).unwrap_err().to_string();
        assert!(e.contains("\"triple\"") && e.contains("terms"), "{e}");
        let none: [&str; 0] = [];
        assert!(Terms::parse(&none).is_err());
    }
}
