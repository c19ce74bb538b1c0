//! Compacts the paths after tracing and groups them by material kind, so that each shading
//! system runs over one contiguous queue. Paths end here when their ray found nothing (they
//! left the scene, or shading or Russian roulette ended them and left them no ray), or when
//! they reached the depth cap (after their emission was added).

use crate::bsdf::MaterialKind;
use crate::components::{CHUNK, MISS};
use crate::integrators::pt::{MaterialRanges, PtState};
use crate::pipeline::Flow;
use rayon::prelude::*;

pub struct SortByMaterial;

/// Queue of each kind, in slot order: non-delta kinds first (see `MaterialRanges`).
fn queue_of(kind: MaterialKind) -> u8 {
    match kind {
        MaterialKind::Diffuse => 0,
        MaterialKind::Conductor => 1,
        MaterialKind::Dielectric => 2,
    }
}

const DROPPED: u8 = 3;
/// The three material queues and the dropped paths.
pub const QUEUES: usize = 4;

crate::system! {
    SortByMaterial = "sort_by_material";
    on PtState {
        read scene = data.scene, max_depth = settings.max_depth;
        write hits, paths, rays, sample_radiance, ranges, active, scratch;
    }
    run {
        let taken = *active;
        let max_depth = *max_depth;
        let chunks = taken.div_ceil(CHUNK);
        scratch.chunk_counts.clear();
        scratch.chunk_counts.resize(chunks, [0; QUEUES]);
        // Pass 1, per chunk in parallel: each slot's queue and the chunk's count per queue.
        {
            let (hits, depth) = (&*hits, &paths.depth);
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
                        } else {
                            let material = scene.triangles.material[tri as usize];
                            queue_of(scene.materials[material as usize].kind())
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
        let kept = counts[0] + counts[1] + counts[2];
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
        // Moves the kept paths to slots 0..kept. Only what later systems of the bounce read
        // moves: the path state, the ray direction (wo) and the hit's triangle and
        // barycentrics. The ray origins and hit distances left behind are stale until shading
        // and tracing write them again.
        {
            use crate::components::gather_column;
            use std::mem::swap;
            scratch.paths.gather_from(paths, &order);
            gather_column(&mut scratch.rays.dir, &rays.dir, &order);
            gather_column(&mut scratch.hits.triangle, &hits.triangle, &order);
            gather_column(&mut scratch.hits.b1, &hits.b1, &order);
            gather_column(&mut scratch.hits.b2, &hits.b2, &order);
            swap(paths, &mut scratch.paths);
            swap(&mut rays.dir, &mut scratch.rays.dir);
            swap(&mut hits.triangle, &mut scratch.hits.triangle);
            swap(&mut hits.b1, &mut scratch.hits.b1);
            swap(&mut hits.b2, &mut scratch.hits.b2);
        }
        *active = kept;
        scratch.order = order;
        *ranges = MaterialRanges {
            diffuse: 0..counts[0],
            conductor: counts[0]..counts[0] + counts[1],
            dielectric: counts[0] + counts[1]..kept,
        };
        Flow::new(taken, kept)
    }
}
