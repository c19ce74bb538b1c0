//! Veach's caustic perturbation, for paths ending (L|D) S+ D E: the direction leaving the
//! non-specular vertex before the specular chain turns by an angle log-uniform in
//! [1e-4, 0.1] radians, the chain is retraced through the same lobes to a new diffuse vertex,
//! which is joined to the camera. The turn's density is symmetric, so T(y -> x) / T(x -> y)
//! is the ratio of the Jacobians from that direction to the regrown vertices' areas.

use crate::components::metropolis::PathMltSettings;
use crate::mlt::path_chains::PathChains;
use crate::mlt::path_chains::{MutationKind, MutationSet, Proposal};
use crate::mlt::path_space::{PathSpace, StepNumbers, dir, perturb_direction, specular_lobe};
use crate::path::{Vertex, to_area};
use crate::scene::SceneData;
use std::sync::Arc;

/// The non-specular vertex b before the specular chain x_{b+1} .. x_{n-3}, when the path ends
/// (L|D) S+ D E.
pub fn suitable(ps: &PathSpace, x: &[Vertex]) -> Option<usize> {
    let n = x.len();
    if n < 4 || ps.is_specular(&x[n - 2]) {
        return None;
    }
    let mut b = n - 3;
    while b >= 1 && ps.is_specular(&x[b]) {
        b -= 1;
    }
    // A light at infinity is a direction, not a point to turn a direction about: the
    // bidirectional mutation moves such paths.
    (b < n - 3 && !ps.is_specular(&x[b]) && !x[b].is_at_infinity()).then_some(b)
}

/// Area density of vertices b+1 ..= n-2 per unit solid angle at x_b.
fn jacobian(p: &[Vertex], b: usize) -> f64 {
    (b + 1..p.len() - 1)
        .map(|i| f64::from(to_area(1.0, &p[i - 1], &p[i])))
        .product()
}

pub fn propose(
    ps: &PathSpace,
    set: &MutationSet,
    x: &[Vertex],
    u: &mut StepNumbers,
) -> Option<Proposal> {
    let b = suitable(ps, x)?;
    let n = x.len();
    let mut y = x.to_vec();
    let mut w = perturb_direction(
        dir(&x[b], &x[b + 1]),
        u.get2(),
        set.angle_min,
        set.angle_max,
    );
    for i in b + 1..n - 1 {
        let hit = ps.in_role_of(ps.trace(&y[i - 1], w)?, &x[i]);
        if i < n - 2 {
            if !ps.is_specular(&hit) {
                return None;
            }
            let reflect = specular_lobe(&x[i], dir(&x[i], &x[i - 1]), dir(&x[i], &x[i + 1]))?;
            w = ps.follow_specular(&hit, dir(&hit, &y[i - 1]), reflect)?;
        } else if ps.is_specular(&hit) {
            return None;
        }
        y[i] = hit;
    }
    PathSpace::fix_kinds(&mut y);
    if !ps.visible(&y[n - 2], &y[n - 1]) {
        return None;
    }
    let (dx, dy) = (jacobian(x, b), jacobian(&y, b));
    Some(Proposal {
        path: y,
        ratio: if dy > 0.0 { dx / dy } else { 0.0 },
        sampled_density: dy,
        recomputed_density: dy,
    })
}

pub struct CausticPerturbation;

crate::system! {
    CausticPerturbation = "caustic_perturbation";
    read data: Arc<SceneData>, settings: PathMltSettings;
    write chains: PathChains;
    run {
        super::path_mutation::run(data, &settings.mutations, chains, MutationKind::Caustic, propose)
    }
}
