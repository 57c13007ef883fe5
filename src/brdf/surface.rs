//! [`Surface`]: the microsurface the BRDF's terms read (the spec, the masking correlation
//! and the masking-excess table), below [`super::material::Material`], which adds the
//! terms' albedo and escape tables on top of it.

use super::spec::MaterialSpec;
use crate::microfacet::masking::{self, ZTable, TABLE_NODES};
use crate::microfacet::{seed, Correlation, Distribution, MaskingEval, Shadowing, SmithG1};

/// The microsurface of a material: what the single and double terms and their albedo
/// integrals ([`super::single`], [`super::double`], [`super::albedo`](mod@super::albedo)) need. Built by
/// [`super::material::Material::new`] from a validated spec ([`Surface::new`]); a
/// `Material` dereferences to its `Surface` (`mat.spec`, `mat.correlation`,
/// `mat.masking_excess(..)`).
#[derive(Debug, Clone)]
pub struct Surface {
    pub spec: MaterialSpec,
    pub correlation: Correlation,
    /// APS masking excess `N_D(theta)` table (when `masking = Table` and `shadowing = Aps`).
    pub(crate) n_table: Option<ZTable>,
    /// The single term's masking calibrated to a traced surface: `G' = G s(theta_i)
    /// s(theta_o)`, `s` tabulated in `z` ([`super::calibration::calibrate_masking`]).
    pub calibration: Option<ZTable>,
}

impl Surface {
    /// The surface of a spec that [`super::material::Material::new`] has validated: the
    /// correlation (its default for the shadowing model) and the APS masking-excess table
    /// where the masking is tabulated (or `"exact"` with albedo tables to fill).
    pub fn new(spec: MaterialSpec) -> Self {
        let correlation = spec.correlation.unwrap_or(match spec.shadowing {
            Shadowing::Aps => Correlation::Seed,
            _ => Correlation::None,
        });
        let mut surf = Surface {
            spec,
            correlation,
            n_table: None,
            calibration: None,
        };
        let dist = surf.spec.distribution;
        let needs_albedo = surf.spec.terms.multiple || surf.spec.terms.diffuse;
        let exact = surf.spec.masking == MaskingEval::Exact;
        if (surf.spec.shadowing == Shadowing::Aps || surf.smith_is_aps())
            && (surf.spec.masking == MaskingEval::Table || (exact && needs_albedo))
        {
            // Beckmann and GGX tabulate their closed form (equal to the quadrature to
            // 1e-15, 512 evaluations in microseconds instead of 18 ms of quadratures).
            surf.n_table = Some(ZTable::build(dist.table_scale(), TABLE_NODES, |t| {
                let (s, c) = t.sin_cos();
                masking::aps_excess_closed_form(&dist, c, s)
                    .unwrap_or_else(|| masking::aps_excess(&dist, t))
            }));
        }
        surf
    }

    /// The masking excess `N(k)` such that `P(k) = c/(c + N)` and `P(k)/c = 1/(c + N)`
    /// for a direction with `cos theta = c`, `sin theta = s` (APS: `N_D`; Smith: `c Lambda`).
    #[inline]
    pub fn masking_excess(&self, c: f64, s: f64) -> f64 {
        self.masking_excess_z(c, s, self.z_of(c, s))
    }

    /// The table coordinate `z` of a direction (shared by all per-material tables).
    #[inline]
    pub fn z_of(&self, c: f64, s: f64) -> f64 {
        let den = self.spec.distribution.table_scale() * s + c;
        if den <= 0.0 {
            0.0
        } else {
            (c / den).clamp(0.0, 1.0)
        }
    }

    /// `(c_b N(a)) / (c_a N(b)) = Lambda(a) / Lambda(b)`, the ratio of the masking
    /// functions of two directions (`c`, `s`: cosine and sine of each), in closed form
    /// where the masking has one (APS, or Smith's exact `G1`, of Beckmann and GGX), in
    /// logarithms: near the normal both excesses are far below what the table resolves
    /// (it returns 0 for Beckmann beyond `cot theta / alpha` of about 9) or f64 holds
    /// (`exp(-a^2)` underflows beyond `a` = 27), while their ratio is finite and decides
    /// the correlated blocking of the double bounce ([`super::double`]). None where the
    /// masking has no closed form (Blinn-Phong, the approximate Smith `G1`s, no shadowing).
    pub fn masking_ratio(&self, ca: f64, sa: f64, cb: f64, sb: f64) -> Option<f64> {
        let aps = match self.spec.shadowing {
            Shadowing::Aps => self.spec.masking != MaskingEval::Seed,
            Shadowing::Smith => self.spec.smith_g1 == SmithG1::Exact,
            Shadowing::None => false,
        };
        if !aps {
            return None;
        }
        let (la, lb) = (
            masking::ln_lambda_closed_form(&self.spec.distribution, ca, sa)?,
            masking::ln_lambda_closed_form(&self.spec.distribution, cb, sb)?,
        );
        Some(if lb == f64::NEG_INFINITY {
            // b along the normal: never masked; a too (the same limit) or a masked at all
            if la == f64::NEG_INFINITY {
                1.0
            } else {
                f64::INFINITY
            }
        } else {
            (la - lb).exp()
        })
    }

    /// [`Self::masking_excess`] with the table coordinate already computed.
    #[inline]
    pub fn masking_excess_z(&self, c: f64, s: f64, z: f64) -> f64 {
        match self.spec.shadowing {
            Shadowing::None => 0.0,
            // Blinn-Phong's exact Smith function is the APS excess (masking.rs docs).
            Shadowing::Smith if !self.smith_is_aps() => {
                c * masking::smith_lambda(&self.spec.distribution, self.spec.smith_g1, c, s * s)
            }
            Shadowing::Smith | Shadowing::Aps => match self.spec.masking {
                MaskingEval::Table => self.n_table.as_ref().unwrap().eval_z(z).max(0.0),
                MaskingEval::Exact => masking::aps_excess(&self.spec.distribution, s.atan2(c)),
                MaskingEval::Seed => match self.spec.distribution {
                    Distribution::BlinnPhong { m } => seed::seed_aps_excess_cos(m, c),
                    _ => unreachable!("checked in Material::new"),
                },
            },
        }
    }

    /// Smith masking that is evaluated as the APS excess `N_D` (the exact Smith function of
    /// a Blinn-Phong distribution, `smith_g1 = "exact"`).
    #[inline]
    pub fn smith_is_aps(&self) -> bool {
        self.spec.shadowing == Shadowing::Smith
            && self.spec.smith_g1 == SmithG1::Exact
            && matches!(self.spec.distribution, Distribution::BlinnPhong { .. })
    }
}
