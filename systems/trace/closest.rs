//! Finds the closest hit of every live ray.

use crate::accel::{Accel, Hit};
#[cfg(target_arch = "x86_64")]
use crate::accel::{PACKET_WIDTH, RayColumns};
use crate::components::Hits;
use crate::components::{HitsChunk, MISS, Rays};
use crate::pipeline::Flow;
use glam::Vec3;
use rayon::prelude::*;

/// Traces rays `0..live` of a state's ray queue. A ray whose direction is zero is absent (its
/// path has ended): it is not traced and finds nothing.
pub struct TraceClosest;

crate::system! {
    TraceClosest = "trace_closest";
    read accel: Accel, rays: Rays, live: usize;
    write hits: Hits;
    run {
        trace(accel, rays, *live, hits, false)
    }
}

/// `TraceClosest` for a queue of coherent rays: neighbours in the queue leave nearby points in
/// nearly the same direction, as camera rays of neighbouring pixels do. On AVX2 they are traced
/// as packets of eight, which on such rays find the hits 1.5-2.2x as fast as single rays do
/// but lose a quarter to a third on later bounces (docs/measurements/2026-12-02-avx2-packets.md);
/// elsewhere as `TraceClosest`. The same hits either way.
pub struct TraceCoherentClosest;

crate::system! {
    TraceCoherentClosest = "trace_coherent_closest";
    read accel: Accel, rays: Rays, live: usize;
    write hits: Hits;
    run {
        trace(accel, rays, *live, hits, true)
    }
}

/// The closest hits of rays `0..live`, in parallel chunks; eight-ray packets on AVX2 where
/// `coherent`.
fn trace(accel: &Accel, rays: &Rays, live: usize, hits: &mut Hits, coherent: bool) -> Flow {
    let (traced, found) = hits
        .chunks_mut(0..live)
        .into_par_iter()
        .map(|h| {
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx512() {
                // SAFETY: the CPU has AVX-512 (F, DQ, VL, BW), AVX2 and FMA (checked just above).
                return unsafe { trace_chunk_avx512(accel, rays, h) };
            }
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx2_fma() {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                return unsafe {
                    if coherent {
                        trace_chunk_avx2_packets(accel, rays, h)
                    } else {
                        trace_chunk_avx2(accel, rays, h)
                    }
                };
            }
            trace_chunk(rays, h, |o, d| accel.closest_hit(o, d, f32::INFINITY))
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    Flow::new(traced, found)
}

/// `trace_chunk` compiled for AVX2 and FMA, with the traversal inlined (see `crate::cpu`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn trace_chunk_avx2(accel: &Accel, rays: &Rays, h: HitsChunk) -> (usize, usize) {
    trace_chunk(rays, h, |o, d| {
        // SAFETY: this function is compiled for AVX2 and FMA and only called where the CPU
        // has them.
        unsafe { accel.trace_in_avx2::<false>(o, d, f32::INFINITY) }
    })
}

/// The closest hits of one chunk's live rays as packets of eight in slot order (see
/// `Accel::closest_hits8`), compiled for AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn trace_chunk_avx2_packets(accel: &Accel, rays: &Rays, h: HitsChunk) -> (usize, usize) {
    trace_chunk_in_packets(rays, h, 8, |packet, hits| {
        // SAFETY: this function is compiled for AVX2 and FMA and only called where the CPU
        // has them.
        unsafe { accel.closest_hits8(packet, hits) }
    })
}

/// The closest hits of one chunk's live rays as packets of sixteen in slot order (see
/// `Accel::closest_hits16`: the same hits as ray by ray), compiled for AVX-512 (see
/// `crate::cpu::has_avx512`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
fn trace_chunk_avx512(accel: &Accel, rays: &Rays, h: HitsChunk) -> (usize, usize) {
    trace_chunk_in_packets(rays, h, PACKET_WIDTH, |packet, hits| {
        // SAFETY: this function is compiled for AVX-512, AVX2 and FMA and only called where
        // the CPU has them.
        unsafe { accel.closest_hits16(packet, hits) }
    })
}

/// The closest hits of one chunk's live rays, `width` at a time in slot order by
/// `closest_hits`; returns (rays traced, hits).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn trace_chunk_in_packets(
    rays: &Rays,
    mut h: HitsChunk,
    width: usize,
    closest_hits: impl Fn(&RayColumns, &mut [Option<Hit>; PACKET_WIDTH]),
) -> (usize, usize) {
    let (mut traced, mut found) = (0, 0);
    let view = rays.view(h.start..h.start + h.len());
    let mut packet = RayColumns::new();
    let mut slots = [0usize; PACKET_WIDTH];
    let mut hits = [None; PACKET_WIDTH];
    for i in 0..h.len() {
        if view.dir[i] == Vec3::ZERO {
            h.triangle[i] = MISS;
        } else {
            slots[packet.len] = i;
            packet.push(view.origin[i], view.dir[i], f32::INFINITY);
        }
        if packet.len == width || (i + 1 == h.len() && packet.len > 0) {
            closest_hits(&packet, &mut hits);
            for (&slot, &hit) in slots[..packet.len].iter().zip(&hits) {
                found += usize::from(write_hit(&mut h, slot, hit));
            }
            traced += packet.len;
            packet.clear();
        }
    }
    (traced, found)
}

/// Closest hits of the rays of one chunk with `closest_hit`; returns (rays traced, hits).
#[inline(always)]
fn trace_chunk(
    rays: &Rays,
    mut h: HitsChunk,
    closest_hit: impl Fn(Vec3, Vec3) -> Option<Hit>,
) -> (usize, usize) {
    let (mut traced, mut found) = (0, 0);
    let rays = rays.view(h.start..h.start + h.len());
    for i in 0..h.len() {
        if rays.dir[i] == Vec3::ZERO {
            h.triangle[i] = MISS;
            continue;
        }
        traced += 1;
        found += usize::from(write_hit(
            &mut h,
            i,
            closest_hit(rays.origin[i], rays.dir[i]),
        ));
    }
    (traced, found)
}

/// Writes `hit` (or a miss) into slot `i` of the chunk's hit columns; whether it hit.
#[inline(always)]
fn write_hit(h: &mut HitsChunk, i: usize, hit: Option<Hit>) -> bool {
    match hit {
        Some(hit) => {
            h.t[i] = hit.t;
            h.triangle[i] = hit.triangle;
            h.b1[i] = hit.b1;
            h.b2[i] = hit.b2;
            true
        }
        None => {
            h.triangle[i] = MISS;
            false
        }
    }
}
