//! Numbers as the report, the plot and the thesis tables write them, and the fitted slope
//! their legends and tables share.

use super::{Comparison, RunResult, fit_log_slope};
use crate::integrators::IntegratorKind;

/// A number in three significant digits, scientific when small or large.
pub fn sci(x: f64) -> String {
    if !x.is_finite() {
        return if x > 0.0 { "inf".into() } else { "n/a".into() };
    }
    if x != 0.0 && !(1e-2..1e4).contains(&x.abs()) {
        format!("{x:.2e}")
    } else {
        format!("{x:.3}")
    }
}

/// Seconds, with fewer decimals as they grow.
pub fn secs(t: f64) -> String {
    if t < 0.01 {
        format!("{t:.1e}")
    } else if t >= 100.0 {
        format!("{t:.0}")
    } else if t >= 10.0 {
        format!("{t:.1}")
    } else {
        format!("{t:.2}")
    }
}

/// An integrator's runs as (wall seconds, relMSE), sorted by time.
pub fn points(runs: &[&RunResult]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = runs.iter().map(|r| (r.wall, r.metrics.relmse)).collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    p
}

/// An integrator's fitted slope for legends and tables.
pub fn slope_of(c: &Comparison, kind: IntegratorKind) -> Option<f64> {
    fit_log_slope(&points(&c.runs_of(kind)))
}
