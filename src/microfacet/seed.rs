//! The seed's closed-form approximations of the masking average (seed eq. 18-23).

/// Wallis integral `A(m) = int_0^{pi/2} cos^m = sqrt(pi)/2 Gamma((m+1)/2) / Gamma(m/2 + 1)`.
pub fn wallis(m: f64) -> f64 {
    use statrs::function::gamma::ln_gamma;
    0.5 * std::f64::consts::PI.sqrt() * (ln_gamma(0.5 * (m + 1.0)) - ln_gamma(0.5 * m + 1.0)).exp()
}