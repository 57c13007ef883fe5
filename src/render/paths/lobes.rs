//! The lobes a path draws its directions from at a surface: the BRDF the path sampler
//! evaluates and samples ([`PathBrdf`], the scene's [`Materials`]), the mixture of the
//! specular lobe (normals from the distribution) and the cosine-weighted depolarizing lobe,
//! and its density.

use super::*;

/// The least probability of each lobe where a material has both.
pub const MIN_LOBE_P: f64 = 0.1;

/// The lobes to sample at a surface: the specular lobe's distribution of normals (if any)
/// and the probability of choosing it (the rest: the cosine-weighted depolarizing lobe).
#[derive(Debug, Clone, Copy)]
pub struct Lobes {
    pub specular: Option<Distribution>,
    pub p_specular: f64,
}

/// A BRDF the path sampler evaluates and samples.
pub trait PathBrdf: Sync {
    /// Material `mat`'s Mueller BRDF at unit shading normal `n` for unit `wi`, `wo` above
    /// it (world frame), all elements, with its bases ([`Framed`]).
    fn eval(&self, mat: usize, n: V3, wi: V3, wo: V3) -> Framed;
    /// The lobes of `mat` toward `w_out` at `cos(theta) = cos_o`, `sin(theta) = sin_o`
    /// about the normal; `None` where it reflects nothing.
    fn lobes(&self, mat: usize, cos_o: f64, sin_o: f64) -> Option<Lobes>;
}

/// The scene's materials as the path sampler sees them (module docs: single + multiple +
/// diffuse terms; the specular lobe's weight the white single-bounce albedo times the
/// normal-incidence Fresnel reflectance, the depolarizing lobe's its albedo).
pub struct Materials<'a> {
    mats: &'a [Arc<Material>],
    /// Each material's unpolarized reflectance at normal incidence (once, not per path).
    r0: Vec<f64>,
}

impl<'a> Materials<'a> {
    pub fn new(mats: &'a [Arc<Material>]) -> Self {
        let r0 = mats.iter().map(|m| reflectance(1.0, m.spec.eta)).collect();
        Materials { mats, r0 }
    }
}

impl PathBrdf for Materials<'_> {
    fn eval(&self, mat: usize, n: V3, wi: V3, wo: V3) -> Framed {
        let mats = self.mats;
        // the seed's double term is a quadrature per call; the path banks' order 2 is a
        // table lookup and stays in
        let f = |m: usize, a: V3, b: V3| {
            let skip = mats[m].surface_orders.is_none().then_some(Term::Double);
            sum_terms_except(&mats[m], a, b, Frame::Sp, skip)
        };
        f.eval_framed(mat, n, wi, wo, 0xffff)
    }

    fn lobes(&self, mat: usize, cos_o: f64, sin_o: f64) -> Option<Lobes> {
        let m = &self.mats[mat];
        let terms = m.spec.terms;
        let w_spec = if terms.single {
            m.white_albedo(cos_o, sin_o).unwrap_or(1.0) * self.r0[mat]
        } else {
            0.0
        };
        let w_dep = if terms.multiple || terms.diffuse {
            let (ms, d) = m.depolarizing_albedo(cos_o, sin_o);
            // with orders="surface" the banks' orders (sampled by this lobe too)
            ms + d + m.bank_albedo(cos_o, true)
        } else {
            0.0
        };
        lobes_from_weights(m.spec.distribution, w_spec, w_dep)
    }
}

/// [`Lobes`] from the two lobes' weights (probabilities kept within
/// `[MIN_LOBE_P, 1 - MIN_LOBE_P]` where both lobes exist).
pub fn lobes_from_weights(dist: Distribution, w_spec: f64, w_dep: f64) -> Option<Lobes> {
    let (s, d) = (w_spec.max(0.0), w_dep.max(0.0));
    if s + d <= 0.0 || (s + d).is_nan() {
        return None;
    }
    if d == 0.0 {
        return Some(Lobes {
            specular: Some(dist),
            p_specular: 1.0,
        });
    }
    if s == 0.0 {
        return Some(Lobes {
            specular: None,
            p_specular: 0.0,
        });
    }
    Some(Lobes {
        specular: Some(dist),
        p_specular: (s / (s + d)).clamp(MIN_LOBE_P, 1.0 - MIN_LOBE_P),
    })
}

/// The lobes of the surface `v` for a path going on toward `w_out` (its angle to the
/// shading normal).
pub(super) fn lobes_toward(
    brdf: &(impl PathBrdf + ?Sized),
    v: &Vertex,
    w_out: V3,
) -> Option<Lobes> {
    let s = cross(v.n, w_out);
    brdf.lobes(v.mat, dot(v.n, w_out), dot(s, s).sqrt())
}

/// A unit vector normal to unit `n`, and a second one completing a right-handed frame.
fn tangents(n: V3) -> (V3, V3) {
    let a = if n.x.abs() < 0.9 { V3::X } else { V3::Y };
    let t1 = normalize(cross(a, n));
    (t1, cross(n, t1))
}

/// The density (1/sr) of drawing `w` at a surface with shading normal `n` toward `w_out`.
pub(super) fn pdf(lobes: &Lobes, n: V3, w_out: V3, w: V3) -> f64 {
    let c = dot(n, w);
    if c <= 0.0 {
        return 0.0;
    }
    let mut p = (1.0 - lobes.p_specular) * c / PI;
    if let Some(dist) = lobes.specular {
        let h = w + w_out;
        let l = dot(h, h).sqrt();
        if l > 0.0 {
            let h = h / l;
            let ch = dot(h, n);
            let wh = dot(w_out, h);
            if ch > 0.0 && wh > 0.0 {
                let nxh = cross(n, h);
                let d = dist.d(ch, dot(nxh, nxh).min(1.0));
                p += lobes.p_specular * d * ch / (4.0 * wh);
            }
        }
    }
    p
}

/// A direction drawn at a surface with shading normal `n` toward `w_out` from the
/// uniforms `(u_lobe, u1, u2)`; `None` when the draw falls below the horizon.
pub(super) fn sample(lobes: &Lobes, n: V3, w_out: V3, u: [f64; 3]) -> Option<V3> {
    let (t1, t2) = tangents(n);
    let phi = 2.0 * PI * u[2];
    let (sp, cp) = phi.sin_cos();
    let w = match lobes.specular {
        Some(dist) if u[0] < lobes.p_specular => {
            let (ch, s2h) = dist.sample_theta(u[1]);
            let sh = s2h.max(0.0).sqrt();
            let h = sh * cp * t1 + sh * sp * t2 + ch * n;
            let wh = dot(w_out, h);
            if wh <= 0.0 {
                return None;
            }
            2.0 * wh * h - w_out
        }
        _ => {
            let r = u[1].sqrt();
            let z = (1.0 - u[1]).max(0.0).sqrt();
            r * cp * t1 + r * sp * t2 + z * n
        }
    };
    (dot(w, n) > 0.0).then_some(w)
}

#[cfg(test)]
mod tests {
    use super::super::tests::uniform_stream;
    use super::*;

    /// The directions [`sample`] draws follow [`pdf`] (the specular lobe's Jacobian
    /// `1 / (4 w_out . h)`, the cosine lobe and their mixture): a histogram of 400,000 draws
    /// in 16 x 16 cells of `(cos theta, phi)` over the hemisphere about a tilted shading
    /// normal, against the density integrated over each cell (Gauss-Legendre 8 x 8); every
    /// cell with at least 100 expected draws within 5 sigma of Poisson, and the draws lost
    /// below the horizon as many as the density leaves outside it. Lobes wide enough for the
    /// grid; `w_out` from the normal to 75 deg. A density 10% off in either lobe fails it.
    #[test]
    fn draws_follow_the_density() {
        let n_draws = 400_000usize;
        let n = normalize(V3::new(0.3, -0.2, 1.0));
        let (t1, t2) = tangents(n);
        let lobes = [
            (Distribution::Beckmann { alpha: 0.3 }, 0.7),
            (Distribution::Ggx { alpha: 0.6 }, 1.0),
            (Distribution::BlinnPhong { m: 20.0 }, 0.4),
        ];
        for (dist, p_specular) in lobes {
            let lobes = Lobes {
                specular: Some(dist),
                p_specular,
            };
            for theta_o in [0.0f64, 45.0, 75.0] {
                let (so, co) = theta_o.to_radians().sin_cos();
                let w_out = so * (0.6 * t1 + 0.8 * t2) + co * n;
                let local = |c: f64, ph: f64| {
                    let s = (1.0 - c * c).max(0.0).sqrt();
                    s * ph.cos() * t1 + s * ph.sin() * t2 + c * n
                };
                let k = 16usize;
                let mut counts = vec![0usize; k * k];
                let mut rand = uniform_stream(0x9e37_79b9_7f4a_7c15);
                let mut kept = 0usize;
                for _ in 0..n_draws {
                    let Some(w) = sample(&lobes, n, w_out, [rand(), rand(), rand()]) else {
                        continue;
                    };
                    kept += 1;
                    let c = dot(w, n);
                    let ph = dot(w, t2).atan2(dot(w, t1)).rem_euclid(2.0 * PI);
                    let ic = ((c * k as f64) as usize).min(k - 1);
                    let ip = ((ph / (2.0 * PI) * k as f64) as usize).min(k - 1);
                    counts[ic * k + ip] += 1;
                }
                let mut total = 0.0;
                for ic in 0..k {
                    for ip in 0..k {
                        let (c0, c1) = (ic as f64 / k as f64, (ic + 1) as f64 / k as f64);
                        let (p0, p1) = (
                            ip as f64 * 2.0 * PI / k as f64,
                            (ip + 1) as f64 * 2.0 * PI / k as f64,
                        );
                        let mass = crate::quad::integrate(8, c0, c1, |c| {
                            crate::quad::integrate(8, p0, p1, |ph| {
                                pdf(&lobes, n, w_out, local(c, ph))
                            })
                        });
                        total += mass;
                        let want = mass * n_draws as f64;
                        if want < 100.0 {
                            continue;
                        }
                        let got = counts[ic * k + ip] as f64;
                        assert!(
                            (got - want).abs() < 5.0 * want.sqrt(),
                            "{dist:?} theta_o {theta_o} cell ({ic}, {ip}): {got} draws, {want:.1} expected"
                        );
                    }
                }
                let want = total * n_draws as f64;
                assert!(
                    (kept as f64 - want).abs() < 5.0 * want.sqrt() + 1e-3 * want,
                    "{dist:?} theta_o {theta_o}: {kept} draws above the horizon, {want:.0} expected"
                );
            }
        }
    }
}
