//! `adopt_seed_paths`: the chains of path-space MLT start from the paths of the multiplexed
//! BDPT bootstrap (`crate::integrators::mlt`'s, run nested): chain i's seed is the strategy
//! (s, t) path of its replayed evaluation, the light subpath's first s vertices (for s = 1 the
//! light point next-event estimation drew) then the camera subpath's first t, reversed. The
//! seeds were drawn by weight (MIS-weighted luminance with the balance heuristic: the
//! luminance of f over the density of all strategies), so they start the chains near their
//! stationary distribution; every chain splats b / chains per step, b from the same pool.

use crate::integrators::bdpt::{DIM_LIGHT_PICK, DIM_LIGHT_POINT, camera_vertex_dim};
use crate::integrators::path_mlt::PathMltState;
use crate::mlt::path_chains::{chunk_starts, store_path};
use crate::mlt::path_space::{MAX_VERTICES, Path, PathSpace};
use crate::path::{Vertex, VertexKind};
use crate::pipeline::Flow;
use crate::sampling::Stream;

pub struct AdoptSeedPaths;

crate::system! {
    AdoptSeedPaths = "adopt_seed_paths";
    on PathMltState {
        read data, pixels;
        write seeding, chains, splat_scale, seeded, seed_mismatches;
    }
    run {
        *seeded = true;
        let n = chains.chains();
        let Some(selection) = seeding.selection.as_ref() else {
            return Flow::new(n, 0);
        };
        let ps = PathSpace::new(data);
        let bdpt = &seeding.bdpt;
        let cap = bdpt.capacity;
        let sampler = bdpt.sampler.sampler();
        let mut paths: Vec<Path> = Vec::with_capacity(n);
        let mut mismatches = 0;
        for i in 0..n {
            let depth = selection.group[i] as usize;
            let s = bdpt.chosen_s[i] as usize;
            let t = depth + 2 - s;
            let (nc, nl) = (bdpt.subpath_len[i] as usize, bdpt.subpath_len[cap + i] as usize);
            let vertex = |slot: usize, d: usize| {
                Vertex::from_store(&bdpt.vertices[d].view(0..bdpt.vertices[d].capacity()), slot, d)
            };
            let mut path: Path = Vec::with_capacity(depth + 2);
            if s == 1 && t >= 2 {
                let key = bdpt.sampler.key(&sampler, Stream::Connection, bdpt.wave, *pixels, i);
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
            for v in path.iter_mut() {
                v.beta = glam::Vec3::ZERO;
                v.pdf_fwd = 0.0;
                v.pdf_rev = 0.0;
                v.delta = false;
                if v.kind == VertexKind::Light {
                    v.kind = VertexKind::Surface;
                }
            }
            PathSpace::fix_kinds(&mut path);
            let ok = path.len() == depth + 2
                && seeding.chains.current_contributions.target[i] > 0.0
                && ps.contribution(&path).is_some();
            if !ok {
                mismatches += (seeding.chains.current_contributions.target[i] > 0.0) as usize;
                path.clear();
            }
            paths.push(path);
        }
        *seed_mismatches = mismatches;
        let starts = chunk_starts(n);
        let mut stores = chains.current.split_mut(&starts, n * MAX_VERTICES);
        let mut live = 0;
        for (i, path) in paths.iter().enumerate() {
            let c = i / crate::components::CHUNK;
            let local = i % crate::components::CHUNK;
            store_path(&mut stores[c], local, path);
            chains.current_len[i] = path.len() as u8;
            match ps.contribution(path) {
                Some((f, pixel)) => {
                    chains.current_f[i] = f;
                    chains.current_pixel[i] = pixel;
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
