//! Emits the next wave of the pass's photons: an emitter picked by power, a point uniform on it, a direction
//! cosine-distributed about its emitting side, and the power `Le pi / pdf(point)`.

use crate::geometry::offset_ray_origin;
use crate::math::Frame;
use crate::photons::PhotonTracing;
use crate::photons::{DIM_DIRECTION, DIM_PICK, DIM_POINT};
use crate::pipeline::Flow;
use crate::sampling::{Stream, cosine_hemisphere};
use crate::scene::SceneData;
use crate::scene::lights;
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;
use std::sync::Arc;

pub struct EmitPhotons;

crate::system! {
    EmitPhotons = "emit_photons";
    read data: Arc<SceneData>;
    write tracing: PhotonTracing;
    run {
        let (data, t): (&SceneData, _) = (data, tracing);
        let n = t.remaining().min(t.walkers.capacity() as u64) as usize;
        t.first = t.next;
        t.len = n;
        t.next += n as u64;
        let emitters = &data.scene.emitters;

        if emitters.triangle.is_empty() {
            // Nothing emits: the pass is over.
            t.next = t.photons_per_pass;
            t.active = 0;
            return Flow::new(0, 0);
        }
        let (sampler, pass, first) = (t.sampler, t.pass, t.first);
        let rays = t.rays.chunks_mut(0..n);
        t.walkers
            .chunks_mut(0..n)
            .into_par_iter()
            .zip(rays)
            .for_each(|(w, r)| {
                for i in 0..w.len() {
                    let key = sampler.key(Stream::Photon, first + (w.start + i) as u64, pass);
                    if let Some((e, env)) = emitters.environment()
                        && crate::sampling::sample_cdf(&emitters.cdf, sampler.get(key, DIM_PICK)) == e
                    {
                        // From the light at infinity: a direction by its own density, from a
                        // point on the disk across the scene; radiance over the pick, the
                        // direction's and the disk's densities.
                        let (towards_light, pdf_dir) = env.sample(sampler.get2(key, DIM_DIRECTION));
                        let origin = emitters
                            .disk
                            .origin(towards_light, sampler.get2(key, DIM_POINT));
                        let pdf = emitters.pmf[e] * pdf_dir * emitters.disk.pdf();
                        let alive = pdf > 0.0;
                        w.key[i] = key;
                        w.power[i] = if alive {
                            env.eval(towards_light) * (1.0 / pdf)
                        } else {
                            Vec3::ZERO
                        };
                        w.depth[i] = 0;
                        w.specular_chain[i] = true;
                        w.alive[i] = alive;
                        r.origin[i] = origin;
                        r.dir[i] = if alive { -towards_light } else { Vec3::ZERO };
                        continue;
                    }
                    let light = data
                        .scene
                        .sample_emitter(sampler.get(key, DIM_PICK), sampler.get2(key, DIM_POINT));
                    let (e, sp) = (light.emitter, light.point);
                    let u_dir = sampler.get2(key, DIM_DIRECTION);
                    let pdf_point = light.pdf_area;
                    if emitters.is_directional(e) {
                        // Its one direction, from a point on the disk across the scene.
                        let dir = emitters.position[e];
                        let origin = emitters.disk.origin(-dir, sampler.get2(key, DIM_POINT));
                        w.key[i] = key;
                        w.power[i] =
                            emitters.radiance[e] * (1.0 / (pdf_point * emitters.disk.pdf()));
                        w.depth[i] = 0;
                        w.specular_chain[i] = true;
                        w.alive[i] = true;
                        r.origin[i] = origin;
                        r.dir[i] = dir;
                        continue;
                    }
                    let (dir, alive, power) = if emitters.is_point(e) {
                        // Intensity over the pick probability and the direction's density.
                        let (dir, pdf_dir) = lights::sample_direction(&emitters.profile[e], u_dir);
                        let power = emitters.intensity_towards(e, dir) * (1.0 / (pdf_point * pdf_dir));
                        (dir, true, power)
                    } else {
                        let local = cosine_hemisphere(u_dir);
                        let dir = Frame::from_normal(sp.ng).to_world(local).normalize();
                        // Le cos / (pdf_point cos / pi); a direction in the tangent plane
                        // carries nothing and is not traced.
                        (dir, local.z > 0.0, emitters.radiance[e] * (PI / pdf_point))
                    };
                    w.key[i] = key;
                    w.power[i] = power;
                    w.depth[i] = 0;
                    w.specular_chain[i] = true;
                    w.alive[i] = alive;
                    r.origin[i] = offset_ray_origin(sp.p, sp.p_error, sp.ng, dir);
                    r.dir[i] = if alive { dir } else { Vec3::ZERO };
                }
            });
        t.active = n;
        t.emitted += n as u64;
        Flow::new(n, n)
    }
}
