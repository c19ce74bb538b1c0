//! Compacts the paths after tracing and groups them by material kind, so that each shading
//! system runs over one contiguous queue. Paths that left the scene, or reached the depth cap
//! (after their emission was added), end here.

use crate::bsdf::MaterialKind;
use crate::components::MISS;
use crate::integrators::pt::{MaterialRanges, PtState};
use crate::pipeline::{Flow, System};

pub struct SortByMaterial;

/// Queue of each kind, in slot order: non-delta kinds first (see `MaterialRanges`).
fn queue_of(kind: MaterialKind) -> usize {
    match kind {
        MaterialKind::Diffuse => 0,
        MaterialKind::Conductor => 1,
        MaterialKind::Dielectric => 2,
    }
}

const DROPPED: usize = 3;

impl System<PtState> for SortByMaterial {
    fn name(&self) -> &'static str {
        "sort_by_material"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["hits", "paths.depth"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &[
            "rays",
            "hits",
            "paths",
            "sample_radiance",
            "material_ranges",
        ]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let taken = s.active;
        let max_depth = s.settings.max_depth;
        let classify = |s: &PtState, slot: usize| -> usize {
            let tri = s.hits.triangle[slot];
            if tri == MISS || s.paths.depth[slot] >= max_depth {
                return DROPPED;
            }
            let scene = &s.data.scene;
            queue_of(scene.materials[scene.triangles.material[tri as usize] as usize].kind())
        };
        let mut counts = [0usize; 4];
        for slot in 0..taken {
            let q = classify(s, slot);
            counts[q] += 1;
            if q == DROPPED {
                s.finish_path(slot);
            }
        }
        let mut next = [0, counts[0], counts[0] + counts[1]];
        let kept = counts[0] + counts[1] + counts[2];
        let mut order = std::mem::take(&mut s.scratch.order);
        order.clear();
        order.resize(kept, 0);
        for slot in 0..taken {
            let q = classify(s, slot);
            if q != DROPPED {
                order[next[q]] = slot as u32;
                next[q] += 1;
            }
        }
        s.scratch.order = order;
        s.reorder(true);
        s.ranges = MaterialRanges {
            diffuse: 0..counts[0],
            conductor: counts[0]..counts[0] + counts[1],
            dielectric: counts[0] + counts[1]..kept,
        };
        Flow::new(taken, kept)
    }
}
