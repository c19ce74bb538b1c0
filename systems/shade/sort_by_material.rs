//! Compacts the paths after tracing and groups them by material kind, so that each shading
//! system runs over one contiguous queue. Paths end here when their ray found nothing (they
//! left the scene, or shading or Russian roulette ended them and left them no ray), or when
//! they reached the depth cap (after their emission was added). The same pass that moves a
//! kept path computes the surface point of its hit (position with its error bound, geometric
//! and shading normals) for the light-sampling and shading systems.

use crate::bsdf::MaterialKind;
use crate::components::Hits;
use crate::components::Paths;
use crate::components::Rays;
use crate::components::Surfaces;
use crate::components::path_tracing::MaterialRanges;
use crate::components::path_tracing::Scratch;
use crate::components::{CHUNK, MISS};
use crate::components::{PathsChunk, SurfacesChunk};
use crate::geometry::{SurfacePoint, TriangleColumns, surface_point};
use crate::pipeline::Flow;
use crate::scene::PreparedScene;
use glam::Vec3;
use rayon::prelude::*;

pub struct SortByMaterial;

/// Queue of each kind, in slot order: non-delta kinds first (see `MaterialKind`).
fn queue_of(kind: MaterialKind) -> u8 {
    kind as u8
}

/// The queue after the material kinds': paths that end here.
const DROPPED: u8 = MaterialKind::COUNT as u8;
pub use crate::components::path_tracing::QUEUES;

crate::system! {
    SortByMaterial = "sort_by_material";
    read scene: PreparedScene, max_depth: u32;
    write hits: Hits, paths: Paths, rays: Rays, sample_radiance: Vec<Vec3>, ranges: MaterialRanges,
        active: usize, scratch: Scratch, surfaces: Surfaces;
    reorder rays[dir], hits[triangle];
    run {
        let taken = *active;
        let max_depth = *max_depth;
        let chunks = taken.div_ceil(CHUNK);
        scratch.chunk_counts.clear();
        scratch.chunk_counts.resize(chunks, [0; QUEUES]);
        // A scene of one material kind has one queue, and a path's queue needs no look-up of
        // its triangle's material (a cache miss per path on big scenes).
        let only_kind = scene.materials.first().map(|m| m.kind()).filter(|&kind| {
            scene.materials.iter().all(|m| m.kind() == kind)
        });
        // Pass 1, per chunk in parallel: each slot's queue and the chunk's count per queue.
        {
            let (hits, depth, dirs) = (&*hits, &paths.depth, &rays.dir);
            scratch.queue[..taken]
                .par_chunks_mut(CHUNK)
                .zip(scratch.chunk_counts.par_iter_mut())
                .enumerate()
                .for_each(|(c, (queue, counts))| {
                    for (i, q) in queue.iter_mut().enumerate() {
                        let slot = c * CHUNK + i;
                        let tri = hits.triangle[slot];
                        *q = if tri == MISS || depth[slot] >= max_depth {
                            DROPPED
                        } else if let Some(kind) = only_kind {
                            queue_of(kind)
                        } else {
                            // The side matters where a twosided has two BSDFs.
                            queue_of(scene.kind_seen(tri, dirs[slot]))
                        };
                        counts[*q as usize] += 1;
                    }
                });
        }
        let mut counts = [0usize; QUEUES];
        for chunk in &scratch.chunk_counts {
            for (total, n) in counts.iter_mut().zip(chunk) {
                *total += n;
            }
        }
        let kept: usize = counts[..MaterialKind::COUNT].iter().sum();
        // Pass 2, per chunk in parallel: each chunk writes its slots into its own stretch of
        // every queue (queues in slot order, dropped paths last), so the order is the same as a
        // serial stable partition's, whatever the thread count.
        let mut order = std::mem::take(&mut scratch.order);
        order.clear();
        order.resize(taken, 0);
        let mut rest: &mut [u32] = &mut order;
        let mut queue_parts: [&mut [u32]; QUEUES] = Default::default();
        for (part, &n) in queue_parts.iter_mut().zip(&counts) {
            let (head, tail) = std::mem::take(&mut rest).split_at_mut(n);
            *part = head;
            rest = tail;
        }
        let mut stretches: Vec<[&mut [u32]; QUEUES]> = Vec::with_capacity(chunks);
        for chunk in &scratch.chunk_counts {
            let mut parts: [&mut [u32]; QUEUES] = Default::default();
            for q in 0..QUEUES {
                let (head, tail) = std::mem::take(&mut queue_parts[q]).split_at_mut(chunk[q]);
                parts[q] = head;
                queue_parts[q] = tail;
            }
            stretches.push(parts);
        }
        scratch.queue[..taken]
            .par_chunks(CHUNK)
            .zip(stretches.into_par_iter())
            .enumerate()
            .for_each(|(c, (queue, parts))| {
                let mut next = [0usize; QUEUES];
                for (i, &q) in queue.iter().enumerate() {
                    let q = q as usize;
                    parts[q][next[q]] = (c * CHUNK + i) as u32;
                    next[q] += 1;
                }
            });
        // Ended paths hand their radiance to their samples (a scatter by sample index).
        for &slot in &order[kept..] {
            let slot = slot as usize;
            sample_radiance[paths.sample[slot] as usize] = paths.radiance[slot];
        }
        order.truncate(kept);
        // Moves the kept paths to slots 0..kept and interpolates each one's surface point, in
        // one parallel pass over the destination, where the hit is being read anyway (it was
        // a pass per column plus a system for the surfaces). Only what later systems of the
        // bounce read moves: the path state, the ray direction (wo) and the hit's
        // triangle. The ray origins, hit distances and barycentrics left behind are stale
        // until shading and tracing write them again.
        {
            let tris = &scene.triangles;
            let prefetch = tris.memory_bytes() >= PREFETCH_FROM_BYTES;
            // Without textures, the material each hit sees is found here, once, where its
            // triangle is read anyway (the shading systems read it from the surface).
            let uniform = !scene.has_textures();
            let (from_paths, from_dir, from_hits) = (&*paths, &rays.dir, &*hits);
            let dirs = scratch.rays.dir[..kept].par_chunks_mut(CHUNK);
            let triangles = scratch.hits.triangle[..kept].par_chunks_mut(CHUNK);
            scratch
                .paths
                .chunks_mut(0..kept)
                .into_par_iter()
                .zip(surfaces.chunks_mut(0..kept))
                .zip(dirs)
                .zip(triangles)
                .zip(order.par_chunks(CHUNK))
                .for_each(|((((p, s), dir), triangle), from)| {
                    let chunk = KeptChunk { p, s, dir, triangle };
                    let from_state = (from_paths, &from_dir[..], from_hits);
                    if prefetch {
                        move_kept::<true>(scene, uniform, from_state, chunk, from);
                    } else {
                        move_kept::<false>(scene, uniform, from_state, chunk, from);
                    }
                });
            std::mem::swap(paths, &mut scratch.paths);
            std::mem::swap(&mut rays.dir, &mut scratch.rays.dir);
            std::mem::swap(&mut hits.triangle, &mut scratch.hits.triangle);
        }
        *active = kept;
        scratch.order = order;
        *ranges = MaterialRanges::from_counts(&counts[..MaterialKind::COUNT]);
        Flow::new(taken, kept)
    }
}

/// One chunk of the destination of the kept paths.
struct KeptChunk<'a> {
    p: PathsChunk<'a>,
    s: SurfacesChunk<'a>,
    dir: &'a mut [Vec3],
    triangle: &'a mut [u32],
}

/// Moves the kept paths of slots `from` into `to` and interpolates their surface points (and,
/// where `uniform`, finds the material each one sees), prefetching the triangles ahead where
/// `PREFETCH` (a copy of the loop each way, so that small scenes run the loop without it).
#[inline(always)]
fn move_kept<const PREFETCH: bool>(
    scene: &PreparedScene,
    uniform: bool,
    (from_paths, from_dir, from_hits): (&Paths, &[Vec3], &Hits),
    to: KeptChunk,
    from: &[u32],
) {
    let tris = &scene.triangles;
    let KeptChunk {
        mut p,
        s,
        dir,
        triangle,
    } = to;
    for (i, &slot) in from.iter().enumerate() {
        if PREFETCH {
            if let Some(&ahead) = from.get(i + PREFETCH_AHEAD) {
                prefetch_triangle(tris, from_hits.triangle[ahead as usize]);
            }
            if let Some(&near) = from.get(i + PREFETCH_AHEAD / 2) {
                prefetch_vertex_normals(tris, from_hits.triangle[near as usize]);
            }
        }
        let slot = slot as usize;
        p.set(i, from_paths.get(slot));
        dir[i] = from_dir[slot];
        let t = from_hits.triangle[slot];
        triangle[i] = t;
        let sp = shading_point(tris, t, from_hits.b1[slot], from_hits.b2[slot]);
        s.p[i] = sp.p;
        s.p_error[i] = sp.p_error;
        s.ng[i] = sp.ng;
        s.ns[i] = sp.ns;
        if uniform {
            s.material[i] = scene.uniform_material_index_seen(t, -dir[i], sp.ng);
        }
    }
}

/// Scenes whose triangle columns take at least this many bytes prefetch the triangles of the
/// hits ahead while interpolating surface points: their columns are far beyond the caches,
/// and each surface point reads five of them (and the vertex normals) at a random triangle.
/// Smaller scenes stay in the caches, where prefetches only cost instructions.
const PREFETCH_FROM_BYTES: usize = 4 << 20;

/// How many paths ahead of the one being moved its triangle's columns are asked for (the
/// vertex normals, which need the triangle's `smooth` entry, half as far ahead).
const PREFETCH_AHEAD: usize = 16;

/// Asks the CPU to bring into the cache what `surface_point` (and the material look-up) reads
/// of `triangle`.
#[inline(always)]
fn prefetch_triangle(tris: &TriangleColumns, triangle: u32) {
    let i = triangle as usize;
    if i < tris.len() {
        crate::cpu::prefetch(&tris.p0[i]);
        crate::cpu::prefetch(&tris.p1[i]);
        crate::cpu::prefetch(&tris.p2[i]);
        crate::cpu::prefetch(&tris.normal[i]);
        crate::cpu::prefetch(&tris.smooth[i]);
        crate::cpu::prefetch(&tris.material[i]);
    }
}

/// Asks the CPU to bring into the cache the vertex normals of `triangle`, if it has them.
#[inline(always)]
fn prefetch_vertex_normals(tris: &TriangleColumns, triangle: u32) {
    if let Some(&k) = tris.smooth.get(triangle as usize)
        && let Some(normals) = tris.vertex_normals.get(k as usize)
    {
        crate::cpu::prefetch(normals);
    }
}

/// The surface point of a hit with its shading normal turned into the hemisphere of the
/// geometric one: the per-path step that this system runs for every kept path, shared with
/// the megakernel (`systems/trace/paths.rs`).
#[inline(always)]
pub fn shading_point(tris: &TriangleColumns, triangle: u32, b1: f32, b2: f32) -> SurfacePoint {
    let sp = surface_point(tris, triangle, b1, b2);
    SurfacePoint {
        ns: if sp.ns.dot(sp.ng) < 0.0 {
            -sp.ns
        } else {
            sp.ns
        },
        ..sp
    }
}
