//! Aiming 3-bounce paths from their middle surface at the glossy flat surfaces that mirror
//! the transmitter ([`Mirrors`], [`aim`]).

use super::*;

/// The glossy flat surfaces of one attitude a 3-bounce path may be aimed at from its middle
/// surface: each a mirror of the transmitter, blurred by its roughness. A path through a
/// glossy surface, then a diffuse one, then a glossy one (the bus showing the paint it
/// lights) is drawn poorly from either end (each end evaluates the other's narrow lobe in a
/// direction drawn without it); aimed, the middle surface draws the direction toward the
/// last one from the last one's lobe about the transmitter's mirror direction: a surface
/// `S` chosen with probability `P(S)` (its lit area, projected along `wi`, times its
/// specular lobe's probability), a normal `h` drawn from its distribution, the direction
/// toward `S` opposite the reflection of `wi` about `h`; kept when the ray meets `S` on its
/// lit side. Density `P(S) D(h) cos(theta_h) / (4 wi . h)`, combined with the middle
/// surface's own lobe sampling by the balance heuristic.
pub(super) struct Mirrors {
    /// Per face: the index in `list` of its surface if that is a candidate, else `u32::MAX`.
    pub(super) of_face: Vec<u32>,
    pub(super) list: Vec<Mirror>,
    /// The cumulative probabilities of `list`.
    pub(super) cdf: Vec<f64>,
}

pub(super) struct Mirror {
    /// The surface's normal on its lit side.
    pub(super) n: V3,
    /// Its specular lobe alone (what aiming draws from).
    pub(super) lobe: Lobes,
    /// `P(S)`.
    pub(super) p: f64,
}

/// The least probability of the specular lobe for a surface to be a [`Mirror`].
pub(super) const MIRROR_MIN_SPECULAR: f64 = 0.5;

impl Mirrors {
    pub(super) fn none(n_faces: usize) -> Self {
        Mirrors {
            of_face: vec![u32::MAX; n_faces],
            list: Vec::new(),
            cdf: Vec::new(),
        }
    }

    /// The candidates of `posed` lit along `wi`: flat surfaces ([`Mesh::surfaces`]) whose
    /// lit side is open ([`open_sides`]) and whose material's specular lobe has at least
    /// [`MIRROR_MIN_SPECULAR`] of the probability at `wi`; `area[s]` the area of the
    /// surface whose first face is `s`.
    pub(super) fn new(
        posed: &Posed<'_>,
        brdf: &(impl PathBrdf + ?Sized),
        wi: V3,
        area: &[f64],
    ) -> Self {
        let mesh = posed.mesh;
        let surf = mesh.surfaces();
        let mut out = Mirrors::none(mesh.faces.len());
        let mut index_of_root = std::collections::HashMap::new();
        let mut weights = Vec::new();
        for (t, &root) in surf.iter().enumerate() {
            if root as usize != t || area[t] <= 0.0 {
                continue;
            }
            let [a, b, c] = posed.tris[t];
            let n = normalize(cross(b - a, c - a));
            let cw = dot(n, wi);
            if !n.is_finite() || cw == 0.0 {
                continue;
            }
            let (n, side) = if cw > 0.0 { (n, 0) } else { (-n, 1) };
            if !posed.open[t][side] {
                continue;
            }
            let ci = cw.abs();
            let si = (1.0 - ci * ci).max(0.0).sqrt();
            let mat = mesh.face_material[t] as usize;
            let Some(Lobes {
                specular: Some(dist),
                p_specular,
            }) = brdf.lobes(mat, ci, si)
            else {
                continue;
            };
            if p_specular < MIRROR_MIN_SPECULAR {
                continue;
            }
            index_of_root.insert(root, out.list.len() as u32);
            weights.push(area[t] * ci * p_specular);
            let lobe = Lobes {
                specular: Some(dist),
                p_specular: 1.0,
            };
            out.list.push(Mirror { n, lobe, p: 0.0 });
        }
        let total: f64 = weights.iter().sum();
        if total <= 0.0 || total.is_nan() {
            return Mirrors::none(mesh.faces.len());
        }
        let mut acc = 0.0;
        for (m, w) in out.list.iter_mut().zip(&weights) {
            m.p = w / total;
            acc += m.p;
            out.cdf.push(acc);
        }
        for (t, &root) in surf.iter().enumerate() {
            if let Some(&j) = index_of_root.get(&root) {
                out.of_face[t] = j;
            }
        }
        out
    }

    /// The candidate drawn by the uniform `u`.
    pub(super) fn pick(&self, u: f64) -> usize {
        self.cdf
            .partition_point(|&c| c <= u)
            .min(self.list.len() - 1)
    }

    /// The aiming density (per unit solid angle at the middle surface) of the direction `d`
    /// toward the surface `v` lies on, or 0 when `v` is not a candidate met on its lit
    /// side.
    pub(super) fn density(&self, v: &Vertex, d: V3, wi: V3) -> f64 {
        let j = self.of_face[v.tri];
        if j == u32::MAX {
            return 0.0;
        }
        let m = &self.list[j as usize];
        if dot(v.ng, m.n) <= 0.0 {
            return 0.0;
        }
        m.p * mirror_pdf(m, wi, d)
    }
}

/// The density of the direction `d` (toward the mirror) drawn by aiming at `m`: that of
/// its reflection of `wi`, `-d`, about a normal drawn from its distribution.
pub(super) fn mirror_pdf(m: &Mirror, wi: V3, d: V3) -> f64 {
    pdf(&m.lobe, m.n, wi, -d)
}

/// The aimed 3-bounce path from the middle surface `v` (its throughput part `(M, x_out)`:
/// `f_v(d, w_out) cos / pdf L f_3(wi, -d) cos_i`, weighted by the balance heuristic against
/// `v`'s own `lobes`, in the bases `x_out` (normal to `w_out`) and the returned `x_in`
/// (normal to `wi`)), and the path's length from `v` on (`|p3 - v| - p3 . wi`); `None` when
/// the aimed ray misses its mirror or the mirror is shadowed (`Mirrors`).
#[allow(clippy::too_many_arguments)]
pub(super) fn aim(
    setup: &Setup<'_>,
    posed: &Posed<'_>,
    brdf: &(impl PathBrdf + ?Sized),
    mirrors: &Mirrors,
    v: &Vertex,
    w_out: V3,
    lobes: &Lobes,
    [u_pick, u1, u2]: [f64; 3],
) -> Option<((Mat4, V3), V3, f64)> {
    let wi = setup.wi;
    let j = mirrors.pick(u_pick);
    let m = &mirrors.list[j];
    // the light leaving the mirror about its specular direction, and the way to it
    let d = -sample(&m.lobe, m.n, wi, [0.0, u1, u2])?;
    if dot(d, v.ng) <= 0.0 || dot(d, v.n) <= 0.0 {
        return None;
    }
    let p3 = posed.trace(v.p + posed.eps * v.ng, d)?;
    if mirrors.of_face[p3.tri] != j as u32
        || dot(p3.ng, m.n) <= 0.0
        || dot(p3.n, -d) <= 0.0
        || !posed.sees(&p3, wi)
    {
        return None;
    }
    let pdf_aim = m.p * mirror_pdf(m, wi, d);
    let pdf_lobe = pdf(lobes, v.n, w_out, d);
    if pdf_aim <= 0.0 || pdf_aim.is_nan() {
        return None;
    }
    let f = brdf.eval(v.mat, v.n, d, w_out);
    let g = brdf.eval(p3.mat, p3.n, wi, -d);
    let fm = scale(&f.m, dot(v.n, d) / (pdf_aim + pdf_lobe));
    let gm = scale(&g.m, dot(p3.n, wi));
    let m = chain(&fm, f.x_in, &gm, g.x_out, -d);
    Some(((m, f.x_out), g.x_in, (p3.p - v.p).length() - dot(p3.p, wi)))
}
