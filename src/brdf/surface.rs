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
