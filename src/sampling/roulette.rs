//! Russian roulette, one rule for every walk (camera paths, subpaths, camera chains,
//! photons): a walk survives with probability q = min(max channel of its throughput relative
//! to where it started, `MAX_SURVIVAL`) and its throughput is divided by q, which keeps every
//! estimate unbiased.

use glam::Vec3;

/// Roulette starts after this many bounces (camera walks; photons play it at every bounce,
/// by the bounce's weight).
pub const ROULETTE_DEPTH: u32 = 3;

/// Highest survival probability: even a walk whose throughput stays at 1 (a closed scene of
/// reflectance 1, a lossless glass cube) ends after about 1 / (1 - 0.95) = 20 more bounces on
/// average, so every wave terminates.
pub const MAX_SURVIVAL: f32 = 0.95;

/// Survival probability of a walk with throughput `beta` that started at `scale`.
#[inline]
pub fn survival(beta: Vec3, scale: f32) -> f32 {
    (beta.max_element() / scale).min(MAX_SURVIVAL)
}

/// Whether a walk with survival probability `q` survives the roulette number `u`. A NaN or
/// non-positive `q` ends it.
#[inline]
pub fn survives(q: f32, u: f32) -> bool {
    !(q.is_nan() || q <= 0.0 || u >= q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn survival_is_capped_and_relative_to_the_start() {
        assert_eq!(survival(Vec3::new(0.2, 0.5, 0.1), 1.0), 0.5);
        assert_eq!(survival(Vec3::splat(4.0), 1.0), MAX_SURVIVAL);
        assert_eq!(survival(Vec3::splat(2.0), 4.0), 0.5);
        assert!(survives(0.5, 0.49) && !survives(0.5, 0.5));
        assert!(!survives(f32::NAN, 0.0) && !survives(0.0, 0.0));
    }
}
