//! The grid of a table part: which terms it holds, its node counts and `z` scale (with
//! their defaults and bounds), and the cell of a coordinate.

/// Upper bound on the intervals per axis and on the nodes per part.
pub const MAX_NODES: usize = 1 << 16;
pub const MAX_TOTAL_NODES: usize = 1 << 22;

/// Which terms a part holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartKind {
    /// The single bounce.
    Single,
    /// The multiple and diffuse terms (whichever are enabled): depolarizing, and separable
    /// in the two directions (each a product of functions of theta_i and theta_o).
    Depolarizing,
    /// The double bounce (with its coherent backscatter as configured) at this order.
    Double(usize),
}

impl PartKind {
    pub fn name(&self) -> &'static str {
        match self {
            PartKind::Single => "single",
            PartKind::Depolarizing => "multiple+diffuse",
            PartKind::Double(_) => "double",
        }
    }
}

/// A part's grid with the defaults filled in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartGrid {
    pub kind: PartKind,
    pub n_z: usize,
    pub n_psi: usize,
    pub scale: f64,
}

/// Default `(n_z, n_psi, scale)` of a part for a distribution of width `alpha` (chosen
/// from the measurements in `docs/render-table.md`): the single term on a fine grid with
/// `scale = 1/sqrt(alpha)`, which balances the node density near normal incidence
/// (`dtheta = dz / scale`, the lobe has width `alpha`) against that near grazing
/// (`dtheta = scale dz`); the multiple + diffuse terms on the grid of the material's own
/// albedo tables (`scale = min(alpha, 1)`, 256 intervals: the nodes coincide with theirs); the
/// double bounce, which is smooth, on a coarse grid.
pub fn default_grid(kind: PartKind, alpha: f64, _beta: f64) -> (usize, usize, f64) {
    match kind {
        PartKind::Single => (256, 32, 1.0 / alpha.sqrt()),
        // the material's table scale (`Distribution::table_scale`)
        PartKind::Depolarizing => (256, 8, alpha.min(1.0)),
        PartKind::Double(_) => (32, 8, 1.0),
    }
}

/// Interval `i = min(floor(x), n - 1)` (x clamped to `[0, n]`) and the fraction `x - i`.
#[inline]
pub fn cell(x: f64, n: usize) -> (usize, f64) {
    let x = x.clamp(0.0, n as f64);
    let i = (x as usize).min(n - 1);
    (i, x - i as f64)
}

/// `z` of a polar angle given by `(cos, sin)` for the mapping scale `s`.
#[inline]
pub fn z_of(scale: f64, cos_t: f64, sin_t: f64) -> f64 {
    let den = scale * sin_t + cos_t;
    if den <= 0.0 {
        0.0
    } else {
        (cos_t / den).clamp(0.0, 1.0)
    }
}
