//! Records the rays the trace systems just traced, and what they found, into a `RayRecord`
//! (`stagelight rays`): placed right after `trace_closest` and `trace_shadow` in a graph, they
//! see exactly the rays those traced.

use crate::components::ray_record::{RayRecord, TracedHit, ray_row};
use crate::components::{Hits, MISS, Rays, ShadowRays, Wave};
use crate::pipeline::Flow;
use glam::Vec3;

/// Appends the closest-hit rays `0..live` that were traced (non-zero direction) and their
/// hits to the record's current bounce; the first run of a wave is its bounce 0.
pub struct RecordClosestRays;

crate::system! {
    RecordClosestRays = "record_closest_rays";
    read rays: Rays, hits: Hits, live: usize, wave: Wave;
    write record: RayRecord;
    run {
        if record.wave_first == Some(wave.first) {
            record.bounce += 1;
        } else {
            record.wave_first = Some(wave.first);
            record.bounce = 0;
        }
        let store = RayRecord::bounce_store(&mut record.closest, record.bounce);
        let mut taken = 0;
        for i in 0..*live {
            let (origin, dir) = (rays.origin[i], rays.dir[i]);
            // A zero direction is an ended path, which trace_closest skips.
            if dir == Vec3::ZERO {
                continue;
            }
            taken += 1;
            store.rays.push(ray_row(origin, 0.0, dir, f32::INFINITY));
            store.hits.push(if hits.triangle[i] == MISS {
                TracedHit { t: f32::INFINITY, triangle: MISS }
            } else {
                TracedHit { t: hits.t[i], triangle: hits.triangle[i] }
            });
        }
        Flow::new(taken, taken)
    }
}

/// Appends the shadow rays `0..len` that were tested (`t_max > 0`) and whether each was
/// occluded to the record's current bounce (that of the closest-hit rays before them).
pub struct RecordShadowRays;

crate::system! {
    RecordShadowRays = "record_shadow_rays";
    read shadow: ShadowRays, len: usize;
    write record: RayRecord;
    run {
        let store = RayRecord::bounce_store(&mut record.shadow, record.bounce);
        let mut taken = 0;
        for i in 0..*len {
            if shadow.t_max[i] <= 0.0 {
                continue;
            }
            taken += 1;
            store.rays.push(ray_row(shadow.origin[i], 0.0, shadow.dir[i], shadow.t_max[i]));
            store.occluded.push(!shadow.unoccluded[i]);
        }
        Flow::new(taken, taken)
    }
}
