//! Veach's multi-chain perturbation, for paths seen through two or more specular chains
//! (E S* D S+ D ..., e.g. a diffuse surface seen through glass and lit through it): a lens
//! perturbation moves the camera chain's diffuse vertex, then each following specular chain is
//! retraced from the new diffuse vertex along the old direction turned by a small angle (as
//! the caustic perturbation), until a vertex can be joined to the kept rest of the path or
//! the light is reached. All the perturbations are symmetric, so T(y -> x) / T(x -> y) is the
//! ratio of the Jacobians D(x) / D(y).

use super::lens_perturbation::{camera_chain_end, camera_chain_jacobian, retrace_camera_chain};
use crate::components::metropolis::PathMltSettings;
use crate::mlt::path_chains::PathChains;
use crate::mlt::path_chains::{MutationKind, MutationSet, Proposal};
use crate::mlt::path_space::{
    PathSpace, StepNumbers, dir, perturb_direction, perturb_offset, specular_lobe,
};
use crate::path::Vertex;
use crate::scene::SceneData;
use std::sync::Arc;

/// The camera chain's diffuse vertex c, when x_{c-1} is specular (a second chain follows).
pub fn suitable(ps: &PathSpace, x: &[Vertex]) -> Option<usize> {
    let c = camera_chain_end(ps, x)?;
    (c >= 2 && ps.is_specular(&x[c - 1])).then_some(c)
}

pub fn propose(
    ps: &PathSpace,
    set: &MutationSet,
    x: &[Vertex],
    u: &mut StepNumbers,
) -> Option<Proposal> {
    let c = suitable(ps, x)?;
    let n = x.len();
    let raster = ps.ctx.camera.raster_of(dir(&x[n - 1], &x[n - 2]))?;
    let moved = raster + perturb_offset(u.get2(), set.lens_min, set.lens_max);
    let mut y = retrace_camera_chain(ps, x, c, moved)?;
    let mut i = c; // a new non-specular vertex, x_{i-1} specular
    let last = loop {
        let mut w = perturb_direction(
            dir(&x[i], &x[i - 1]),
            u.get2(),
            set.angle_min,
            set.angle_max,
        );
        let mut j = i - 1;
        loop {
            let hit = if j == 0 {
                ps.trace_or_sky(&y[j + 1], w)?
            } else {
                ps.in_role_of(ps.trace(&y[j + 1], w)?, &x[j])
            };
            if ps.is_specular(&x[j]) {
                if !ps.is_specular(&hit) || j == 0 {
                    return None;
                }
                let reflect = specular_lobe(&x[j], dir(&x[j], &x[j + 1]), dir(&x[j], &x[j - 1]))?;
                y[j] = hit;
                w = ps.follow_specular(&hit, dir(&hit, &y[j + 1]), reflect)?;
                j -= 1;
            } else {
                if j >= 1 && ps.is_specular(&hit) {
                    return None;
                }
                y[j] = hit;
                break;
            }
        }
        if j == 0 {
            break 0;
        }
        if !ps.is_specular(&x[j - 1]) {
            if !ps.visible(&x[j - 1], &y[j]) {
                return None;
            }
            break j;
        }
        i = j;
    };
    PathSpace::fix_kinds(&mut y);
    // Each turn is symmetric and each lobe taken with probability 1, as the lens's chain.
    let (dx, dy) = (
        camera_chain_jacobian(ps, x, last),
        camera_chain_jacobian(ps, &y, last),
    );
    Some(Proposal {
        path: y,
        ratio: if dy > 0.0 { dx / dy } else { 0.0 },
        sampled_density: dy,
        recomputed_density: dy,
    })
}

pub struct MultiChainPerturbation;

crate::system! {
    MultiChainPerturbation = "multichain_perturbation";
    read data: Arc<SceneData>, settings: PathMltSettings;
    write chains: PathChains;
    run {
        super::path_mutation::run(data, &settings.mutations, chains, MutationKind::MultiChain, propose)
    }
}
