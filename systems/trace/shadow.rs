//! Tests every shadow ray for occlusion (any hit before its end).

use crate::accel::{Accel, NO_HINT};
#[cfg(target_arch = "x86_64")]
use crate::accel::{PACKET_WIDTH, RayColumns};
use crate::components::ShadowRays;
use crate::components::ShadowRaysChunk;
use crate::pipeline::Flow;
use glam::Vec3;
use rayon::prelude::*;

/// Tests shadow rays `0..len` of a state; a ray with `t_max == 0` is absent.
pub struct TraceShadow;

crate::system! {
    TraceShadow = "trace_shadow";
    read accel: Accel, len: usize;
    write shadow: ShadowRays;
    run {
        trace(accel, *len, shadow, false)
    }
}

/// `TraceShadow` for a queue of coherent shadow rays (neighbours leave nearby points towards
/// nearby points, as those from the first hits of neighbouring camera rays do): on AVX2 as
/// packets of eight (see `closest::TraceCoherentClosest`), elsewhere as `TraceShadow`. The same
/// answers either way.
pub struct TraceCoherentShadow;

crate::system! {
    TraceCoherentShadow = "trace_coherent_shadow";
    read accel: Accel, len: usize;
    write shadow: ShadowRays;
    run {
        trace(accel, *len, shadow, true)
    }
}

/// The occlusion of shadow rays `0..len`, in parallel chunks; eight-ray packets on AVX2 where
/// `coherent`.
fn trace(accel: &Accel, len: usize, shadow: &mut ShadowRays, coherent: bool) -> Flow {
    let (taken, unoccluded) = shadow
        .chunks_mut(0..len)
        .into_par_iter()
        .map(|c| {
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx512() {
                // SAFETY: the CPU has AVX-512 (F, DQ, VL, BW), AVX2 and FMA (checked just above).
                return unsafe { trace_chunk_avx512(accel, c) };
            }
            #[cfg(target_arch = "x86_64")]
            if crate::cpu::has_avx2_fma() {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                return unsafe {
                    if coherent {
                        trace_chunk_avx2_packets(accel, c)
                    } else {
                        trace_chunk_avx2(accel, c)
                    }
                };
            }
            trace_chunk(c, |o, d, t_max, hint| {
                accel.any_hit_with_hint(o, d, t_max, hint)
            })
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    Flow::new(taken, unoccluded)
}

/// `trace_chunk` compiled for AVX2 and FMA, with the traversal inlined (see `crate::cpu`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn trace_chunk_avx2(accel: &Accel, c: ShadowRaysChunk) -> (usize, usize) {
    trace_chunk(c, |o, d, t_max, hint| {
        // SAFETY: this function is compiled for AVX2 and FMA and only called where the CPU
        // has them.
        unsafe { accel.any_hit_hinted_in_avx2(o, d, t_max, hint) }
    })
}

/// Occlusion of one chunk's shadow rays as packets of eight in slot order (see
/// `Accel::occluded8`), compiled for AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn trace_chunk_avx2_packets(accel: &Accel, c: ShadowRaysChunk) -> (usize, usize) {
    trace_chunk_in_packets(c, 8, |packet, hint| {
        // SAFETY: this function is compiled for AVX2 and FMA and only called where the CPU
        // has them.
        unsafe { accel.occluded8(packet, hint) }
    })
}

/// Occlusion of one chunk's shadow rays as packets of sixteen in slot order (see
/// `Accel::occluded16`: the same answers as ray by ray), compiled for AVX-512 (see
/// `crate::cpu::has_avx512`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
fn trace_chunk_avx512(accel: &Accel, c: ShadowRaysChunk) -> (usize, usize) {
    trace_chunk_in_packets(c, PACKET_WIDTH, |packet, hint| {
        // SAFETY: this function is compiled for AVX-512, AVX2 and FMA and only called where
        // the CPU has them.
        unsafe { accel.occluded16(packet, hint) }
    })
}

/// Occlusion of one chunk's shadow rays, `width` at a time in slot order by `occluded` (a
/// bit per ray, the hint passed from packet to packet); returns (rays taken, rays
/// unoccluded).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn trace_chunk_in_packets(
    c: ShadowRaysChunk,
    width: usize,
    occluded: impl Fn(&RayColumns, &mut u32) -> u32,
) -> (usize, usize) {
    let (mut taken, mut clear) = (0, 0);
    let mut packet = RayColumns::new();
    let mut slots = [0usize; PACKET_WIDTH];
    let mut hint = NO_HINT;
    for i in 0..c.len() {
        if c.t_max[i] <= 0.0 {
            c.unoccluded[i] = false;
        } else {
            slots[packet.len] = i;
            packet.push(c.origin[i], c.dir[i], c.t_max[i]);
        }
        if packet.len == width || (i + 1 == c.len() && packet.len > 0) {
            let occluded = occluded(&packet, &mut hint);
            for (k, &slot) in slots[..packet.len].iter().enumerate() {
                let open = occluded & (1 << k) == 0;
                c.unoccluded[slot] = open;
                clear += usize::from(open);
            }
            taken += packet.len;
            packet.clear();
        }
    }
    (taken, clear)
}

/// Occlusion of the shadow rays of one chunk with `any_hit`, each ray first trying the
/// triangles that blocked the ray before it, if that one was blocked (neighbouring slots are
/// rays from nearby points, which the same triangles often block; the answers are
/// `any_hit`'s whatever the hint); returns (rays taken, rays unoccluded). Measured with
/// `bench --rays` (docs/measurements/2026-11-26-rays-against-embree.md): door_ajar's shadow
/// rays 1.28x (its camera rays' 2.3x), cornell_box's and big_1m's unchanged within noise.
#[inline(always)]
fn trace_chunk(
    c: ShadowRaysChunk,
    any_hit: impl Fn(Vec3, Vec3, f32, &mut u32) -> bool,
) -> (usize, usize) {
    let (mut taken, mut clear) = (0, 0);
    let mut hint = NO_HINT;
    for i in 0..c.len() {
        if c.t_max[i] <= 0.0 {
            c.unoccluded[i] = false;
            continue;
        }
        taken += 1;
        let open = !any_hit(c.origin[i], c.dir[i], c.t_max[i], &mut hint);
        c.unoccluded[i] = open;
        clear += open as usize;
    }
    (taken, clear)
}
