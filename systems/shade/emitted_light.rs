//! Adds the light of emitters that paths hit, and of the light at infinity to paths that
//! leave the scene, weighted by multiple importance sampling against the light sampling that
//! could also have found them.

use crate::accel::Hit;
use crate::components::Hits;
use crate::components::Paths;
use crate::components::Rays;
use crate::components::{MISS, PathFlags};
use crate::geometry::surface_point;
use crate::pipeline::Flow;
use crate::sampling::power_heuristic;
use crate::scene::NO_EMITTER;
use crate::scene::SceneData;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct AddEmittedLight;

crate::system! {
    AddEmittedLight = "add_emitted_light";
    read data: Arc<SceneData>, hits: Hits, rays: Rays, live: usize;
    write paths: Paths;
    run {
        let found: usize = paths
            .chunks_mut(0..*live)
            .into_par_iter()
            .map(|p| {
                let mut found = 0;
                let range = p.start..p.start + p.len();
                let (hits, rays) = (hits.view(range.clone()), rays.view(range));
                for i in 0..p.len() {
                    let triangle = hits.triangle[i];
                    if triangle == MISS {
                        if let Some(light) = escaped_light(
                            data,
                            rays.dir[i],
                            p.throughput[i],
                            p.flags[i],
                            p.bsdf_pdf[i],
                        ) {
                            p.radiance[i] += light;
                            found += 1;
                        }
                        continue;
                    }
                    let hit = Hit { t: hits.t[i], triangle, b1: hits.b1[i], b2: hits.b2[i] };
                    if let Some(light) = emitted_light(
                        data,
                        &hit,
                        rays.dir[i],
                        p.throughput[i],
                        p.flags[i],
                        p.bsdf_pdf[i],
                    ) {
                        p.radiance[i] += light;
                        found += 1;
                    }
                }
                found
            })
            .sum();
        Flow::new(*live, found)
    }
}

/// What a path of `throughput` that found `hit` along `dir` receives from it if it is an
/// emitter seen from its front (emitters are one-sided), MIS-weighted against light sampling
/// unless the path's last scattering was specular (`flags`) and light sampling could not have
/// found it; `bsdf_pdf` is the density of the BSDF sample that made the ray. The one
/// per-path step of this system, shared with the megakernel (`systems/trace/paths.rs`).
#[inline(always)]
pub fn emitted_light(
    data: &SceneData,
    hit: &Hit,
    dir: Vec3,
    throughput: Vec3,
    flags: PathFlags,
    bsdf_pdf: f32,
) -> Option<Vec3> {
    let emitters = &data.scene.emitters;
    let tris = &data.scene.triangles;
    let e = tris.emitter[hit.triangle as usize];
    if e == NO_EMITTER {
        return None;
    }
    let sp = surface_point(tris, hit.triangle, hit.b1, hit.b2);
    let cos_light = -dir.dot(sp.ng);
    if cos_light <= 0.0 {
        return None;
    }
    let le = emitters.radiance[e as usize];
    let weight = if flags.has(PathFlags::SPECULAR) {
        1.0
    } else {
        let t = hit.t;
        let light_pdf = emitters.pmf[e as usize] / emitters.area[e as usize] * t * t / cos_light;
        power_heuristic(bsdf_pdf, light_pdf)
    };
    Some(throughput * le * weight)
}

/// What a path of `throughput` that left the scene along unit `dir` receives from the light at
/// infinity, if the scene has one, MIS-weighted as `emitted_light`; nothing for a path that
/// ended (its ray's direction is zero). Shared with the megakernel.
#[inline(always)]
pub fn escaped_light(
    data: &SceneData,
    dir: Vec3,
    throughput: Vec3,
    flags: PathFlags,
    bsdf_pdf: f32,
) -> Option<Vec3> {
    let (_, env) = data.scene.emitters.environment()?;
    if dir == Vec3::ZERO {
        return None;
    }
    let le = env.eval(dir);
    let weight = if flags.has(PathFlags::SPECULAR) {
        1.0
    } else {
        power_heuristic(bsdf_pdf, data.scene.environment_light_pdf(dir))
    };
    Some(throughput * le * weight)
}
