//! Numbers as the reports print them, for every layer that prints one (the integrators'
//! report notes as well as `crate::report`).

/// A rate with a k or M prefix and three decimals; small rates (passes/s) plain with two.
pub fn mega(x: f64) -> String {
    if x >= 1e6 {
        format!("{:.3} M", x / 1e6)
    } else if x >= 1e3 {
        format!("{:.3} k", x / 1e3)
    } else {
        format!("{x:.2}")
    }
}
