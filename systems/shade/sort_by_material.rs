//! Compacts the paths after tracing and groups them by material kind, so that each shading
//! system runs over one contiguous queue. Paths end here when their ray found nothing (they
//! left the scene, or shading or Russian roulette ended them and left them no ray), or when
//! they reached the depth cap (after their emission was added).

use crate::bsdf::MaterialKind;
use crate::components::{CHUNK, MISS};
use crate::integrators::pt::{MaterialRanges, PtState};
use crate::pipeline::{Flow, System};
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

impl System<PtState> for SortByMaterial {
    fn name(&self) -> &'static str {
        "sort_by_material"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["hits", "paths.depth"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &[
            "rays.dir",
            "hits.triangle",
            "hits.b1",
            "hits.b2",
            "paths",
            "sample_radiance",
            "material_ranges",
        ]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let taken = s.active;
        let max_depth = s.settings.max_depth;
        let scene = &s.data.scene;
        let (hits, depth) = (&s.hits, &s.paths.depth);
        let scratch = &mut s.scratch;
        let chunks = taken.div_ceil(CHUNK);
        scratch.chunk_counts.clear();
        scratch.chunk_counts.resize(chunks, [0; QUEUES]);
        // Pass 1, per chunk in parallel: each slot's queue and the chunk's count per queue.
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
            s.finish_path(slot as usize);
        }
        order.truncate(kept);
        s.scratch.order = order;
        s.reorder();
        s.ranges = MaterialRanges {
            diffuse: 0..counts[0],
            conductor: counts[0]..counts[0] + counts[1],
            dielectric: counts[0] + counts[1]..kept,
        };
        Flow::new(taken, kept)
    }
}
