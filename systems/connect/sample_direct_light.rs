//! Direct light at the photon mappers' visible points: an emitter picked by power, a point
//! uniform on it, and a shadow ray carrying what that point brings if unoccluded. Light
//! sampling alone (no MIS): the visible point never samples its BSDF toward a light, and the
//! photons that land first at a surface are not gathered, so nothing else counts this light.

use crate::components::NO_VISIBLE_POINT;
use crate::integrators::{pm::PmState, sppm::ProgressiveState};
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::Stream;
use rayon::prelude::*;

pub struct SampleDirectLight;

crate::system! {
    SampleDirectLight = "sample_direct_light";
    on PmState {
        read data, visible = camera_walk.visible, points = camera_walk.points, sampler = camera_walk.sampler, index = pass;
        write shadow;
    }
    on ProgressiveState {
        read data, visible = camera_walk.visible, points = camera_walk.points, sampler = camera_walk.sampler, index = pass;
        write shadow;
    }
    run {
        let index = *index;
        let scene = &data.scene;
        let pixels = *points;
        let has_emitters = !scene.emitters.triangle.is_empty();
        let cast: usize = shadow
            .chunks_mut(0..pixels)
            .into_par_iter()
            .map(|c| {
                let mut cast = 0;
                for i in 0..c.len() {
                    c.t_max[i] = 0.0;
                    let pixel = c.start + i;
                    let tri = visible.triangle[pixel];
                    if tri == NO_VISIBLE_POINT || !has_emitters {
                        continue;
                    }
                    // A pixel's hit points (PPM's ray tree) draw from its key's dimensions
                    // in turn.
                    let key = sampler.key(Stream::DirectLight, visible.pixel[pixel] as u64, index);
                    let dim = 3 * visible.branch[pixel];
                    let wo = visible.wo[pixel];
                    let Some(light) = scene.sample_light_from(
                        visible.p[pixel],
                        visible.p_error[pixel],
                        visible.ng[pixel],
                        wo,
                        sampler.get(key, dim),
                        sampler.get2(key, dim + 1),
                    ) else {
                        continue;
                    };
                    let material = scene.materials[scene.triangles.material[tri as usize] as usize];
                    let frame = Frame::from_normal(visible.ns[pixel]);
                    let wi_local = frame.to_local(light.wi);
                    let f = material.eval(frame.to_local(wo), wi_local);
                    if f.max_element() <= 0.0 {
                        continue;
                    }
                    c.origin[i] = light.origin;
                    c.dir[i] = light.dir;
                    c.t_max[i] = light.t_max;
                    c.contribution[i] =
                        visible.beta[pixel] * f * (wi_local.z.abs() / light.pdf) * light.radiance;
                    cast += 1;
                }
                cast
            })
            .sum();
        Flow::new(pixels, cast)
    }
}
