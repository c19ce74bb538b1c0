//! Film sums in fixed point: each sample's channels are rounded once to whole units of the
//! film and summed as `i128`. Integer addition is associative, so a pixel's sum does not
//! depend on the order its samples came in, and the films of disjoint pass ranges (shards, a
//! resumed render) add up to the film of all the passes, bit for bit.
//!
//! The unit is 2^(E - 64), where E, the film's unit exponent, is taken from the scene: the
//! power of two of its brightest emission (`unit_exponent`; 2^-64 exactly for a brightest
//! emission between 1 and 2). A sum holds up to 2^(E + 63) in magnitude, so the range and the
//! precision follow the scene's light, whatever its units: emission of 1e-20 and of 1e20
//! render the same image, scaled. Every film of one scene has the same unit, so shards and
//! resumed renders add; films made from f64 images (the biased integrators) take theirs from
//! their largest sum.
//!
//! What the rounding costs, with L the brightest emission (2^E <= L < 2^(E+1)): a sample of
//! magnitude 2^(E-41) (about L x 4.5e-13) or more is a whole number of units and is added
//! exactly; a smaller one is rounded to the nearest unit, off by at most 2^(E-65) (L x
//! 2.7e-20), so a pixel's mean is off by at most that, whatever the sample count. The sum
//! itself is then exact, where an f64 running sum rounds at every addition (relative 2^-53
//! each). The sum is rounded to f64 once, when it is read.
//!
//! The range: a sum must stay within +-2^(E+63) (L x 4.6e18 at least). A sample whose
//! channel is beyond it, or whose addition would take its pixel's sum beyond it, is rejected
//! and counted (the film's `out_of_range`), never wrapped; with samples below L x 2^32 a pixel
//! holds 2^31 of them before that can happen. Whether a sum overflows depends on the order of
//! its samples only at the edge of the range, and such a rejection is reported either way.

use glam::{DVec3, Vec3};

/// Fractional bits below the film's scale 2^E: the unit is 2^(E - 64).
pub const FRACTION_BITS: i32 = 64;

/// Bytes of one pixel's three sums (little-endian two's complement).
pub const FIXED_RGB_BYTES: usize = 3 * 16;

/// The unit exponent of a film for a scene whose brightest emission channel is `brightest`:
/// its power of two, floor(log2(brightest)), so that 2^E <= brightest < 2^(E+1). 0 (unit
/// 2^-64) for a scene without light.
pub fn unit_exponent(brightest: f32) -> i32 {
    if !(brightest.is_finite() && brightest > 0.0) {
        return 0;
    }
    let biased = ((brightest.to_bits() >> 23) & 0xff) as i32;
    // Subnormal light (below 2^-126) sums in the unit of 2^-126: still exact to 2^-167.
    biased.max(1) - 127
}

/// The unit exponent of a film made from f64 sums whose largest magnitude is `largest`: 40
/// binary orders below it, so that the largest sum is held to 2^-104 of itself and 2^22 such
/// films add without leaving the range. 0 when there is no finite non-zero sum.
pub fn unit_exponent_of_sums(largest: f64) -> i32 {
    if !(largest.is_finite() && largest > 0.0) {
        return 0;
    }
    let biased = ((largest.to_bits() >> 52) & 0x7ff) as i32;
    // Kept where 2^(E - 64) and 2^(E + 63) are normal f64 numbers.
    (biased.max(1) - 1023 - 40).clamp(-900, 900)
}

/// A filter weight (in [0, 1]) in units of 2^-64, rounded to nearest: weights sum exactly,
/// in any order, as the samples do. None when it is not finite or not below 2^63.
#[inline]
pub fn weight_units(w: f32) -> Option<i128> {
    units_of_f32(w, 0)
}

/// Units of 2^-64 (`weight_units`) back to f64.
pub fn weight_of_units(units: i128) -> f64 {
    f64_of_units(units, 0)
}

/// Why a sample did not go into a sum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rejected {
    /// A channel is NaN or infinite.
    NonFinite,
    /// A channel, or the pixel's sum with it, is beyond +-2^(E+63).
    OutOfRange,
}

/// `v` in units of 2^(exponent - 64), rounded to nearest (ties to even); None beyond
/// +-2^(exponent + 63) or not finite.
#[inline]
fn units_of_f32(v: f32, exponent: i32) -> Option<i128> {
    let bits = v.to_bits();
    let biased = ((bits >> 23) & 0xff) as i32;
    if biased == 0xff {
        return None;
    }
    let fraction = (bits & 0x7f_ffff) as u64;
    let mantissa = if biased == 0 {
        fraction
    } else {
        fraction | 1 << 23
    };
    // |v| = mantissa * 2^(max(biased, 1) - 150) = mantissa * 2^shift units.
    let shift = biased.max(1) - 150 + FRACTION_BITS - exponent;
    // mantissa < 2^24: up to shift 103 the units stay below 2^127; from 104 on (a normal
    // mantissa) |v| >= 2^(exponent + 63).
    if shift >= 104 {
        return None;
    }
    let magnitude = if shift >= 0 {
        (mantissa as i128) << shift
    } else {
        let r = shift.unsigned_abs();
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

/// `v` in units of 2^(exponent - 64), rounded to nearest (ties to even); None beyond
/// +-2^(exponent + 63) or not finite.
fn units_of_f64(v: f64, exponent: i32) -> Option<i128> {
    if v.is_nan() || v.abs() >= 2f64.powi(63 + exponent) {
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
    let shift = biased.max(1) - 1075 + FRACTION_BITS - exponent;
    let magnitude = if shift >= 0 {
        mantissa << shift
    } else {
        let r = shift.unsigned_abs();
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

/// Units of 2^(exponent - 64) to f64, rounded to nearest.
#[inline]
fn f64_of_units(units: i128, exponent: i32) -> f64 {
    // `as` rounds to nearest; scaling by a power of two is exact here.
    units as f64 * 2f64.powi(exponent - FRACTION_BITS)
}

/// Units of 2^(from - 64) in units of 2^(to - 64), rounded to nearest (ties to even); None
/// when they do not fit.
fn rescale_units(units: i128, from: i32, to: i32) -> Option<i128> {
    let magnitude = units.unsigned_abs();
    let scaled = if to <= from {
        let up = (from - to).unsigned_abs();
        match magnitude {
            0 => 0,
            _ if up >= 127 => return None,
            _ => magnitude.checked_mul(1u128 << up)?,
        }
    } else {
        let down = (to - from).unsigned_abs();
        if down >= 128 {
            0
        } else {
            let kept = magnitude >> down;
            let rest = magnitude & ((1u128 << down) - 1);
            let half = 1u128 << (down - 1);
            kept + u128::from(rest > half || (rest == half && kept & 1 == 1))
        }
    };
    let signed = i128::try_from(scaled).ok()?;
    Some(if units < 0 { -signed } else { signed })
}

/// The fixed-point sums of a pixel's three channels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FixedRgb(pub [i128; 3]);

impl FixedRgb {
    pub const ZERO: FixedRgb = FixedRgb([0; 3]);

    /// A sample, each channel rounded to the unit 2^(exponent - 64).
    #[inline(always)]
    pub fn of(value: Vec3, exponent: i32) -> Result<FixedRgb, Rejected> {
        match (
            units_of_f32(value.x, exponent),
            units_of_f32(value.y, exponent),
            units_of_f32(value.z, exponent),
        ) {
            (Some(x), Some(y), Some(z)) => Ok(FixedRgb([x, y, z])),
            _ if !value.is_finite() => Err(Rejected::NonFinite),
            _ => Err(Rejected::OutOfRange),
        }
    }

    /// Adds a sample in units of 2^(exponent - 64) (nothing is added when it is rejected).
    #[inline(always)]
    pub fn add_sample(&mut self, value: Vec3, exponent: i32) -> Result<(), Rejected> {
        let units = FixedRgb::of(value, exponent)?;
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

    /// The sums, in units of 2^(exponent - 64), each rounded to the nearest f64.
    pub fn to_dvec3(&self, exponent: i32) -> DVec3 {
        let [x, y, z] = self.0;
        DVec3::new(
            f64_of_units(x, exponent),
            f64_of_units(y, exponent),
            f64_of_units(z, exponent),
        )
    }

    /// f64 sums (a film made from an f64 image, an older checkpoint's sums), each rounded to
    /// the unit 2^(exponent - 64); None when a channel is not finite or beyond
    /// +-2^(exponent + 63).
    pub fn from_dvec3(v: DVec3, exponent: i32) -> Option<FixedRgb> {
        Some(FixedRgb([
            units_of_f64(v.x, exponent)?,
            units_of_f64(v.y, exponent)?,
            units_of_f64(v.z, exponent)?,
        ]))
    }

    /// The sums in units of 2^(from - 64) as sums in units of 2^(to - 64), each rounded to
    /// the nearest unit; None when a channel does not fit.
    pub fn rescaled(&self, from: i32, to: i32) -> Option<FixedRgb> {
        let [x, y, z] = self.0;
        Some(FixedRgb([
            rescale_units(x, from, to)?,
            rescale_units(y, from, to)?,
            rescale_units(z, from, to)?,
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
            let units = units_of_f32(v, 0).unwrap();
            assert_eq!(f64_of_units(units, 0), v as f64, "{v}");
        }
    }

    #[test]
    fn smaller_samples_round_to_the_nearest_unit_ties_to_even() {
        let u = unit() as f32;
        assert_eq!(units_of_f32(0.5 * u, 0), Some(0), "a tie goes to even (0)");
        assert_eq!(units_of_f32(1.5 * u, 0), Some(2), "a tie goes to even (2)");
        assert_eq!(units_of_f32(2.5 * u, 0), Some(2));
        assert_eq!(units_of_f32(0.75 * u, 0), Some(1));
        assert_eq!(units_of_f32(-0.75 * u, 0), Some(-1));
        assert_eq!(units_of_f32(0.25 * u, 0), Some(0));
        assert_eq!(units_of_f32(1e-45, 0), Some(0), "the smallest subnormal");
        assert_eq!(units_of_f32(-0.0, 0), Some(0));
        // Against an independent rounding in f64 (exact: these have few bits).
        for k in 1..2000 {
            let v = k as f32 * 0.001 * 2f32.powi(-50);
            let expected = (v as f64 / unit()).round_ties_even() as i128;
            assert_eq!(units_of_f32(v, 0), Some(expected), "{v}");
        }
    }

    #[test]
    fn the_range_ends_at_2_to_the_63() {
        assert_eq!(units_of_f32(2f32.powi(63), 0), None);
        assert_eq!(units_of_f32(-2f32.powi(63), 0), None);
        assert_eq!(units_of_f32(f32::INFINITY, 0), None);
        assert_eq!(units_of_f32(f32::NAN, 0), None);
        assert_eq!(
            FixedRgb::of(Vec3::new(1.0, f32::NAN, 0.0), 0),
            Err(Rejected::NonFinite)
        );
        assert_eq!(
            FixedRgb::of(Vec3::new(1.0, 1e30, 0.0), 0),
            Err(Rejected::OutOfRange)
        );
        // A sum that would leave the range is refused and left as it was.
        let mut s = FixedRgb::ZERO;
        let big = Vec3::splat(2f32.powi(62) * 1.5);
        assert_eq!(s.add_sample(big, 0), Ok(()));
        let before = s;
        assert_eq!(s.add_sample(big, 0), Err(Rejected::OutOfRange));
        assert_eq!(s, before);
        assert_eq!(s.add_sample(-big, 0), Ok(()));
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
                s.add_sample(v, 0).unwrap();
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
        assert_eq!(s.to_dvec3(0).x, 1e-10f32 as f64);
        assert_eq!((1e10f64 + 1e-10f32 as f64) - 1e10, 0.0);
    }

    #[test]
    fn f64_values_round_to_the_unit() {
        assert_eq!(units_of_f64(1.0, 0), Some(1 << 64));
        assert_eq!(units_of_f64(-2.5, 0), Some(-(5 << 63)));
        assert_eq!(units_of_f64(0.3 * unit(), 0), Some(0));
        assert_eq!(units_of_f64(0.5 * unit(), 0), Some(0));
        assert_eq!(units_of_f64(0.7 * unit(), 0), Some(1));
        assert_eq!(units_of_f64(1e-300, 0), Some(0));
        assert_eq!(units_of_f64(2f64.powi(63), 0), None);
        assert_eq!(units_of_f64(f64::NAN, 0), None);
        let v = 1234.5678901234;
        assert_eq!(f64_of_units(units_of_f64(v, 0).unwrap(), 0), v);
        let back = FixedRgb::from_le_bytes(
            &FixedRgb::from_dvec3(DVec3::new(-3.25, 1e18, 7.0 * 2f64.powi(-40)), 0)
                .unwrap()
                .to_le_bytes(),
        );
        assert_eq!(
            back.to_dvec3(0),
            DVec3::new(-3.25, 1e18, 7.0 * 2f64.powi(-40))
        );
    }

    #[test]
    fn a_scenes_unit_follows_its_brightest_light() {
        assert_eq!(unit_exponent(1.0), 0);
        assert_eq!(unit_exponent(1.999), 0);
        assert_eq!(unit_exponent(2.0), 1);
        assert_eq!(unit_exponent(17.0), 4);
        assert_eq!(unit_exponent(0.75), -1);
        assert_eq!(unit_exponent(1e30), 99);
        assert_eq!(unit_exponent(1e-20), -67);
        assert_eq!(unit_exponent(1e-45), -126);
        assert_eq!(unit_exponent(0.0), 0);
        assert_eq!(unit_exponent(f32::NAN), 0);
        // The same samples scaled by 2^k sum to the same units in a film of exponent E + k:
        // range and precision follow the light.
        let values: Vec<f32> = (1..500)
            .map(|i| (i as f32 * 0.731).sin() * 2f32.powi(i % 50 - 40))
            .collect();
        for k in [-100, -64, -20, 0, 33, 64, 99] {
            let scale = 2f32.powi(k);
            // (Where both are normal f32: scaling a subnormal loses bits.)
            for &v in values.iter().filter(|v| (**v * scale).is_normal()) {
                assert_eq!(
                    units_of_f32(v * scale, k),
                    units_of_f32(v, 0),
                    "{v} x 2^{k}"
                );
            }
            // The range ends at 2^(E + 63).
            if 62 + k < 127 {
                assert_eq!(units_of_f32(2f32.powi(62) * 1.5 * scale, k), Some(3 << 125));
            }
            if k + 63 < 128 {
                assert_eq!(units_of_f32(2f32.powi(63 + k), k), None, "2^(63 + {k})");
            }
            assert_eq!(units_of_f32(f32::INFINITY, k), None);
            assert_eq!(units_of_f32(f32::NAN, k), None);
            let v = 1234.5678901234 * 2f64.powi(k);
            assert_eq!(f64_of_units(units_of_f64(v, k).unwrap(), k), v);
            assert_eq!(units_of_f64(2f64.powi(63 + k), k), None);
        }
        // Without it, light of 2^-70 would round to nothing and light of 2^64 be rejected.
        assert_eq!(units_of_f32(2f32.powi(-70), 0), Some(0));
        assert_eq!(units_of_f32(2f32.powi(64), 0), None);
    }

    #[test]
    fn rescaling_rounds_to_the_coarser_unit_and_refuses_what_does_not_fit() {
        assert_eq!(rescale_units(12, 0, 2), Some(3));
        assert_eq!(rescale_units(-12, 0, 2), Some(-3));
        assert_eq!(rescale_units(10, 0, 2), Some(2), "2.5 ties to even");
        assert_eq!(rescale_units(14, 0, 2), Some(4), "3.5 ties to even");
        assert_eq!(rescale_units(11, 0, 2), Some(3));
        assert_eq!(rescale_units(5, 0, 200), Some(0));
        assert_eq!(rescale_units(3, 2, 0), Some(12));
        assert_eq!(rescale_units(-3, 2, 0), Some(-12));
        assert_eq!(rescale_units(1 << 100, 30, 0), None);
        assert_eq!(rescale_units(0, 300, 0), Some(0));
        assert_eq!(rescale_units(7, 5, 5), Some(7));
        let v = DVec3::new(1.5, -2.25, 1e10);
        let fine = FixedRgb::from_dvec3(v, -10).unwrap();
        assert_eq!(fine.rescaled(-10, 3).unwrap().to_dvec3(3), v);
    }

    #[test]
    fn sums_take_their_unit_from_their_largest() {
        assert_eq!(unit_exponent_of_sums(1.0), -40);
        assert_eq!(unit_exponent_of_sums(3.0e9), 31 - 40);
        assert_eq!(unit_exponent_of_sums(0.0), 0);
        assert_eq!(unit_exponent_of_sums(f64::INFINITY), 0);
        assert_eq!(unit_exponent_of_sums(1e300), 900);
        assert_eq!(unit_exponent_of_sums(1e-300), -900);
    }
}
