//! Ends the camera chains that stopped this bounce: each writes its gather point (or none)
//! and the emission it met to its pixel's slot of `visible` (in a ray tree, appends them,
//! when it has either); keeps the glossy points met this bounce, in chunk order, each
//! numbered among its pixel's; the live chains move to the front, in slot order, and the
//! branches split off this bounce start after them, in chunk order.

use crate::components::{CameraChain, NO_VISIBLE_POINT, VisiblePoint, gather_column, live_slots};
use crate::integrators::camera_walk::CameraWalk;
use crate::pipeline::Flow;
use glam::Vec3;

pub struct CompactCameraChains;

crate::system! {
    CompactCameraChains = "compact_camera_chains";
    on CameraWalk {
        read tree;
        write chains, rays, hits, active, visible, points, spawned, order, scratch_chains, scratch_rays, glossy, glossy_points, glossy_rank, met_glossy;
    }
    run {
        use std::mem::swap;
        let n = *active;
        let c = &*chains;
        for i in (0..n).filter(|&i| !c.alive[i]) {
            let slot = if *tree {
                if c.triangle[i] == NO_VISIBLE_POINT && c.emitted[i] == Vec3::ZERO {
                    continue;
                }
                visible.reserve_slots(*points + 1);
                *points += 1;
                *points - 1
            } else {
                // Each pixel has one chain: ended chains write disjoint slots.
                c.pixel[i] as usize
            };
            visible.set(
                slot,
                VisiblePoint {
                    pixel: c.pixel[i],
                    branch: 0,
                    p: c.p[i],
                    p_error: c.p_error[i],
                    ng: c.ng[i],
                    ns: c.ns[i],
                    wo: c.wo[i],
                    triangle: c.triangle[i],
                    beta: c.beta[i],
                    emitted: c.emitted[i],
                },
            );
        }
        for mut g in met_glossy.iter_mut().flat_map(|m| m.drain(..)) {
            let rank = &mut glossy_rank[g.pixel as usize];
            g.branch = *rank;
            *rank += 1;
            glossy.reserve_slots(*glossy_points + 1);
            glossy.set(*glossy_points, g);
            *glossy_points += 1;
        }
        live_slots(&c.alive[..n], order);
        scratch_chains.gather_from(chains, order);
        gather_column(&mut scratch_rays.origin, &rays.origin, order);
        gather_column(&mut scratch_rays.dir, &rays.dir, order);
        swap(chains, scratch_chains);
        swap(rays, scratch_rays);
        let mut slot = order.len();
        let branches: usize = spawned.iter().map(Vec::len).sum();
        if branches > 0 {
            let needed = slot + branches;
            for store in [&mut *chains, &mut *scratch_chains] {
                store.reserve_slots(needed);
            }
            for store in [&mut *rays, &mut *scratch_rays] {
                store.reserve_slots(needed);
            }
            hits.reserve_slots(needed);
        }
        for b in spawned.iter_mut().flat_map(|s| s.drain(..)) {
            chains.set(
                slot,
                CameraChain {
                    pixel: b.pixel,
                    key: b.key,
                    beta: b.beta,
                    emitted: Vec3::ZERO,
                    bsdf_pdf: 0.0,
                    depth: b.depth,
                    alive: true,
                    p: Vec3::ZERO,
                    p_error: Vec3::ZERO,
                    ng: Vec3::ZERO,
                    ns: Vec3::ZERO,
                    wo: Vec3::ZERO,
                    triangle: NO_VISIBLE_POINT,
                },
            );
            rays.origin[slot] = b.origin;
            rays.dir[slot] = b.dir;
            slot += 1;
        }
        *active = slot;
        Flow::new(n, *active)
    }
}
