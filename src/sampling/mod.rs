//! Random numbers and warps from the unit square.
//!
//! Every random number is a pure function of (seed, stream, sample, dimension), where the
//! stream is a pixel (or a light path's index) and the sample is its sample index. No generator
//! carries state between threads, so the image does not depend on which thread ran which path.
//! Which numbers those are is the render's [`Sampler`]'s choice (independent hashes,
//! Owen-scrambled Sobol', or a primary-sample store).

mod morton;
mod primary;
pub mod roulette;
mod sampler;
mod sobol;
pub use primary::{PrimarySamples, SampleBlock};
pub use sampler::{
    DEFAULT_LOG2_SPP, MAX_LOG2_RES, MAX_LOG2_SPP, PRIMARY_STREAMS, Sampler, SamplerKind, Stream,
    UnknownSampler,
};

use crate::lanes::{Real, V3};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A 64-bit mixing function (the finaliser of SplitMix64): a bijection with good avalanche.
#[inline]
pub fn mix64(mut x: u64) -> u64 {
    x ^= x >> 30;
    x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x ^= x >> 27;
    x = x.wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The random-number source of one (seed, stream, sample): `get(dim)` is a pure function of its
/// four inputs. Copy it freely; it is 8 bytes (it is stored per path slot, vertex and photon).
///
/// `SampleKey::new` and `get` are the independent sampler's hash. A key made by
/// [`Sampler::key`] is only meaningful to that sampler's `get`/`get2` (a Sobol key packs its
/// stream, batch and Sobol' index, a primary key its stream and slot); under
/// `Sampler::Independent` the two ways agree bit for bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleKey(u64);

impl SampleKey {
    /// The independent sampler's key of (seed, tagged stream index, sample).
    #[inline]
    pub fn new(seed: u64, stream: u64, sample: u64) -> SampleKey {
        let a = mix64(seed ^ 0x9e37_79b9_7f4a_7c15);
        let b = mix64(a ^ stream.wrapping_mul(0xd1b5_4a32_d192_ed03));
        SampleKey(mix64(b ^ sample.wrapping_mul(0x8cb9_2ba7_2f3d_8dd7)))
    }

    /// The key's 64 bits, as a seed for further keys.
    #[inline]
    pub fn bits(self) -> u64 {
        self.0
    }

    /// A uniform number in [0, 1) for dimension `dim`.
    #[inline]
    pub fn get(self, dim: u32) -> f32 {
        let bits = mix64(self.0 ^ (dim as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        // 24 random bits: exactly representable, strictly below 1.
        (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    #[inline]
    pub fn get2(self, dim: u32) -> Vec2 {
        Vec2::new(self.get(dim), self.get(dim + 1))
    }

    /// `keys[l].get(dims[l])` for every lane, written so that the compiler runs the hash in
    /// vector lanes (the same numbers as `get`).
    #[inline(always)]
    pub fn get_lanes<const N: usize>(keys: &[SampleKey; N], dims: &[u32; N]) -> [f32; N] {
        let mut out = [0.0; N];
        for l in 0..N {
            out[l] = keys[l].get(dims[l]);
        }
        out
    }
}

/// Cosine-weighted direction on the +z hemisphere (concentric mapping, Shirley and Chiu).
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    cosine_hemisphere_of(u.x, u.y).into()
}

/// `cosine_hemisphere` for one path (`f32`) or lanes (`F<N>`): the one body of both.
#[inline(always)]
pub fn cosine_hemisphere_of<T: Real>(ux: T, uy: T) -> V3<T> {
    let (dx, dy) = concentric_disk_of(ux, uy);
    let z = (T::splat(1.0) - dx * dx - dy * dy)
        .max(T::splat(0.0))
        .sqrt();
    V3::new(dx, dy, z)
}

/// Uniform point on the unit disk with low distortion (Shirley and Chiu's concentric map).
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let (x, y) = concentric_disk_of(u.x, u.y);
    Vec2::new(x, y)
}

/// `concentric_disk` for one path or lanes.
#[inline(always)]
pub fn concentric_disk_of<T: Real>(ux: T, uy: T) -> (T, T) {
    let (ox, oy) = (T::splat(2.0) * ux - 1.0, T::splat(2.0) * uy - 1.0);
    let zero = T::splat(0.0);
    let centre = ox.equal(zero) & oy.equal(zero);
    let wide = ox.abs().greater(oy.abs());
    let r = T::select(wide, ox, oy);
    // The angle is phi (wide) or pi/2 - phi, with phi within [-pi/4, pi/4]: its sine and
    // cosine swap for the second.
    let phi = T::splat(0.25 * PI) * T::select(wide, oy / ox, ox / oy);
    let (sin, cos) = phi.sin_cos_quarter();
    // The centre's phi is 0 / 0: its lanes take 0 whatever the sine and cosine give.
    (
        T::select(centre, zero, r * T::select(wide, cos, sin)),
        T::select(centre, zero, r * T::select(wide, sin, cos)),
    )
}

/// Uniform barycentrics (b1, b2) on a triangle (the square-root parameterisation).
#[inline]
pub fn uniform_triangle(u: Vec2) -> Vec2 {
    let su = u.x.sqrt();
    Vec2::new(1.0 - su, u.y * su)
}

/// The density of `uniform_sphere`'s directions: 1 / (4 pi).
pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * std::f32::consts::PI);

/// Uniform direction on the unit sphere.
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// The power heuristic (beta = 2) weight of a strategy with density `f` against one with `g`.
#[inline]
pub fn power_heuristic(f: f32, g: f32) -> f32 {
    let f2 = f * f;
    let g2 = g * g;
    if f2 + g2 == 0.0 {
        0.0
    } else if f2.is_infinite() {
        1.0
    } else {
        f2 / (f2 + g2)
    }
}

/// Index of the first cdf entry greater than `u`, for a cdf that ends at 1.
#[inline]
pub fn sample_cdf(cdf: &[f32], u: f32) -> usize {
    cdf.partition_point(|&c| c <= u).min(cdf.len() - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_key_is_pure_and_uniform() {
        let k = SampleKey::new(7, 123, 4);
        assert_eq!(k.get(5), SampleKey::new(7, 123, 4).get(5));
        assert_ne!(k.get(5), SampleKey::new(7, 124, 4).get(5));
        let n = 100_000;
        let mut bins = [0u32; 10];
        for s in 0..n {
            let x = SampleKey::new(1, 2, s).get(3);
            assert!((0.0..1.0).contains(&x));
            bins[(x * 10.0) as usize] += 1;
        }
        // Chi-square with 9 degrees of freedom; 27.9 is the 0.1% critical value.
        let expected = n as f64 / 10.0;
        let chi2: f64 = bins
            .iter()
            .map(|&b| (b as f64 - expected).powi(2) / expected)
            .sum();
        assert!(chi2 < 27.9, "chi2 = {chi2}");
    }

    #[test]
    fn warps_stay_on_their_domains() {
        for i in 0..64 {
            for j in 0..64 {
                let u = Vec2::new(i as f32 / 64.0, j as f32 / 64.0);
                let d = cosine_hemisphere(u);
                assert!((d.length() - 1.0).abs() < 1e-4 && d.z >= 0.0);
                let b = uniform_triangle(u);
                assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
                assert!((uniform_sphere(u).length() - 1.0).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn sample_cdf_picks_by_weight() {
        let cdf = [0.25, 0.25, 1.0];
        assert_eq!(sample_cdf(&cdf, 0.0), 0);
        assert_eq!(sample_cdf(&cdf, 0.2499), 0);
        assert_eq!(sample_cdf(&cdf, 0.25), 2);
        assert_eq!(sample_cdf(&cdf, 0.99), 2);
    }
}
