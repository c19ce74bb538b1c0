//! Exact sums of f32 values: a fixed-point integer of 384 bits whose unit is 2^-149, the
//! smallest f32. Every finite f32 is a whole multiple of that unit and below 2^128, so any
//! sum of up to 2^62 of them is held exactly; and because integer addition is associative,
//! the sum does not depend on the order the values came in. That is what lets a render's
//! passes be split between machines (shards) and added back into the film one machine would
//! have made, bit for bit, and lets a film be added to a film.
//!
//! The value is rounded to f64 only when it is read (correctly rounded, to nearest).

/// 64-bit words of an exact sum, least significant first, two's complement.
pub const LIMBS: usize = 6;

/// log2 of the unit: the smallest f32 (subnormal) is 2^-149.
const UNIT_EXPONENT: i32 = -149;

/// An exact sum of f32 values (and of such sums).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ExactSum(pub [u64; LIMBS]);

/// 2^e as an f64, for e in the normal range.
fn power_of_two(e: i32) -> f64 {
    debug_assert!((-1022..=1023).contains(&e));
    f64::from_bits(((1023 + e) as u64) << 52)
}

impl ExactSum {
    pub const ZERO: ExactSum = ExactSum([0; LIMBS]);

    /// Adds a finite f32 (callers leave out NaN and infinities: they are counted, not added).
    #[inline]
    pub fn add_f32(&mut self, value: f32) {
        debug_assert!(value.is_finite());
        let bits = value.to_bits();
        let biased = (bits >> 23) & 0xff;
        let fraction = (bits & 0x7f_ffff) as u64;
        // value = mantissa * 2^(shift - 149)
        let (mantissa, shift) = if biased == 0 {
            (fraction, 0)
        } else {
            (fraction | 1 << 23, biased - 1)
        };
        if mantissa == 0 {
            return;
        }
        self.add_shifted(mantissa, shift, bits >> 31 == 1);
    }

    /// Adds (or subtracts) `mantissa * unit * 2^shift`; `mantissa` below 2^63.
    #[inline]
    fn add_shifted(&mut self, mantissa: u64, shift: u32, negative: bool) {
        let limb = (shift / 64) as usize;
        let offset = shift % 64;
        let low = mantissa << offset;
        let high = if offset == 0 {
            0
        } else {
            mantissa >> (64 - offset)
        };
        if negative {
            let (d, borrow) = self.0[limb].overflowing_sub(low);
            self.0[limb] = d;
            let mut borrow = high + borrow as u64;
            for word in &mut self.0[limb + 1..] {
                if borrow == 0 {
                    break;
                }
                let (d, b) = word.overflowing_sub(borrow);
                *word = d;
                borrow = b as u64;
            }
        } else {
            let (s, carry) = self.0[limb].overflowing_add(low);
            self.0[limb] = s;
            let mut carry = high + carry as u64;
            for word in &mut self.0[limb + 1..] {
                if carry == 0 {
                    break;
                }
                let (s, c) = word.overflowing_add(carry);
                *word = s;
                carry = c as u64;
            }
        }
    }

    /// Adds another exact sum.
    pub fn add(&mut self, other: &ExactSum) {
        let mut carry = false;
        for (a, &b) in self.0.iter_mut().zip(&other.0) {
            let (s1, c1) = a.overflowing_add(b);
            let (s2, c2) = s1.overflowing_add(carry as u64);
            *a = s2;
            carry = c1 || c2;
        }
    }

    fn is_negative(&self) -> bool {
        self.0[LIMBS - 1] >> 63 == 1
    }

    fn negated(&self) -> ExactSum {
        let mut out = ExactSum(self.0.map(|w| !w));
        out.add(&ExactSum::one_unit());
        out
    }

    fn one_unit() -> ExactSum {
        let mut one = ExactSum::ZERO;
        one.0[0] = 1;
        one
    }

    /// The sum, rounded to the nearest f64.
    pub fn to_f64(&self) -> f64 {
        let negative = self.is_negative();
        let magnitude = if negative { self.negated() } else { *self };
        let Some(top) = (0..LIMBS).rev().find(|&i| magnitude.0[i] != 0) else {
            return 0.0;
        };
        let value = if top == 0 {
            magnitude.0[0] as f64 * power_of_two(UNIT_EXPONENT)
        } else {
            // The two top words hold at least 65 significant bits; any bit below them only
            // breaks a tie, so it is folded into the lowest bit (a sticky bit).
            let mut wide = (magnitude.0[top] as u128) << 64 | magnitude.0[top - 1] as u128;
            if magnitude.0[..top - 1].iter().any(|&w| w != 0) {
                wide |= 1;
            }
            wide as f64 * power_of_two(64 * (top as i32 - 1) + UNIT_EXPONENT)
        };
        if negative { -value } else { value }
    }

    /// An f64 as an exact sum: None when it is not a whole number of units (below 2^-149's
    /// grid) or too large to hold (|v| >= 2^200), or not finite. Every partial sum of f32
    /// values that a film summed in f64 is a whole number of units.
    pub fn from_f64_exact(value: f64) -> Option<ExactSum> {
        let (mantissa, exponent) = decompose(value)?;
        let mut out = ExactSum::ZERO;
        if mantissa == 0 {
            return Some(out);
        }
        let shift = exponent - UNIT_EXPONENT;
        if shift < 0 {
            let drop = (-shift) as u32;
            if drop >= 64 || mantissa & ((1u64 << drop) - 1) != 0 {
                return None;
            }
            out.add_shifted(mantissa >> drop, 0, value < 0.0);
        } else {
            if shift + 53 > 349 {
                return None;
            }
            out.add_shifted(mantissa, shift as u32, value < 0.0);
        }
        Some(out)
    }

    /// An f64 as an exact sum, rounded to the nearest unit (ties to even) and clamped to
    /// +-2^200; NaN is 0. For films made from f64 images (the photon mappers, MLT).
    pub fn from_f64_rounded(value: f64) -> ExactSum {
        if let Some(exact) = ExactSum::from_f64_exact(value) {
            return exact;
        }
        let Some((mantissa, exponent)) = decompose(value) else {
            return ExactSum::ZERO;
        };
        let shift = exponent - UNIT_EXPONENT;
        let mut out = ExactSum::ZERO;
        if shift >= 0 {
            // Too large: the largest value held with this sign.
            out.add_shifted((1 << 53) - 1, 349 - 53, value < 0.0);
            return out;
        }
        let drop = (-shift) as u32;
        let units = if drop >= 64 {
            0
        } else {
            let kept = mantissa >> drop;
            let rest = mantissa & ((1u64 << drop) - 1);
            let half = 1u64 << (drop - 1);
            if rest > half || (rest == half && kept & 1 == 1) {
                kept + 1
            } else {
                kept
            }
        };
        if units != 0 {
            out.add_shifted(units, 0, value < 0.0);
        }
        out
    }
}

/// A finite f64 as (|mantissa|, exponent) with |v| = mantissa * 2^exponent; None for NaN and
/// infinities.
fn decompose(value: f64) -> Option<(u64, i32)> {
    if !value.is_finite() {
        return None;
    }
    let bits = value.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1 << 52) - 1);
    Some(if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | 1 << 52, biased - 1075)
    })
}

/// Exact sums of the three channels of a pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ExactRgb(pub [ExactSum; 3]);

impl ExactRgb {
    pub const ZERO: ExactRgb = ExactRgb([ExactSum::ZERO; 3]);

    /// Adds a finite value.
    #[inline]
    pub fn add_vec3(&mut self, value: glam::Vec3) {
        self.0[0].add_f32(value.x);
        self.0[1].add_f32(value.y);
        self.0[2].add_f32(value.z);
    }

    pub fn add(&mut self, other: &ExactRgb) {
        for (a, b) in self.0.iter_mut().zip(&other.0) {
            a.add(b);
        }
    }

    pub fn to_dvec3(&self) -> glam::DVec3 {
        glam::DVec3::new(self.0[0].to_f64(), self.0[1].to_f64(), self.0[2].to_f64())
    }

    /// Each channel exactly (None: see `ExactSum::from_f64_exact`).
    pub fn from_dvec3_exact(v: glam::DVec3) -> Option<ExactRgb> {
        Some(ExactRgb([
            ExactSum::from_f64_exact(v.x)?,
            ExactSum::from_f64_exact(v.y)?,
            ExactSum::from_f64_exact(v.z)?,
        ]))
    }

    pub fn from_dvec3_rounded(v: glam::DVec3) -> ExactRgb {
        ExactRgb([
            ExactSum::from_f64_rounded(v.x),
            ExactSum::from_f64_rounded(v.y),
            ExactSum::from_f64_rounded(v.z),
        ])
    }

    pub fn is_zero(&self) -> bool {
        *self == ExactRgb::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sum_of(values: &[f32]) -> ExactSum {
        let mut s = ExactSum::ZERO;
        for &v in values {
            s.add_f32(v);
        }
        s
    }

    #[test]
    fn order_does_not_change_the_sum() {
        let values = [
            1e30f32,
            1.0,
            -1e30,
            3e-45,
            0.1,
            -7.25,
            f32::MAX,
            -f32::MAX,
            1e-38,
        ];
        let forward = sum_of(&values);
        let mut reversed = values;
        reversed.reverse();
        assert_eq!(forward, sum_of(&reversed));
        // In f64 the 1.0 and the tiny values are lost to 1e30 - 1e30; here they are not.
        let expected = 1.0f64 + 3e-45f32 as f64 + 0.1f32 as f64 - 7.25 + 1e-38f32 as f64;
        assert_eq!(forward.to_f64(), expected);
    }

    #[test]
    fn split_sums_add_to_the_whole() {
        let values: Vec<f32> = (0..1000)
            .map(|i| (i as f32 * 0.37).sin() * 10f32.powi(i % 9 - 4))
            .collect();
        let whole = sum_of(&values);
        let mut parts = sum_of(&values[..333]);
        parts.add(&sum_of(&values[333..]));
        assert_eq!(parts, whole);
    }

    #[test]
    fn single_values_read_back_exactly() {
        for v in [
            0.0f32,
            1.0,
            -1.0,
            0.1,
            f32::MAX,
            -f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
            -3e-40,
        ] {
            assert_eq!(sum_of(&[v]).to_f64(), v as f64, "{v}");
        }
    }

    #[test]
    fn rounding_to_f64_is_to_nearest() {
        // 2^53 + 1 lies halfway between two f64s: a tie, rounded to even (down); a further
        // 2^-100 tips it up.
        let mut s = ExactSum::from_f64_exact(2f64.powi(53)).unwrap();
        s.add(&ExactSum::from_f64_exact(1.0).unwrap());
        assert_eq!(s.to_f64(), 2f64.powi(53));
        s.add(&ExactSum::from_f64_exact(2f64.powi(-100)).unwrap());
        assert_eq!(s.to_f64(), 2f64.powi(53) + 2.0);
    }

    #[test]
    fn f64_conversions() {
        assert_eq!(ExactSum::from_f64_exact(1e-300), None);
        assert_eq!(ExactSum::from_f64_exact(1e100), None);
        assert_eq!(ExactSum::from_f64_exact(f64::NAN), None);
        assert_eq!(ExactSum::from_f64_exact(-2.5).unwrap().to_f64(), -2.5);
        assert_eq!(ExactSum::from_f64_rounded(1e-300), ExactSum::ZERO);
        assert_eq!(ExactSum::from_f64_rounded(0.1).to_f64(), 0.1);
        assert!(ExactSum::from_f64_rounded(1e100).to_f64() > 1e59);
        assert!(ExactSum::from_f64_rounded(-1e100).to_f64() < -1e59);
        let tiny = 1.5 * 2f64.powi(-149);
        assert_eq!(
            ExactSum::from_f64_rounded(tiny).to_f64(),
            2.0 * 2f64.powi(-149)
        );
    }
}
