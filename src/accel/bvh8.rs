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
use rayon::prelude::*;

/// A child reference: a node index (0, the root, is never a child: 0 marks an empty slot),
/// or (with `LEAF` set) a packet index shifted left by `LANES` with the leaf's lanes of that
/// packet in the low bits.
pub(super) const LEAF: u32 = 1 << 31;
/// The lane mask of a leaf reference.
const LANE_MASK: u32 = (1 << LANES) - 1;
/// The box test's padding, relative to the magnitudes involved (see `BoxRay`).
const PADDING: f32 = 1.0 / (1u32 << 18) as f32;
/// The most triangles a leaf holds: one packet.
pub(super) const LEAF_MAX: u32 = LANES as u32;
/// The most packets a tree may hold (the bits of a leaf reference).
pub(super) const MAX_PACKETS: usize = 1 << (31 - LANES);

/// Eight children with exact f32 boxes, as `collapse` builds them (224 bytes); `Bvh8::new`
/// quantizes each into a `Node`.
#[derive(Clone, Copy, Debug)]
pub(super) struct BuildNode {
    /// `planes[axis][0]` are the children's minima along `axis`, `planes[axis][1]` their
    /// maxima. Empty slots hold an inverted box (+inf, -inf).
    planes: [[[f32; 8]; 2]; 3],
    pub(super) child: [u32; 8],
}

impl BuildNode {
    pub(super) const EMPTY: BuildNode = BuildNode {
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

/// Eight children with quantized boxes: 96 bytes (a third of a float node's 224 less a
/// little), so that the big trees' nodes, which traversal mostly reads from memory, take two
/// cache lines instead of four. Each child's box is a whole number of grid steps from the
/// node's origin, 8 bits per plane, rounded outwards from its padded float box (see
/// `Node::quantize`), so boxes only grow and no ray misses a box it entered before.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct Node {
    pub(super) child: [u32; 8],
    /// The corner the grid starts at.
    origin: [f32; 3],
    /// Per axis, the grid step as a power of two: `2^exponent`.
    exponent: [i8; 3],
    /// Bit `c` set where slot `c` holds a child (empty slots are never entered).
    occupied: u8,
    /// `grid[axis][0][c]`: child `c`'s minimum along `axis` in grid steps from `origin`
    /// (rounded down), `grid[axis][1][c]` its maximum (rounded up).
    grid: [[[u8; 8]; 2]; 3],
}

const _: () = assert!(std::mem::size_of::<Node>() == 96);

/// The least magnitude `Node::quantize` pads by: a node whose coordinates are all smaller (far
/// below any real scene's) is padded as if they reached it, which keeps its grid steps normal
/// f32 (2^-126 or more).
const TINY_MAGNITUDE: f64 = 1.0 / (1u128 << 100) as f64;

impl Node {
    /// The quantized `node`. Each child's float box is first padded by `PADDING` times
    /// `17/16` of the largest coordinate magnitude among the node's children's boxes, which
    /// bounds the magnitudes of every plane of the quantized node and of its origin (they lie
    /// between the padded node box's minimum, rounded down to f32, and its maximum plus a grid
    /// step, which is under 1/63 of the node's extent); the box test's rounding, which that
    /// padding must dominate, is proportional to those magnitudes (see `BoxRay`). The grid is
    /// then fitted to the padded boxes in f64, whose rounding (2^-52 of the magnitudes) is far
    /// below the padding.
    fn quantize(node: &BuildNode) -> Node {
        let occupied = (0..8)
            .filter(|&c| node.child[c] != 0)
            .fold(0u8, |m, c| m | (1 << c));
        let mut quantized = Node {
            child: node.child,
            origin: [0.0; 3],
            exponent: [0; 3],
            occupied,
            grid: [[[0; 8]; 2]; 3],
        };
        let slots = move || (0..8).filter(move |&c| (occupied >> c) & 1 != 0);
        if occupied == 0 {
            return quantized;
        }
        let p = &node.planes;
        let magnitude = slots()
            .flat_map(|c| (0..3).flat_map(move |a| [p[a][0][c].abs(), p[a][1][c].abs()]))
            .fold(0.0f32, f32::max);
        let pad = f64::from(PADDING) * 17.0 / 16.0 * f64::from(magnitude).max(TINY_MAGNITUDE);
        for (axis, [los, his]) in p.iter().enumerate() {
            let lo = |c: usize| f64::from(los[c]) - pad;
            let hi = |c: usize| f64::from(his[c]) + pad;
            let node_lo = slots().map(lo).fold(f64::INFINITY, f64::min);
            let node_hi = slots().map(hi).fold(f64::NEG_INFINITY, f64::max);
            let origin = f32_at_or_below(node_lo);
            // The finest step whose 255 steps from the origin reach the node's maximum.
            let fits = |e: i32| f64::from(origin) + 255.0 * 2f64.powi(e) >= node_hi;
            let mut e = ((node_hi - f64::from(origin)) / 255.0)
                .log2()
                .ceil()
                .clamp(-126.0, 127.0) as i32;
            while e > -126 && fits(e - 1) {
                e -= 1;
            }
            while e < 127 && !fits(e) {
                e += 1;
            }
            let step = 2f64.powi(e);
            for c in slots() {
                let q_lo = ((lo(c) - f64::from(origin)) / step).floor();
                let q_hi = ((hi(c) - f64::from(origin)) / step).ceil();
                quantized.grid[axis][0][c] = q_lo.clamp(0.0, 255.0) as u8;
                quantized.grid[axis][1][c] = q_hi.clamp(0.0, 255.0) as u8;
            }
            quantized.origin[axis] = origin;
            quantized.exponent[axis] = e as i8;
        }
        quantized
    }

    /// The grid steps, `2^exponent` per axis (exponents lie in -126..=127: normal f32).
    #[inline(always)]
    fn steps(&self) -> [f32; 3] {
        self.exponent
            .map(|e| f32::from_bits(((i32::from(e) + 127) as u32) << 23))
    }
}

/// The largest f32 at or below `x` (finite).
fn f32_at_or_below(x: f64) -> f32 {
    let y = x as f32;
    if f64::from(y) > x { y.next_down() } else { y }
}

/// Trees of at least this many bytes (nodes and packets) prefetch the children a node's ray
/// will visit later; smaller ones stay in the caches, where the prefetches only cost
/// instructions. Measured (docs/measurements/2026-11-26-rays-against-embree.md, bench --rays,
/// one thread, 4 rounds): without prefetching, closest-hit rays 4% and shadow rays 1-2%
/// faster on cornell_box and door_ajar (a tree of 0.9 MB), and 3% slower on the 1M-triangle scene.
const PREFETCH_FROM_BYTES: usize = 4 << 20;

pub(crate) struct Bvh8 {
    nodes: Vec<Node>,
    /// Whether traversal prefetches the children it will visit later (big trees only).
    prefetch: bool,
}

impl Bvh8 {
    /// Bytes of the tree's nodes.
    pub(crate) fn memory_bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node>()
    }

    /// A tree of `nodes` over `packets` triangle packets: the nodes' exact boxes are padded
    /// and quantized here (see `Node::quantize` and `BoxRay`).
    pub(super) fn new(build_nodes: Vec<BuildNode>, packets: usize) -> Bvh8 {
        let mut nodes = Vec::with_capacity(build_nodes.len());
        super::collapse::advise_huge_pages(&nodes);
        nodes.par_extend(build_nodes.par_iter().map(Node::quantize));
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
    /// with the `avx2` and `fma` target features (see `Accel::traverse_avx2`), which only runs
    /// where the CPU has them.
    #[inline(always)]
    pub(crate) fn traverse<const ANY: bool, const AVX2: bool>(
        &self,
        tris: &LeafTriangles,
        ray: &TraversalRay,
        mut t_max: f32,
    ) -> Option<TriangleHit> {
        let box_ray = BoxRay::new(ray);
        let mut hit = None;
        // Pending children: the entry distance (non-negative, so its bits order like the
        // value) in the high half, the child reference in the low half.
        let mut stack = TraversalStack::<u64, 24>::new();
        let mut current = 0u32;
        loop {
            if current & LEAF != 0 {
                let packet = ((current & !LEAF) >> LANES) as usize;
                if let Some((lane, (t, b1, b2))) =
                    ray.intersect4::<ANY>(&tris.packets[packet], current & LANE_MASK, &mut t_max)
                {
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
                    // AVX2 and FMA (see the doc comment above).
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
                            &mut t_max,
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
/// magnitude of the node's planes and grid origin: its part `2^-18 m` is added to the
/// children's float boxes before they are quantized (`Node::quantize`), its part
/// `pad = 2^-18 max |o|` moves the origin here. A plane `origin + q step` (q a whole number
/// of grid steps, `step` a power of two) is reached at `((origin - o) + q step) * inv_dir`:
/// `q step` is exact, so the rounding is that of `origin - o`, of the sum and of the product
/// with the rounded reciprocal (each relative 2^-24 of at most `|o| + m`, times `|inv_dir|`),
/// far below the padding, as is the rounding of the triangle test for a triangle in that box
/// (a few 2^-24 of the same magnitudes). So the box test is conservative: a ray never misses a
/// box that holds a triangle it hits. Padding by each node's own magnitudes, not the scene's
/// largest, keeps one huge triangle (a floor 2e10 wide) from enlarging every box in the scene:
/// with the scene's, a 4 m room's boxes grew by 38 km and every ray entered every box.
struct BoxRay {
    /// Per axis: the index (0: minima, 1: maxima) of the planes the ray enters by.
    near: [usize; 3],
    /// The origin moved back along the ray by `pad` (for the entry planes) and forwards (for
    /// the exit planes).
    o_near: Vec3A,
    o_far: Vec3A,
    inv: [f32; 3],
}

impl BoxRay {
    #[inline(always)]
    fn new(ray: &TraversalRay) -> BoxRay {
        let o = ray.origin;
        let pad = o.abs().max_element() * PADDING;
        let neg = ray.neg;
        // Entering through min - pad (positive direction): (min - pad) - o = min - (o + pad);
        // through max + pad (negative direction): max - (o - pad). Lane by lane, the same
        // scalar operations; the sign of `inv_dir` is that of the direction.
        let signed_pad = Vec3A::splat(pad).copysign(ray.inv_dir);
        BoxRay {
            near: [0, 1, 2].map(|axis| ((neg >> axis) & 1) as usize),
            o_near: o + signed_pad,
            o_far: o - signed_pad,
            inv: ray.inv_dir.to_array(),
        }
    }

    /// Per axis, `node`'s grid origin relative to the entry and to the exit origins, and its
    /// grid step.
    #[inline(always)]
    fn grid(&self, node: &Node) -> ([f32; 3], [f32; 3], [f32; 3]) {
        let origin = Vec3A::from(node.origin);
        (
            (origin - self.o_near).to_array(),
            (origin - self.o_far).to_array(),
            node.steps(),
        )
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
    let (near_rel, far_rel, steps) = ray.grid(node);
    // SAFETY: SSE2 is part of the x86_64 baseline, so these intrinsics are always available;
    // the loads and stores are unaligned ones on `[u8; 8]`, `[u32; 8]` and `[f32; 8]` arrays
    // borrowed (or owned) here.
    unsafe {
        let zero = _mm_setzero_si128();
        // Eight grid offsets as two vectors of four f32.
        let offsets = |q: &[u8; 8]| {
            let words = _mm_unpacklo_epi8(_mm_loadl_epi64(q.as_ptr().cast()), zero);
            (
                _mm_cvtepi32_ps(_mm_unpacklo_epi16(words, zero)),
                _mm_cvtepi32_ps(_mm_unpackhi_epi16(words, zero)),
            )
        };
        let mut t0 = (_mm_setzero_ps(), _mm_setzero_ps());
        let mut t1 = (_mm_set1_ps(t_max), _mm_set1_ps(t_max));
        for axis in 0..3 {
            let n = ray.near[axis];
            let inv = _mm_set1_ps(ray.inv[axis]);
            let step = _mm_set1_ps(steps[axis]);
            let (near_lo, near_hi) = offsets(&node.grid[axis][n]);
            let (far_lo, far_hi) = offsets(&node.grid[axis][1 - n]);
            // `q * step` is exact, so this is the AVX2 version's fused multiply-add, bit for
            // bit.
            let slab = |q, rel| _mm_mul_ps(_mm_add_ps(_mm_mul_ps(q, step), rel), inv);
            let (on, of) = (_mm_set1_ps(near_rel[axis]), _mm_set1_ps(far_rel[axis]));
            // max_ps(a, b) is `a > b ? a : b` and min_ps(a, b) is `a < b ? a : b`: a NaN slab
            // distance (0 * inf: the ray runs in a slab's plane) constrains nothing.
            t0 = (
                _mm_max_ps(slab(near_lo, on), t0.0),
                _mm_max_ps(slab(near_hi, on), t0.1),
            );
            t1 = (
                _mm_min_ps(slab(far_lo, of), t1.0),
                _mm_min_ps(slab(far_hi, of), t1.1),
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
        ((lo | (hi << 4)) & u32::from(node.occupied), leaves, t)
    }
}

/// `box_hits8` with eight lanes per instruction (AVX2 and FMA): the same arithmetic, lane for
/// lane, so the same results.
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn box_hits8_avx2(node: &Node, ray: &BoxRay, t_max: f32) -> (u32, u32, [f32; 8]) {
    use std::arch::x86_64::*;
    // The node's origin, then its exponents and occupancy bytes, in one load; the grid's
    // origin relative to the ray's entry and exit origins and the steps (`Node::steps`) in
    // three lanes each, as `BoxRay::grid` computes them.
    // SAFETY: an unaligned 16-byte load of `node.origin`, `node.exponent` and
    // `node.occupied`, which are contiguous (`repr(C)`).
    let header = unsafe { _mm_loadu_si128(node.origin.as_ptr().cast()) };
    let origin = _mm_castsi128_ps(header);
    let near_rel = _mm_sub_ps(origin, ray.o_near.into());
    let far_rel = _mm_sub_ps(origin, ray.o_far.into());
    let exponents = _mm_cvtepi8_epi32(_mm_srli_si128::<12>(header));
    let steps = _mm_castsi128_ps(_mm_add_epi32(
        _mm_slli_epi32::<23>(exponents),
        _mm_set1_epi32(127 << 23),
    ));
    // Eight grid offsets as eight f32.
    // SAFETY: an unaligned load of the eight bytes of a `[u8; 8]` array of `node`.
    let offsets = |q: &[u8; 8]| {
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(unsafe {
            _mm_loadl_epi64(q.as_ptr().cast())
        }))
    };
    let mut t0 = _mm256_setzero_ps();
    let mut t1 = _mm256_set1_ps(t_max);
    let mut slabs = |axis: usize, near_rel: __m128, far_rel: __m128, step: __m128| {
        let n = ray.near[axis] & 1;
        let near = offsets(&node.grid[axis][n]);
        let far = offsets(&node.grid[axis][1 - n]);
        let inv = _mm256_set1_ps(ray.inv[axis]);
        let step = _mm256_broadcastss_ps(step);
        // One rounding of `q * step + rel`, as in `box_hits8` (`q * step` is exact).
        let tn = _mm256_mul_ps(
            _mm256_fmadd_ps(near, step, _mm256_broadcastss_ps(near_rel)),
            inv,
        );
        let tf = _mm256_mul_ps(
            _mm256_fmadd_ps(far, step, _mm256_broadcastss_ps(far_rel)),
            inv,
        );
        // As in `box_hits8`: a NaN slab distance constrains nothing.
        t0 = _mm256_max_ps(tn, t0);
        t1 = _mm256_min_ps(tf, t1);
    };
    slabs(0, near_rel, far_rel, steps);
    slabs(
        1,
        _mm_permute_ps::<0x55>(near_rel),
        _mm_permute_ps::<0x55>(far_rel),
        _mm_permute_ps::<0x55>(steps),
    );
    slabs(
        2,
        _mm_permute_ps::<0xaa>(near_rel),
        _mm_permute_ps::<0xaa>(far_rel),
        _mm_permute_ps::<0xaa>(steps),
    );
    let hits = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t0, t1)) as u32;
    // SAFETY: an unaligned load of the eight u32 of `node.child`, read as f32 for their sign
    // bits only.
    let leaves =
        _mm256_movemask_ps(unsafe { _mm256_loadu_ps(node.child.as_ptr().cast::<f32>()) }) as u32;
    let mut t = [0.0f32; 8];
    // SAFETY: an unaligned store of eight f32 into a local `[f32; 8]`.
    unsafe { _mm256_storeu_ps(t.as_mut_ptr(), t0) };
    (hits & u32::from(node.occupied), leaves, t)
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
    let (near_rel, far_rel, steps) = ray.grid(node);
    let mut t0 = [0.0f32; 8];
    let mut t1 = [t_max; 8];
    for axis in 0..3 {
        let n = ray.near[axis];
        let (near, far) = (&node.grid[axis][n], &node.grid[axis][1 - n]);
        let inv = ray.inv[axis];
        for c in 0..8 {
            let tn = (f32::from(near[c]) * steps[axis] + near_rel[axis]) * inv;
            let tf = (f32::from(far[c]) * steps[axis] + far_rel[axis]) * inv;
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
    (hits & u32::from(node.occupied), leaves, t0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::SampleKey;

    /// A node's quantized boxes hold its children's float boxes padded by `PADDING` times
    /// the largest magnitude of the quantized node's planes and origin (what `BoxRay`'s
    /// conservativeness needs), checked in f64 on random nodes of one to eight children at
    /// every scale from 1e-30 to 1e12, boxes from points (zero extent) to the node's whole
    /// size, and nodes that hold one huge child among tiny ones.
    #[test]
    fn quantized_boxes_hold_the_padded_float_boxes() {
        let r = |i: u64, d: u32| f64::from(SampleKey::new(31, i, 0).get(d));
        for i in 0..20_000u64 {
            let scale = 10f64.powf(-30.0 + 42.0 * r(i, 0));
            // Far from the origin relative to its size, or around it.
            let centre =
                [1, 2, 3].map(|d| (r(i, d) * 2.0 - 1.0) * scale * 10f64.powf(6.0 * r(i, 4)));
            let children = 1 + (r(i, 5) * 8.0) as usize % 8;
            let mut node = BuildNode::EMPTY;
            for c in 0..children {
                let d = 10 + 10 * c as u32;
                let size = match (r(i, d) * 4.0) as u32 {
                    0 => 0.0,
                    1 => scale * 1e-7 * r(i, d + 1),
                    2 if c == 0 => scale * 1e6,
                    _ => scale * r(i, d + 1),
                };
                let lo =
                    Vec3::from([0, 1, 2].map(|a| {
                        (centre[a] + (r(i, d + 2 + a as u32) * 2.0 - 1.0) * scale) as f32
                    }));
                // Some axes flat (zero extent), the rest of random extent.
                let extent = Vec3::from([0, 1, 2].map(|a| {
                    if r(i, d + 6 + a) < 0.2 {
                        0.0
                    } else {
                        (size * r(i, d + 9)) as f32
                    }
                }));
                let hi = lo + extent;
                let reference = if c % 2 == 0 {
                    LEAF | c as u32
                } else {
                    1 + c as u32
                };
                node.set_child(c, reference, lo, hi);
            }
            let q = Node::quantize(&node);
            assert_eq!(q.child, node.child);
            assert_eq!(u32::from(q.occupied), (1 << children) - 1);
            let plane = |a: usize, side: usize, c: usize| {
                f64::from(q.origin[a])
                    + f64::from(q.grid[a][side][c]) * 2f64.powi(i32::from(q.exponent[a]))
            };
            let magnitude = (0..3)
                .flat_map(|a| {
                    let origin = f64::from(q.origin[a]).abs();
                    (0..children)
                        .flat_map(move |c| [plane(a, 0, c).abs(), plane(a, 1, c).abs()])
                        .chain([origin])
                })
                .fold(0.0f64, f64::max);
            let pad = f64::from(PADDING) * magnitude;
            for c in 0..children {
                for a in 0..3 {
                    let (lo, hi) = (node.planes[a][0][c], node.planes[a][1][c]);
                    assert!(
                        plane(a, 0, c) <= f64::from(lo) - pad
                            && plane(a, 1, c) >= f64::from(hi) + pad,
                        "node {i}, child {c}, axis {a}: {lo}..{hi} quantized to {}..{}",
                        plane(a, 0, c),
                        plane(a, 1, c)
                    );
                }
            }
        }
    }
}
