//! WGSL sources: one kernel per file in `shaders/`, and the pieces they share in
//! `shaders/shared/`.
//!
//! A kernel pulls in a shared file with a line `//#include "shared/NAME.wgsl"` (the whole
//! line; leading spaces allowed; a comment to WGSL itself), which [`expand`] replaces by
//! the file's text when the module is built. The binary carries every shared file
//! ([`SHARED`], by `include_str!`). Including a file that [`SHARED`] does not list, or one
//! already included into the module, is an error: a shared file is pulled in once, and
//! WGSL's module-scope declarations may come in any order, so it need not precede its
//! users. Shared files may include others.

pub const VISIBILITY: &str = include_str!("../../shaders/visibility.wgsl");
/// The multiview visibility pass's vertex stage (needs the MULTIVIEW capability).
pub const VISIBILITY_VIEWS: &str = include_str!("../../shaders/visibility_views.wgsl");
/// The shade kernel as written (with its include lines; [`shade_module`] expands them).
pub const SHADE: &str = include_str!("../../shaders/shade.wgsl");
/// The pulse functions (plain functions, valid on their own), included into the shade
/// kernel.
pub const PULSE: &str = include_str!("../../shaders/shared/pulse.wgsl");
pub const GATHER: &str = include_str!("../../shaders/gather.wgsl");
/// Closest hits of rays against the flat BVH ([`crate::render::gpu::raycast`]).
pub const RAYCAST: &str = include_str!("../../shaders/raycast.wgsl");
/// The paths' random numbers on the device (the twin check of `shared/rng.wgsl`).
pub const PATH_NUMBERS: &str = include_str!("../../shaders/path_numbers.wgsl");

/// The files an include line may name, by their path under `shaders/`.
pub const SHARED: &[(&str, &str)] = &[
    (
        "shared/constants.wgsl",
        include_str!("../../shaders/shared/constants.wgsl"),
    ),
    ("shared/pulse.wgsl", PULSE),
    (
        "shared/raster.wgsl",
        include_str!("../../shaders/shared/raster.wgsl"),
    ),
    (
        "shared/table.wgsl",
        include_str!("../../shaders/shared/table.wgsl"),
    ),
    (
        "shared/complex.wgsl",
        include_str!("../../shaders/shared/complex.wgsl"),
    ),
    (
        "shared/microfacet.wgsl",
        include_str!("../../shaders/shared/microfacet.wgsl"),
    ),
    (
        "shared/in_kernel.wgsl",
        include_str!("../../shaders/shared/in_kernel.wgsl"),
    ),
    (
        "shared/shadow.wgsl",
        include_str!("../../shaders/shared/shadow.wgsl"),
    ),
    (
        "shared/coverage.wgsl",
        include_str!("../../shaders/shared/coverage.wgsl"),
    ),
    (
        "shared/rng.wgsl",
        include_str!("../../shaders/shared/rng.wgsl"),
    ),
];

/// The directive, at the start of a (trimmed) line.
const INCLUDE: &str = "//#include";

/// `src` (named `name` in messages) with its include lines replaced by the files they name,
/// recursively; an unknown, malformed or repeated include is an error.
pub fn expand(name: &str, src: &str) -> Result<String, String> {
    let mut out = String::with_capacity(2 * src.len());
    expand_into(name, src, &mut vec![], &mut out)?;
    Ok(out)
}

fn expand_into(
    name: &str,
    src: &str,
    seen: &mut Vec<&'static str>,
    out: &mut String,
) -> Result<(), String> {
    for (i, line) in src.lines().enumerate() {
        let Some(rest) = line.trim().strip_prefix(INCLUDE) else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let at = format!("{name}:{}", i + 1);
        let path = rest
            .trim()
            .strip_prefix('"')
            .and_then(|r| r.strip_suffix('"'))
            .ok_or_else(|| format!("{at}: malformed include {line:?} (want {INCLUDE} \"path\")"))?;
        let &(path, text) = SHARED
            .iter()
            .find(|(p, _)| *p == path)
            .ok_or_else(|| format!("{at}: no shared file {path:?} (list it in shaders::SHARED)"))?;
        if seen.contains(&path) {
            return Err(format!("{at}: {path:?} is included twice"));
        }
        seen.push(path);
        expand_into(path, text, seen, out)?;
    }
    Ok(())
}

/// The complete visibility module (one layer per pass).
pub fn visibility_module() -> String {
    expand("visibility.wgsl", VISIBILITY).unwrap_or_else(|e| panic!("{e}"))
}

/// The complete multiview visibility module (several layers per pass).
pub fn visibility_views_module() -> String {
    expand("visibility_views.wgsl", VISIBILITY_VIEWS).unwrap_or_else(|e| panic!("{e}"))
}

/// The complete path-numbers module.
pub fn path_numbers_module() -> String {
    expand("path_numbers.wgsl", PATH_NUMBERS).unwrap_or_else(|e| panic!("{e}"))
}

/// The complete shade module (the kernel with its shared files).
pub fn shade_module() -> String {
    expand("shade.wgsl", SHADE).unwrap_or_else(|e| panic!("{e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel expands without error and leaves no include line; every shared file is
    /// included somewhere, and every file in `shaders/shared/` is listed in [`SHARED`].
    #[test]
    fn includes_expand_and_every_shared_file_is_used() {
        let mut used = vec![];
        for (name, src) in [
            ("visibility.wgsl", VISIBILITY),
            ("visibility_views.wgsl", VISIBILITY_VIEWS),
            ("shade.wgsl", SHADE),
            ("gather.wgsl", GATHER),
            ("raycast.wgsl", RAYCAST),
            ("path_numbers.wgsl", PATH_NUMBERS),
        ] {
            let mut seen = vec![];
            let mut out = String::new();
            expand_into(name, src, &mut seen, &mut out).unwrap();
            assert!(
                !out.lines().any(|l| l.trim().starts_with(INCLUDE)),
                "{name}"
            );
            used.extend(seen);
        }
        for (path, _) in SHARED {
            assert!(used.contains(path), "{path} is included by no kernel");
        }
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/shared");
        for entry in std::fs::read_dir(dir).unwrap() {
            let file = entry.unwrap().file_name().into_string().unwrap();
            let path = format!("shared/{file}");
            assert!(
                SHARED.iter().any(|(p, _)| *p == path),
                "{path} is not listed in shaders::SHARED"
            );
        }
    }

    #[test]
    fn include_errors_are_reported() {
        let e = expand("k", "a\n//#include \"shared/nope.wgsl\"\n").unwrap_err();
        assert!(e.contains("k:2") && e.contains("no shared file"), "{e}");
        let twice = "//#include \"shared/complex.wgsl\"\n  //#include \"shared/complex.wgsl\"";
        let e = expand("k", twice).unwrap_err();
        assert!(e.contains("k:2") && e.contains("twice"), "{e}");
        let e = expand("k", "//#include shared/complex.wgsl").unwrap_err();
        assert!(e.contains("malformed"), "{e}");
        let ok = expand("k", "x\n  //#include \"shared/complex.wgsl\"\ny").unwrap();
        let complex = SHARED
            .iter()
            .find(|(p, _)| *p == "shared/complex.wgsl")
            .unwrap()
            .1;
        assert_eq!(ok, format!("x\n{complex}y\n"));
    }

    /// The module-scope `const NAME[: T] = value;` declarations of `src`: name and value
    /// text.
    fn wgsl_consts(src: &str) -> Vec<(String, String)> {
        src.lines()
            .filter_map(|l| l.trim().strip_prefix("const "))
            .map(|l| {
                let (lhs, rhs) = l.split_once('=').expect("const NAME = value");
                let name = lhs.split(':').next().unwrap().trim().to_string();
                let value = rhs.split(';').next().unwrap().trim().to_string();
                (name, value)
            })
            .collect()
    }

    /// A WGSL integer literal (`3u`, `0xffffffffu`).
    fn wgsl_uint(v: &str) -> u64 {
        let v = v.trim_end_matches('u');
        match v.strip_prefix("0x") {
            Some(h) => u64::from_str_radix(h, 16).unwrap(),
            None => v.parse().unwrap(),
        }
    }

    /// A WGSL f32 literal, rounded as WGSL rounds it (to the nearest f32).
    fn wgsl_f32(v: &str) -> f32 {
        v.trim_end_matches('f').parse().unwrap()
    }

    /// The WGSL constants that mirror Rust ones equal them (integers exactly, f32 bit for
    /// bit: the layout of the tables, the visibility samples, the pulse's f32 constants
    /// of [`crate::render::pulse::PulseFloat`]); the constants file holds no other constant than these and the WGSL-only ones
    /// listed here.
    #[test]
    fn wgsl_constants_equal_the_rust_ones() {
        use crate::render::gpu;
        use crate::render::pulse::PulseFloat;
        let module = shade_module();
        let consts = wgsl_consts(&module);
        let value = |name: &str| {
            let found: Vec<_> = consts.iter().filter(|(n, _)| n == name).collect();
            assert_eq!(found.len(), 1, "const {name} in the shade module");
            found[0].1.clone()
        };
        let uints: [(&str, u64); 4] = [
            ("MAX_PARTS", gpu::MAX_PARTS as u64),
            ("HEADER_WORDS", gpu::HEADER_WORDS as u64),
            ("SHADER_PART", gpu::SHADER_PART as u64),
            ("MAX_SAMPLES", crate::render::samples::MAX_SAMPLES as u64),
        ];
        for (name, want) in uints {
            assert_eq!(wgsl_uint(&value(name)), want, "{name}");
        }
        type P = f32;
        let floats: [(&str, f32); 6] = [
            ("PI", std::f32::consts::PI),
            ("PULSE_ALPHA", crate::render::pulse::ALPHA_F32),
            ("PULSE_BETA", crate::render::pulse::BETA_F32),
            ("PULSE_INV_SQRT_2PI", <P as PulseFloat>::INV_SQRT_2PI),
            ("PULSE_FRAC_1_SQRT_2", <P as PulseFloat>::FRAC_1_SQRT_2),
            ("PULSE_T_CLAMP", <P as PulseFloat>::T_CLAMP),
        ];
        for (name, want) in floats {
            assert_eq!(wgsl_f32(&value(name)).to_bits(), want.to_bits(), "{name}");
        }
        // array<f32, 6>(...)
        let inv_fact = value("PULSE_INV_FACT_EVEN");
        let items: Vec<u32> = inv_fact
            .split_once('(')
            .and_then(|(_, r)| r.strip_suffix(')'))
            .expect("array<f32, N>(...)")
            .split(',')
            .map(|v| wgsl_f32(v.trim()).to_bits())
            .collect();
        let want: Vec<u32> = <P as PulseFloat>::INV_FACT_EVEN
            .iter()
            .map(|x| x.to_bits())
            .collect();
        assert_eq!(items, want, "PULSE_INV_FACT_EVEN");
        let wgsl_only = ["LN_FLOOR_F32"];
        let constants = SHARED[0];
        assert_eq!(constants.0, "shared/constants.wgsl");
        for (name, _) in wgsl_consts(constants.1) {
            assert!(
                uints.iter().any(|(n, _)| *n == name)
                    || floats.iter().any(|(n, _)| *n == name)
                    || wgsl_only.contains(&name.as_str()),
                "{name} in shared/constants.wgsl: compare it with its Rust constant here"
            );
        }
    }
}
