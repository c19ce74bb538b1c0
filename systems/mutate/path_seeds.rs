//! `adopt_seed_paths`: the chains of path-space MLT start from the paths of the BDPT
//! bootstrap (pssmlt's, run nested, full BDPT as in pssmlt: every strategy
//! of every evaluation, MIS-weighted with the balance heuristic), as Mitsuba seeds its MLT:
//! every strategy's path of every evaluation is a candidate, weighted by its MIS-weighted
//! luminance. The evaluations were resampled by their targets (the sum of those weights), and
//! here chain i takes one strategy (s, t) of its replayed evaluation with probability its
//! weight over that sum: together, candidate paths in proportion to their weights. The path is
//! the light subpath's first s vertices (for s = 1 the light point next-event estimation drew)
//! then the camera subpath's first t, reversed. Every chain splats b / chains per step, b the
//! mean target per evaluation from the same pool.
//!
//! Why full BDPT rather than the multiplexed (one strategy of one depth per evaluation)
//! bootstrap: light that only one strategy finds, such as torus_glass' torus lit through the
//! glass (s = 0 only), is seen by every full evaluation but by one multiplexed evaluation in
//! (depths x strategies). With the multiplexed bootstrap, b on torus_glass came out 0.049 where
//! the truth is 0.025 (heavy tail), and a fifth of 32768 chains started on a handful of paths.

use crate::components::subpaths::DIM_LIGHT_PICK;
use crate::components::subpaths::DIM_LIGHT_POINT;
use crate::components::subpaths::{Numbers, camera_vertex_dim};
use crate::components::{Connections, PathVertices, ShadowRays, Wave};
use crate::math::luminance;
use crate::mlt::SeedSelection;
use crate::mlt::path_chains::PathChains;
use crate::mlt::path_chains::{INLINE_VERTICES, chunk_starts, path_len, store_path};
use crate::mlt::path_space::{Path, PathSpace};
use crate::path::{Vertex, VertexKind};
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Stream, mix64};
use crate::scene::SceneData;
use std::sync::Arc;

pub struct AdoptSeedPaths;

crate::system! {
    AdoptSeedPaths = "adopt_seed_paths";
    read data: Arc<SceneData>, pixels: u64, selection: Option<SeedSelection>, seed: u64,
        targets: Vec<f32>, capacity: usize, numbers: Numbers, wave: Wave,
        subpath_len: Vec<u32>, vertices: Vec<PathVertices>, connection_start: Vec<usize>,
        shadow: ShadowRays, connections: Connections;
    write chains: PathChains, splat_scale: f32, seeded: bool, seed_mismatches: usize;
    run {
        *seeded = true;
        let n = chains.chains();
        let Some(selection) = selection.as_ref() else {
            return Flow::new(n, 0);
        };
        let ps = PathSpace::new(data);
        let cap = *capacity;
        let sampler = numbers.sampler();
        let mut paths: Vec<Path> = Vec::with_capacity(n);
        let mut mismatches = 0;
        let pick_seed = mix64(seed ^ STRATEGY_DOMAIN);
        for i in 0..n {
            let target = targets[i];
            let mut path: Path = Vec::new();
            // The replayed sample's strategy, by its share of the sample's luminance.
            let u = SampleKey::new(pick_seed, i as u64, 0).get(0);
            let Some((s, t)) = pick_strategy((connection_start, shadow, connections), i, target, u) else {
                mismatches += (target > 0.0) as usize;
                paths.push(path);
                continue;
            };
            let (nc, nl) = (subpath_len[i] as usize, subpath_len[cap + i] as usize);
            let vertex = |slot: usize, d: usize| {
                Vertex::from_store(&vertices[d].view(0..vertices[d].capacity()), slot, d)
            };
            if s == 1 && t >= 2 {
                let key = numbers.key(&sampler, Stream::Connection, *wave, *pixels, i);
                let dim = camera_vertex_dim(t - 1);
                if let Some(v) = ps.sample_light_origin(
                    sampler.get(key, dim + DIM_LIGHT_PICK),
                    sampler.get2(key, dim + DIM_LIGHT_POINT),
                ) {
                    path.push(v);
                }
            } else if s <= nl {
                path.extend((0..s).map(|d| vertex(cap + i, d)));
            }
            if t <= nc {
                path.extend((0..t).rev().map(|d| vertex(i, d)));
            }
            let mut path: Path = path.iter().map(|v| ps.reshade(v)).collect();
            for (k, v) in path.iter_mut().enumerate() {
                v.beta = glam::Vec3::ZERO;
                v.pdf_fwd = 0.0;
                v.pdf_rev = 0.0;
                // A subpath vertex's `delta` (its lobe going on was a delta) is its role in
                // the path (`PathSpace::is_specular`), but at the joint, s - 1 and s, where
                // the connection evaluated the non-delta lobe, and at the ends.
                if v.kind != VertexKind::Surface || k + 1 == s || k == s {
                    v.delta = false;
                }
                if v.kind == VertexKind::Light {
                    v.kind = VertexKind::Surface;
                }
            }
            PathSpace::fix_kinds(&mut path);
            if path.len() != s + t || ps.contribution(&path).is_none() {
                mismatches += 1;
                path.clear();
            }
            paths.push(path);
        }
        *seed_mismatches = mismatches;
        let starts = chunk_starts(n);
        let mut stores = chains.current.split_mut(&starts, n * INLINE_VERTICES);
        let mut live = 0;
        for (i, path) in paths.iter().enumerate() {
            let c = i / crate::components::CHUNK;
            let local = i % crate::components::CHUNK;
            store_path(&mut stores[c], &mut chains.current_overflow[i], local, path);
            chains.current_len[i] = path_len(path.len());
            match ps.contribution(path) {
                Some((f, landing)) => {
                    chains.current_f[i] = f;
                    chains.current_landing[i] = landing;
                    chains.current_target[i] = PathSpace::target(f);
                    live += 1;
                }
                None => {
                    chains.current_f[i] = glam::DVec3::ZERO;
                    chains.current_target[i] = 0.0;
                }
            }
        }
        // Chains without a seed (none, in practice: `seed_mismatches` says) never splat, so the
        // others share b.
        *splat_scale = (selection.total_normalisation() / live.max(1) as f64) as f32;
        Flow::new(n, live)
    }
}

/// Separates the strategy picks from every other use of the seed.
const STRATEGY_DOMAIN: u64 = 0x6d6c_745f_7374_7261;

/// The strategy (s, t) of replayed sample `k` whose path seeds its chain: among the sample's
/// connections that reached the film (s = 0, or an unoccluded connection), the first whose
/// running luminance passes `u` x the sample's target (the sum of them all), so each is picked
/// with probability its luminance over the target. None for a black sample.
fn pick_strategy(
    (connection_start, shadow, conns): (&[usize], &ShadowRays, &Connections),
    k: usize,
    target: f32,
    u: f32,
) -> Option<(usize, usize)> {
    if target <= 0.0 {
        return None;
    }
    let slots = connection_start[k]..connection_start[k + 1];
    let reached = |&slot: &usize| conns.s[slot] == 0 || shadow.unoccluded[slot];
    let weight = |slot: usize| luminance(shadow.contribution[slot]) as f64;
    let total: f64 = slots.clone().filter(reached).map(weight).sum();
    if total <= 0.0 {
        return None;
    }
    let goal = u as f64 * total;
    let mut running = 0.0;
    let mut last = None;
    for slot in slots.filter(reached) {
        let w = weight(slot);
        if w <= 0.0 {
            continue;
        }
        last = Some((conns.s[slot] as usize, conns.t[slot] as usize));
        running += w;
        if running > goal {
            break;
        }
    }
    last
}
