//! Traversal of obvhs' compressed wide BVH8 (Ylitie et al. 2017): eight children per node,
//! child boxes quantised to 8 bits per plane on a power-of-two grid anchored at the node's
//! minimum corner, children visited nearest octant first.

use super::stack::TraversalStack;
use super::triangle::TraversalRay;
use super::{LeafTriangles, TriangleHit};
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::{CwBvhNode, extract_byte64};

/// Relative padding of the decoded child boxes, far above the few roundings of decoding and of
/// the slab distances (about 2^-22 relative to the magnitudes involved): with it, the box test
/// is conservative and a ray never misses a box that holds a triangle it hits.
const PAD: f32 = 1.0 / (1u32 << 20) as f32;

pub(crate) struct CwBvhAccel {
    nodes: Vec<CwBvhNode>,
}

impl CwBvhAccel {
    /// Takes the built tree; returns it with the permutation from leaf slots to input indices.
    pub(crate) fn new(bvh: CwBvh) -> (CwBvhAccel, Vec<u32>) {
        (CwBvhAccel { nodes: bvh.nodes }, bvh.primitive_indices)
    }

    /// Closest hit (`ANY = false`) or the first hit found (`ANY = true`) with t in (0, t_max).
    #[inline(always)]
    pub(crate) fn traverse<const ANY: bool>(
        &self,
        tris: &LeafTriangles,
        ray: &TraversalRay,
        mut t_max: f32,
    ) -> Option<TriangleHit> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut hit = None;
        let oct_inv4 = octant_inv4(ray);
        // A group is (base index, bits): the high byte of bits marks the children still to
        // visit among the nodes from `base`, the low byte is the parent's inner-node mask; for a
        // primitive group, the low 24 bits mark triangles from `base`.
        let mut stack = TraversalStack::<(u32, u32), 32>::new();
        let mut nodes_group = (0u32, 0x8000_0000u32);
        let mut prims_group = (0u32, 0u32);
        loop {
            while prims_group.1 != 0 {
                let bit = 31 - prims_group.1.leading_zeros();
                prims_group.1 &= !(1 << bit);
                let slot = (prims_group.0 + bit) as usize;
                if tris.intersect_range::<ANY>(ray, slot..slot + 1, &mut t_max, &mut hit) && ANY {
                    return hit;
                }
            }

            if nodes_group.1 & 0xff00_0000 != 0 {
                let hits = nodes_group.1;
                let bit = 31 - hits.leading_zeros();
                nodes_group.1 &= !(1 << bit);
                if nodes_group.1 & 0xff00_0000 != 0 {
                    stack.push(nodes_group);
                }
                let slot = (bit - 24) ^ (oct_inv4 & 0xff);
                let relative = (hits & !(u32::MAX << slot)).count_ones();
                let node = &self.nodes[(nodes_group.0 + relative) as usize];
                let mask = child_hits(node, ray, t_max, oct_inv4);
                nodes_group = (
                    node.child_base_idx,
                    (mask & 0xff00_0000) | node.imask as u32,
                );
                prims_group = (node.primitive_base_idx, mask & 0x00ff_ffff);
            } else {
                nodes_group = (0, 0);
            }

            if prims_group.1 == 0 && nodes_group.1 & 0xff00_0000 == 0 {
                match stack.pop() {
                    Some(group) => nodes_group = group,
                    None => return hit,
                }
            }
        }
    }
}

/// The ray's octant in the form the builder's child ordering expects (the same in each byte).
#[inline(always)]
fn octant_inv4(ray: &TraversalRay) -> u32 {
    (if ray.neg[0] { 0 } else { 0x0404_0404 })
        | (if ray.neg[1] { 0 } else { 0x0202_0202 })
        | (if ray.neg[2] { 0 } else { 0x0101_0101 })
}

/// Tests the ray against the eight child boxes of `node`: the node's hit mask (inner children
/// in the high byte, in traversal order; leaf triangles in the low 24 bits).
#[inline(always)]
fn child_hits(node: &CwBvhNode, ray: &TraversalRay, t_max: f32, oct_inv4: u32) -> u32 {
    let hit8 = box_hits8(node, ray, t_max);
    if hit8 == 0 {
        return 0;
    }
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut mask = 0;
    let mut left = hit8;
    while left != 0 {
        let c = left.trailing_zeros();
        left &= left - 1;
        mask |= extract_byte64(child_bits8, c as usize) << extract_byte64(bit_index8, c as usize);
    }
    mask
}

/// The per-axis constants of the slab test of a node's children: for each axis, the node's
/// origin relative to the ray's, padded outwards on the near and on the far side.
#[inline(always)]
fn slab_bases(node: &CwBvhNode, ray: &TraversalRay) -> ([f32; 3], [f32; 3], [f32; 3]) {
    let extent = node.compute_extent().to_array();
    let p = node.p.to_array();
    let o = ray.origin.to_array();
    let mut near = [0.0; 3];
    let mut far = [0.0; 3];
    for axis in 0..3 {
        let e = extent[axis];
        let pad = (p[axis].abs() + o[axis].abs() + 256.0 * e) * PAD;
        let base = p[axis] - o[axis];
        if ray.neg[axis] {
            (near[axis], far[axis]) = (base + pad, base - pad);
        } else {
            (near[axis], far[axis]) = (base - pad, base + pad);
        }
    }
    (near, far, extent)
}

/// The quantised near and far planes of the children along `axis`, for the ray's direction.
#[inline(always)]
fn planes<'a>(node: &'a CwBvhNode, ray: &TraversalRay, axis: usize) -> (&'a [u8; 8], &'a [u8; 8]) {
    let (lo, hi) = match axis {
        0 => (&node.child_min_x, &node.child_max_x),
        1 => (&node.child_min_y, &node.child_max_y),
        _ => (&node.child_min_z, &node.child_max_z),
    };
    if ray.neg[axis] { (hi, lo) } else { (lo, hi) }
}

/// Which of the eight child slots the ray's padded slab test passes (bit c for slot c; empty
/// slots, whose quantised boxes are inverted, fail or are masked out by the child bits).
/// SSE2 (always present on x86_64), four children per instruction; the same arithmetic, in
/// the same order, as the portable version below, so both give identical masks.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn box_hits8(node: &CwBvhNode, ray: &TraversalRay, t_max: f32) -> u32 {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of the x86_64 baseline, so these intrinsics are always available;
    // none of them accesses memory through a pointer.
    unsafe {
        let (near_base, far_base, extent) = slab_bases(node, ray);
        let inv = ray.inv_dir.to_array();
        let zero = _mm_setzero_si128();
        // Eight quantised planes as two vectors of four f32 (exact: integers up to 255).
        let widen = |q: &[u8; 8]| {
            let v = _mm_cvtsi64_si128(i64::from_le_bytes(*q));
            let w = _mm_unpacklo_epi8(v, zero);
            (
                _mm_cvtepi32_ps(_mm_unpacklo_epi16(w, zero)),
                _mm_cvtepi32_ps(_mm_unpackhi_epi16(w, zero)),
            )
        };
        let mut t0 = (_mm_setzero_ps(), _mm_setzero_ps());
        let mut t1 = (_mm_set1_ps(t_max), _mm_set1_ps(t_max));
        for axis in 0..3 {
            let (q_near, q_far) = planes(node, ray, axis);
            let e = _mm_set1_ps(extent[axis]);
            let inv = _mm_set1_ps(inv[axis]);
            let bn = _mm_set1_ps(near_base[axis]);
            let bf = _mm_set1_ps(far_base[axis]);
            let (n_lo, n_hi) = widen(q_near);
            let (f_lo, f_hi) = widen(q_far);
            let near = |q| _mm_mul_ps(_mm_add_ps(bn, _mm_mul_ps(q, e)), inv);
            let far = |q| _mm_mul_ps(_mm_add_ps(bf, _mm_mul_ps(q, e)), inv);
            // max_ps(a, b) is `a > b ? a : b` and min_ps(a, b) is `a < b ? a : b`: a NaN slab
            // distance (0 * inf: the ray runs in a slab's plane) constrains nothing.
            t0 = (_mm_max_ps(near(n_lo), t0.0), _mm_max_ps(near(n_hi), t0.1));
            t1 = (_mm_min_ps(far(f_lo), t1.0), _mm_min_ps(far(f_hi), t1.1));
        }
        let lo = _mm_movemask_ps(_mm_cmple_ps(t0.0, t1.0)) as u32;
        let hi = _mm_movemask_ps(_mm_cmple_ps(t0.1, t1.1)) as u32;
        lo | (hi << 4)
    }
}

/// Which of the eight child slots the ray's padded slab test passes (portable version).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn box_hits8(node: &CwBvhNode, ray: &TraversalRay, t_max: f32) -> u32 {
    let (near_base, far_base, extent) = slab_bases(node, ray);
    let inv = ray.inv_dir.to_array();
    let mut t0 = [0.0f32; 8];
    let mut t1 = [t_max; 8];
    for axis in 0..3 {
        let (q_near, q_far) = planes(node, ray, axis);
        let (e, inv) = (extent[axis], inv[axis]);
        for c in 0..8 {
            let near = (near_base[axis] + f32::from(q_near[c]) * e) * inv;
            let far = (far_base[axis] + f32::from(q_far[c]) * e) * inv;
            // NaN (0 * inf: the ray runs in a slab's plane) constrains nothing.
            if near > t0[c] {
                t0[c] = near;
            }
            if far < t1[c] {
                t1[c] = far;
            }
        }
    }
    let mut hits = 0;
    for c in 0..8 {
        if t0[c] <= t1[c] {
            hits |= 1 << c;
        }
    }
    hits
}
