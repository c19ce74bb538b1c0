//! The acceleration structure over the scene's triangles, watertight ray-triangle
//! intersection, and robust spawning of rays from surfaces.
//!
//! obvhs builds a binary tree (PLOC, then reinsertion), which we collapse into our own
//! eight-wide nodes with exact f32 child boxes by a surface area heuristic (see `collapse`),
//! with leaves of up to four triangles that share four-lane packets with their siblings (see
//! `bvh8`). Traversal is our own, nearest child first, with a conservative box test (no box that
//! holds a hit triangle is ever culled) and the watertight triangle test of Woop, Benthin and
//! Wald, four triangles (one packet) at a time, so that rays never slip through shared edges
//! or vertices. Where the CPU has AVX-512, the trace systems send rays sixteen at a time
//! through the same tree as packets (see `packet`, which also traces eight-ray AVX2 packets,
//! so far only in tests), which find the same hits as single rays:
//! ties in t go to the lower leaf-order slot (`triangle::closer`), whatever the order of visits.
//!
//! Measured against a binary BVH (obvhs' BVH2, SAH-collapsed leaves of up to 8 triangles, with
//! our own traversal of the same robustness: nearest child first, entry distances on the
//! stack), an eight-wide tree was 40-45% faster for closest hits and 30% faster for any hits
//! on incoherent rays, in both the Cornell box and a 10k-triangle door_ajar stand-in, so the
//! BVH2 was removed.

mod bvh8;
mod collapse;
#[cfg(target_arch = "x86_64")]
mod packet;
mod stack;
mod triangle;

use crate::geometry::TriangleColumns;
use bvh8::Bvh8;
use glam::{DVec3, Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use rayon::prelude::*;
use triangle::{LANES, TraversalRay, columns};

/// The most rays in a packet: `Accel::closest_hits16`'s and `Accel::occluded16`'s (the
/// eight-ray packets use the first half).
#[cfg(target_arch = "x86_64")]
pub const PACKET_WIDTH: usize = packet::WIDTH;
#[cfg(target_arch = "x86_64")]
pub(crate) use packet::RayColumns;

/// A hint for `Accel::any_hit_with_hint` that names no packet.
pub const NO_HINT: u32 = u32::MAX;

/// A closest hit: distance along the (unnormalised) direction, triangle id, barycentrics of
/// p1 and p2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
    pub b1: f32,
    pub b2: f32,
}

/// The accelerator: a BVH over the triangles with non-zero area, and those triangles in the
/// tree's leaf order. Shared freely across threads.
pub struct Accel {
    /// `None` when no triangle has a non-zero area: nothing is ever hit.
    tree: Option<Bvh8>,
    tris: LeafTriangles,
    /// Whether the CPU has AVX2 (checked once, here, rather than per ray): traversal then runs
    /// as code compiled for it.
    avx2: bool,
}

/// The triangles in leaf order, as four-lane packets (unused lanes are zero triangles, never
/// tested), each with the id in `TriangleColumns` of its lanes' triangles (`u32::MAX` if
/// unused).
pub(crate) struct LeafTriangles {
    packets: Vec<triangle::TrianglePacket>,
    /// The number of triangles (used lanes).
    len: usize,
}

/// A hit on the triangle in lane `slot % LANES` of packet `slot / LANES`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriangleHit {
    t: f32,
    slot: u32,
    b1: f32,
    b2: f32,
}

/// Whether `origin` and `dir` are finite and `dir` is not zero, in a few vector operations.
#[inline(always)]
fn finite_nonzero(origin: Vec3A, dir: Vec3A) -> bool {
    origin.is_finite() && dir.is_finite() && dir.cmpne(Vec3A::ZERO).any()
}

/// Whether the triangle has exactly zero area, or a vertex that is not finite or lies beyond
/// `geometry::MAX_COORDINATE` (prepared scenes have none: this guards the tree's build, whose
/// box areas overflow f32 from about 1e19). The differences of f32 coordinates are exact in
/// f64 for any realistic scene, so "zero" here means what it says.
fn is_degenerate(p0: Vec3, p1: Vec3, p2: Vec3) -> bool {
    let within =
        |p: Vec3| p.is_finite() && p.abs().max_element() < crate::geometry::MAX_COORDINATE as f32;
    if !(within(p0) && within(p1) && within(p2)) {
        return true;
    }
    let (p0, p1, p2) = (p0.as_dvec3(), p1.as_dvec3(), p2.as_dvec3());
    (p1 - p0).cross(p2 - p0) == DVec3::ZERO
}

/// A triangle's corners as bits, rotated so the smallest comes first: equal for the same
/// triangle whichever corner it starts at, different for the reversed winding.
fn cyclic_key(corners: [Vec3; 3]) -> [[u32; 3]; 3] {
    let bits = corners.map(|p| p.to_array().map(f32::to_bits));
    let first = (0..3).min_by_key(|&k| bits[k]).unwrap_or(0);
    [bits[first], bits[(first + 1) % 3], bits[(first + 2) % 3]]
}

/// A hash of a `cyclic_key` in the high 32 bits of a word (each key word mixed in with a
/// multiply and xor-shift): equal keys hash equal; the unequal keys that collide are told
/// apart by comparing the keys.
fn key_hash(key: &[[u32; 3]; 3]) -> u64 {
    let h = key
        .iter()
        .flatten()
        .fold(0x9e37_79b9_7f4a_7c15u64, |h, &w| {
            let h = (h ^ u64::from(w)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            h ^ (h >> 31)
        });
    h & !u64::from(u32::MAX)
}

/// The triangles the tree holds, in increasing order: those with a non-zero area, and of
/// exact copies (the same corners in the same cyclic order) only the first. A copy is never
/// the nearest hit before its original, and thousands of them (a polygon that repeats its
/// vertices) make a binary tree as deep as they are many. Copies are found by sorting words
/// of (hash, index) in parallel, not with a hash set, which took a third of the build.
fn kept_triangles(triangles: &TriangleColumns) -> Vec<u32> {
    let corners = |i: usize| [triangles.p0[i], triangles.p1[i], triangles.p2[i]];
    let mut hashed: Vec<u64> = (0..triangles.len())
        .into_par_iter()
        .filter_map(|i| {
            let c = corners(i);
            (!is_degenerate(c[0], c[1], c[2])).then(|| key_hash(&cyclic_key(c)) | i as u64)
        })
        .collect();
    let mut kept: Vec<u32> = hashed.par_iter().map(|&h| h as u32).collect();
    hashed.par_sort_unstable();
    let hash = |h: u64| h >> 32;
    // Within a run of equal hashes, in increasing index: a copy of an earlier one goes.
    let mut copies: Vec<u32> = hashed
        .par_chunk_by(|a, b| hash(*a) == hash(*b))
        .filter(|run| run.len() > 1)
        .flat_map_iter(|run| {
            let keys: Vec<_> = run
                .iter()
                .map(|&h| cyclic_key(corners(h as u32 as usize)))
                .collect();
            (1..run.len())
                .filter(move |&j| keys[..j].contains(&keys[j]))
                .map(move |j| run[j] as u32)
        })
        .collect();
    if !copies.is_empty() {
        copies.par_sort_unstable();
        kept.retain(|i| copies.binary_search(i).is_err());
    }
    kept
}

/// obvhs' settings for the binary tree: its medium preset (PLOC with a search radius of 14,
/// 64-bit Morton codes) with the reinsertion batches of its fast preset (2% of the nodes, not
/// 5%). Measured on the big scenes (PT samples/s, 2 threads): trees of the slow settings (radius
/// 24, 20% batches) traced no faster and took 1.7x as long to build at 5M triangles; radius 6
/// or no reinsertion traced 4-10% slower at 1M; 2% batches instead of 5% cost at most 3% and
/// saved 0.2 s of the 5M build.
const BUILD_PARAMS: BvhBuildParams = BvhBuildParams {
    reinsertion_batch_ratio: 0.02,
    ..BvhBuildParams::medium_build()
};

/// How much larger than the triangles' centres' bounds the union of their boxes may be before
/// the boxes the binary tree is built from are clipped (`clipped_to_the_scene`).
const OUTSIZED: f32 = 16.0;

/// The boxes the binary tree is built from. obvhs scales its Morton codes to the union of the
/// boxes, so one outsized triangle (a floor 2e10 wide under a room of 4 m) puts every other
/// triangle in one Morton cell, and PLOC's tree degrades towards a linear scan (door_ajar with
/// such a floor traced 200x slower). Where the union is over `OUTSIZED` times the centres'
/// bounds, every box is clipped to those bounds grown by their own size: the tree's structure
/// follows the scene, and the eight-wide nodes, whose boxes `collapse` computes from the
/// vertices, still hold each triangle whole (an outsized one widens only the nodes above its
/// leaf). Ordinary scenes are left as they are (their union is about their centres' bounds).
fn clipped_to_the_scene(aabbs: Vec<Aabb>) -> Vec<Aabb> {
    let mut union = Aabb::empty();
    let mut centres = Aabb::empty();
    for b in &aabbs {
        union = union.union(b);
        centres.extend(b.center());
    }
    let size = centres.diagonal().length();
    if union.diagonal().length() <= OUTSIZED * size {
        return aabbs;
    }
    let grown = Aabb::new(
        centres.min - Vec3A::splat(size),
        centres.max + Vec3A::splat(size),
    );
    aabbs.iter().map(|b| b.intersection(&grown)).collect()
}

impl Accel {
    /// Builds the tree. Zero-area triangles and exact copies are left out: they are never hit.
    pub fn build(triangles: &TriangleColumns) -> Accel {
        let kept = kept_triangles(triangles);
        if kept.is_empty() {
            return Accel {
                tree: None,
                tris: LeafTriangles {
                    packets: Vec::new(),
                    len: 0,
                },
                avx2: false,
            };
        }
        let kept_verts: Vec<[Vec3; 3]> = kept
            .par_iter()
            .map(|&i| {
                let i = i as usize;
                [triangles.p0[i], triangles.p1[i], triangles.p2[i]]
            })
            .collect();
        let aabbs: Vec<Aabb> = kept_verts
            .par_iter()
            .map(|&[a, b, c]| Aabb::new(Vec3A::from(a.min(b).min(c)), Vec3A::from(a.max(b).max(c))))
            .collect();
        let params = BUILD_PARAMS;
        let aabbs = clipped_to_the_scene(aabbs);
        let mut bvh2 = obvhs::ploc::PlocBuilder::with_capacity(aabbs.len()).build(
            params.ploc_search_distance,
            &aabbs,
            (0..aabbs.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        obvhs::bvh2::reinsertion::ReinsertionOptimizer::default().run(
            &mut bvh2,
            params.reinsertion_batch_ratio,
            None,
        );
        let mut collapsed = collapse::collapse(&bvh2, &kept_verts);
        // The lanes' indices into `kept` become the packets' triangle ids.
        collapsed
            .packets
            .par_iter_mut()
            .zip(collapsed.lanes.par_chunks(LANES))
            .for_each(|(packet, lanes)| {
                for (id, &k) in packet.ids.iter_mut().zip(lanes) {
                    *id = kept.get(k as usize).copied().unwrap_or(u32::MAX);
                }
            });
        Accel {
            tree: Some(collapsed.tree),
            tris: LeafTriangles {
                packets: collapsed.packets,
                len: kept.len(),
            },
            avx2: crate::cpu::has_avx2_fma(),
        }
    }

    /// Bytes the tree holds: (its nodes, its triangles in leaf order).
    pub fn memory_bytes(&self) -> (usize, usize) {
        let nodes = self.tree.as_ref().map_or(0, |t| t.memory_bytes());
        let t = &self.tris;
        let triangles = t.packets.capacity() * std::mem::size_of::<triangle::TrianglePacket>();
        (nodes, triangles)
    }

    /// The number of triangles in the tree (those with a non-zero area).
    pub fn len(&self) -> usize {
        self.tris.len
    }

    pub fn is_empty(&self) -> bool {
        self.tris.len == 0
    }

    #[inline(always)]
    fn traverse<const ANY: bool, const AVX2: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
    ) -> Option<Hit> {
        let (origin, dir) = (Vec3A::from(origin), Vec3A::from(dir));
        // Also rejects NaN and a zero direction, which hit nothing.
        if !(t_max > 0.0 && finite_nonzero(origin, dir)) {
            return None;
        }
        let ray = TraversalRay::new(origin, dir);
        let hit = self
            .tree
            .as_ref()?
            .traverse::<ANY, AVX2>(&self.tris, &ray, t_max)?;
        Some(Hit {
            t: hit.t,
            triangle: self.tris.packets[hit.slot as usize / LANES].ids[hit.slot as usize % LANES],
            b1: hit.b1,
            b2: hit.b2,
        })
    }

    /// The traversal compiled for AVX2 (and FMA, which the compiler never uses to contract
    /// separate multiplies and adds, so results are the same bits): eight-lane box tests, and
    /// three-operand VEX forms everywhere, which spare most register copies (measured on the
    /// Cornell box: the recompilation alone takes 7% of the instructions of traversal, the
    /// eight-lane box test with the four-lane finish of the triangle test about as much again).
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA (`self.avx2`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn traverse_avx2<const ANY: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
    ) -> Option<Hit> {
        self.traverse::<ANY, true>(origin, dir, t_max)
    }

    #[cfg(not(target_arch = "x86_64"))]
    unsafe fn traverse_avx2<const ANY: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
    ) -> Option<Hit> {
        self.traverse::<ANY, false>(origin, dir, t_max)
    }

    /// `any_hit`, testing first the triangle packet `hint` names (`NO_HINT`: none; any value
    /// is safe), and setting `hint` to the packet of the hit that traversal finds (`NO_HINT`
    /// when nothing is hit). A run of
    /// shadow rays from nearby points towards one light is often blocked by the same triangles,
    /// so passing each ray's hint on to the next skips most traversals of occluded rays. The
    /// answer is `any_hit`'s: a hit in the hinted packet passes the same triangle test, and
    /// traversal never culls a box that holds a hit triangle.
    #[inline(always)]
    fn any_hit_hinted<const AVX2: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        hint: &mut u32,
    ) -> bool {
        let (origin, dir) = (Vec3A::from(origin), Vec3A::from(dir));
        if !(t_max > 0.0 && finite_nonzero(origin, dir)) {
            return false;
        }
        let Some(tree) = self.tree.as_ref() else {
            return false;
        };
        let ray = TraversalRay::new(origin, dir);
        let packet = *hint as usize;
        if let Some(triangles) = self.tris.packets.get(packet) {
            let used = (0..LANES)
                .filter(|&lane| triangles.ids[lane] != u32::MAX)
                .fold(0u32, |m, lane| m | (1 << lane));
            let (mut t, mut best) = (t_max, 0);
            let base = (packet * LANES) as u32;
            if ray
                .intersect4::<true>(triangles, used, base, &mut t, &mut best)
                .is_some()
            {
                return true;
            }
        }
        match tree.traverse::<true, AVX2>(&self.tris, &ray, t_max) {
            Some(hit) => {
                *hint = hit.slot / LANES as u32;
                true
            }
            None => {
                // After an unblocked ray the next is likely unblocked too: no packet to try.
                *hint = NO_HINT;
                false
            }
        }
    }

    /// `any_hit_hinted` for code compiled for AVX2 and FMA (see `trace_in_avx2`).
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA, and the caller must be compiled for them.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn any_hit_hinted_in_avx2(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        hint: &mut u32,
    ) -> bool {
        self.any_hit_hinted::<true>(origin, dir, t_max, hint)
    }

    /// Whether anything is hit with t in (0, t_max), trying the packet `hint` first (see
    /// `any_hit_hinted`); the portable traversal (code compiled for AVX2 calls
    /// `any_hit_hinted_in_avx2`).
    pub fn any_hit_with_hint(&self, origin: Vec3, dir: Vec3, t_max: f32, hint: &mut u32) -> bool {
        self.any_hit_hinted::<false>(origin, dir, t_max, hint)
    }

    /// `closest_hit` (`ANY = false`) or `any_hit` for code that is itself compiled for AVX2
    /// and FMA (see `crate::cpu`), inlined there.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA, and the caller must be compiled for them.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(crate) unsafe fn trace_in_avx2<const ANY: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
    ) -> Option<Hit> {
        self.traverse::<ANY, true>(origin, dir, t_max)
    }

    /// The closest hits with t in (0, t_max) of up to sixteen rays traced together as one
    /// packet (see `packet`), into `hits[i]` for lane i: the same hits, bit for bit, as
    /// `closest_hit` gives ray by ray.
    ///
    /// # Safety
    /// The CPU must support AVX-512 (F, DQ, VL, BW), AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    pub(crate) unsafe fn closest_hits16(
        &self,
        rays: &RayColumns,
        hits: &mut [Option<Hit>; PACKET_WIDTH],
    ) {
        // SAFETY: the caller guarantees AVX-512's features, and this is compiled for them.
        unsafe { self.closest_hits_packet::<packet::Avx512>(rays, hits) }
    }

    /// `closest_hits16` for up to eight rays, with AVX2 and FMA (the first eight hits).
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub(crate) unsafe fn closest_hits8(
        &self,
        rays: &RayColumns,
        hits: &mut [Option<Hit>; PACKET_WIDTH],
    ) {
        // SAFETY: the caller guarantees AVX2 and FMA, and this is compiled for them.
        unsafe { self.closest_hits_packet::<packet::Avx2>(rays, hits) }
    }

    /// Which of up to sixteen shadow rays hit anything with t in (0, t_max), traced together
    /// as one packet (see `packet`), a bit per lane: the same answers as `any_hit` ray by ray.
    /// `hint` is passed from packet to packet as `any_hit_with_hint` passes it from ray to ray.
    ///
    /// # Safety
    /// As for `closest_hits16`.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
    pub(crate) unsafe fn occluded16(&self, rays: &RayColumns, hint: &mut u32) -> u32 {
        // SAFETY: as for `closest_hits16`.
        unsafe { self.occluded_packet::<packet::Avx512>(rays, hint) }
    }

    /// `occluded16` for up to eight rays, with AVX2 and FMA.
    ///
    /// # Safety
    /// As for `closest_hits8`.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub(crate) unsafe fn occluded8(&self, rays: &RayColumns, hint: &mut u32) -> u32 {
        // SAFETY: as for `closest_hits8`.
        unsafe { self.occluded_packet::<packet::Avx2>(rays, hint) }
    }

    /// The closest hits of a packet of `S::WIDTH` rays at most.
    ///
    /// # Safety
    /// The CPU must have `S`'s features, and this be inlined in code compiled for them.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn closest_hits_packet<S: packet::Simd>(
        &self,
        rays: &RayColumns,
        hits: &mut [Option<Hit>; PACKET_WIDTH],
    ) {
        let Some(tree) = self.tree.as_ref() else {
            *hits = [None; PACKET_WIDTH];
            return;
        };
        let mut best = packet::Best::none(rays);
        // SAFETY: as the caller guarantees.
        let traced = unsafe { tree.closest_packet::<S>(&self.tris, rays, &mut best) };
        for (i, h) in hits.iter_mut().enumerate() {
            let slot = best.slot[i] as usize;
            *h = (traced & (1 << i) != 0 && best.slot[i] != u32::MAX).then(|| Hit {
                t: best.t[i],
                triangle: self.tris.packets[slot / LANES].ids[slot % LANES],
                b1: best.b1[i],
                b2: best.b2[i],
            });
        }
    }

    /// The occlusion of a packet of `S::WIDTH` shadow rays at most.
    ///
    /// # Safety
    /// As for `closest_hits_packet`.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    unsafe fn occluded_packet<S: packet::Simd>(&self, rays: &RayColumns, hint: &mut u32) -> u32 {
        match self.tree.as_ref() {
            // SAFETY: as the caller guarantees.
            Some(tree) => unsafe { tree.occluded_packet::<S>(&self.tris, rays, hint) },
            None => 0,
        }
    }

    #[inline(always)]
    fn dispatch<const ANY: bool>(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        if self.avx2 {
            // SAFETY: `avx2` is only set when the CPU was found to support AVX2 and FMA.
            unsafe { self.traverse_avx2::<ANY>(origin, dir, t_max) }
        } else {
            self.traverse::<ANY, false>(origin, dir, t_max)
        }
    }

    /// The nearest hit with t in (0, t_max) along `origin + t dir` (`dir` need not be unit).
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        self.dispatch::<false>(origin, dir, t_max)
    }

    /// Whether anything is hit with t in (0, t_max) along `origin + t dir`.
    pub fn any_hit(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        self.dispatch::<true>(origin, dir, t_max).is_some()
    }

    /// The hit that `any_hit` stops at (the first it finds, not necessarily the nearest), if
    /// any: for checking occlusion against another tracer hit by hit.
    pub fn any_hit_found(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        self.dispatch::<true>(origin, dir, t_max)
    }
}

/// The watertight ray-triangle test that the accelerator runs, on one triangle: `(t, b1, b2)`
/// of the hit with t in (0, t_max), if any. For brute-force references and tests.
pub fn intersect_triangle(
    origin: Vec3,
    dir: Vec3,
    triangle: &[Vec3; 3],
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let (origin, dir) = (Vec3A::from(origin), Vec3A::from(dir));
    if !(t_max > 0.0 && finite_nonzero(origin, dir)) {
        return None;
    }
    let [p0, p1, p2] = *triangle;
    if is_degenerate(p0, p1, p2) {
        return None;
    }
    TraversalRay::new(origin, dir)
        .intersect(&columns(triangle), t_max)
        .filter(|h| h.0 < t_max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{FLAT, NO_EMITTER};
    use crate::sampling::{SampleKey, uniform_sphere};
    use glam::Vec2;

    /// The traversal this CPU runs (AVX2 where present) and the baseline SSE2 one give the
    /// same hits, bit for bit, closest and any, on a soup of overlapping triangles.
    #[test]
    fn avx2_and_baseline_traversals_agree() {
        let r = |i: u64, d: u32| SampleKey::new(11, i, 0).get(d);
        let n = 300;
        let centre = |i: u64| Vec3::new(r(i, 0), r(i, 1), r(i, 2)) * 10.0;
        let vertex = |i: u64, d: u32| {
            centre(i) + uniform_sphere(Vec2::new(r(i, d), r(i, d + 1))) * (2.0 * r(i, d + 2))
        };
        let tris = TriangleColumns {
            p0: (0..n).map(|i| vertex(i, 3)).collect(),
            p1: (0..n).map(|i| vertex(i, 6)).collect(),
            p2: (0..n).map(|i| vertex(i, 9)).collect(),
            normal: vec![Vec3::Z; n as usize],
            material: vec![0; n as usize],
            emitter: vec![NO_EMITTER; n as usize],
            smooth: vec![FLAT; n as usize],
            vertex_normals: Vec::new(),
        };
        let accel = Accel::build(&tris);
        for i in 0..20_000u64 {
            let o = Vec3::new(r(i, 20), r(i, 21), r(i, 22)) * 12.0 - 1.0;
            let d = uniform_sphere(Vec2::new(r(i, 23), r(i, 24)));
            let t_max = if i % 2 == 0 {
                f32::INFINITY
            } else {
                15.0 * r(i, 25)
            };
            assert_eq!(
                accel.dispatch::<false>(o, d, t_max),
                accel.traverse::<false, false>(o, d, t_max)
            );
            assert_eq!(
                accel.dispatch::<true>(o, d, t_max).is_some(),
                accel.traverse::<true, false>(o, d, t_max).is_some()
            );
        }
    }

    /// Triangles of the given corners, flat and of one material.
    fn soup(corners: Vec<[Vec3; 3]>) -> TriangleColumns {
        let n = corners.len();
        TriangleColumns {
            p0: corners.iter().map(|c| c[0]).collect(),
            p1: corners.iter().map(|c| c[1]).collect(),
            p2: corners.iter().map(|c| c[2]).collect(),
            normal: vec![Vec3::Z; n],
            material: vec![0; n],
            emitter: vec![NO_EMITTER; n],
            smooth: vec![FLAT; n],
            vertex_normals: Vec::new(),
        }
    }

    /// Packets of sixteen rays (AVX-512) and of eight (AVX2) find the hits that single rays
    /// find, bit for bit (t, triangle,
    /// barycentrics), and the same occlusion of shadow rays, on a soup of overlapping triangles and on a grid with a second,
    /// coplanar triangulation over it, aimed at its vertices and edges, where many hits tie in
    /// t and only the tie-break decides. Packets of coherent rays (from near one point, in a
    /// narrow cone), of incoherent ones, and part-filled packets with dead rays among them.
    /// Each width is tested where the CPU has its ISA (the CI machines have AVX2, some
    /// AVX-512 too).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn packets_find_the_hits_of_single_rays() {
        let widths: Vec<usize> = [
            (16, crate::cpu::has_avx512()),
            (8, crate::cpu::has_avx2_fma()),
        ]
        .into_iter()
        .filter_map(|(width, has)| has.then_some(width))
        .collect();
        if widths.is_empty() {
            eprintln!("packets untested: this CPU has neither AVX2 nor AVX-512");
        }
        for width in widths {
            packets_of_width_find_the_hits_of_single_rays(width);
        }
    }

    #[cfg(target_arch = "x86_64")]
    fn packets_of_width_find_the_hits_of_single_rays(width: usize) {
        let r = |i: u64, d: u32| SampleKey::new(13, i, 0).get(d);
        let vertex = |i: u64, d: u32, centre: Vec3| {
            centre + uniform_sphere(Vec2::new(r(i, d), r(i, d + 1))) * (2.0 * r(i, d + 2))
        };
        let blobs = (0..400u64)
            .map(|i| {
                let centre = Vec3::new(r(i, 0), r(i, 1), r(i, 2)) * 10.0;
                [3, 6, 9].map(|d| vertex(i, d, centre))
            })
            .collect();
        let mut grid = Vec::new();
        for (x, y) in (0..12).flat_map(|x| (0..12).map(move |y| (x as f32, y as f32))) {
            let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, 0.0);
            grid.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
            grid.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
            // The other diagonal, coplanar with the two above.
            grid.push([p(1.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
        }
        let (mut checked, mut shadowed) = (0, 0);
        let mut hint = NO_HINT;
        for (scene, tris) in [("soup", soup(blobs)), ("grid", soup(grid))] {
            let accel = Accel::build(&tris);
            for p in 0..600u64 {
                let coherent = p % 2 == 0;
                let base = Vec3::new(r(p, 20), r(p, 21), r(p, 22)) * 12.0 - 1.0;
                let aim = uniform_sphere(Vec2::new(r(p, 23), r(p, 24)));
                let rays: Vec<(Vec3, Vec3)> = (0..width as u64)
                    .map(|k| {
                        let i = p * 100 + k;
                        if scene == "grid" {
                            // From above the grid to a vertex, the middle of an edge or a
                            // random point of it.
                            let o = Vec3::new(r(i, 30) * 12.0, r(i, 31) * 12.0, 3.0 + r(i, 32));
                            let (gx, gy) = ((r(i, 33) * 12.0).floor(), (r(i, 34) * 12.0).floor());
                            let target = match i % 3 {
                                0 => Vec3::new(gx, gy, 0.0),
                                1 => Vec3::new(gx + 0.5, gy, 0.0),
                                _ => Vec3::new(r(i, 35) * 12.0, r(i, 36) * 12.0, 0.0),
                            };
                            return (o, target - o);
                        }
                        if coherent {
                            let o = base + Vec3::new(r(i, 25), r(i, 26), r(i, 27)) * 0.1;
                            let d = aim + uniform_sphere(Vec2::new(r(i, 28), r(i, 29))) * 0.05;
                            (o, d)
                        } else {
                            let o = Vec3::new(r(i, 25), r(i, 26), r(i, 27)) * 12.0 - 1.0;
                            (o, uniform_sphere(Vec2::new(r(i, 28), r(i, 29))))
                        }
                    })
                    .map(|(o, d)| {
                        if p % 7 == 3 && r(p, 40) < 0.3 {
                            (o, Vec3::ZERO)
                        } else {
                            (o, d)
                        }
                    })
                    .collect();
                let len = if p % 5 == 4 {
                    1 + p as usize % width
                } else {
                    width
                };
                // Every third packet's rays end at a random distance, or at exactly the
                // distance of their hit without an end (which then does not count).
                let ends: Vec<f32> = rays[..len]
                    .iter()
                    .enumerate()
                    .map(|(k, &(o, d))| match (p % 3, k % 2) {
                        (1, 0) => 15.0 * r(p * 100 + k as u64, 42),
                        (1, _) => accel.closest_hit(o, d, f32::INFINITY).map_or(1.0, |h| h.t),
                        _ => f32::INFINITY,
                    })
                    .collect();
                let mut columns = RayColumns::new();
                for (&(o, d), &end) in rays[..len].iter().zip(&ends) {
                    columns.push(o, d, end);
                }
                let mut hits = [None; PACKET_WIDTH];
                // SAFETY: the CPU has the ISA of `width` (checked by the caller).
                unsafe {
                    if width == 16 {
                        accel.closest_hits16(&columns, &mut hits)
                    } else {
                        accel.closest_hits8(&columns, &mut hits)
                    }
                };
                for (k, (&(o, d), &end)) in rays[..len].iter().zip(&ends).enumerate() {
                    let single = accel.closest_hit(o, d, end);
                    assert_eq!(hits[k], single, "{scene}, packet {p}, ray {k}");
                    checked += usize::from(single.is_some());
                }
                assert!(hits[len..].iter().all(Option::is_none));
                let hits: Vec<Option<Hit>> = rays[..len]
                    .iter()
                    .map(|&(o, d)| accel.closest_hit(o, d, f32::INFINITY))
                    .collect();
                // Shadow rays: to a random distance, or to exactly the closest hit (which
                // then does not count), or to just beyond it.
                let mut shadow = RayColumns::new();
                let mut ends = Vec::new();
                for (k, &(o, d)) in rays[..len].iter().enumerate() {
                    let t = hits[k].map_or(5.0, |h| h.t);
                    let t_max = match k % 3 {
                        0 => 15.0 * r(p * 100 + k as u64, 41),
                        1 => t,
                        _ => t * 1.0001,
                    };
                    shadow.push(o, d, t_max);
                    ends.push((o, d, t_max));
                }
                // SAFETY: as above.
                let occluded = unsafe {
                    if width == 16 {
                        accel.occluded16(&shadow, &mut hint)
                    } else {
                        accel.occluded8(&shadow, &mut hint)
                    }
                };
                assert_eq!(occluded >> len, 0);
                for (k, &(o, d, t_max)) in ends.iter().enumerate() {
                    let blocked = occluded & (1 << k) != 0;
                    assert_eq!(
                        blocked,
                        accel.any_hit(o, d, t_max),
                        "{scene}, shadow {p}, ray {k}"
                    );
                    shadowed += usize::from(blocked);
                }
            }
        }
        assert!(checked > 5000 * width / 16, "{width} wide: {checked} hits");
        assert!(
            shadowed > 2000 * width / 16,
            "{width} wide: {shadowed} shadow rays occluded"
        );
    }

    /// Any-hit with a hint answers as any-hit does, whatever the hint: the packet of the
    /// previous ray's occluder (a run of rays from nearby points, as shadow rays come), a
    /// stale or out-of-range one, or none; and the hint does take effect (most occluded rays
    /// after an occluded one are answered by the hinted packet, without a traversal).
    #[test]
    fn hinted_any_hit_agrees_with_any_hit() {
        let r = |i: u64, d: u32| SampleKey::new(12, i, 0).get(d);
        let tris = TriangleColumns {
            p0: vec![Vec3::new(-1.0, -1.0, 1.0), Vec3::new(-1.0, -1.0, 2.0)],
            p1: vec![Vec3::new(1.0, -1.0, 1.0), Vec3::new(1.0, 1.0, 2.0)],
            p2: vec![Vec3::new(1.0, 1.0, 1.0), Vec3::new(-1.0, 1.0, 2.0)],
            normal: vec![Vec3::Z; 2],
            material: vec![0; 2],
            emitter: vec![NO_EMITTER; 2],
            smooth: vec![FLAT; 2],
            vertex_normals: Vec::new(),
        };
        let accel = Accel::build(&tris);
        let mut hint = NO_HINT;
        // Occluded rays after an occluded ray (whose hint they get), and how many of them
        // still needed a traversal (which changes the hint).
        let (mut followers, mut traversals, mut previous_occluded) = (0, 0, false);
        for i in 0..4000u64 {
            // Rays from a small patch towards random points beyond both triangles.
            let o = Vec3::new(r(i, 0), r(i, 1), 0.0) * 0.2;
            let target = Vec3::new(r(i, 2) * 4.0 - 2.0, r(i, 3) * 4.0 - 2.0, 3.0);
            let t_max = if i % 3 == 0 { 0.4 } else { 1.0 };
            let reset = i % 97 == 0;
            if reset {
                hint = [NO_HINT, 7, u32::MAX - 1][(i / 97 % 3) as usize];
            }
            let before = hint;
            let expected = accel.any_hit(o, target - o, t_max);
            let got = accel.any_hit_with_hint(o, target - o, t_max, &mut hint);
            assert_eq!(got, expected, "ray {i}");
            if got && previous_occluded && !reset {
                followers += 1;
                traversals += (hint != before) as usize;
            }
            previous_occluded = got;
        }
        assert!(followers > 1000, "{followers}");
        assert!(traversals * 10 < followers, "{traversals} of {followers}");
    }
}
