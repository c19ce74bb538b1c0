//! Starts both subpaths of every sample of the wave: the camera vertex and a camera ray
//! (uniform inside the sample's pixel), and a light vertex (an emitter picked by power, a
//! point uniform on it) with a cosine-distributed ray leaving its emitting side.
//!
//! Under primary-sample numbers (MLT) the raster position is the camera stream's first two
//! numbers over the whole film, and a multiplexed sample (MMLT) first picks its strategy s
//! from its connection stream: its camera subpath then walks to exactly t = depth + 2 - s
//! vertices and its light subpath to s (none for s = 0, the light vertex alone for s = 1).
//! A multiplexed sample comes with its group in `multiplex` and leaves with its depth there
//! (the tail group's depth drawn from its connection stream: `bdpt::multiplexed_depth`).

use crate::components::PathVertices;
use crate::components::Rays;
use crate::components::Walkers;
use crate::components::Wave;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::CAMERA_DIM_PIXEL;
use crate::components::subpaths::CONNECTION_DIM_STRATEGY;
use crate::components::subpaths::CONNECTION_DIM_TAIL_DEPTH;
use crate::components::subpaths::LIGHT_DIM_DIRECTION;
use crate::components::subpaths::LIGHT_DIM_PICK;
use crate::components::subpaths::LIGHT_DIM_POINT;
use crate::components::subpaths::Numbers;
use crate::components::subpaths::multiplexed_depth;
use crate::components::{CAMERA_VERTEX, PathVertex};
use crate::geometry::offset_ray_origin;
use crate::math::Frame;
use crate::pipeline::Flow;
use crate::sampling::{Stream, cosine_hemisphere};
use crate::scene::SceneData;
use crate::scene::lights;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

pub struct StartSubpaths;

crate::system! {
    StartSubpaths = "start_subpaths";
    read wave: Wave, data: Arc<SceneData>, pixels: u64, numbers: Numbers, capacity: usize,
        settings: BdptSettings;
    write vertices: Vec<PathVertices>, walkers: Walkers, rays: Rays, subpath_len: Vec<u32>,
        active: usize, depth: usize, sample_pixel: Vec<u32>, sample_raster: Vec<Vec2>,
        chosen_s: Vec<u16>, multiplex: Vec<u32>;
    run {
        let n = wave.len;
        let cap = *capacity;
        let cam = data.scene.camera.frustum();
        let (wave, pixels) = (*wave, *pixels);
        let w = cam.width as u64;
        let emitters = &data.scene.emitters;
        let sampler = numbers.sampler();
        let sampler = &sampler;
        let film_wide = numbers.is_primary();
        let size = glam::Vec2::new(cam.width as f32, cam.height as f32);

        let has_light = !emitters.triangle.is_empty();
        // The camera key, the raster position and its pixel of sample k.
        let raster_of = |k: usize| {
            let key = numbers.key(sampler, Stream::Camera, wave, pixels, k);
            let u = sampler.get2(key, CAMERA_DIM_PIXEL);
            if film_wide {
                let raster = u * size;
                let x = (raster.x as u64).min(w - 1);
                let y = (raster.y as u64).min(cam.height as u64 - 1);
                (key, raster, y * w + x)
            } else {
                let pixel = (wave.first + k as u64) % pixels;
                (key, Vec2::new((pixel % w) as f32, (pixel / w) as f32) + u, pixel)
            }
        };
        let multiplexed = !multiplex.is_empty();
        if multiplexed {
            // The group each sample came with becomes its depth (the tail group's drawn).
            let max_depth = settings.max_depth;
            chosen_s[..n]
                .par_iter_mut()
                .zip(multiplex[..n].par_iter_mut())
                .enumerate()
                .with_min_len(crate::components::CHUNK)
                .for_each(|(k, (s, depth))| {
                    let key = numbers.key(sampler, Stream::Connection, wave, pixels, k);
                    *depth = multiplexed_depth(*depth, sampler.get(key, CONNECTION_DIM_TAIL_DEPTH), max_depth);
                    let strategies = *depth + 2;
                    let u = sampler.get(key, CONNECTION_DIM_STRATEGY);
                    *s = ((u * strategies as f32) as u32).min(strategies - 1) as u16;
                });
        }
        let multiplex = &*multiplex;
        // Vertices each subpath of sample k may have (camera, light) for a multiplexed one.
        let lengths = |k: usize| {
            let s = chosen_s[k] as u32;
            (multiplex[k] + 2 - s, s)
        };

        // Camera subpaths: subpath k, walker slot k.
        let views = vertices[0].chunks_mut(0..n);
        let camera_walkers = walkers.chunks_mut(0..n);
        let camera_rays = rays.chunks_mut(0..n);
        // Chunks of CHUNK items from 0, as the stores' `chunks_mut` cut them.
        let sample_pixels = sample_pixel[..n].par_chunks_mut(crate::components::CHUNK);
        let sample_rasters = sample_raster[..n].par_chunks_mut(crate::components::CHUNK);
        // An orthographic camera's rays leave points of its near plane in one direction: a
        // delta direction, which no light vertex can be joined to (t = 1) and which the MIS
        // walk leaves out as it does any delta vertex's strategies.
        let pinhole = cam.is_pinhole();
        views
            .into_par_iter()
            .zip(camera_walkers)
            .zip(camera_rays)
            .zip(sample_pixels.zip(sample_rasters))
            .for_each(|(((mut v, wk), r), (sample_pixel, sample_raster))| {
                for (i, (sample_pixel, sample_raster)) in
                    sample_pixel.iter_mut().zip(sample_raster).enumerate()
                {
                    let k = v.start + i;
                    let (key, raster, pixel) = raster_of(k);
                    *sample_pixel = pixel as u32;
                    *sample_raster = raster;
                    let (origin, dir) = cam.ray(raster);
                    // A multiplexed sample with t = 1 needs only the camera vertex.
                    let walks = !multiplexed || lengths(k).0 >= 2;
                    v.set(
                        i,
                        PathVertex {
                            p: origin,
                            p_error: Vec3::ZERO,
                            ng: cam.forward,
                            ns: cam.forward,
                            triangle: CAMERA_VERTEX,
                            beta: Vec3::ONE,
                            pdf_fwd: 1.0,
                            pdf_rev: 0.0,
                            delta: !pinhole,
                        },
                    );
                    wk.subpath[i] = k as u32;
                    wk.key[i] = key;
                    wk.beta[i] = Vec3::ONE;
                    // 0 for the orthographic camera's delta direction: its first vertex's
                    // forward density is then "no choice" (1 in the walk), which only the
                    // left-out t = 1 strategies would read.
                    wk.pdf_dir[i] = cam.pdf_dir(dir);
                    wk.roulette_scale[i] = 1.0;
                    wk.alive[i] = walks;
                    r.origin[i] = origin;
                    r.dir[i] = if walks { dir } else { Vec3::ZERO };
                }
            });
        subpath_len[..n].fill(1);
        subpath_len[cap..cap + n].fill(if has_light { 1 } else { 0 });
        if multiplexed && has_light {
            for k in 0..n {
                subpath_len[cap + k] = lengths(k).1.min(1);
            }
        }
        if !has_light {
            *active = n;
            *depth = 1;
            return Flow::new(n, n);
        }

        // Light subpaths: subpath cap + k, walker slot n + k (slots stay in subpath order).
        let views = vertices[0].chunks_mut(cap..cap + n);
        let walkers = walkers.chunks_mut(n..2 * n);
        let rays = rays.chunks_mut(n..2 * n);
        views
            .into_par_iter()
            .zip(walkers)
            .zip(rays)
            .for_each(|((mut v, wk), r)| {
                for i in 0..v.len() {
                    let k = v.start - cap + i;
                    let key = numbers.key(sampler, Stream::Light, wave, pixels, k);
                    // A multiplexed sample with s <= 1 walks no light subpath.
                    let walks = !multiplexed || lengths(k).1 >= 2;
                    // A light at infinity (the environment, or a directional light): a
                    // direction and a point on the disk across the scene facing it. The
                    // origin's density is in solid angle; the disk's plays the direction
                    // density's part (see `to_area`).
                    let picked =
                        crate::sampling::sample_cdf(&emitters.cdf, sampler.get(key, LIGHT_DIM_PICK));
                    let from_infinity = match emitters.environment() {
                        Some((e, env)) if e == picked => {
                            let (towards_light, pdf_dir) =
                                env.sample(sampler.get2(key, LIGHT_DIM_DIRECTION));
                            Some((towards_light, env.eval(towards_light), emitters.pmf[e] * pdf_dir))
                        }
                        _ if emitters.is_directional(picked) => Some((
                            -emitters.position[picked],
                            emitters.radiance[picked],
                            emitters.pmf[picked],
                        )),
                        _ => None,
                    };
                    if let Some((towards_light, le, pdf_origin)) = from_infinity {
                        let origin = emitters
                            .disk
                            .origin(towards_light, sampler.get2(key, LIGHT_DIM_POINT));
                        let dir = -towards_light;
                        let pdf_disk = emitters.disk.pdf();
                        let live = pdf_origin > 0.0;
                        v.set(
                            i,
                            PathVertex {
                                p: origin,
                                p_error: Vec3::ZERO,
                                ng: dir,
                                ns: dir,
                                triangle: emitters.triangle[picked],
                                beta: if live { le / pdf_origin } else { Vec3::ZERO },
                                pdf_fwd: pdf_origin,
                                pdf_rev: 0.0,
                                delta: false,
                            },
                        );
                        let beta = if live {
                            le * (1.0 / (pdf_origin * pdf_disk))
                        } else {
                            Vec3::ZERO
                        };
                        wk.subpath[i] = (cap + k) as u32;
                        wk.key[i] = key;
                        wk.beta[i] = beta;
                        wk.pdf_dir[i] = pdf_disk;
                        wk.roulette_scale[i] = beta.max_element().max(f32::MIN_POSITIVE);
                        let walks = walks && live;
                        wk.alive[i] = walks;
                        r.origin[i] = origin;
                        r.dir[i] = if walks { dir } else { Vec3::ZERO };
                        continue;
                    }
                    let light = data
                        .scene
                        .sample_emitter(
                        sampler.get(key, LIGHT_DIM_PICK),
                        sampler.get2(key, LIGHT_DIM_POINT),
                    );
                    let (e, tri, sp) = (light.emitter, light.triangle, light.point);
                    let pdf_origin = light.pdf_area;
                    let le = emitters.radiance[e];
                    let u_dir = sampler.get2(key, LIGHT_DIM_DIRECTION);
                    let point_light = emitters.is_point(e);
                    let (dir, pdf_dir) = if point_light {
                        lights::sample_direction(&emitters.profile[e], u_dir)
                    } else {
                        let local = cosine_hemisphere(u_dir);
                        let dir = Frame::from_normal(sp.ng).to_world(local).normalize();
                        (dir, local.z * FRAC_1_PI)
                    };
                    v.set(
                        i,
                        PathVertex {
                            p: sp.p,
                            p_error: sp.p_error,
                            ng: sp.ng,
                            ns: sp.ng,
                            triangle: tri,
                            beta: le / pdf_origin,
                            pdf_fwd: pdf_origin,
                            pdf_rev: 0.0,
                            delta: false,
                        },
                    );
                    // Le cos / (pdf_origin pdf_dir), with pdf_dir = cos / pi; a point
                    // light's intensity over its densities.
                    let beta = if point_light {
                        emitters.intensity_towards(e, dir) * (1.0 / (pdf_origin * pdf_dir))
                    } else if pdf_dir > 0.0 {
                        le * (std::f32::consts::PI / pdf_origin)
                    } else {
                        Vec3::ZERO
                    };
                    wk.subpath[i] = (cap + k) as u32;
                    wk.key[i] = key;
                    wk.beta[i] = beta;
                    wk.pdf_dir[i] = pdf_dir;
                    wk.roulette_scale[i] = beta.max_element().max(f32::MIN_POSITIVE);
                    let walks = walks && pdf_dir > 0.0;
                    wk.alive[i] = walks;
                    r.origin[i] = offset_ray_origin(sp.p, sp.p_error, sp.ng, dir);
                    r.dir[i] = if walks { dir } else { Vec3::ZERO };
                }
            });
        *active = 2 * n;
        *depth = 1;
        Flow::new(n, 2 * n)
    }
}
