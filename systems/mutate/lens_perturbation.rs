//! Veach's lens perturbation, for paths whose camera end is E S* D followed by a vertex a
//! connection can reach (or the light itself): the raster position moves by an offset of
//! length log-uniform between `--lens-min` and sqrt(0.05 W H / pi) pixels, the new camera ray
//! follows the same specular lobes as before to a new non-specular vertex, which is joined to
//! the kept rest. The offset's density is symmetric, so T(y -> x) / T(x -> y) is the ratio of
//! the Jacobians from raster to the regrown vertices' areas, D(x) / D(y).

use crate::components::metropolis::PathMltSettings;
use crate::mlt::path_chains::PathChains;
use crate::mlt::path_chains::{MutationKind, MutationSet, Proposal};
use crate::mlt::path_space::{PathSpace, StepNumbers, dir, perturb_offset, specular_lobe};
use crate::path::{Vertex, to_area};
use crate::scene::SceneData;
use glam::Vec2;
use std::sync::Arc;

/// The first non-specular vertex c counted from the camera, when the lens perturbation
/// applies: x_{c+1} .. x_{n-2} specular, and x_{c-1} not (or c = 0, the light).
pub fn suitable(ps: &PathSpace, x: &[Vertex]) -> Option<usize> {
    let c = camera_chain_end(ps, x)?;
    (c == 0 || !ps.is_specular(&x[c - 1])).then_some(c)
}

/// The first non-specular vertex from the camera (x_{n-2} and down), if any.
pub fn camera_chain_end(ps: &PathSpace, x: &[Vertex]) -> Option<usize> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let mut c = n - 2;
    while c >= 1 && ps.is_specular(&x[c]) {
        c -= 1;
    }
    Some(c)
}

/// Area density of the camera-side vertices `c..=n-2` per unit raster area (up to the
/// constant raster density): camera ray, then each specular lobe with probability 1.
pub fn camera_chain_jacobian(ps: &PathSpace, p: &[Vertex], c: usize) -> f64 {
    let n = p.len();
    let cam = &p[n - 1];
    let mut d = f64::from(to_area(
        ps.ctx.camera.pdf_dir(dir(cam, &p[n - 2])),
        cam,
        &p[n - 2],
    ));
    for i in (c..n - 2).rev() {
        d *= f64::from(to_area(1.0, &p[i + 1], &p[i]));
    }
    d
}

/// Retraces the camera chain of `x` from raster position `raster`: the vertices
/// `c..=n-2` of the new path (the others copied from x), following x's lobes.
pub fn retrace_camera_chain(
    ps: &PathSpace,
    x: &[Vertex],
    c: usize,
    raster: Vec2,
) -> Option<Vec<Vertex>> {
    let n = x.len();
    let cam = &ps.ctx.camera;
    if !(0.0..cam.width as f32).contains(&raster.x) || !(0.0..cam.height as f32).contains(&raster.y)
    {
        return None;
    }
    let mut y = x.to_vec();
    let mut w = cam.direction(raster);
    for i in (c..n - 1).rev() {
        let hit = if i == 0 {
            ps.trace_or_sky(&y[i + 1], w)?
        } else {
            ps.in_role_of(ps.trace(&y[i + 1], w)?, &x[i])
        };
        if i > c {
            if !ps.is_specular(&hit) {
                return None;
            }
            let reflect = specular_lobe(&x[i], dir(&x[i], &x[i + 1]), dir(&x[i], &x[i - 1]))?;
            w = ps.follow_specular(&hit, dir(&hit, &y[i + 1]), reflect)?;
        } else if c >= 1 && ps.is_specular(&hit) {
            return None;
        }
        y[i] = hit;
    }
    PathSpace::fix_kinds(&mut y);
    Some(y)
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
    let y = retrace_camera_chain(ps, x, c, moved)?;
    if c >= 1 && !ps.visible(&x[c - 1], &y[c]) {
        return None;
    }
    let (dx, dy) = (
        camera_chain_jacobian(ps, x, c),
        camera_chain_jacobian(ps, &y, c),
    );
    Some(Proposal {
        path: y,
        ratio: if dy > 0.0 { dx / dy } else { 0.0 },
        sampled_density: dy,
        recomputed_density: dy,
    })
}

pub struct LensPerturbation;

crate::system! {
    LensPerturbation = "lens_perturbation";
    read data: Arc<SceneData>, settings: PathMltSettings;
    write chains: PathChains;
    run {
        super::path_mutation::run(data, &settings.mutations, chains, MutationKind::Lens, propose)
    }
}
