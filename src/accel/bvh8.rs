//! An eight-wide BVH with exact f32 child boxes, collapsed from obvhs' binary PLOC tree, whose
//! leaves (up to four triangles each) share four-lane triangle packets with their siblings.
//!
//! Each node stores its children's boxes as exact f32 planes (the min and max of the
//! children's triangle vertices, computed in `collapse`), eight per plane, so that one node is
//! tested against a ray with a few SSE2 instructions (or fewer AVX2 ones, where the CPU has
//! them: see `crate::cpu`). The box test is made conservative by one padding per ray (see
//! `BoxRay`), not per node.
//!
//! A node's leaf children are packed together into as few packets as fit (first fit,
//! largest leaves first), each leaf naming its packet and its lanes there: when a ray enters
//! several leaf boxes of one node that share a packet, the packet is tested once, with the
//! union of their lanes. A closest-hit ray visits a node's children, leaves and nodes alike,
//! nearest first (their entry distances kept on the stack), and skips those beyond its nearest
//! hit; an any-hit ray tests a node's leaves before it descends, as they may end the search.

use super::LeafTriangles;
use super::TriangleHit;
use super::stack::TraversalStack;
use super::triangle::{LANES, TraversalRay, TrianglePacket};
use glam::{Vec3, Vec3A};

/// A child reference: a node index (0, the root, is never a child: 0 marks an empty slot),
/// or (with `LEAF` set) a packet index shifted left by `LANES` with the leaf's lanes of that
/// packet in the low bits.
pub(super) const LEAF: u32 = 1 << 31;
/// The lane mask of a leaf reference.
pub(super) const LANE_MASK: u32 = (1 << LANES) - 1;
/// The reference of the root node.
pub(super) const ROOT: u32 = 0;
/// The box test's padding, relative to the magnitudes involved (see `BoxRay`).
pub(super) const PADDING: f32 = 1.0 / (1u32 << 18) as f32;
/// The most triangles a leaf holds: one packet.
pub(super) const LEAF_MAX: u32 = LANES as u32;
/// The most packets a tree may hold (the bits of a leaf reference).
pub(super) const MAX_PACKETS: usize = 1 << (31 - LANES);

/// Eight children: 224 bytes (seven 32-byte lines' worth, aligned for the eight-lane loads).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct Node {
    /// `planes[axis][0]` are the children's minima along `axis`, `planes[axis][1]` their
    /// maxima. Empty slots hold an inverted box (+inf, -inf), which no ray enters.
    pub(super) planes: [[[f32; 8]; 2]; 3],
    pub(super) child: [u32; 8],
}

impl Node {
    pub(super) const EMPTY: Node = Node {
        planes: [[[f32::INFINITY; 8], [f32::NEG_INFINITY; 8]]; 3],
        child: [0; 8],
    };

    /// Puts the child `reference`, whose box is `lo..hi`, in slot `slot`.
    pub(super) fn set_child(&mut self, slot: usize, reference: u32, lo: Vec3, hi: Vec3) {
        for axis in 0..3 {
            self.planes[axis][0][slot] = lo[axis];
            self.planes[axis][1][slot] = hi[axis];
        }
        self.child[slot] = reference;
    }

    /// Enlarges each child's box by `PADDING` times its largest coordinate magnitude (rounded
    /// outwards by the padding's own size: 2^-24 of it is far below it).
    fn pad(&mut self) {
        for slot in 0..8 {
            let m = (0..3)
                .map(|a| {
                    self.planes[a][0][slot]
                        .abs()
                        .max(self.planes[a][1][slot].abs())
                })
                .fold(0.0f32, f32::max);
            // Empty slots (+inf, -inf) stay as they are.
            if !m.is_finite() {
                continue;
            }
            for a in 0..3 {
                self.planes[a][0][slot] -= m * PADDING;
                self.planes[a][1][slot] += m * PADDING;
            }
        }
    }

    /// The box of all the children.
    pub(super) fn bounds(&self) -> (Vec3, Vec3) {
        let p = &self.planes;
        let lo =
            Vec3::from([0, 1, 2].map(|a| p[a][0].iter().copied().fold(f32::INFINITY, f32::min)));
        let hi = Vec3::from(
            [0, 1, 2].map(|a| p[a][1].iter().copied().fold(f32::NEG_INFINITY, f32::max)),
        );
        (lo, hi)
    }
}

/// Trees of at least this many bytes (nodes and packets) prefetch the children a node's ray
/// will visit later; smaller ones stay in the caches, where the prefetches only cost
/// instructions. Measured (docs/measurements/2026-11-26-rays-against-embree.md, bench --rays,
/// one thread, 4 rounds): without prefetching, closest-hit rays 4% and shadow rays 1-2%
/// faster on cornell_box and door_ajar (a tree of 0.9 MB), and 3% slower on the 1M-triangle scene.
const PREFETCH_FROM_BYTES: usize = 4 << 20;

pub(crate) struct Bvh8 {
    pub(super) nodes: Vec<Node>,
    /// Whether traversal prefetches the children it will visit later (big trees only).
    prefetch: bool,
}

impl Bvh8 {
    /// Bytes of the tree's nodes.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node>()
    }

    /// A tree of `nodes` over `packets` triangle packets; the nodes' planes are the children's
    /// exact boxes, padded here (see `BoxRay`).
    pub(super) fn new(mut nodes: Vec<Node>, packets: usize) -> Bvh8 {
        nodes.iter_mut().for_each(Node::pad);
        let bytes = nodes.len() * std::mem::size_of::<Node>()
            + packets * std::mem::size_of::<TrianglePacket>();
        let prefetch = bytes >= PREFETCH_FROM_BYTES;
        Bvh8 { nodes, prefetch }
    }

    /// Asks the CPU to bring the node or packet `reference` into the cache.
    #[inline(always)]
    fn prefetch(&self, tris: &LeafTriangles, reference: u32) {
        let (start, bytes) = if reference & LEAF != 0 {
            let packet = ((reference & !LEAF) >> LANES) as usize;
            (
                tris.packets.as_ptr().wrapping_add(packet).cast::<u8>(),
                std::mem::size_of::<TrianglePacket>(),
            )
        } else {
            (
                self.nodes
                    .as_ptr()
                    .wrapping_add(reference as usize)
                    .cast::<u8>(),
                std::mem::size_of::<Node>(),
            )
        };
        for offset in (0..bytes).step_by(64) {
            crate::cpu::prefetch(start.wrapping_add(offset));
        }
    }

    /// Closest hit (`ANY = false`) or the first hit found (`ANY = true`) with t in (0, t_max).
    /// `AVX2` selects the eight-lane box test; it must only be set inside a function compiled
    /// with the `avx2` target feature (see `Accel::traverse_avx2`), which only runs where the
    /// CPU has it.
    #[inline(always)]
    pub(crate) fn traverse<const ANY: bool, const AVX2: bool>(
        &self,
        tris: &LeafTriangles,
        ray: &TraversalRay,
        t_max: f32,
    ) -> Option<TriangleHit> {
        self.traverse_from::<ANY, AVX2>(tris, ray, ROOT, t_max, None)
    }

    /// `traverse` of the subtree `start` (a node or leaf reference), for a closest hit with
    /// `hit` the best found so far elsewhere (at `t_max` if any): the closer of the two.
    #[inline(always)]
    pub(crate) fn traverse_from<const ANY: bool, const AVX2: bool>(
        &self,
        tris: &LeafTriangles,
        ray: &TraversalRay,
        start: u32,
        mut t_max: f32,
        mut hit: Option<TriangleHit>,
    ) -> Option<TriangleHit> {
        let box_ray = BoxRay::new(ray);
        // The slot of the best hit: `closer` breaks ties in t by it. Before any hit (and for
        // any hit) no tie is taken: a hit at exactly t_max is beyond the range.
        let mut best = if ANY { 0 } else { hit.map_or(0, |h| h.slot) };
        // Pending children: the entry distance (non-negative, so its bits order like the
        // value) in the high half, the child reference in the low half.
        let mut stack = TraversalStack::<u64, 24>::new();
        let mut current = start;
        loop {
            if current & LEAF != 0 {
                let packet = ((current & !LEAF) >> LANES) as usize;
                if let Some((lane, (t, b1, b2))) = ray.intersect4::<ANY>(
                    &tris.packets[packet],
                    current & LANE_MASK,
                    (packet * LANES) as u32,
                    &mut t_max,
                    &mut best,
                ) {
                    hit = Some(TriangleHit {
                        t,
                        slot: (packet * LANES + lane as usize) as u32,
                        b1,
                        b2,
                    });
                    if ANY {
                        return hit;
                    }
                }
            } else {
                let node = &self.nodes[current as usize];
                let (mask, leaf_bits, mut t_near) = if AVX2 {
                    // SAFETY: `AVX2` is only set in code compiled for, and run on, CPUs with
                    // AVX2 (see the doc comment above).
                    unsafe { box_hits8_avx2(node, &box_ray, t_max) }
                } else {
                    box_hits8(node, &box_ray, t_max)
                };
                // The leaves entered that share a packet become one visit of the packet with
                // the union of their lanes (at the nearest of their entry distances), put in
                // the slot of the first of them.
                let mut refs = node.child;
                let mut mask = mask;
                let mut leaves = mask & leaf_bits;
                while leaves != 0 {
                    let first = leaves.trailing_zeros() as usize;
                    leaves &= leaves - 1;
                    let mut others = leaves;
                    while others != 0 {
                        let c = others.trailing_zeros() as usize;
                        others &= others - 1;
                        if (refs[c] ^ refs[first]) & !LANE_MASK == 0 {
                            refs[first] |= refs[c];
                            t_near[first] = t_near[first].min(t_near[c]);
                            leaves &= !(1 << c);
                            mask &= !(1 << c);
                        }
                    }
                }
                if ANY && mask & leaf_bits != 0 {
                    // Any hit will do: the leaves first, as they may end the search.
                    let mut leaves = mask & leaf_bits;
                    while leaves != 0 {
                        let c = leaves.trailing_zeros() as usize;
                        leaves &= leaves - 1;
                        let packet = ((refs[c] & !LEAF) >> LANES) as usize;
                        if let Some((lane, (t, b1, b2))) = ray.intersect4::<ANY>(
                            &tris.packets[packet],
                            refs[c] & LANE_MASK,
                            (packet * LANES) as u32,
                            &mut t_max,
                            &mut best,
                        ) {
                            return Some(TriangleHit {
                                t,
                                slot: (packet * LANES + lane as usize) as u32,
                                b1,
                                b2,
                            });
                        }
                    }
                    mask &= !leaf_bits;
                }
                if self.prefetch && mask & (mask.wrapping_sub(1)) != 0 {
                    // Two or more children to visit: fetch them all while the nearest is
                    // visited, so those popped later are in the cache.
                    let mut pf = mask;
                    while pf != 0 {
                        let c = pf.trailing_zeros() as usize;
                        pf &= pf - 1;
                        self.prefetch(tris, refs[c]);
                    }
                }
                if mask != 0 && mask & (mask - 1) == 0 {
                    current = refs[mask.trailing_zeros() as usize];
                    continue;
                }
                if ANY && mask != 0 {
                    // No need for an order.
                    current = refs[mask.trailing_zeros() as usize];
                    mask &= mask - 1;
                    while mask != 0 {
                        let c = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        stack.push(u64::from(refs[c]));
                    }
                    continue;
                }
                if mask != 0 {
                    // At least two children: visit them nearest first (by entry distance, then
                    // child reference). Two (the common case) need one comparison; more are
                    // sorted farthest first (insertion sort of at most eight keys), all but the
                    // nearest pushed.
                    let key = |c: u32| {
                        (u64::from(t_near[c as usize].to_bits()) << 32)
                            | u64::from(refs[c as usize])
                    };
                    let k0 = key(mask.trailing_zeros());
                    mask &= mask - 1;
                    let k1 = key(mask.trailing_zeros());
                    mask &= mask - 1;
                    let (near, far) = if k0 < k1 { (k0, k1) } else { (k1, k0) };
                    if mask == 0 {
                        stack.push(far);
                        current = near as u32;
                        continue;
                    }
                    let mut keys = [far, near, 0, 0, 0, 0, 0, 0];
                    let mut n = 2;
                    while mask != 0 {
                        let k = key(mask.trailing_zeros());
                        mask &= mask - 1;
                        let mut j = n;
                        while j > 0 && keys[j - 1] < k {
                            keys[j] = keys[j - 1];
                            j -= 1;
                        }
                        keys[j] = k;
                        n += 1;
                    }
                    for &k in &keys[..n - 1] {
                        stack.push(k);
                    }
                    current = keys[n - 1] as u32;
                    continue;
                }
            }
            // The next pending child that may still hold a hit before t_max.
            loop {
                match stack.pop() {
                    Some(key) => {
                        if f32::from_bits((key >> 32) as u32) <= t_max {
                            current = key as u32;
                            break;
                        }
                    }
                    None => return hit,
                }
            }
        }
    }
}

/// The ray as the box test sees it. The test computes `(plane - o) * inv_dir` per slab with
/// every box enlarged on each side by `2^-18 (max |o| + m)`, `m` the largest coordinate
/// magnitude of that child's box: its part `2^-18 m` is added to the child's planes when the
/// tree is made (`Node::pad`), its part `pad = 2^-18 max |o|` moves the origin here. That is far
/// above the rounding of `o +- pad` (2^-24 of it), of the subtraction and of the product with
/// the rounded reciprocal (relative 3 * 2^-24 of `|plane - o| <= |o| + m`, which the padding
/// also dominates in t, as it adds its length times `|inv_dir|` on each side), and above the
/// rounding of the triangle test for a triangle in that box (a few 2^-24 of the same
/// magnitudes). So the box test is conservative: a ray never misses a box that holds a
/// triangle it hits. Padding by each box's own magnitudes, not the scene's largest, keeps one
/// huge triangle (a floor 2e10 wide) from enlarging every box in the scene: with the scene's,
/// a 4 m room's boxes grew by 38 km and every ray entered every box.
pub(super) struct BoxRay {
    /// Per axis: the index (0: minima, 1: maxima) of the planes the ray enters by.
    pub(super) near: [usize; 3],
    /// The origin moved back along the ray by `pad` (for the entry planes) and forwards (for
    /// the exit planes).
    pub(super) o_near: [f32; 3],
    pub(super) o_far: [f32; 3],
    pub(super) inv: [f32; 3],
}

impl BoxRay {
    #[inline(always)]
    pub(super) fn new(ray: &TraversalRay) -> BoxRay {
        let o = ray.origin;
        let pad = o.abs().max_element() * PADDING;
        let neg = ray.neg;
        // Entering through min - pad (positive direction): (min - pad) - o = min - (o + pad);
        // through max + pad (negative direction): max - (o - pad). Lane by lane, the same
        // scalar operations; the sign of `inv_dir` is that of the direction.
        let signed_pad = Vec3A::splat(pad).copysign(ray.inv_dir);
        BoxRay {
            near: [0, 1, 2].map(|axis| ((neg >> axis) & 1) as usize),
            o_near: (o + signed_pad).to_array(),
            o_far: (o - signed_pad).to_array(),
            inv: ray.inv_dir.to_array(),
        }
    }
}

/// Which children's padded boxes the ray enters with t in [0, t_max] (bit c for slot c), which
/// children are leaves (the sign bits of the references), and the entry distances.
/// SSE2 (always present on x86_64), four children per instruction; the same arithmetic, in
/// the same order, as the portable version below, so both give identical results.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn box_hits8(node: &Node, ray: &BoxRay, t_max: f32) -> (u32, u32, [f32; 8]) {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of the x86_64 baseline, so these intrinsics are always available;
    // the loads and stores are unaligned ones on `[f32; 8]` and `[u32; 8]` arrays borrowed
    // (or owned) here.
    unsafe {
        let mut t0 = (_mm_setzero_ps(), _mm_setzero_ps());
        let mut t1 = (_mm_set1_ps(t_max), _mm_set1_ps(t_max));
        for axis in 0..3 {
            let n = ray.near[axis];
            let near = &node.planes[axis][n];
            let far = &node.planes[axis][1 - n];
            let inv = _mm_set1_ps(ray.inv[axis]);
            let on = _mm_set1_ps(ray.o_near[axis]);
            let of = _mm_set1_ps(ray.o_far[axis]);
            let slab = |p: &[f32; 8], o, half: usize| {
                _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(p.as_ptr().add(half)), o), inv)
            };
            // max_ps(a, b) is `a > b ? a : b` and min_ps(a, b) is `a < b ? a : b`: a NaN slab
            // distance (0 * inf: the ray runs in a slab's plane) constrains nothing.
            t0 = (
                _mm_max_ps(slab(near, on, 0), t0.0),
                _mm_max_ps(slab(near, on, 4), t0.1),
            );
            t1 = (
                _mm_min_ps(slab(far, of, 0), t1.0),
                _mm_min_ps(slab(far, of, 4), t1.1),
            );
        }
        let lo = _mm_movemask_ps(_mm_cmple_ps(t0.0, t1.0)) as u32;
        let hi = _mm_movemask_ps(_mm_cmple_ps(t0.1, t1.1)) as u32;
        let child = node.child.as_ptr().cast::<f32>();
        let leaves = _mm_movemask_ps(_mm_loadu_ps(child)) as u32
            | ((_mm_movemask_ps(_mm_loadu_ps(child.add(4))) as u32) << 4);
        let mut t = [0.0f32; 8];
        _mm_storeu_ps(t.as_mut_ptr(), t0.0);
        _mm_storeu_ps(t.as_mut_ptr().add(4), t0.1);
        (lo | (hi << 4), leaves, t)
    }
}

/// `box_hits8` with eight lanes per instruction (AVX2): the same arithmetic, lane for lane,
/// so the same results.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn box_hits8_avx2(node: &Node, ray: &BoxRay, t_max: f32) -> (u32, u32, [f32; 8]) {
    use std::arch::x86_64::*;
    let mut t0 = _mm256_setzero_ps();
    let mut t1 = _mm256_set1_ps(t_max);
    for axis in 0..3 {
        let n = ray.near[axis] & 1;
        // SAFETY: unaligned loads of eight f32 from `[f32; 8]` arrays of `node`.
        let (near, far) = unsafe {
            (
                _mm256_loadu_ps(node.planes[axis][n].as_ptr()),
                _mm256_loadu_ps(node.planes[axis][1 - n].as_ptr()),
            )
        };
        let inv = _mm256_set1_ps(ray.inv[axis]);
        let tn = _mm256_mul_ps(_mm256_sub_ps(near, _mm256_set1_ps(ray.o_near[axis])), inv);
        let tf = _mm256_mul_ps(_mm256_sub_ps(far, _mm256_set1_ps(ray.o_far[axis])), inv);
        // As in `box_hits8`: a NaN slab distance constrains nothing.
        t0 = _mm256_max_ps(tn, t0);
        t1 = _mm256_min_ps(tf, t1);
    }
    let hits = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
    // SAFETY: an unaligned load of the eight u32 of `node.child`, read as f32 for their sign
    // bits only.
    let leaves =
        _mm256_movemask_ps(unsafe { _mm256_loadu_ps(node.child.as_ptr().cast::<f32>()) }) as u32;
    let mut t = [0.0f32; 8];
    // SAFETY: an unaligned store of eight f32 into a local `[f32; 8]`.
    unsafe { _mm256_storeu_ps(t.as_mut_ptr(), t0) };
    (hits, leaves, t)
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
unsafe fn box_hits8_avx2(node: &Node, ray: &BoxRay, t_max: f32) -> (u32, u32, [f32; 8]) {
    box_hits8(node, ray, t_max)
}

/// Which children's padded boxes the ray enters (portable version).
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn box_hits8(node: &Node, ray: &BoxRay, t_max: f32) -> (u32, u32, [f32; 8]) {
    let mut t0 = [0.0f32; 8];
    let mut t1 = [t_max; 8];
    for axis in 0..3 {
        let n = ray.near[axis];
        let (near, far) = (&node.planes[axis][n], &node.planes[axis][1 - n]);
        let inv = ray.inv[axis];
        for c in 0..8 {
            let tn = (near[c] - ray.o_near[axis]) * inv;
            let tf = (far[c] - ray.o_far[axis]) * inv;
            // NaN (0 * inf: the ray runs in a slab's plane) constrains nothing.
            if tn > t0[c] {
                t0[c] = tn;
            }
            if tf < t1[c] {
                t1[c] = tf;
            }
        }
    }
    let mut hits = 0;
    let mut leaves = 0;
    for c in 0..8 {
        if t0[c] <= t1[c] {
            hits |= 1 << c;
        }
        if node.child[c] & LEAF != 0 {
            leaves |= 1 << c;
        }
    }
    (hits, leaves, t0)
}
