//! Ends the camera chains that stopped this bounce: each writes its gather point (or none)
//! and the emission it met to its pixel's slot of `visible` (in a ray tree, appends them,
//! when it has either); keeps the glossy points met this bounce, in chunk order, each
//! numbered among its pixel's; the live chains move to the front, in slot order, and the
//! branches split off this bounce start after them, in chunk order.

use crate::components::Hits;
use crate::components::Rays;
use crate::components::camera_walk::Branch;
use crate::components::{
    CHUNK, CameraChain, CameraChains, NO_VISIBLE_POINT, Ray, VisiblePoint, VisiblePoints,
    gather_column, live_slots,
};
use crate::pipeline::Flow;
use glam::Vec3;
use rayon::prelude::*;

pub struct CompactCameraChains;

crate::system! {
    CompactCameraChains = "compact_camera_chains";
    read tree: bool;
    write chains: CameraChains, rays: Rays, hits: Hits, active: usize, visible: VisiblePoints,
        points: usize, spawned: Vec<Vec<Branch>>, order: Vec<u32>, scratch_chains: CameraChains,
        scratch_rays: Rays, glossy: VisiblePoints, glossy_points: usize, glossy_rank: Vec<u32>,
        met_glossy: Vec<Vec<VisiblePoint>>;
    reorder hits[];
    run {
        use std::mem::swap;
        let n = *active;
        write_visible_points(chains, n, *tree, visible, points);
        for mut g in met_glossy.iter_mut().flat_map(|m| m.drain(..)) {
            let rank = &mut glossy_rank[g.pixel as usize];
            g.branch = *rank;
            *rank += 1;
            glossy.reserve_slots(*glossy_points + 1);
            glossy.set(*glossy_points, g);
            *glossy_points += 1;
        }
        live_slots(&chains.alive[..n], order);
        scratch_chains.gather_from(chains, order);
        gather_column(&mut scratch_rays.origin, &rays.origin, order);
        gather_column(&mut scratch_rays.dir, &rays.dir, order);
        swap(chains, scratch_chains);
        swap(rays, scratch_rays);
        let live = order.len();
        let mut starts = Vec::with_capacity(spawned.len());
        let mut end = live;
        for s in spawned.iter() {
            starts.push(end);
            end += s.len();
        }
        if end > live {
            for store in [&mut *chains, &mut *scratch_chains] {
                store.reserve_slots(end);
            }
            for store in [&mut *rays, &mut *scratch_rays] {
                store.reserve_slots(end);
            }
            hits.reserve_slots(end);
            // The branches after the live chains, in chunk order; each chunk's into its own
            // slots, in parallel.
            chains
                .split_mut(&starts, end)
                .into_par_iter()
                .zip(rays.split_mut(&starts, end))
                .zip(spawned.par_iter_mut())
                .with_max_len(1)
                .for_each(|((mut c, mut r), branches)| {
                    for (i, b) in branches.drain(..).enumerate() {
                        c.set(
                            i,
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
                        r.set(i, Ray { origin: b.origin, dir: b.dir });
                    }
                });
        }
        *active = end;
        Flow::new(n, *active)
    }
}

/// Whether ended chain `i` writes a visible point: in a ray tree only a chain that found a
/// surface or met emission (it appends), else every ended chain (its pixel's slot).
fn writes(c: &CameraChains, i: usize, tree: bool) -> bool {
    !c.alive[i] && (!tree || c.triangle[i] != NO_VISIBLE_POINT || c.emitted[i] != Vec3::ZERO)
}

fn visible_point(c: &CameraChains, i: usize) -> VisiblePoint {
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
        depth: c.depth[i],
    }
}

/// Each ended chain's visible point: in a ray tree appended after the `points` so far in slot
/// order, else into its pixel's slot. In parallel over fixed chunks of chains (one serial loop
/// was this system's serial stretch): in a tree each chunk appends into the slots after the
/// chunks before it; else, since chains keep their pixel order (they start in pixel order
/// and compaction is stable), chunk k writes only pixels from its first chain's up to the
/// next chunk's first, a slice of its own. Chains out of pixel order are written serially.
fn write_visible_points(
    c: &CameraChains,
    n: usize,
    tree: bool,
    visible: &mut VisiblePoints,
    points: &mut usize,
) {
    let chunks = n.div_ceil(CHUNK);
    let chunk_of = |k: usize| k * CHUNK..((k + 1) * CHUNK).min(n);
    let (starts, end) = if tree {
        let counts: Vec<usize> = (0..chunks)
            .into_par_iter()
            .map(|k| chunk_of(k).filter(|&i| writes(c, i, tree)).count())
            .collect();
        let mut starts = Vec::with_capacity(chunks);
        let mut end = *points;
        for count in counts {
            starts.push(end);
            end += count;
        }
        visible.reserve_slots(end);
        *points = end;
        (starts, end)
    } else {
        let pixels = &c.pixel[..n];
        if !pixels.par_windows(2).all(|w| w[0] < w[1]) {
            for i in (0..n).filter(|&i| writes(c, i, tree)) {
                visible.set(c.pixel[i] as usize, visible_point(c, i));
            }
            return;
        }
        let starts: Vec<usize> = (0..chunks).map(|k| pixels[k * CHUNK] as usize).collect();
        (starts, pixels.last().map_or(0, |&p| p as usize + 1))
    };
    visible
        .split_mut(&starts, end)
        .into_par_iter()
        .enumerate()
        .with_max_len(1)
        .for_each(|(k, mut out)| {
            let mut appended = 0;
            for i in chunk_of(k).filter(|&i| writes(c, i, tree)) {
                let slot = if tree {
                    appended += 1;
                    appended - 1
                } else {
                    c.pixel[i] as usize - out.start
                };
                out.set(slot, visible_point(c, i));
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel writes give what one serial loop over the ended chains gives: in a tree
    /// appended in slot order, else into each chain's pixel slot (chains in pixel order or not).
    #[test]
    fn visible_points_are_written_as_a_serial_loop_would() {
        let n = 5 * CHUNK + 321;
        for (tree, shuffled) in [(true, false), (false, false), (false, true)] {
            let mut c = CameraChains::new(n);
            for i in 0..n {
                let h = crate::sampling::mix64(i as u64);
                // Pixels increasing with gaps, or a permutation of them.
                c.pixel[i] = if shuffled {
                    ((i * 7919) % n) as u32 * 3
                } else {
                    i as u32 * 3
                };
                c.alive[i] = h.is_multiple_of(3);
                c.triangle[i] = if h.is_multiple_of(5) {
                    NO_VISIBLE_POINT
                } else {
                    i as u32
                };
                c.emitted[i] = Vec3::splat(h.is_multiple_of(7) as u8 as f32);
                c.p[i] = Vec3::splat(i as f32);
            }
            let (first, capacity) = (11, 3 * n);
            let mut expected = VisiblePoints::new(capacity);
            let mut expected_points = first;
            for i in (0..n).filter(|&i| writes(&c, i, tree)) {
                let slot = if tree {
                    expected_points += 1;
                    expected_points - 1
                } else {
                    c.pixel[i] as usize
                };
                expected.set(slot, visible_point(&c, i));
            }
            let mut visible = VisiblePoints::new(capacity);
            let mut points = first;
            write_visible_points(&c, n, tree, &mut visible, &mut points);
            assert_eq!(points, expected_points, "tree {tree}");
            assert!(points > first || !tree);
            assert_eq!(
                visible.pixel, expected.pixel,
                "tree {tree}, shuffled {shuffled}"
            );
            assert_eq!(visible.p, expected.p, "tree {tree}, shuffled {shuffled}");
            assert_eq!(visible.triangle, expected.triangle);
        }
    }
}
