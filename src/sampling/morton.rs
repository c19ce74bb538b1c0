//! Morton (Z-order) codes of pixels and the random base-4 digit permutation of ZSobol.
//!
//! A Morton code puts the pixels of every aligned 2^k x 2^k square at consecutive codes, so a
//! pixel's block of Sobol' indices (code << log2 spp) lies next to its neighbours' blocks:
//! the samples of a square of pixels together are one larger net (Ahmed and Wonka 2020,
//! "Screen-space blue-noise diffusion of Monte Carlo sampling error via hierarchical ordering
//! of pixels"). Left as it is, the order would be the same in every quad (the top-left child
//! always first), which shows as a regular pattern; each quadtree node therefore permutes its
//! four children's digits by one of the 24 permutations, picked by a hash of the node.

use super::mix64;

/// The low 32 bits of `v` on the even bits of the result.
#[inline]
fn spread(v: u32) -> u64 {
    let mut x = v as u64;
    x = (x | (x << 16)) & 0x0000_ffff_0000_ffff;
    x = (x | (x << 8)) & 0x00ff_00ff_00ff_00ff;
    x = (x | (x << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | (x << 2)) & 0x3333_3333_3333_3333;
    (x | (x << 1)) & 0x5555_5555_5555_5555
}

/// The Morton code of pixel (x, y): x on the even bits, y on the odd bits, so base-4 digit i
/// is the pixel's quadrant within its node of the level-i quadtree.
#[inline]
pub fn encode(x: u32, y: u32) -> u64 {
    spread(x) | (spread(y) << 1)
}

/// All 24 permutations of (0, 1, 2, 3), in lexicographic order, built at compile time.
const PERMUTATIONS: [[u8; 4]; 24] = {
    let mut table = [[0u8; 4]; 24];
    let mut n = 0;
    let mut code = 0;
    while code < 256 {
        let p = [code & 3, (code >> 2) & 3, (code >> 4) & 3, (code >> 6) & 3];
        let seen = (1 << p[0]) | (1 << p[1]) | (1 << p[2]) | (1 << p[3]);
        if seen == 0b1111 {
            table[n] = [p[0] as u8, p[1] as u8, p[2] as u8, p[3] as u8];
            n += 1;
        }
        code += 1;
    }
    assert!(n == 24);
    table
};

/// Permutes the `digits` base-4 digits of `code` from the most significant down: digit i is
/// mapped by a permutation chosen from the digits above it (its quadtree node) and `seed`.
/// A nested permutation, so every aligned block of 4^k codes (a quadtree node: a square of
/// pixels) maps onto an aligned block of 4^k codes, and it is a bijection on [0, 4^digits).
/// Costs one `mix64` per digit.
#[inline]
pub fn permute_digits(code: u64, digits: u32, seed: u64) -> u64 {
    debug_assert!(digits <= 31 && code >> (2 * digits) == 0);
    let mut out = 0;
    for i in (0..digits).rev() {
        let shift = 2 * i;
        let digit = (code >> shift) & 3;
        // The node: the digits above, with a leading 1 so that nodes of different levels differ.
        let node = (code >> (shift + 2)) | (1 << (2 * (digits - 1 - i)));
        let h = mix64(node ^ seed);
        // A uniform index in 0..24 from the top 32 bits (multiply-shift, no division).
        let p = (((h >> 32) * 24) >> 32) as usize;
        out |= (PERMUTATIONS[p][digit as usize] as u64) << shift;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutations_are_the_24_distinct_ones() {
        for (i, p) in PERMUTATIONS.iter().enumerate() {
            let mut s = *p;
            s.sort_unstable();
            assert_eq!(s, [0, 1, 2, 3]);
            assert!(PERMUTATIONS[..i].iter().all(|q| q != p));
        }
    }

    #[test]
    fn encode_interleaves() {
        assert_eq!(encode(0, 0), 0);
        assert_eq!(encode(1, 0), 1);
        assert_eq!(encode(0, 1), 2);
        assert_eq!(encode(3, 3), 15);
        assert_eq!(encode(u32::MAX, 0), 0x5555_5555_5555_5555);
        assert_eq!(encode(0b101, 0b110), 0b11_10_01);
    }

    #[test]
    fn permuted_codes_are_a_bijection_that_keeps_quadtree_nodes() {
        let digits = 4; // a 16 x 16 image
        let n = 1u64 << (2 * digits);
        for seed in [0, 1, 0xdead_beef] {
            let image: Vec<u64> = (0..n).map(|c| permute_digits(c, digits, seed)).collect();
            let mut sorted = image.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, (0..n).collect::<Vec<_>>());
            // Every node of 4^k codes lands in one aligned block of 4^k codes.
            for k in 0..=digits {
                let size = 1u64 << (2 * k);
                for node in image.chunks(size as usize) {
                    let block = node[0] / size;
                    assert!(node.iter().all(|&c| c / size == block));
                }
            }
            // And the permutations differ between nodes (not the plain Morton order).
            assert_ne!(image, (0..n).collect::<Vec<_>>());
        }
    }
}
