//! Rays sixteen at a time through the eight-wide tree, one AVX-512 lane a ray: closest hits
//! and shadow rays (Wald, Slusallek, Benthin and Wagner's packets, with Benthin, Wald, Woop,
//! Ernst and Mark's fall-back to single rays once few of a packet's rays are left at a node).
//!
//! A node's eight child boxes are tested against the packet's active rays one child at a time,
//! and a leaf's triangles one triangle at a time, each against all sixteen rays in one pass of
//! the same watertight test the single-ray traversal runs (the same operations on the same
//! inputs, lane by lane, so the same t and barycentrics). Where a ray's edge function rounds
//! to exactly zero, that ray's test of that triangle is redone by the scalar test, as in the
//! single-ray one. The packet visits children in the order of the nearest entry distance of
//! its rays, not each ray's own order; `closer`'s tie-break makes the closest hit the same
//! whatever the order, so every ray finds the hit the single-ray traversal finds, bit for bit,
//! and every shadow ray the same answer. Measured against single rays on cornell_box,
//! door_ajar and big_1m in docs/measurements/2026-11-29-ray-packets.md.

use super::bvh8::{Bvh8, LANE_MASK, LEAF, PADDING, ROOT};
use super::stack::TraversalStack;
use super::triangle::{LANES, RANGE_MARGIN, TraversalRay, TrianglePacket, closer};
use super::{LeafTriangles, NO_HINT, TriangleHit};
use crate::math::gamma;
use glam::{Vec3, Vec3A};
use std::arch::x86_64::*;

/// Rays in a packet.
pub(crate) const WIDTH: usize = 16;

/// Below this many active rays at a node, the packet's rays there go on one at a time (the
/// single-ray traversal of that subtree), as a few rays waste most of a packet's lanes.
/// Measured (one thread, shares of the render in `trace_closest` and `trace_shadow`, 2
/// rounds): 2, 3 and 4 are within 1-2% of each other on cornell_box, door_ajar and big_1m;
/// never falling back wins on cornell_box (32 triangles) but loses a fifth of the shadow
/// rays' speed on big_1m; 8 or more loses on cornell_box and door_ajar
/// (docs/measurements/2026-11-29-ray-packets.md).
const SINGLE_BELOW: u32 = 3;

/// Up to sixteen rays by component, as a packet reads them: lanes `len..` and lanes whose ray
/// is not finite, has a zero direction or a `t_max` that is not positive are traced by none.
pub(crate) struct RayColumns {
    origin: [[f32; WIDTH]; 3],
    dir: [[f32; WIDTH]; 3],
    t_max: [f32; WIDTH],
    pub(crate) len: usize,
}

impl RayColumns {
    pub(crate) fn new() -> RayColumns {
        RayColumns {
            origin: [[0.0; WIDTH]; 3],
            dir: [[0.0; WIDTH]; 3],
            t_max: [0.0; WIDTH],
            len: 0,
        }
    }

    /// Adds a ray in lane `len` (which must be below `WIDTH`).
    #[inline(always)]
    pub(crate) fn push(&mut self, origin: Vec3, dir: Vec3, t_max: f32) {
        let i = self.len;
        for axis in 0..3 {
            self.origin[axis][i] = origin[axis];
            self.dir[axis][i] = dir[axis];
        }
        self.t_max[i] = t_max;
        self.len += 1;
    }

    /// The ray of lane `i` for the single-ray traversal and the scalar triangle test.
    #[inline(always)]
    fn ray(&self, i: usize) -> TraversalRay {
        let column = |c: &[[f32; WIDTH]; 3]| Vec3A::new(c[0][i], c[1][i], c[2][i]);
        TraversalRay::new(column(&self.origin), column(&self.dir))
    }
}

/// The best hit of each ray so far: t (the ray's t_max), leaf-order slot (`u32::MAX`: none)
/// and barycentrics.
pub(crate) struct Best {
    pub(crate) t: [f32; WIDTH],
    pub(crate) slot: [u32; WIDTH],
    pub(crate) b1: [f32; WIDTH],
    pub(crate) b2: [f32; WIDTH],
}

impl Best {
    /// No hit yet, each ray up to its `t_max`.
    #[inline(always)]
    pub(crate) fn none(rays: &RayColumns) -> Best {
        Best {
            t: rays.t_max,
            slot: [u32::MAX; WIDTH],
            b1: [0.0; WIDTH],
            b2: [0.0; WIDTH],
        }
    }
}

/// A child still to visit: its reference, the rays that entered its box, and their entry
/// distances.
#[derive(Clone, Copy)]
struct Pending {
    reference: u32,
    rays: u16,
    entry: [f32; WIDTH],
}

impl Default for Pending {
    fn default() -> Pending {
        Pending {
            reference: 0,
            rays: 0,
            entry: [0.0; WIDTH],
        }
    }
}

/// The packet's rays as lanes: the box test's (see `BoxRay`) and the triangle test's (see
/// `TraversalRay`) constants.
struct Lanes {
    o_near: [__m512; 3],
    o_far: [__m512; 3],
    inv: [__m512; 3],
    /// Per axis, the rays whose direction is negative along it (they enter by the maxima).
    neg: [u16; 3],
    /// The rays whose direction is largest along x, and along y (the rest: along z): which
    /// axes the triangle test rotates to x, y and z.
    along_x: u16,
    along_y: u16,
    o_k: [__m512; 3],
    sx: __m512,
    sy: __m512,
    sz: __m512,
}

impl Lanes {
    /// The lanes of `rays`, computed sixteen at a time with the scalar constructors'
    /// operations (`TraversalRay::new`, `BoxRay::new`), so the same values; and the lanes
    /// with a ray to trace.
    ///
    /// # Safety
    /// The CPU must support AVX-512 F and DQ.
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    unsafe fn new(rays: &RayColumns) -> (Lanes, u16) {
        // SAFETY: unaligned loads of sixteen f32 from arrays of `rays`.
        let load = |c: &[f32; WIDTH]| unsafe { _mm512_loadu_ps(c.as_ptr()) };
        let o = [0, 1, 2].map(|a| load(&rays.origin[a]));
        let d = [0, 1, 2].map(|a| load(&rays.dir[a]));
        let t_max = load(&rays.t_max);
        let zero = _mm512_setzero_ps();
        // x - x is 0 unless x is infinite or NaN.
        let finite = |x: __m512| _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(_mm512_sub_ps(x, x), zero);
        let nonzero = _mm512_cmp_ps_mask::<_CMP_NEQ_OQ>(d[0], zero)
            | _mm512_cmp_ps_mask::<_CMP_NEQ_OQ>(d[1], zero)
            | _mm512_cmp_ps_mask::<_CMP_NEQ_OQ>(d[2], zero);
        let all_finite = (0..3).fold(u16::MAX, |m, a| m & finite(o[a]) & finite(d[a]));
        let in_len = ((1u32 << rays.len) - 1) as u16;
        let valid = in_len & all_finite & nonzero & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(t_max, zero);
        let one = _mm512_set1_ps(1.0);
        let inv = [0, 1, 2].map(|a| _mm512_div_ps(one, d[a]));
        let sign_bit = _mm512_set1_ps(-0.0);
        let neg = [0, 1, 2].map(|a| _mm512_movepi32_mask(_mm512_castps_si512(d[a])));
        let abs = [0, 1, 2].map(|a| _mm512_abs_ps(d[a]));
        // The axis the direction is largest along, as `TraversalRay::new` chooses it.
        let x_over_y = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(abs[0], abs[1]);
        let along_x = x_over_y & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(abs[0], abs[2]);
        let along_y = !x_over_y & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(abs[1], abs[2]);
        // The axes k per lane: along x (1, 2, 0), along y (2, 0, 1), else (0, 1, 2).
        let rotate = |v: &[__m512; 3]| {
            [
                _mm512_mask_blend_ps(along_y, _mm512_mask_blend_ps(along_x, v[0], v[1]), v[2]),
                _mm512_mask_blend_ps(along_y, _mm512_mask_blend_ps(along_x, v[1], v[2]), v[0]),
                _mm512_mask_blend_ps(along_y, _mm512_mask_blend_ps(along_x, v[2], v[0]), v[1]),
            ]
        };
        let dk = rotate(&d);
        let sz = _mm512_div_ps(one, dk[2]);
        let negate = |v: __m512| _mm512_xor_ps(v, sign_bit);
        let largest = _mm512_max_ps(
            _mm512_max_ps(_mm512_abs_ps(o[0]), _mm512_abs_ps(o[1])),
            _mm512_abs_ps(o[2]),
        );
        let pad = _mm512_mul_ps(largest, _mm512_set1_ps(PADDING));
        // The padding with the sign of the direction (that of its reciprocal).
        let signed_pad = [0, 1, 2].map(|a| _mm512_or_ps(pad, _mm512_and_ps(d[a], sign_bit)));
        let lanes = Lanes {
            o_near: [0, 1, 2].map(|a| _mm512_add_ps(o[a], signed_pad[a])),
            o_far: [0, 1, 2].map(|a| _mm512_sub_ps(o[a], signed_pad[a])),
            inv,
            neg,
            along_x,
            along_y,
            o_k: rotate(&o),
            sx: _mm512_mul_ps(negate(dk[0]), sz),
            sy: _mm512_mul_ps(negate(dk[1]), sz),
            sz,
        };
        (lanes, valid)
    }
}

impl Bvh8 {
    /// The closest hits with t in (0, t_max) of `rays` into `best` (which starts as
    /// `Best::none(rays)`), exactly those of `traverse::<false, _>` ray by ray. Returns the
    /// rays that were traced.
    ///
    /// # Safety
    /// The CPU must support AVX-512 F, DQ, VL and BW, AVX2 and FMA.
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    pub(crate) unsafe fn closest16(
        &self,
        tris: &LeafTriangles,
        rays: &RayColumns,
        best: &mut Best,
    ) -> u16 {
        // SAFETY: as the caller guarantees.
        unsafe { self.trace16::<false>(tris, rays, best, NO_HINT).0 }
    }

    /// Which of `rays` hit anything with t in (0, t_max): exactly `traverse::<true, _>`'s
    /// answers ray by ray (a bit per ray). The triangles of packet `hint` (any value is safe)
    /// are tried first, as `Accel::any_hit_with_hint` does for single rays; `hint` becomes the
    /// packet of an occluder found, or `NO_HINT` if no ray was occluded.
    ///
    /// # Safety
    /// As for `closest16`.
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    pub(crate) unsafe fn occluded16(
        &self,
        tris: &LeafTriangles,
        rays: &RayColumns,
        hint: &mut u32,
    ) -> u16 {
        let mut best = Best::none(rays);
        // SAFETY: as the caller guarantees.
        let (_, occluded, last) = unsafe { self.trace16::<true>(tris, rays, &mut best, *hint) };
        *hint = if occluded != 0 {
            last / LANES as u32
        } else {
            NO_HINT
        };
        occluded
    }

    /// The packet traversal: with `ANY`, until each ray has a hit below its `t_max`, trying
    /// the triangle packet `hint` first; else the closest hits, into `best`. Returns the rays
    /// traced and, with `ANY`, those that hit and the slot of the last hit found.
    ///
    /// # Safety
    /// As for `closest16`.
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    unsafe fn trace16<const ANY: bool>(
        &self,
        tris: &LeafTriangles,
        rays: &RayColumns,
        best: &mut Best,
        hint: u32,
    ) -> (u16, u16, u32) {
        // SAFETY: the caller guarantees AVX-512 F and DQ.
        let (lanes, valid) = unsafe { Lanes::new(rays) };
        // With `ANY`, the rays that hit something (and need go no further), and the slot of
        // the last hit found.
        let mut done = 0u16;
        let mut last = u32::MAX;
        if ANY && let Some(packet) = tris.packets.get(hint as usize) {
            // The triangles that blocked the previous packet's rays first.
            for l in (0..LANES).filter(|&l| packet.ids[l] != u32::MAX) {
                let slot = (hint as usize * LANES + l) as u32;
                // SAFETY: the caller guarantees AVX-512 F and DQ.
                let hit = unsafe {
                    test_triangle::<true>(&lanes, rays, packet, l, slot, valid & !done, best)
                };
                if hit != 0 {
                    done |= hit;
                    last = slot;
                }
            }
            if done == valid {
                return (valid, done, last);
            }
        }
        let mut stack = TraversalStack::<Pending, 24>::new();
        let (mut current, mut active) = (ROOT, valid);
        loop {
            if active.count_ones() < SINGLE_BELOW {
                // A few rays: each goes on through this subtree alone.
                let mut left = active;
                while left != 0 {
                    let i = left.trailing_zeros() as usize;
                    left &= left - 1;
                    let ray = &rays.ray(i);
                    if ANY {
                        if let Some(h) =
                            self.traverse_from::<true, true>(tris, ray, current, best.t[i], None)
                        {
                            done |= 1 << i;
                            last = h.slot;
                        }
                        continue;
                    }
                    let so_far = (best.slot[i] != u32::MAX).then_some(TriangleHit {
                        t: best.t[i],
                        slot: best.slot[i],
                        b1: best.b1[i],
                        b2: best.b2[i],
                    });
                    if let Some(h) =
                        self.traverse_from::<false, true>(tris, ray, current, best.t[i], so_far)
                    {
                        (best.t[i], best.slot[i], best.b1[i], best.b2[i]) =
                            (h.t, h.slot, h.b1, h.b2);
                    }
                }
            } else if current & LEAF != 0 {
                let packet = ((current & !LEAF) >> LANES) as usize;
                let mut leaf_lanes = current & LANE_MASK;
                while leaf_lanes != 0 && active != 0 {
                    let l = leaf_lanes.trailing_zeros() as usize;
                    leaf_lanes &= leaf_lanes - 1;
                    // SAFETY: the caller guarantees AVX-512 F and DQ.
                    let hit = unsafe {
                        test_triangle::<ANY>(
                            &lanes,
                            rays,
                            &tris.packets[packet],
                            l,
                            (packet * LANES + l) as u32,
                            active,
                            best,
                        )
                    };
                    if ANY && hit != 0 {
                        done |= hit;
                        active &= !hit;
                        last = (packet * LANES + l) as u32;
                    }
                }
                if ANY && done == valid {
                    return (valid, done, last);
                }
            } else {
                // SAFETY: the caller guarantees AVX-512 F and DQ.
                let next = unsafe { self.visit_node(current, &lanes, active, best, &mut stack) };
                if let Some((reference, rays)) = next {
                    (current, active) = (reference, rays);
                    continue;
                }
            }
            if ANY && done == valid {
                return (valid, done, last);
            }
            // The next pending child that some of its rays may still hit before their t_max.
            loop {
                let Some(p) = stack.pop() else {
                    return (valid, done, last);
                };
                // SAFETY: the caller guarantees AVX-512 F; unaligned loads of sixteen f32.
                let rays = unsafe {
                    _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(
                        p.rays & !done,
                        _mm512_loadu_ps(p.entry.as_ptr()),
                        _mm512_loadu_ps(best.t.as_ptr()),
                    )
                };
                if rays != 0 {
                    (current, active) = (p.reference, rays);
                    break;
                }
            }
        }
    }

    /// Tests the children of node `node` against the `active` rays: pushes all the entered
    /// children but the nearest (farthest first), and returns the nearest with its rays.
    /// Children are ordered by their nearest entry distance over the rays (then reference).
    ///
    /// # Safety
    /// The CPU must support AVX-512 F and DQ.
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    unsafe fn visit_node(
        &self,
        node: u32,
        lanes: &Lanes,
        active: u16,
        best: &Best,
        stack: &mut TraversalStack<Pending, 24>,
    ) -> Option<(u32, u16)> {
        let node = &self.nodes[node as usize];
        // SAFETY: the caller guarantees AVX-512 F and DQ; unaligned loads of sixteen f32.
        unsafe {
            let t_max = _mm512_loadu_ps(best.t.as_ptr());
            let mut entered = [Pending::default(); 8];
            let mut keys = [0u64; 8];
            let mut n = 0;
            for c in 0..8 {
                let reference = node.child[c];
                if reference == 0 {
                    continue;
                }
                let mut t0 = _mm512_setzero_ps();
                let mut t1 = t_max;
                for axis in 0..3 {
                    let lo = _mm512_set1_ps(node.planes[axis][0][c]);
                    let hi = _mm512_set1_ps(node.planes[axis][1][c]);
                    let neg = lanes.neg[axis];
                    let near = _mm512_mask_blend_ps(neg, lo, hi);
                    let far = _mm512_mask_blend_ps(neg, hi, lo);
                    let inv = lanes.inv[axis];
                    let tn = _mm512_mul_ps(_mm512_sub_ps(near, lanes.o_near[axis]), inv);
                    let tf = _mm512_mul_ps(_mm512_sub_ps(far, lanes.o_far[axis]), inv);
                    // As in `box_hits8`: a NaN slab distance constrains nothing.
                    t0 = _mm512_max_ps(tn, t0);
                    t1 = _mm512_min_ps(tf, t1);
                }
                let rays = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(active, t0, t1);
                if rays == 0 {
                    continue;
                }
                let nearest = _mm512_mask_reduce_min_ps(rays, t0);
                let mut pending = Pending {
                    reference,
                    rays,
                    entry: [0.0; WIDTH],
                };
                _mm512_storeu_ps(pending.entry.as_mut_ptr(), t0);
                // Entry distances are not negative, so their bits order like their values.
                let key = (u64::from(nearest.to_bits()) << 32) | n as u64;
                // Insertion by key, farthest first.
                let mut j = n;
                while j > 0 && keys[j - 1] < key {
                    keys[j] = keys[j - 1];
                    j -= 1;
                }
                keys[j] = key;
                entered[n] = pending;
                n += 1;
            }
            if n == 0 {
                return None;
            }
            for &k in &keys[..n - 1] {
                stack.push(entered[k as u32 as usize]);
            }
            let nearest = &entered[keys[n - 1] as u32 as usize];
            Some((nearest.reference, nearest.rays))
        }
    }
}

/// The watertight test of the triangle in lane `l` of `packet` (leaf-order slot `slot`)
/// against the `active` rays, `intersect4`'s operations lane for lane; each hit `closer` than
/// a ray's best becomes it, or with `ANY` each hit below the ray's t_max counts. Returns the
/// rays whose hit counted.
///
/// # Safety
/// The CPU must support AVX-512 F and DQ.
#[inline]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
unsafe fn test_triangle<const ANY: bool>(
    lanes: &Lanes,
    rays: &RayColumns,
    packet: &TrianglePacket,
    l: usize,
    slot: u32,
    active: u16,
    best: &mut Best,
) -> u16 {
    let mut taken = 0;
    // SAFETY: the caller guarantees AVX-512 F and DQ; the loads and stores are unaligned ones
    // of sixteen lanes from and to local or borrowed arrays.
    unsafe {
        let (ax, ay) = (lanes.along_x, lanes.along_y);
        // Vertex i rotated per ray (its axes k) and sheared, as `intersect4`'s `vertex`.
        let vertex = |i: usize| {
            let v = |axis: usize| _mm512_set1_ps(packet.v[i][axis][l]);
            let (vx, vy, vz) = (v(0), v(1), v(2));
            let kx = _mm512_mask_blend_ps(ay, _mm512_mask_blend_ps(ax, vx, vy), vz);
            let ky = _mm512_mask_blend_ps(ay, _mm512_mask_blend_ps(ax, vy, vz), vx);
            let kz = _mm512_mask_blend_ps(ay, _mm512_mask_blend_ps(ax, vz, vx), vy);
            let x = _mm512_sub_ps(kx, lanes.o_k[0]);
            let y = _mm512_sub_ps(ky, lanes.o_k[1]);
            let z = _mm512_sub_ps(kz, lanes.o_k[2]);
            (
                _mm512_add_ps(x, _mm512_mul_ps(lanes.sx, z)),
                _mm512_add_ps(y, _mm512_mul_ps(lanes.sy, z)),
                z,
            )
        };
        let (x0, y0, z0) = vertex(0);
        let (x1, y1, z1) = vertex(1);
        let (x2, y2, z2) = vertex(2);
        let e0 = _mm512_sub_ps(_mm512_mul_ps(x2, y1), _mm512_mul_ps(y2, x1));
        let e1 = _mm512_sub_ps(_mm512_mul_ps(x0, y2), _mm512_mul_ps(y0, x2));
        let e2 = _mm512_sub_ps(_mm512_mul_ps(x1, y0), _mm512_mul_ps(y1, x0));
        let zero = _mm512_setzero_ps();
        let lt = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(e0, zero)
            | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(e1, zero)
            | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(e2, zero);
        let gt = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(e0, zero)
            | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(e1, zero)
            | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(e2, zero);
        let eq = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e0, zero)
            | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e1, zero)
            | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(e2, zero);
        let exact = eq & active;
        let mut hits = active & !exact & !(lt & gt);
        if hits != 0 {
            let t_max = _mm512_loadu_ps(best.t.as_ptr());
            let det = _mm512_add_ps(_mm512_add_ps(e0, e1), e2);
            let az = _mm512_mul_ps(lanes.sz, z0);
            let bz = _mm512_mul_ps(lanes.sz, z1);
            let cz = _mm512_mul_ps(lanes.sz, z2);
            let t_scaled = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(e0, az), _mm512_mul_ps(e1, bz)),
                _mm512_mul_ps(e2, cz),
            );
            let sign = _mm512_and_ps(det, _mm512_set1_ps(-0.0));
            let ts = _mm512_xor_ps(t_scaled, sign);
            let limit = _mm512_mul_ps(
                _mm512_xor_ps(_mm512_mul_ps(t_max, det), sign),
                _mm512_set1_ps(RANGE_MARGIN),
            );
            hits &= _mm512_cmp_ps_mask::<_CMP_GT_OQ>(ts, zero)
                & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(ts, limit);
            if hits != 0 {
                let abs = |v: __m512| _mm512_abs_ps(v);
                let max3 = |a: __m512, b: __m512, c: __m512| {
                    _mm512_max_ps(_mm512_max_ps(abs(a), abs(b)), abs(c))
                };
                let inv_det = _mm512_div_ps(_mm512_set1_ps(1.0), det);
                let t = _mm512_mul_ps(t_scaled, inv_det);
                let max_z = max3(az, bz, cz);
                let max_x = max3(x0, x1, x2);
                let max_y = max3(y0, y1, y2);
                let g = |n: i32| _mm512_set1_ps(gamma(n));
                let delta_z = _mm512_mul_ps(g(3), max_z);
                let delta_x = _mm512_mul_ps(g(5), _mm512_add_ps(max_x, max_z));
                let delta_y = _mm512_mul_ps(g(5), _mm512_add_ps(max_y, max_z));
                let delta_e = _mm512_mul_ps(
                    _mm512_set1_ps(2.0),
                    _mm512_add_ps(
                        _mm512_add_ps(
                            _mm512_mul_ps(_mm512_mul_ps(g(2), max_x), max_y),
                            _mm512_mul_ps(delta_y, max_x),
                        ),
                        _mm512_mul_ps(delta_x, max_y),
                    ),
                );
                let max_e = max3(e0, e1, e2);
                let delta_t = _mm512_mul_ps(
                    _mm512_mul_ps(
                        _mm512_set1_ps(3.0),
                        _mm512_add_ps(
                            _mm512_add_ps(
                                _mm512_mul_ps(_mm512_mul_ps(g(3), max_e), max_z),
                                _mm512_mul_ps(delta_e, max_z),
                            ),
                            _mm512_mul_ps(delta_z, max_e),
                        ),
                    ),
                    abs(inv_det),
                );
                // `closer`: a nearer t, or the same t on a lower slot than the best's (any
                // hit takes no tie).
                let best_slot = _mm512_loadu_si512(best.slot.as_ptr().cast());
                let lower_slot = if ANY {
                    0
                } else {
                    // Rays without a hit yet (slot `u32::MAX`) take no tie: t_max is
                    // beyond their range.
                    _mm512_cmplt_epu32_mask(_mm512_set1_epi32(slot as i32), best_slot)
                        & _mm512_cmpneq_epu32_mask(best_slot, _mm512_set1_epi32(-1))
                };
                taken = hits
                    & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(t, delta_t)
                    & (_mm512_cmp_ps_mask::<_CMP_LT_OQ>(t, t_max)
                        | (_mm512_cmp_ps_mask::<_CMP_EQ_OQ>(t, t_max) & lower_slot));
                if !ANY && taken != 0 {
                    let b1 = _mm512_mul_ps(e1, inv_det);
                    let b2 = _mm512_mul_ps(e2, inv_det);
                    _mm512_storeu_ps(best.t.as_mut_ptr(), _mm512_mask_mov_ps(t_max, taken, t));
                    _mm512_storeu_si512(
                        best.slot.as_mut_ptr().cast(),
                        _mm512_mask_mov_epi32(best_slot, taken, _mm512_set1_epi32(slot as i32)),
                    );
                    let old_b1 = _mm512_loadu_ps(best.b1.as_ptr());
                    let old_b2 = _mm512_loadu_ps(best.b2.as_ptr());
                    _mm512_storeu_ps(best.b1.as_mut_ptr(), _mm512_mask_mov_ps(old_b1, taken, b1));
                    _mm512_storeu_ps(best.b2.as_mut_ptr(), _mm512_mask_mov_ps(old_b2, taken, b2));
                }
            }
        }
        // Rays with an edge function of exactly zero: the scalar test, which redoes it exactly.
        let mut left = exact;
        while left != 0 {
            let i = left.trailing_zeros() as usize;
            left &= left - 1;
            // No tie is taken before a hit (slot `u32::MAX`), nor by any hit.
            let tie_below = if ANY || best.slot[i] == u32::MAX {
                0
            } else {
                best.slot[i]
            };
            if let Some((t, b1, b2)) = rays
                .ray(i)
                .intersect(&packet.columns(l), best.t[i])
                .filter(|h| closer(h.0, slot, best.t[i], tie_below))
            {
                taken |= 1 << i;
                if !ANY {
                    (best.t[i], best.slot[i], best.b1[i], best.b2[i]) = (t, slot, b1, b2);
                }
            }
        }
    }
    taken
}
