//! Scatters paths at Lambertian surfaces (cosine-weighted sampling).

use super::surface::scatter_paths;
use crate::bsdf::{Material, MaterialKind, diffuse};
use crate::integrators::pt::PtState;
use crate::pipeline::{Flow, System};

pub struct ShadeDiffuse;

impl System<PtState> for ShadeDiffuse {
    fn name(&self) -> &'static str {
        "shade_diffuse"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["hits", "surfaces", "rays.dir", "paths", "material_ranges"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["rays", "paths"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let range = s.ranges.of(MaterialKind::Diffuse);
        scatter_paths(s, range, |surf, u| match surf.material {
            Material::Diffuse { reflectance } => diffuse::sample(reflectance, surf.wo_local, u),
            _ => None,
        })
    }
}
