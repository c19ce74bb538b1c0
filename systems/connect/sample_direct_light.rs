//! Direct light at the photon mappers' visible points and at the glossy surfaces their camera
//! chains followed: an emitter picked by power, a point uniform on it, and a shadow ray
//! carrying what that point brings if unoccluded (shadow slots `0..points` for the visible
//! points, then one per glossy point).
//!
//! At a visible point, light sampling alone (no MIS): the chain ends there, so no BSDF sample
//! could find the light, and the photons that land first at a surface are not gathered, so
//! nothing else counts this light. At a followed glossy surface the chain's own bounce can
//! hit the light too (`extend_camera_chains` weighs that emission): both are weighted by the
//! power heuristic, as a path tracer's.

use crate::bsdf::scatters_between;
use crate::components::NO_VISIBLE_POINT;
use crate::components::ShadowRays;
use crate::components::VisiblePoints;
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::Sampler;
use crate::sampling::{Stream, power_heuristic};
use crate::scene::SceneData;
use rayon::prelude::*;
use std::sync::Arc;

/// First light-sample dimension of a pixel's glossy points (its visible points take
/// `3 * branch`): glossy point `branch` takes `GLOSSY_DIM + 3 * branch`.
pub const GLOSSY_DIM: u32 = 1 << 24;

pub struct SampleDirectLight;

crate::system! {
    SampleDirectLight = "sample_direct_light";
    read data: Arc<SceneData>, visible: VisiblePoints, points: usize, glossy: VisiblePoints,
        glossy_points: usize, sampler: Sampler<'static>, index: u64;
    write shadow: ShadowRays, shadow_len: usize;
    run {
        let index = *index;
        let scene = &data.scene;
        let (points, total) = (*points, *points + *glossy_points);
        shadow.reserve_slots(total);
        *shadow_len = total;
        let has_emitters = !scene.emitters.triangle.is_empty();
        let cast: usize = shadow
            .chunks_mut(0..total)
            .into_par_iter()
            .map(|c| {
                let mut cast = 0;
                for i in 0..c.len() {
                    c.t_max[i] = 0.0;
                    let slot = c.start + i;
                    // A visible point, or a followed glossy surface (MIS).
                    let (at, k, dim, mis) = if slot < points {
                        (visible, slot, 3 * visible.branch[slot], false)
                    } else {
                        let k = slot - points;
                        (glossy, k, GLOSSY_DIM + 3 * glossy.branch[k], true)
                    };
                    let tri = at.triangle[k];
                    if tri == NO_VISIBLE_POINT || !has_emitters {
                        continue;
                    }
                    // A pixel's points draw from its key's dimensions in turn.
                    let key = sampler.key(Stream::DirectLight, at.pixel[k] as u64, index);
                    let wo = at.wo[k];
                    let material = scene.material_facing(tri, at.p[k], wo, at.ns[k]);
                    let kind = material.kind();
                    let Some(light) = scene.sample_light_from(
                        at.p[k],
                        at.p_error[k],
                        at.ng[k],
                        wo,
                        kind.transmits(),
                        sampler.get(key, dim),
                        sampler.get2(key, dim + 1),
                    ) else {
                        continue;
                    };
                    let frame = Frame::from_normal(at.ns[k]);
                    let (wo_local, wi_local) = (frame.to_local(wo), frame.to_local(light.wi));
                    if kind.transmits()
                        && !scatters_between(
                            kind,
                            wo.dot(at.ng[k]),
                            light.wi.dot(at.ng[k]),
                            wo_local.z,
                            wi_local.z,
                        )
                    {
                        continue;
                    }
                    let f = material.eval(wo_local, wi_local);
                    if f.max_element() <= 0.0 {
                        continue;
                    }
                    let weight = if mis && !light.delta {
                        power_heuristic(light.pdf, material.pdf(wo_local, wi_local))
                    } else {
                        1.0
                    };
                    c.origin[i] = light.origin;
                    c.dir[i] = light.dir;
                    c.t_max[i] = light.t_max;
                    c.contribution[i] = at.beta[k]
                        * f
                        * (weight * wi_local.z.abs() / light.pdf)
                        * light.radiance;
                    cast += 1;
                }
                cast
            })
            .sum();
        Flow::new(total, cast)
    }
}
