//! Scatters the paths on one material kind: a BSDF sample per path (cosine-weighted at
//! Lambertian surfaces, visible normals at conductors, Fresnel choice at glass and thin glass). The graph
//! holds one of these per material kind its scene uses, each over its kind's contiguous queue.

use super::surface::ScatterPaths;
use crate::bsdf::{Material, MaterialKind};
use crate::components::Paths;
use crate::components::Rays;
use crate::components::Surfaces;
use crate::components::path_tracing::MaterialRanges;
use crate::lanes::LaneWidth;
use crate::sampling::Sampler;
use crate::scene::SceneData;
use std::sync::Arc;

pub struct ShadeMaterial(pub MaterialKind);

crate::system! {
    ShadeMaterial;
    name(this) = this.0.shading_system();
    read data: Arc<SceneData>, sampler: Sampler<'static>, lanes: LaneWidth,
        triangles: Vec<u32>, surfaces: Surfaces, materials: Vec<Material>, ranges: MaterialRanges;
    write rays: Rays, paths: Paths;
    run(this) {
        this.0.visit(ScatterPaths {
            data,
            sampler,
            lanes: *lanes,
            triangles,
            surfaces,
            looked_up: materials,
            rays,
            paths,
            range: ranges.of(this.0),
        })
    }
}
