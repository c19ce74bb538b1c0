//! Sobol' dimensions 0 and 1, Owen-scrambled by a hash, and the nested shuffle of indices.
//!
//! Only the first two Sobol' dimensions are needed: every 2D pair of a sampler draws from
//! them with its own scramble (padding), so no direction-number table is stored. Both have
//! closed forms: dimension 0 is the van der Corput sequence (the index's bits reversed), and
//! dimension 1's generator matrix is Pascal's triangle mod 2, whose digit j is the parity of
//! the index bits i with C(i, j) odd, that is (Lucas) the bits i that contain j bitwise.
//! Points 0..2^m of the pair are a (0, m, 2)-net, and so is every aligned block of 2^m.
//!
//! Fractions are `u32`s whose most significant bit is the first binary digit. Functions named
//! `*_reversed` work on digit-reversed words (bit j = digit j), where a nested (Owen)
//! scramble is a Laine-Karras permutation: bit j flipped by a function of the bits below it.

/// A Laine-Karras permutation: bit j of the result is bit j of `v` flipped by a pseudo-random
/// function of bits 0..j and `seed` (each step only carries upward or multiplies by an odd
/// number), so it is a bijection, and on a digit-reversed fraction it is a nested uniform
/// (Owen) scramble. The multipliers are Vegdahl's ("Building a better LK hash", 2021), which
/// pass his avalanche tests far better than Laine and Karras's originals.
#[inline]
pub fn laine_karras(mut v: u32, seed: u32) -> u32 {
    v ^= v.wrapping_mul(0x3d20_adea);
    v = v.wrapping_add(seed);
    v = v.wrapping_mul((seed >> 16) | 1);
    v ^= v.wrapping_mul(0x0552_6c56);
    v ^= v.wrapping_mul(0x53a2_2864);
    v
}

/// Digits of Sobol' dimension 1 at `index`, digit-reversed (bit j = digit j): bit j is the
/// XOR of the index bits i with j ⊆ i, computed as a superset-XOR transform over the five
/// bits of the bit position (one shift-and-mask step per position bit, no table).
#[inline]
pub fn pascal_reversed(index: u32) -> u32 {
    let mut a = index;
    a ^= (a >> 1) & 0x5555_5555;
    a ^= (a >> 2) & 0x3333_3333;
    a ^= (a >> 4) & 0x0f0f_0f0f;
    a ^= (a >> 8) & 0x00ff_00ff;
    a ^= (a >> 16) & 0x0000_ffff;
    a
}

/// Unscrambled Sobol' dimension 0 (van der Corput) as a fraction.
#[cfg(test)]
pub fn sobol0(index: u32) -> u32 {
    index.reverse_bits()
}

/// Unscrambled Sobol' dimension 1 as a fraction.
#[cfg(test)]
pub fn sobol1(index: u32) -> u32 {
    pascal_reversed(index).reverse_bits()
}

/// Owen scramble of a digit-reversed 24-digit fraction (bit j = digit j), as a fraction (its
/// low 8 bits zero). The digits go to the top of the hashed word: at its bottom,
/// Laine-Karras would flip the first digits by nearly affine functions of the digits above,
/// while here the seed fills the bits below them, and its products and carries make those
/// flips depend on the seed far more richly.
#[inline]
fn owen24(digits: u32, seed: u32) -> u32 {
    debug_assert!(digits >> 24 == 0);
    laine_karras(digits << 8, seed).reverse_bits() << 8
}

/// Owen-scrambled Sobol' dimension 0 at `index` (below 2^24). The digit-reversed van der
/// Corput fraction is the index itself, so the scramble needs one bit reversal, not two.
#[inline]
pub fn owen_sobol0(index: u32, seed: u32) -> u32 {
    owen24(index, seed)
}

/// Owen-scrambled Sobol' dimension 1 at `index` (below 2^24).
#[inline]
pub fn owen_sobol1(index: u32, seed: u32) -> u32 {
    owen24(pascal_reversed(index), seed)
}

/// A nested permutation of the `bits`-bit index `s` (`s < 2^bits`, `bits <= 32`): bit i is
/// flipped by a function of the bits above it. The first 2^k indices therefore map onto one
/// aligned block of 2^k indices for every k, and the Sobol' points of an aligned block are a
/// net: any power-of-two prefix of the shuffled order is still stratified. A different seed per
/// dimension decorrelates the dimensions that share one set of points (Burley 2020, "Practical
/// hash-based Owen scrambling": shuffling by an Owen scramble of the reversed index).
#[cfg(test)]
pub fn nested_shuffle(s: u32, bits: u32, seed: u32) -> u32 {
    shuffle_reversed(reverse_low(s, bits), bits, seed)
}

/// `nested_shuffle` of the index whose `bits` bits, reversed, are `reversed`. The bits are
/// hashed at the top of the word, for the reason given at `owen24`.
#[inline]
pub fn shuffle_reversed(reversed: u32, bits: u32, seed: u32) -> u32 {
    debug_assert!(bits <= 32 && (bits == 32 || reversed >> bits == 0));
    if bits == 0 {
        return 0;
    }
    (laine_karras(reversed << (32 - bits), seed).reverse_bits()) & (u32::MAX >> (32 - bits))
}

/// The low `bits` bits of `v`, in reverse order (the bits above are dropped).
#[inline]
pub fn reverse_low(v: u32, bits: u32) -> u32 {
    if bits == 0 {
        0
    } else {
        v.reverse_bits() >> (32 - bits)
    }
}

/// A fraction as an `f32` in [0, 1): its top 24 bits, exactly representable and below 1.
#[inline]
pub fn to_unit(v: u32) -> f32 {
    (v >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Kollig and Keller's bit loops for the two dimensions, as references.
    fn sobol0_loop(mut i: u32) -> u32 {
        let (mut r, mut v) = (0, 1u32 << 31);
        while i != 0 {
            if i & 1 != 0 {
                r ^= v;
            }
            i >>= 1;
            v >>= 1;
        }
        r
    }

    fn sobol1_loop(mut i: u32) -> u32 {
        let (mut r, mut v) = (0, 1u32 << 31);
        while i != 0 {
            if i & 1 != 0 {
                r ^= v;
            }
            i >>= 1;
            v ^= v >> 1;
        }
        r
    }

    #[test]
    fn closed_forms_match_the_generator_loops() {
        let mut x = 0x1234_5678u32;
        for i in (0..4096).chain((0..4096).map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        })) {
            assert_eq!(sobol0(i), sobol0_loop(i), "dim 0 at {i}");
            assert_eq!(sobol1(i), sobol1_loop(i), "dim 1 at {i}");
        }
    }

    /// Whether `points` (fractions) put exactly one point in each elementary interval of
    /// every shape 2^a x 2^(m - a), m = log2(len).
    fn is_net(points: &[(u32, u32)]) -> bool {
        let m = points.len().trailing_zeros();
        assert_eq!(points.len(), 1 << m);
        (0..=m).all(|a| {
            let mut seen = vec![false; points.len()];
            points.iter().all(|&(x, y)| {
                let cx = if a == 0 { 0 } else { (x >> (32 - a)) as usize };
                let cy = if a == m {
                    0
                } else {
                    (y >> (32 - (m - a))) as usize
                };
                let cell = (cx << (m - a)) | cy;
                !std::mem::replace(&mut seen[cell], true)
            })
        })
    }

    #[test]
    fn aligned_blocks_are_nets_scrambled_or_not() {
        for m in 0..=10u32 {
            for block in [0u32, 1, 5, 1000] {
                let start = block << m;
                let plain: Vec<_> = (start..start + (1 << m))
                    .map(|i| (sobol0(i), sobol1(i)))
                    .collect();
                assert!(is_net(&plain), "plain m = {m}, block {block}");
                let scrambled: Vec<_> = (start..start + (1 << m))
                    .map(|i| (owen_sobol0(i, 0x9e37_79b9), owen_sobol1(i, 0x7f4a_7c15)))
                    .collect();
                assert!(is_net(&scrambled), "scrambled m = {m}, block {block}");
            }
        }
    }

    #[test]
    fn laine_karras_flips_bits_by_lower_bits_only() {
        for seed in [0u32, 1, 0xdead_beef] {
            for v in [0u32, 1, 0x1234_5678, u32::MAX] {
                for j in 0..32 {
                    // Changing a bit above j leaves bits 0..=j alone.
                    let mask = if j == 31 {
                        u32::MAX
                    } else {
                        (1u32 << (j + 1)) - 1
                    };
                    for above in j + 1..32 {
                        let w = v ^ (1 << above);
                        assert_eq!(laine_karras(v, seed) & mask, laine_karras(w, seed) & mask);
                    }
                }
            }
        }
    }

    #[test]
    fn nested_shuffle_is_a_bijection_whose_prefixes_are_aligned_blocks() {
        for bits in [0u32, 1, 2, 5, 10] {
            for seed in [0u32, 3, 0xabcd_ef01] {
                let n = 1u32 << bits;
                let image: Vec<u32> = (0..n).map(|s| nested_shuffle(s, bits, seed)).collect();
                let mut sorted = image.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..n).collect::<Vec<_>>());
                for k in 0..=bits {
                    let prefix = &image[..1 << k];
                    let block = prefix[0] >> k;
                    assert!(prefix.iter().all(|&s| s >> k == block), "bits {bits} k {k}");
                }
            }
        }
    }

    #[test]
    fn to_unit_stays_below_one() {
        assert_eq!(to_unit(0), 0.0);
        assert!(to_unit(u32::MAX) < 1.0);
        assert_eq!(to_unit(1 << 31), 0.5);
    }
}
