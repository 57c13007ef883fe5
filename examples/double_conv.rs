//! Convergence of the double-bounce quadrature against its order, for the bench materials.
//!
//! `cargo run --release --example double_conv -- [MATERIAL] [PAIRS_FILE] [ORDERS] [REF]`
//!
//! - `MATERIAL`: `beckmann` (alpha 0.5, eta 0.2+3.4i), `blinn` (m 10, eta 1.5), `ggx`
//!   (alpha 0.3, eta 0.2+3.4i) or `all` (default).
//! - `PAIRS_FILE`: lines `wix wiy wiz wox woy woz [label]`, or `-` for the built-in
//!   grazing pairs (default).
//! - `ORDERS`: comma-separated (default `48,64,96,128`), `REF`: the reference order
//!   (default 384).
//!
//! Prints, per pair, `M00` of the double term at the reference order and the error
//! `max_ij |dM_ij| / M00` of each order; then the max and median per order.

use pprender::brdf::double::eval_double;
use pprender::brdf::material::{Material, MaterialSpec, Terms};
use pprender::microfacet::Distribution;
use pprender::optics::frames::{Frame, V3};
use pprender::optics::fresnel::Eta;
use rayon::prelude::*;
use std::time::Instant;

fn dir(theta_deg: f64, phi_deg: f64) -> V3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    V3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

fn material(name: &str) -> Material {
    let (dist, eta) = match name {
        "beckmann" => (Distribution::Beckmann { alpha: 0.5 }, Eta::new(0.2, 3.4)),
        "blinn" => (Distribution::BlinnPhong { m: 10.0 }, Eta::new(1.5, 0.0)),
        "ggx" => (Distribution::Ggx { alpha: 0.3 }, Eta::new(0.2, 3.4)),
        _ => panic!("unknown material {name}"),
    };
    let mut spec = MaterialSpec::new(dist, eta);
    spec.terms = Terms {
        single: false,
        double: true,
        multiple: false,
        diffuse: false,
    };
    if std::env::var("UNCORR").is_ok() {
        spec.double_correlated = false;
    }
    if std::env::var("EXACT").is_ok() {
        spec.masking = pprender::microfacet::MaskingEval::Exact;
    }
    if std::env::var("SMITH").is_ok() {
        spec.shadowing = pprender::microfacet::Shadowing::Smith;
    }
    Material::new(spec).unwrap()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let mats: Vec<&str> = match args.get(1).map(|s| s.as_str()).unwrap_or("all") {
        "all" => vec!["beckmann", "blinn", "ggx"],
        m => vec![m],
    };
    let pairs: Vec<(V3, V3, String)> = match args.get(2).map(|s| s.as_str()) {
        None | Some("-") => {
            let mut v = vec![];
            for &(ti, to, dphi) in &[
                (88.0, 88.0, 180.0),
                (88.0, 88.0, 0.0),
                (88.1, 88.1, 180.0),
                (89.2, 89.2, 0.0),
                (89.2, 89.2, 180.0),
                (85.0, 85.0, 180.0),
                (80.0, 80.0, 0.0),
                (60.0, 60.0, 180.0),
                (30.0, 70.0, 90.0),
            ] {
                v.push((dir(ti, 0.0), dir(to, dphi), format!("{ti}/{to}/{dphi}")));
            }
            v
        }
        Some(path) => std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let t: Vec<&str> = l.split_whitespace().collect();
                let x: Vec<f64> = t[..6].iter().map(|s| s.parse().unwrap()).collect();
                let label = t.get(6..).map(|s| s.join(" ")).unwrap_or_default();
                (V3::new(x[0], x[1], x[2]), V3::new(x[3], x[4], x[5]), label)
            })
            .collect(),
    };
    let orders: Vec<usize> = args
        .get(3)
        .map(|s| s.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or(vec![48, 64, 96, 128]);
    let ref_order: usize = args.get(4).map(|s| s.parse().unwrap()).unwrap_or(384);
    let verbose = std::env::var("VERBOSE").is_ok();
    for name in mats {
        let mat = material(name);
        let t0 = Instant::now();
        let ref_file = std::env::var("REF_FILE")
            .ok()
            .map(|p| format!("{p}.{name}"));
        let refs: Vec<[[f64; 4]; 4]> = match &ref_file {
            Some(p) if std::path::Path::new(p).exists() => std::fs::read_to_string(p)
                .unwrap()
                .lines()
                .map(|l| {
                    let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
                    let mut m = [[0.0; 4]; 4];
                    for a in 0..4 {
                        for b in 0..4 {
                            m[a][b] = v[4 * a + b];
                        }
                    }
                    m
                })
                .collect(),
            _ => {
                let r: Vec<_> = pairs
                    .par_iter()
                    .map(|(wi, wo, _)| eval_double(&mat, *wi, *wo, Frame::Sp, ref_order, true))
                    .collect();
                if let Some(p) = &ref_file {
                    let txt: String = r
                        .iter()
                        .map(|m| {
                            let v: Vec<String> =
                                m.iter().flatten().map(|x| format!("{x:e}")).collect();
                            v.join(" ") + "\n"
                        })
                        .collect();
                    std::fs::write(p, txt).unwrap();
                }
                r
            }
        };
        let t_ref = t0.elapsed().as_secs_f64();
        let mut errs = vec![vec![0.0; pairs.len()]; orders.len()];
        let mut times = vec![0.0; orders.len()];
        for (k, &n) in orders.iter().enumerate() {
            let t0 = Instant::now();
            let ms: Vec<_> = pairs
                .par_iter()
                .map(|(wi, wo, _)| eval_double(&mat, *wi, *wo, Frame::Sp, n, true))
                .collect();
            times[k] = t0.elapsed().as_secs_f64();
            for (p, m) in ms.iter().enumerate() {
                let r = &refs[p];
                let mut e: f64 = 0.0;
                for a in 0..4 {
                    for b in 0..4 {
                        e = e.max((m[a][b] - r[a][b]).abs());
                    }
                }
                errs[k][p] = if r[0][0] > 0.0 { e / r[0][0] } else { 0.0 };
            }
        }
        println!("== {name} (ref order {ref_order}, {t_ref:.1} s)");
        if verbose || pairs.len() <= 20 {
            for (p, (wi, wo, label)) in pairs.iter().enumerate() {
                let ti = wi[2].acos().to_degrees();
                let to = wo[2].acos().to_degrees();
                let dphi = (wo[1].atan2(wo[0]) - wi[1].atan2(wi[0])).to_degrees();
                print!(
                    "{label:>16} {ti:6.2} {to:6.2} {dphi:8.2} M00 {:.4e}",
                    refs[p][0][0]
                );
                for k in 0..orders.len() {
                    print!("  {:.1e}", errs[k][p]);
                }
                println!();
            }
        }
        for (k, &n) in orders.iter().enumerate() {
            let mut e = errs[k].clone();
            e.sort_by(|a, b| a.partial_cmp(b).unwrap());
            let imax = (0..pairs.len())
                .max_by(|&a, &b| errs[k][a].partial_cmp(&errs[k][b]).unwrap())
                .unwrap();
            println!(
                "order {n:4}: max {:.2e} (pair {imax} {}) median {:.2e}  time {:.2} s",
                e[e.len() - 1],
                pairs[imax].2,
                e[e.len() / 2],
                times[k]
            );
        }
    }
}
