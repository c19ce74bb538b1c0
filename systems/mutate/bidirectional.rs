//! Veach's bidirectional mutation: delete a subpath of the current path (its length from a
//! two-tailed geometric distribution about 2 edges, at most the path's, its place uniform),
//! regrow a new one of a length drawn about the deleted one's (two-tailed geometric with no
//! upper bound, as Mitsuba's, unless the user gave `--max-depth`: paths of any length are
//! reachable), s vertices from the light end and the rest from the camera end, and join them
//! by one edge. Its transition density sums the densities of every split s that could have
//! made the new vertices (each chosen with probability 1 / (added edges)), times the discrete
//! probabilities of the deletion and the added length, which both directions of a move take
//! from `two_tailed`.

use crate::bsdf::TransportMode;
use crate::components::metropolis::PathMltSettings;
use crate::mlt::path_chains::PathChains;
use crate::mlt::path_chains::{MutationKind, MutationSet, Proposal};
use crate::mlt::path_space::{Path, PathSpace, StepNumbers, dir};
use crate::path::{VertexKind, to_area};
use crate::scene::SceneData;
use std::sync::Arc;

/// 2^-j, exact (0 below f64's normal range, where no sum here can tell).
#[inline]
fn pow2_neg(j: usize) -> f64 {
    if j > 1022 {
        0.0
    } else {
        f64::from_bits((1023 - j as u64) << 52)
    }
}

/// sum of 2^-j for j in p..=q (q may be `usize::MAX`: the whole tail), p <= q.
#[inline]
fn geometric_sum(p: usize, q: usize) -> f64 {
    2.0 * pow2_neg(p) - pow2_neg(q)
}

/// The unnormalised weight 2^-|k - center| of a two-tailed geometric distribution.
#[inline]
fn two_tailed_weight(center: usize, k: usize) -> f64 {
    pow2_neg(k.abs_diff(center))
}

/// The weights' sum over [lo, hi] (hi may be `usize::MAX`: no upper bound), in closed form:
/// the geometric sums below and above the center.
fn two_tailed_mass(center: usize, lo: usize, hi: usize) -> f64 {
    let mut mass = 0.0;
    // k in [lo, min(hi, center)]: 2^-(center - k).
    let below = hi.min(center);
    if lo <= below {
        mass += geometric_sum(center - below, center - lo);
    }
    // k in [max(lo, center + 1), hi]: 2^-(k - center).
    let above = lo.max(center + 1);
    if above <= hi {
        mass += geometric_sum(above - center, hi - center);
    }
    mass
}

/// P(k) of a two-tailed geometric distribution about `center` (ratio 1/2), on [lo, hi]; `hi`
/// may be `usize::MAX` (Mitsuba's unbounded tail: only a user's `--max-depth` bounds it).
/// Both directions of a move take their length probabilities from here.
pub fn two_tailed(center: usize, lo: usize, hi: usize, k: usize) -> f64 {
    if k < lo || k > hi {
        return 0.0;
    }
    two_tailed_weight(center, k) / two_tailed_mass(center, lo, hi)
}

/// A draw from `two_tailed(center, lo, hi, .)` (lo <= hi) by its inverse CDF: at most a few
/// dozen terms past the center, where the tail's mass falls below u's resolution.
pub fn sample_two_tailed(center: usize, lo: usize, hi: usize, u: f32) -> usize {
    let norm = two_tailed_mass(center, lo, hi);
    let u = f64::from(u);
    let mut acc = 0.0;
    let mut k = lo;
    while k < hi {
        acc += two_tailed_weight(center, k) / norm;
        // Past 2^-64 of the mass the sum cannot grow towards u (rounding): the last term.
        if u < acc || k > center.saturating_add(64) {
            return k;
        }
        k += 1;
    }
    hi
}

/// The lengths one bidirectional mutation changes: edges l..l + deleted of the path are
/// replaced by `added` edges (edge -1 is the virtual one before the light vertex).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Change {
    /// Last vertex kept on the light side (-1: none).
    pub l: isize,
    pub deleted: usize,
    pub added: usize,
}

/// The added lengths allowed when `kept` vertices stay: the new path's vertex count
/// kept + added - 1 within the set's limits (no upper one unless the user gave a depth cap:
/// then hi is `usize::MAX`, or near it).
fn added_range(set: &MutationSet, kept: usize) -> Option<(usize, usize)> {
    let lo = (set.min_vertices + 1).saturating_sub(kept).max(1);
    let hi = set.max_vertices.saturating_add(1).checked_sub(kept)?;
    (lo <= hi).then_some((lo, hi))
}

/// T(x -> y) for the change `c` that turns x into y.
pub fn transition(
    ps: &PathSpace,
    set: &MutationSet,
    x: &[crate::path::Vertex],
    y: &[crate::path::Vertex],
    c: Change,
) -> f64 {
    let n = x.len();
    if c.deleted == 0 || c.deleted > n || c.added == 0 {
        return 0.0;
    }
    if c.l + c.deleted as isize == 0 && (x[0].is_point_light() || x[0].is_at_infinity()) {
        return 0.0; // as `propose` refuses it
    }
    let positions = n - c.deleted + 1;
    let kept = n - c.deleted + 1;
    let Some((lo, hi)) = added_range(set, kept) else {
        return 0.0;
    };
    let discrete = two_tailed(2, 1, n, c.deleted) / positions as f64
        * two_tailed(c.deleted, lo, hi, c.added)
        / c.added as f64;
    let first_new = (c.l + 1) as usize;
    let count = c.added - 1;
    let sum: f64 = (0..c.added)
        .map(|s| ps.split_density(y, first_new, count, s))
        .sum();
    discrete * sum
}

/// Proposes a mutation of `x`; `None` when the regrown path is impossible (a miss, a joint
/// at a specular vertex, an occluded joint) or could not be turned back into x.
pub fn propose(
    ps: &PathSpace,
    set: &MutationSet,
    x: &[crate::path::Vertex],
    u: &mut StepNumbers,
) -> Option<Proposal> {
    let n = x.len();
    let deleted = sample_two_tailed(2, 1, n, u.get());
    let positions = n - deleted + 1;
    let l = ((u.get() * positions as f32) as usize).min(positions - 1) as isize - 1;
    let m = (l + deleted as isize) as usize;
    if m == 0 && (x[0].is_point_light() || x[0].is_at_infinity()) {
        // The camera side would keep the point light (or a light at infinity) as a surface
        // to scatter from.
        return None;
    }
    let kept = n - deleted + 1;
    let (lo, hi) = added_range(set, kept)?;
    let added = sample_two_tailed(deleted, lo, hi, u.get());
    let count = added - 1;
    let s = ((u.get() * added as f32) as usize).min(added - 1);
    let t = count - s;
    let mut sampled = two_tailed(2, 1, n, deleted) / positions as f64
        * two_tailed(deleted, lo, hi, added)
        / added as f64;

    let mut light: Path = x[..(l + 1) as usize].to_vec();
    for _ in 0..s {
        // The lobe sampled at the vertex a new one is sampled from: its role in the path.
        let mut role = None;
        let next = match light.last() {
            None => {
                let v = ps.sample_light_origin(u.get(), u.get2())?;
                sampled *= f64::from(ps.ctx.pdf_light_origin(&v));
                v
            }
            Some(v) if v.is_at_infinity() => {
                let next = ps.trace_from_infinity(v, u.get2())?;
                sampled *= f64::from(ps.ctx.pdf_light_dir(v, &next));
                next
            }
            Some(v) => {
                let wo = light
                    .len()
                    .checked_sub(2)
                    .map_or(glam::Vec3::ZERO, |i| dir(v, &light[i]));
                let (w, pdf, delta) =
                    ps.sample_direction(v, wo, u.get2(), TransportMode::Importance)?;
                let next = ps.trace(v, w)?;
                sampled *= f64::from(to_area(pdf, v, &next));
                role = Some(delta);
                next
            }
        };
        if let (Some(delta), Some(v)) = (role, light.last_mut()) {
            v.delta = delta;
        }
        light.push(next);
    }
    // The camera side, camera first; kept vertices are all surfaces there.
    let mut camera: Path = x[m..].iter().rev().copied().collect();
    for v in camera.iter_mut().skip(1) {
        v.kind = VertexKind::Surface;
    }
    for k in 0..t {
        let v = *camera.last().expect("the camera is kept");
        let wo = camera
            .len()
            .checked_sub(2)
            .map_or(glam::Vec3::ZERO, |i| dir(&v, &camera[i]));
        let (w, pdf, delta) = ps.sample_direction(&v, wo, u.get2(), TransportMode::Radiance)?;
        if let Some(last) = camera.last_mut() {
            last.delta = delta;
        }
        // The new light vertex, when the camera side makes it, may be the environment.
        let next = if l == -1 && s == 0 && k + 1 == t {
            ps.trace_or_sky(&v, w)?
        } else {
            ps.trace(&v, w)?
        };
        sampled *= f64::from(to_area(pdf, &v, &next));
        camera.push(next);
    }
    // The joint's two vertices scatter by their non-delta lobes (the connection).
    for v in [light.last_mut(), camera.last_mut()].into_iter().flatten() {
        v.delta = false;
    }
    if let Some(a) = light.last() {
        let c = camera.last().expect("the camera is kept");
        if !ps.ctx.is_connectible(a) || !ps.ctx.is_connectible(c) || !ps.visible(a, c) {
            return None;
        }
    }
    let mut y = light;
    y.extend(camera.into_iter().rev());
    PathSpace::fix_kinds(&mut y);
    let change = Change { l, deleted, added };
    let forward = transition(ps, set, x, &y, change);
    let reverse = transition(
        ps,
        set,
        &y,
        x,
        Change {
            l,
            deleted: added,
            added: deleted,
        },
    );
    // No split of x's deleted vertices can be regrown from y (x had a specular vertex next to
    // a kept one, which no joint may touch): the move could never be undone, so it is
    // rejected here, before the acceptance test would (a = 0).
    if reverse <= 0.0 {
        return None;
    }
    let recomputed = two_tailed(2, 1, n, deleted) / positions as f64
        * two_tailed(deleted, lo, hi, added)
        / added as f64
        * ps.split_density(&y, (l + 1) as usize, count, s);
    Some(Proposal {
        path: y,
        ratio: if forward > 0.0 {
            reverse / forward
        } else {
            0.0
        },
        sampled_density: sampled,
        recomputed_density: recomputed,
    })
}

pub struct BidirectionalMutation;

crate::system! {
    BidirectionalMutation = "bidirectional_mutation";
    read data: Arc<SceneData>, settings: PathMltSettings;
    write chains: PathChains;
    run {
        super::path_mutation::run(data, &settings.mutations, chains, MutationKind::Bidirectional, propose)
    }
}
