//! Computes the surface point of every path's hit once per bounce (position with its error
//! bound, geometric and shading normals), for the light-sampling and shading systems.

use crate::geometry::{SurfacePoint, TriangleColumns, surface_point};
use crate::integrators::pt::PtState;
use crate::pipeline::Flow;
use rayon::prelude::*;

pub struct InterpolateSurfaces;

crate::system! {
    InterpolateSurfaces = "interpolate_surfaces";
    on PtState {
        read tris = data.scene.triangles, hits, live = active;
        write surfaces;
    }
    run {
        let n = *live;
        surfaces.chunks_mut(0..n).into_par_iter().for_each(|c| {
            let hits = hits.view(c.start..c.start + c.len());
            for i in 0..c.len() {
                let sp = shading_point(tris, hits.triangle[i], hits.b1[i], hits.b2[i]);
                c.p[i] = sp.p;
                c.p_error[i] = sp.p_error;
                c.ng[i] = sp.ng;
                c.ns[i] = sp.ns;
            }
        });
        Flow::new(n, n)
    }
}

/// The surface point of a hit with its shading normal turned into the hemisphere of the
/// geometric one: the one per-path step of this system, shared with the megakernel
/// (`systems/trace/paths.rs`).
#[inline(always)]
pub fn shading_point(tris: &TriangleColumns, triangle: u32, b1: f32, b2: f32) -> SurfacePoint {
    let sp = surface_point(tris, triangle, b1, b2);
    SurfacePoint {
        ns: if sp.ns.dot(sp.ng) < 0.0 {
            -sp.ns
        } else {
            sp.ns
        },
        ..sp
    }
}
