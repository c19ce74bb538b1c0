//! Rays a packet at a time through the eight-wide tree, one vector lane a ray: sixteen rays
//! with AVX-512, eight with AVX2 (coherent rays only: see `closest::TraceCoherentClosest`), from
//! one source generic over the ISA (`simd`). Closest hits and shadow rays (Wald, Slusallek, Benthin and Wagner's packets, with
//! Benthin, Wald, Woop, Ernst and Mark's fall-back to single rays once few of a packet's rays
//! are left at a node).
//!
//! A node's eight child boxes are tested against the packet's active rays one child at a time,
//! and a leaf's triangles one triangle at a time, each against all the packet's rays in one
//! pass of the same watertight test the single-ray traversal runs (the same operations on the
//! same inputs, lane by lane, so the same t and barycentrics). Where a ray's edge function
//! rounds to exactly zero, that ray's test of that triangle is redone by the scalar test, as in
//! the single-ray one. A closest-hit packet visits children in the order of the nearest entry
//! distance of its rays, not each ray's own order, and a shadow packet in slot order;
//! `closer`'s tie-break makes the closest hit the same whatever the order, so every ray finds
//! the hit the single-ray traversal finds, bit for bit, and every shadow ray the same answer.
//! Measured against single rays on cornell_box, door_ajar and big_1m in
//! docs/measurements/2026-11-29-ray-packets.md (sixteen rays) and
//! docs/measurements/2026-12-02-avx2-packets.md (eight).

mod simd;

pub(crate) use simd::{Avx2, Avx512, Simd};

use super::bvh8::{Bvh8, LANE_MASK, LEAF, Node, PADDING, ROOT};
use super::stack::TraversalStack;
use super::triangle::{LANES, RANGE_MARGIN, TraversalRay, TrianglePacket, closer};
use super::{LeafTriangles, NO_HINT, TriangleHit};
use crate::math::gamma;
use glam::{Vec3, Vec3A};

/// The most rays in a packet (AVX-512's sixteen); AVX2's packets use the first eight lanes.
pub(crate) const WIDTH: usize = 16;

/// Below this many active rays at a node, the packet's rays there go on one at a time (the
/// single-ray traversal of that subtree), as a few rays waste most of a packet's lanes.
/// Measured for sixteen-ray packets (one thread, shares of the render in `trace_closest` and
/// `trace_shadow`, 2 rounds): 2, 3 and 4 are within 1-2% of each other on cornell_box,
/// door_ajar and big_1m; never falling back wins on cornell_box (32 triangles) but loses a
/// fifth of the shadow rays' speed on big_1m; 8 or more loses on cornell_box and door_ajar
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

    /// Empties the packet.
    #[inline(always)]
    pub(crate) fn clear(&mut self) {
        self.len = 0;
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

/// `[e(0), e(1), e(2)]` for the three axes, with no closure: a closure in this generic code
/// would be compiled without the ISA's target features, and its intrinsics called out of
/// line (a closure inherits the features of a `#[target_feature]` function, not of an
/// inlined generic one).
macro_rules! xyz {
    ($a:ident => $e:expr) => {
        [
            {
                let $a = 0;
                $e
            },
            {
                let $a = 1;
                $e
            },
            {
                let $a = 2;
                $e
            },
        ]
    };
}

/// A child still to visit: its reference, the rays that entered its box, and their entry
/// distances.
#[derive(Clone, Copy)]
struct Pending {
    reference: u32,
    rays: u32,
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
struct Lanes<S: Simd> {
    o_near: [S::V; 3],
    o_far: [S::V; 3],
    inv: [S::V; 3],
    /// Per axis, the rays whose direction is negative along it (they enter by the maxima).
    neg: [S::K; 3],
    /// The rays whose direction is largest along x, and along y (the rest: along z): which
    /// axes the triangle test rotates to x, y and z.
    along_x: S::K,
    along_y: S::K,
    o_k: [S::V; 3],
    sx: S::V,
    sy: S::V,
    sz: S::V,
}

impl<S: Simd> Lanes<S> {
    /// The lanes of `rays`, computed a vector at a time with the scalar constructors'
    /// operations (`TraversalRay::new`, `BoxRay::new`), so the same values; and the lanes
    /// with a ray to trace (bits).
    ///
    /// # Safety
    /// The CPU must have `S`'s features, and this be inlined in code compiled for them.
    #[inline(always)]
    unsafe fn new(rays: &RayColumns) -> (Lanes<S>, u32) {
        debug_assert!(rays.len <= S::WIDTH);
        // SAFETY: as the caller guarantees.
        unsafe {
            let o = xyz!(a => S::load(&rays.origin[a]));
            let d = xyz!(a => S::load(&rays.dir[a]));
            let t_max = S::load(&rays.t_max);
            let zero = S::zero();
            let nonzero = S::or_k(
                S::or_k(S::ne(d[0], zero), S::ne(d[1], zero)),
                S::ne(d[2], zero),
            );
            let mut all_finite = u32::MAX;
            for a in 0..3 {
                all_finite &= S::bits(S::and_k(finite::<S>(o[a]), finite::<S>(d[a])));
            }
            let in_len = (1u32 << rays.len) - 1;
            let valid = in_len & all_finite & S::bits(nonzero) & S::bits(S::gt(t_max, zero));
            let one = S::splat(1.0);
            let inv = xyz!(a => S::div(one, d[a]));
            let sign_bit = S::splat(-0.0);
            let neg = xyz!(a => S::sign(d[a]));
            let abs = xyz!(a => S::abs(d[a]));
            // The axis the direction is largest along, as `TraversalRay::new` chooses it.
            let x_over_y = S::gt(abs[0], abs[1]);
            let along_x = S::and_k(x_over_y, S::gt(abs[0], abs[2]));
            let along_y = S::and_not_k(S::gt(abs[1], abs[2]), x_over_y);
            let dk = rotate::<S>(along_x, along_y, &d);
            let sz = S::div(one, dk[2]);
            let largest = S::max(S::max(S::abs(o[0]), S::abs(o[1])), S::abs(o[2]));
            let pad = S::mul(largest, S::splat(PADDING));
            // The padding with the sign of the direction (that of its reciprocal).
            let signed_pad = xyz!(a => S::or(pad, S::and(d[a], sign_bit)));
            let lanes = Lanes {
                o_near: xyz!(a => S::add(o[a], signed_pad[a])),
                o_far: xyz!(a => S::sub(o[a], signed_pad[a])),
                inv,
                neg,
                along_x,
                along_y,
                o_k: rotate::<S>(along_x, along_y, &o),
                sx: S::mul(S::xor(dk[0], sign_bit), sz),
                sy: S::mul(S::xor(dk[1], sign_bit), sz),
                sz,
            };
            (lanes, valid)
        }
    }
}

/// The lanes where `x` is finite (x - x is 0 unless x is infinite or NaN).
///
/// # Safety
/// As for `Lanes::new`.
#[inline(always)]
unsafe fn finite<S: Simd>(x: S::V) -> S::K {
    // SAFETY: as the caller guarantees.
    unsafe { S::eq(S::sub(x, x), S::zero()) }
}

/// `v` with its axes k per lane: along x (1, 2, 0), along y (2, 0, 1), else (0, 1, 2).
///
/// # Safety
/// As for `Lanes::new`.
#[inline(always)]
unsafe fn rotate<S: Simd>(along_x: S::K, along_y: S::K, v: &[S::V; 3]) -> [S::V; 3] {
    // SAFETY: as the caller guarantees.
    unsafe {
        [
            S::blend(along_y, S::blend(along_x, v[0], v[1]), v[2]),
            S::blend(along_y, S::blend(along_x, v[1], v[2]), v[0]),
            S::blend(along_y, S::blend(along_x, v[2], v[0]), v[1]),
        ]
    }
}

/// Vertex `i` of the triangle in lane `l` of `packet`, rotated per ray (its axes k) and
/// sheared, as `intersect4`'s `vertex`.
///
/// # Safety
/// As for `Lanes::new`.
#[inline(always)]
unsafe fn vertex<S: Simd>(
    lanes: &Lanes<S>,
    packet: &TrianglePacket,
    l: usize,
    i: usize,
) -> (S::V, S::V, S::V) {
    // SAFETY: as the caller guarantees.
    unsafe {
        let v = xyz!(axis => S::splat(packet.v[i][axis][l]));
        let k = rotate::<S>(lanes.along_x, lanes.along_y, &v);
        let x = S::sub(k[0], lanes.o_k[0]);
        let y = S::sub(k[1], lanes.o_k[1]);
        let z = S::sub(k[2], lanes.o_k[2]);
        (
            S::add(x, S::mul(lanes.sx, z)),
            S::add(y, S::mul(lanes.sy, z)),
            z,
        )
    }
}

/// The largest magnitude of three, lane by lane.
///
/// # Safety
/// As for `Lanes::new`.
#[inline(always)]
unsafe fn max_abs3<S: Simd>(a: S::V, b: S::V, c: S::V) -> S::V {
    // SAFETY: as the caller guarantees.
    unsafe { S::max(S::max(S::abs(a), S::abs(b)), S::abs(c)) }
}

impl Bvh8 {
    /// The closest hits with t in (0, t_max) of `rays` (at most `S::WIDTH`) into `best`
    /// (which starts as `Best::none(rays)`), exactly those of `traverse::<false, _>` ray by
    /// ray. Returns the rays that were traced (bits).
    ///
    /// # Safety
    /// The CPU must have `S`'s features, and this be inlined in code compiled for them.
    #[inline(always)]
    pub(crate) unsafe fn closest_packet<S: Simd>(
        &self,
        tris: &LeafTriangles,
        rays: &RayColumns,
        best: &mut Best,
    ) -> u32 {
        // SAFETY: as the caller guarantees.
        unsafe { self.trace_packet::<S, false>(tris, rays, best, NO_HINT).0 }
    }

    /// Which of `rays` (at most `S::WIDTH`) hit anything with t in (0, t_max): exactly
    /// `traverse::<true, _>`'s answers ray by ray (a bit per ray). The triangles of packet
    /// `hint` (any value is safe) are tried first, as `Accel::any_hit_with_hint` does for
    /// single rays; `hint` becomes the packet of an occluder found, or `NO_HINT` if no ray was
    /// occluded.
    ///
    /// # Safety
    /// As for `closest_packet`.
    #[inline(always)]
    pub(crate) unsafe fn occluded_packet<S: Simd>(
        &self,
        tris: &LeafTriangles,
        rays: &RayColumns,
        hint: &mut u32,
    ) -> u32 {
        let mut best = Best::none(rays);
        // SAFETY: as the caller guarantees.
        let (_, occluded, last) =
            unsafe { self.trace_packet::<S, true>(tris, rays, &mut best, *hint) };
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
    /// As for `closest_packet`.
    #[inline(always)]
    unsafe fn trace_packet<S: Simd, const ANY: bool>(
        &self,
        tris: &LeafTriangles,
        rays: &RayColumns,
        best: &mut Best,
        hint: u32,
    ) -> (u32, u32, u32) {
        // SAFETY: as the caller guarantees.
        let (lanes, valid) = unsafe { Lanes::<S>::new(rays) };
        // With `ANY`, the rays that hit something (and need go no further), and the slot of
        // the last hit found.
        let mut done = 0u32;
        let mut last = u32::MAX;
        if ANY && let Some(packet) = tris.packets.get(hint as usize) {
            // The triangles that blocked the previous packet's rays first.
            for l in (0..LANES).filter(|&l| packet.ids[l] != u32::MAX) {
                let slot = (hint as usize * LANES + l) as u32;
                // SAFETY: as the caller guarantees.
                let hit = unsafe {
                    test_triangle::<S, true>(&lanes, rays, packet, l, slot, valid & !done, best)
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
                    // SAFETY: as the caller guarantees.
                    let hit = unsafe {
                        test_triangle::<S, ANY>(
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
                // SAFETY: as the caller guarantees.
                let next =
                    unsafe { self.visit_node::<S, ANY>(current, &lanes, active, best, &mut stack) };
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
                // SAFETY: as the caller guarantees.
                let rays = (p.rays & !done)
                    & unsafe { S::bits(S::le(S::load(&p.entry), S::load(&best.t))) };
                if rays != 0 {
                    (current, active) = (p.reference, rays);
                    break;
                }
            }
        }
    }

    /// Tests the children of node `node` against the `active` rays: pushes all the entered
    /// children but one and returns that one with its rays.
    ///
    /// Closest-hit packets (`ANY` false) take the nearest child and push the others farthest
    /// first, ordered by their nearest entry distance over the rays (then slot), which lets
    /// the packet skip the children beyond its hits. Shadow packets take any hit, so they
    /// visit the entered children in slot order (the lowest returned, the others popping
    /// lowest first) with no nearest entry to find per child: against the order by distance
    /// (`bench --rays`, one thread, three alternated rounds on an Intel Xeon: see
    /// docs/measurements/2026-12-03-intel-sitting-and-shadow-packet-order.md) door_ajar's
    /// shadow rays ran 1.63x as fast, cornell_box's 1.06x, big_1m's 1.10x. The answers are
    /// the same whatever the order.
    ///
    /// # Safety
    /// As for `closest_packet`.
    #[inline(always)]
    unsafe fn visit_node<S: Simd, const ANY: bool>(
        &self,
        node: u32,
        lanes: &Lanes<S>,
        active: u32,
        best: &Best,
        stack: &mut TraversalStack<Pending, 24>,
    ) -> Option<(u32, u32)> {
        let node = &self.nodes[node as usize];
        // SAFETY: as the caller guarantees.
        let (t_max, active) = unsafe { (S::load(&best.t), S::from_bits(active)) };
        if ANY {
            let mut first: Option<Pending> = None;
            for c in (0..8).rev() {
                // SAFETY: as the caller guarantees.
                if let Some((pending, _, _)) = unsafe { enter_child(node, c, lanes, active, t_max) }
                    && let Some(later) = first.replace(pending)
                {
                    stack.push(later);
                }
            }
            return first.map(|p| (p.reference, p.rays));
        }
        let mut entered = [Pending::default(); 8];
        let mut keys = [0u64; 8];
        let mut n = 0;
        for c in 0..8 {
            // SAFETY: as the caller guarantees.
            let Some((pending, entering, t0)) =
                (unsafe { enter_child(node, c, lanes, active, t_max) })
            else {
                continue;
            };
            // SAFETY: as the caller guarantees.
            let nearest = unsafe { S::reduce_min(entering, t0) };
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

/// Child `c` of `node` against the `active` rays (up to their `t_max`): the child with the
/// rays that enter its box and their entry distances, and the same as lanes (for the nearest
/// entry, which only the closest-hit order needs); None where no ray enters it or the slot is
/// empty.
///
/// # Safety
/// As for `Lanes::new`.
#[inline(always)]
unsafe fn enter_child<S: Simd>(
    node: &Node,
    c: usize,
    lanes: &Lanes<S>,
    active: S::K,
    t_max: S::V,
) -> Option<(Pending, S::K, S::V)> {
    let reference = node.child[c];
    if reference == 0 {
        return None;
    }
    // SAFETY: as the caller guarantees.
    unsafe {
        let mut t0 = S::zero();
        let mut t1 = t_max;
        for axis in 0..3 {
            let lo = S::splat(node.planes[axis][0][c]);
            let hi = S::splat(node.planes[axis][1][c]);
            let neg = lanes.neg[axis];
            let near = S::blend(neg, lo, hi);
            let far = S::blend(neg, hi, lo);
            let inv = lanes.inv[axis];
            let tn = S::mul(S::sub(near, lanes.o_near[axis]), inv);
            let tf = S::mul(S::sub(far, lanes.o_far[axis]), inv);
            // As in `box_hits8`: a NaN slab distance constrains nothing.
            t0 = S::max(tn, t0);
            t1 = S::min(tf, t1);
        }
        let entering = S::and_k(active, S::le(t0, t1));
        let rays = S::bits(entering);
        if rays == 0 {
            return None;
        }
        let mut pending = Pending {
            reference,
            rays,
            entry: [0.0; WIDTH],
        };
        S::store(&mut pending.entry, t0);
        Some((pending, entering, t0))
    }
}

/// The watertight test of the triangle in lane `l` of `packet` (leaf-order slot `slot`)
/// against the `active` rays, `intersect4`'s operations lane for lane; each hit `closer` than
/// a ray's best becomes it, or with `ANY` each hit below the ray's t_max counts. Returns the
/// rays whose hit counted.
///
/// # Safety
/// The CPU must have `S`'s features, and this be inlined in code compiled for them.
#[inline(always)]
unsafe fn test_triangle<S: Simd, const ANY: bool>(
    lanes: &Lanes<S>,
    rays: &RayColumns,
    packet: &TrianglePacket,
    l: usize,
    slot: u32,
    active: u32,
    best: &mut Best,
) -> u32 {
    let mut taken = 0;
    // SAFETY: as the caller guarantees.
    unsafe {
        let (x0, y0, z0) = vertex(lanes, packet, l, 0);
        let (x1, y1, z1) = vertex(lanes, packet, l, 1);
        let (x2, y2, z2) = vertex(lanes, packet, l, 2);
        let e0 = S::sub(S::mul(x2, y1), S::mul(y2, x1));
        let e1 = S::sub(S::mul(x0, y2), S::mul(y0, x2));
        let e2 = S::sub(S::mul(x1, y0), S::mul(y1, x0));
        let zero = S::zero();
        let lt = S::or_k(S::or_k(S::lt(e0, zero), S::lt(e1, zero)), S::lt(e2, zero));
        let gt = S::or_k(S::or_k(S::gt(e0, zero), S::gt(e1, zero)), S::gt(e2, zero));
        let eq = S::or_k(S::or_k(S::eq(e0, zero), S::eq(e1, zero)), S::eq(e2, zero));
        let exact = S::bits(eq) & active;
        let mut hits = active & !exact & !S::bits(S::and_k(lt, gt));
        if hits != 0 {
            let t_max = S::load(&best.t);
            let det = S::add(S::add(e0, e1), e2);
            let az = S::mul(lanes.sz, z0);
            let bz = S::mul(lanes.sz, z1);
            let cz = S::mul(lanes.sz, z2);
            let t_scaled = S::add(S::add(S::mul(e0, az), S::mul(e1, bz)), S::mul(e2, cz));
            let sign = S::and(det, S::splat(-0.0));
            let ts = S::xor(t_scaled, sign);
            let limit = S::mul(S::xor(S::mul(t_max, det), sign), S::splat(RANGE_MARGIN));
            hits &= S::bits(S::and_k(S::gt(ts, zero), S::le(ts, limit)));
            if hits != 0 {
                let inv_det = S::div(S::splat(1.0), det);
                let t = S::mul(t_scaled, inv_det);
                let max_z = max_abs3::<S>(az, bz, cz);
                let max_x = max_abs3::<S>(x0, x1, x2);
                let max_y = max_abs3::<S>(y0, y1, y2);
                let delta_z = S::mul(S::splat(gamma(3)), max_z);
                let delta_x = S::mul(S::splat(gamma(5)), S::add(max_x, max_z));
                let delta_y = S::mul(S::splat(gamma(5)), S::add(max_y, max_z));
                let delta_e = S::mul(
                    S::splat(2.0),
                    S::add(
                        S::add(
                            S::mul(S::mul(S::splat(gamma(2)), max_x), max_y),
                            S::mul(delta_y, max_x),
                        ),
                        S::mul(delta_x, max_y),
                    ),
                );
                let max_e = max_abs3::<S>(e0, e1, e2);
                let delta_t = S::mul(
                    S::mul(
                        S::splat(3.0),
                        S::add(
                            S::add(
                                S::mul(S::mul(S::splat(gamma(3)), max_e), max_z),
                                S::mul(delta_e, max_z),
                            ),
                            S::mul(delta_z, max_e),
                        ),
                    ),
                    S::abs(inv_det),
                );
                // `closer`: a nearer t, or the same t on a lower slot than the best's (any
                // hit takes no tie).
                let best_slot = S::load_u(&best.slot);
                let nearer = S::lt(t, t_max);
                let counts = if ANY {
                    nearer
                } else {
                    // Rays without a hit yet (slot `u32::MAX`) take no tie: t_max is
                    // beyond their range.
                    let lower_slot = S::and_k(
                        S::lt_u(S::splat_u(slot), best_slot),
                        S::ne_u(best_slot, S::splat_u(u32::MAX)),
                    );
                    S::or_k(nearer, S::and_k(S::eq(t, t_max), lower_slot))
                };
                let taken_lanes = S::and_k(S::and_k(S::from_bits(hits), S::gt(t, delta_t)), counts);
                taken = S::bits(taken_lanes);
                if !ANY && taken != 0 {
                    let b1 = S::mul(e1, inv_det);
                    let b2 = S::mul(e2, inv_det);
                    S::store(&mut best.t, S::blend(taken_lanes, t_max, t));
                    S::store_u(
                        &mut best.slot,
                        S::blend_u(taken_lanes, best_slot, S::splat_u(slot)),
                    );
                    let old_b1 = S::load(&best.b1);
                    let old_b2 = S::load(&best.b2);
                    S::store(&mut best.b1, S::blend(taken_lanes, old_b1, b1));
                    S::store(&mut best.b2, S::blend(taken_lanes, old_b2, b2));
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
