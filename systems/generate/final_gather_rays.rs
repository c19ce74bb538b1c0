//! PM's final gathering: from each visible point, one direction sampled from its BSDF starts
//! a chain (slot = pixel) that follows specular bounces to a surface where the global map is
//! read; the chain's depth counts on from the visible point's. Pixels with no visible point,
//! or whose sample carries nothing, start a dead chain, which the compaction that follows
//! ends with no gather point.

use crate::bsdf::{TransportMode, sample_direction};
use crate::components::CameraChains;
use crate::components::NO_VISIBLE_POINT;
use crate::components::Rays;
use crate::components::VisiblePoints;
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::Sampler;
use crate::sampling::Stream;
use crate::scene::PreparedScene;
use glam::Vec3;
use rayon::prelude::*;

pub struct GenerateFinalGatherRays;

crate::system! {
    GenerateFinalGatherRays = "generate_final_gather_rays";
    read scene: PreparedScene, visible: VisiblePoints, sampler: Sampler<'static>, pass: u64,
        pixels: usize;
    write chains: CameraChains, rays: Rays, active: usize;
    run {
        let (pass, n) = (*pass, *pixels);
        let rays = rays.chunks_mut(0..n);
        let started: usize = chains
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .map(|(c, r)| {
                let mut started = 0;
                for i in 0..c.len() {
                    let pixel = c.start + i;
                    c.pixel[i] = pixel as u32;
                    c.alive[i] = false;
                    c.triangle[i] = NO_VISIBLE_POINT;
                    c.emitted[i] = Vec3::ZERO;
                    c.bsdf_pdf[i] = 0.0;
                    c.depth[i] = 0;
                    let tri = visible.triangle[pixel];
                    if tri == NO_VISIBLE_POINT {
                        continue;
                    }
                    let key = sampler.key(Stream::FinalGather, pixel as u64, pass);
                    c.key[i] = key;
                    let (ng, wo) = (visible.ng[pixel], visible.wo[pixel]);
                    let material =
                        scene.material_facing(tri, visible.p[pixel], wo, visible.ns[pixel]);
                    let frame = Frame::from_normal(visible.ns[pixel]);
                    let wo_local = frame.to_local(wo);
                    // Visible points lie on surfaces that only reflect.
                    let Some((bs, wi)) = sample_direction(
                        &material,
                        &frame,
                        ng,
                        wo,
                        wo_local,
                        sampler.get2(key, 0),
                        TransportMode::Radiance,
                    ) else {
                        continue;
                    };
                    if bs.delta {
                        // A visible point gathers the diffuse lobe alone: a smooth plastic's
                        // reflection is its camera chain's to follow. Dropping the delta choice
                        // leaves the diffuse sample's weight (over its lobe's probability) an
                        // unbiased estimate of that lobe.
                        continue;
                    }
                    let beta = visible.beta[pixel] * bs.value * (bs.wi.z.abs() / bs.pdf);
                    if beta.max_element() <= 0.0 {
                        continue;
                    }
                    c.beta[i] = beta;
                    // The path goes on from the visible point: its bounces count on from
                    // there (the depth cap, and the photons the gather point may gather).
                    c.depth[i] = visible.depth[pixel] + 1;
                    c.alive[i] = true;
                    r.origin[i] = crate::geometry::offset_ray_origin(
                        visible.p[pixel],
                        visible.p_error[pixel],
                        ng,
                        wi,
                    );
                    r.dir[i] = wi;
                    started += 1;
                }
                started
            })
            .sum();
        *active = n;
        Flow::new(n, started)
    }
}
