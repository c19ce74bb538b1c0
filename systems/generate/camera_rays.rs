//! Generates one camera ray per sample of the wave: each sample uniform inside its pixel
//! (the film's filter then weighs it by where it fell: `sample_raster`).

use crate::components::Wave;
use crate::components::path_tracing::DIM_PIXEL;
use crate::components::{CHUNK, Paths, PathsChunk, Rays, RaysChunk};
use crate::components::{Path, PathFlags};
use crate::lanes::{F, LaneKernel, LaneWidth, Real, V3, lanes_of, run_lanes};
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler, Stream};
use crate::scene::Camera;
use crate::scene::Frustum;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub struct GenerateCameraRays;

crate::system! {
    GenerateCameraRays = "generate_camera_rays";
    read wave: Wave, camera: Camera, pixels: u64, sampler: Sampler<'static>, lanes: LaneWidth;
    write rays: Rays, paths: Paths, sample_radiance: Vec<Vec3>, active: usize;
    run {
        let n = wave.len;
        let cam = camera.frustum();
        let (first, pixels) = (wave.first, *pixels);
        let rays = rays.chunks_mut(0..n);
        let paths = paths.chunks_mut(0..n);
        // Each chunk zeroes its own samples' radiance (a serial fill was a stretch with one
        // core idle); slot i holds sample i here.
        let radiance = sample_radiance[..n].par_chunks_mut(CHUNK);
        rays.into_par_iter().zip(paths).zip(radiance).for_each(|((r, p), radiance)| {
            radiance.fill(Vec3::ZERO);
            let chunk = GenerateChunk { sampler, cam: &cam, pixels, first, r, p };
            run_lanes(*lanes, chunk)
        });
        *active = n;
        Flow::new(n, n)
    }
}

/// Camera ray generation's work over one chunk, for `run_lanes` (the keys' 64-bit hashes in
/// vector lanes want AVX-512's 64-bit multiplies).
struct GenerateChunk<'a> {
    sampler: &'a Sampler<'a>,
    cam: &'a Frustum,
    pixels: u64,
    first: u64,
    r: RaysChunk<'a>,
    p: PathsChunk<'a>,
}

impl LaneKernel for GenerateChunk<'_> {
    type Output = ();
    #[inline(always)]
    fn run<const N: usize>(self) {
        let GenerateChunk {
            sampler,
            cam,
            pixels,
            first,
            r,
            p,
        } = self;
        generate_chunk::<N>(sampler, cam, pixels, first, r, p)
    }
}

/// The camera rays and fresh paths of one chunk of the wave's slots (slot i is global sample
/// `first + i`): under the independent sampler `N` at a time, the rest one by one.
#[inline(always)]
fn generate_chunk<const N: usize>(
    sampler: &Sampler,
    cam: &Frustum,
    pixels: u64,
    first: u64,
    r: RaysChunk,
    mut p: PathsChunk,
) {
    let path = |slot: usize, key: SampleKey| Path {
        sample: slot as u32,
        key,
        throughput: Vec3::ONE,
        radiance: Vec3::ZERO,
        depth: 0,
        bsdf_pdf: 0.0,
        flags: PathFlags(PathFlags::SPECULAR),
    };
    let mut i = 0;
    // The lanes' fast path is the pinhole's (an orthographic ray's origin varies).
    if let (Sampler::Independent { .. }, crate::scene::Projection::Perspective) =
        (*sampler, cam.projection)
    {
        while i + N <= r.len() {
            let slot = r.start + i;
            let (keys, dir) = camera_ray_lanes::<N>(sampler, cam, pixels, first + slot as u64);
            for (l, &key) in keys.iter().enumerate() {
                r.origin[i + l] = cam.position;
                r.dir[i + l] = dir.lane(l);
                p.set(i + l, path(slot + l, key));
            }
            i += N;
        }
    }
    for i in i..r.len() {
        let slot = r.start + i;
        let ray = camera_ray(sampler, cam, pixels, first + slot as u64);
        r.origin[i] = ray.origin;
        r.dir[i] = ray.dir;
        p.set(i, path(slot, ray.key));
    }
}

/// `camera_ray` of the `N` global samples from `g` on, under the independent sampler:
/// the jitter's hashes and the directions in lanes, lane by lane the same operations
/// (`Sampler::get2`, `Frustum::direction`), so the same bits (the megakernel's test compares).
#[inline(always)]
fn camera_ray_lanes<const N: usize>(
    sampler: &Sampler,
    cam: &Frustum,
    pixels: u64,
    g: u64,
) -> ([SampleKey; N], V3<F<N>>) {
    let w = cam.width as u64;
    // Pixels and sample indices stepped from the first lane's (no divisions per lane).
    let (mut pixel, mut sample) = (g % pixels, g / pixels);
    let (mut x, mut y) = (pixel % w, pixel / w);
    let mut lane_pixel = [0u64; N];
    let mut lane_sample = [0u64; N];
    let mut raster_x = F::splat(0.0);
    let mut raster_y = F::splat(0.0);
    for l in 0..N {
        lane_pixel[l] = pixel;
        lane_sample[l] = sample;
        // On the whole film: a crop's pixels get the film's own rays, bit for bit.
        raster_x.0[l] = (x + cam.offset.x as u64) as f32;
        raster_y.0[l] = (y + cam.offset.y as u64) as f32;
        pixel += 1;
        x += 1;
        if x == w {
            (x, y) = (0, y + 1);
        }
        if pixel == pixels {
            (pixel, sample, x, y) = (0, sample + 1, 0, 0);
        }
    }
    let keys: [SampleKey; N] = lanes_of(|l| {
        sampler.key(
            Stream::Camera,
            cam.film_pixel(lane_pixel[l]),
            lane_sample[l],
        )
    });
    let (jitter_x, jitter_y) = (
        F(SampleKey::get_lanes(&keys, &[DIM_PIXEL; N])),
        F(SampleKey::get_lanes(&keys, &[DIM_PIXEL + 1; N])),
    );
    let (raster_x, raster_y) = (raster_x + jitter_x, raster_y + jitter_y);
    // Frustum::direction_on_film
    let (w, h) = (cam.film_width as f32, cam.film_height as f32);
    let sx = (2.0 * raster_x / w - 1.0) * cam.tan_half * cam.aspect;
    let sy = (1.0 - 2.0 * raster_y / h) * cam.tan_half;
    let dir = V3::splat(cam.forward) + V3::splat(cam.right) * sx + V3::splat(cam.up) * sy;
    (keys, dir.normalize())
}

/// The camera ray of one sample and the key of its random numbers.
#[derive(Clone, Copy, Debug)]
pub struct CameraRay {
    pub key: SampleKey,
    pub origin: Vec3,
    pub dir: Vec3,
}

/// The camera ray of global sample `g` (pixel `g % pixels`, sample index `g / pixels`): the
/// one per-sample step of this system, shared with the megakernel (`systems/trace/paths.rs`).
#[inline(always)]
pub fn camera_ray(sampler: &Sampler, cam: &Frustum, pixels: u64, g: u64) -> CameraRay {
    let (key, raster) = sample_raster(sampler, cam, pixels, g);
    let (origin, dir) = cam.ray_on_film(raster);
    CameraRay { key, origin, dir }
}

/// The random-number key and position on the whole film (pixels, the crop window's offset
/// included) of global sample `g`: uniform in pixel `g % pixels` of the rendered image, keyed
/// by its place on the whole film, so a crop renders the film's own samples bit for bit. The
/// film's filter weighs the sample by this position.
#[inline(always)]
pub fn sample_raster(sampler: &Sampler, cam: &Frustum, pixels: u64, g: u64) -> (SampleKey, Vec2) {
    let w = cam.width as u64;
    let pixel = g % pixels;
    let key = sampler.key(Stream::Camera, cam.film_pixel(pixel), g / pixels);
    let jitter = sampler.get2(key, DIM_PIXEL);
    let (x, y) = (
        pixel % w + cam.offset.x as u64,
        pixel / w + cam.offset.y as u64,
    );
    (key, Vec2::new(x as f32, y as f32) + jitter)
}
