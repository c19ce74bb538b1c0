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
        // The material lookups run in parallel; the placement below is a cheap serial pass.
        s.scratch.queue[..taken]
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, queue)| {
                for (i, q) in queue.iter_mut().enumerate() {
                    let slot = c * CHUNK + i;
                    let tri = hits.triangle[slot];
                    *q = if tri == MISS || depth[slot] >= max_depth {
                        DROPPED
                    } else {
                        let material = scene.triangles.material[tri as usize];
                        queue_of(scene.materials[material as usize].kind())
                    };
                }
            });
        let mut counts = [0usize; 4];
        for &q in &s.scratch.queue[..taken] {
            counts[q as usize] += 1;
        }
        let mut next = [0, counts[0], counts[0] + counts[1], 0];
        let kept = counts[0] + counts[1] + counts[2];
        let mut order = std::mem::take(&mut s.scratch.order);
        order.clear();
        order.resize(kept, 0);
        for slot in 0..taken {
            let q = s.scratch.queue[slot];
            if q == DROPPED {
                s.finish_path(slot);
            } else {
                order[next[q as usize]] = slot as u32;
                next[q as usize] += 1;
            }
        }
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
