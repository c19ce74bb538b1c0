//! Film sums in fixed point: each sample's channels are rounded once to whole units of 2^-64
//! and summed as `i128`. Integer addition is associative, so a pixel's sum does not depend on
//! the order its samples came in, and the films of disjoint pass ranges (shards, a resumed
//! render) add up to the film of all the passes, bit for bit.
//!
//! What the rounding costs: an f32 sample of magnitude 2^-41 (4.5e-13) or more is a whole
//! number of units and is added exactly; a smaller one is rounded to the nearest unit, off by
//! at most 2^-65 (2.7e-20), so a pixel's mean is off by at most 2^-65 in absolute terms
//! whatever the sample count. The sum itself is then exact, where an f64 running sum rounds
//! at every addition (relative 2^-53 each). The sum is rounded to f64 once, when it is read.
//!
//! The range: a sum must stay within +-2^63 (9.2e18). A sample whose channel is beyond it, or
//! whose addition would take its pixel's sum beyond it, is rejected and counted (the film's
//! `out_of_range`), never wrapped; with samples below 2^32 a pixel holds 2^31 of them before
//! that can happen. Whether a sum overflows depends on the order of its samples only at the
//! edge of the range, and such a rejection is reported either way. The scene format keeps
//! every emission channel at most 2^32 and the brightest at least 2^-32
//! (`scene::format::MAX_RADIANCE`, `MIN_BRIGHTEST_RADIANCE`), so that scenes stay inside
//! both ends of this range.

use glam::{DVec3, Vec3};

/// Fractional bits: the unit is 2^-64.
pub const FRACTION_BITS: i32 = 64;

/// Bytes of one pixel's three sums (little-endian two's complement).
pub const FIXED_RGB_BYTES: usize = 3 * 16;

/// Why a sample did not go into a sum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rejected {
    /// A channel is NaN or infinite.
    NonFinite,
    /// A channel, or the pixel's sum with it, is beyond +-2^63.
    OutOfRange,
}

/// `v` in units of 2^-64, rounded to nearest (ties to even); None beyond +-2^63 or not finite.
#[inline]
fn units_of_f32(v: f32) -> Option<i128> {
    let bits = v.to_bits();
    let biased = (bits >> 23) & 0xff;
    // 2^63 has biased exponent 127 + 63: it and everything above (infinities, NaN) are out.
    if biased >= 127 + 63 {
        return None;
    }
    let fraction = (bits & 0x7f_ffff) as u64;
    let mantissa = if biased == 0 {
        fraction
    } else {
        fraction | 1 << 23
    };
    // |v| = mantissa * 2^(max(biased, 1) - 150) = mantissa * 2^shift units.
    let shift = biased.max(1) as i32 - 150 + FRACTION_BITS;
    let magnitude = if shift >= 0 {
        (mantissa as i128) << shift
    } else {
        let r = (-shift) as u32;
        // mantissa < 2^24: from 2^-25 of a unit down, everything rounds to 0.
        if r >= 25 {
            0
        } else {
            let kept = mantissa >> r;
            let rest = mantissa & ((1 << r) - 1);
            let half = 1 << (r - 1);
            (kept + u64::from(rest > half || (rest == half && kept & 1 == 1))) as i128
        }
    };
    Some(if bits >> 31 == 1 {
        -magnitude
    } else {
        magnitude
    })
}

/// `v` in units of 2^-64, rounded to nearest (ties to even); None beyond +-2^63 or not finite.
fn units_of_f64(v: f64) -> Option<i128> {
    if v.is_nan() || v.abs() >= 2f64.powi(63) {
        return None;
    }
    let bits = v.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1 << 52) - 1);
    let mantissa = if biased == 0 {
        fraction
    } else {
        fraction | 1 << 52
    } as u128;
    let shift = biased.max(1) - 1075 + FRACTION_BITS;
    let magnitude = if shift >= 0 {
        mantissa << shift
    } else {
        let r = (-shift) as u32;
        if r >= 54 {
            0
        } else {
            let kept = mantissa >> r;
            let rest = mantissa & ((1 << r) - 1);
            let half = 1 << (r - 1);
            kept + u128::from(rest > half || (rest == half && kept & 1 == 1))
        }
    } as i128;
    Some(if v < 0.0 { -magnitude } else { magnitude })
}

/// Units to f64, rounded to nearest.
#[inline]
fn f64_of_units(units: i128) -> f64 {
    // `as` rounds to nearest; scaling by a power of two is exact here.
    units as f64 * 2f64.powi(-FRACTION_BITS)
}

/// The fixed-point sums of a pixel's three channels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FixedRgb(pub [i128; 3]);

impl FixedRgb {
    pub const ZERO: FixedRgb = FixedRgb([0; 3]);

    /// A sample, each channel rounded to the unit.
    #[inline]
    pub fn of(value: Vec3) -> Result<FixedRgb, Rejected> {
        match (
            units_of_f32(value.x),
            units_of_f32(value.y),
            units_of_f32(value.z),
        ) {
            (Some(x), Some(y), Some(z)) => Ok(FixedRgb([x, y, z])),
            _ if !value.is_finite() => Err(Rejected::NonFinite),
            _ => Err(Rejected::OutOfRange),
        }
    }

    /// Adds a sample (nothing is added when it is rejected).
    #[inline]
    pub fn add_sample(&mut self, value: Vec3) -> Result<(), Rejected> {
        let units = FixedRgb::of(value)?;
        *self = self.checked_add(&units).ok_or(Rejected::OutOfRange)?;
        Ok(())
    }

    /// The sum of two sums; None when a channel would leave the range.
    #[inline]
    pub fn checked_add(&self, other: &FixedRgb) -> Option<FixedRgb> {
        let [a, b, c] = self.0;
        let [x, y, z] = other.0;
        Some(FixedRgb([
            a.checked_add(x)?,
            b.checked_add(y)?,
            c.checked_add(z)?,
        ]))
    }

    /// The sums, each rounded to the nearest f64.
    pub fn to_dvec3(&self) -> DVec3 {
        let [x, y, z] = self.0;
        DVec3::new(f64_of_units(x), f64_of_units(y), f64_of_units(z))
    }

    /// f64 sums (a film made from an f64 image, an older checkpoint's sums), each rounded to
    /// the unit; None when a channel is not finite or beyond +-2^63.
    pub fn from_dvec3(v: DVec3) -> Option<FixedRgb> {
        Some(FixedRgb([
            units_of_f64(v.x)?,
            units_of_f64(v.y)?,
            units_of_f64(v.z)?,
        ]))
    }

    pub fn is_zero(&self) -> bool {
        *self == FixedRgb::ZERO
    }

    pub fn to_le_bytes(&self) -> [u8; FIXED_RGB_BYTES] {
        let mut out = [0; FIXED_RGB_BYTES];
        for (chunk, v) in out.chunks_exact_mut(16).zip(self.0) {
            chunk.copy_from_slice(&v.to_le_bytes());
        }
        out
    }

    /// From `FIXED_RGB_BYTES` bytes (panics on another length).
    pub fn from_le_bytes(bytes: &[u8]) -> FixedRgb {
        let channel = |i: usize| {
            let mut b = [0; 16];
            b.copy_from_slice(&bytes[16 * i..16 * i + 16]);
            i128::from_le_bytes(b)
        };
        assert_eq!(bytes.len(), FIXED_RGB_BYTES);
        FixedRgb([channel(0), channel(1), channel(2)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact value of `units` as a rational: compared in f64 only where that is exact.
    fn unit() -> f64 {
        2f64.powi(-FRACTION_BITS)
    }

    #[test]
    fn samples_from_2_to_the_minus_41_up_are_held_exactly() {
        for v in [
            1.0f32,
            -1.0,
            0.1,
            17.3,
            -3.0e-5,
            2f32.powi(-41),
            1.5 * 2f32.powi(-41),
            2f32.powi(62) * 1.9999,
            -2f32.powi(62),
        ] {
            let units = units_of_f32(v).unwrap();
            assert_eq!(f64_of_units(units), v as f64, "{v}");
        }
    }

    #[test]
    fn smaller_samples_round_to_the_nearest_unit_ties_to_even() {
        let u = unit() as f32;
        assert_eq!(units_of_f32(0.5 * u), Some(0), "a tie goes to even (0)");
        assert_eq!(units_of_f32(1.5 * u), Some(2), "a tie goes to even (2)");
        assert_eq!(units_of_f32(2.5 * u), Some(2));
        assert_eq!(units_of_f32(0.75 * u), Some(1));
        assert_eq!(units_of_f32(-0.75 * u), Some(-1));
        assert_eq!(units_of_f32(0.25 * u), Some(0));
        assert_eq!(units_of_f32(1e-45), Some(0), "the smallest subnormal");
        assert_eq!(units_of_f32(-0.0), Some(0));
        // Against an independent rounding in f64 (exact: these have few bits).
        for k in 1..2000 {
            let v = k as f32 * 0.001 * 2f32.powi(-50);
            let expected = (v as f64 / unit()).round_ties_even() as i128;
            assert_eq!(units_of_f32(v), Some(expected), "{v}");
        }
    }

    #[test]
    fn the_range_ends_at_2_to_the_63() {
        assert_eq!(units_of_f32(2f32.powi(63)), None);
        assert_eq!(units_of_f32(-2f32.powi(63)), None);
        assert_eq!(units_of_f32(f32::INFINITY), None);
        assert_eq!(units_of_f32(f32::NAN), None);
        assert_eq!(
            FixedRgb::of(Vec3::new(1.0, f32::NAN, 0.0)),
            Err(Rejected::NonFinite)
        );
        assert_eq!(
            FixedRgb::of(Vec3::new(1.0, 1e30, 0.0)),
            Err(Rejected::OutOfRange)
        );
        // A sum that would leave the range is refused and left as it was.
        let mut s = FixedRgb::ZERO;
        let big = Vec3::splat(2f32.powi(62) * 1.5);
        assert_eq!(s.add_sample(big), Ok(()));
        let before = s;
        assert_eq!(s.add_sample(big), Err(Rejected::OutOfRange));
        assert_eq!(s, before);
        assert_eq!(s.add_sample(-big), Ok(()));
        assert!(s.is_zero());
    }

    #[test]
    fn order_and_grouping_do_not_change_the_sum() {
        let values: Vec<Vec3> = (0..1000)
            .map(|i| {
                let x = (i as f32 * 0.37).sin() * 10f32.powi(i % 13 - 6);
                Vec3::new(x, -x * 0.5, x * x)
            })
            .collect();
        let sum_of = |vs: &[Vec3]| {
            let mut s = FixedRgb::ZERO;
            for &v in vs {
                s.add_sample(v).unwrap();
            }
            s
        };
        let whole = sum_of(&values);
        let mut reversed = values.clone();
        reversed.reverse();
        assert_eq!(sum_of(&reversed), whole);
        let parts = sum_of(&values[..333])
            .checked_add(&sum_of(&values[333..]))
            .unwrap();
        assert_eq!(parts, whole);
        // And it is the exact sum where f64 can tell: 1e10 + 1e-10 - 1e10 in f64 loses the
        // small term; here it survives to within one unit's rounding.
        let s = sum_of(&[Vec3::splat(1e10), Vec3::splat(1e-10), Vec3::splat(-1e10)]);
        assert_eq!(s.to_dvec3().x, 1e-10f32 as f64);
        assert_eq!((1e10f64 + 1e-10f32 as f64) - 1e10, 0.0);
    }

    #[test]
    fn f64_values_round_to_the_unit() {
        assert_eq!(units_of_f64(1.0), Some(1 << 64));
        assert_eq!(units_of_f64(-2.5), Some(-(5 << 63)));
        assert_eq!(units_of_f64(0.3 * unit()), Some(0));
        assert_eq!(units_of_f64(0.5 * unit()), Some(0));
        assert_eq!(units_of_f64(0.7 * unit()), Some(1));
        assert_eq!(units_of_f64(1e-300), Some(0));
        assert_eq!(units_of_f64(2f64.powi(63)), None);
        assert_eq!(units_of_f64(f64::NAN), None);
        let v = 1234.5678901234;
        assert_eq!(f64_of_units(units_of_f64(v).unwrap()), v);
        let back = FixedRgb::from_le_bytes(
            &FixedRgb::from_dvec3(DVec3::new(-3.25, 1e18, 7.0 * 2f64.powi(-40)))
                .unwrap()
                .to_le_bytes(),
        );
        assert_eq!(
            back.to_dvec3(),
            DVec3::new(-3.25, 1e18, 7.0 * 2f64.powi(-40))
        );
    }
}
