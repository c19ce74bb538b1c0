//! Scatters paths at GGX conductors (visible-normal sampling).

use super::surface::scatter_paths;
use crate::bsdf::{Material, MaterialKind, conductor};
use crate::integrators::pt::PtState;
use crate::pipeline::{Flow, System};

pub struct ShadeConductor;

impl System<PtState> for ShadeConductor {
    fn name(&self) -> &'static str {
        "shade_conductor"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["hits", "surfaces", "rays.dir", "paths", "material_ranges"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["rays", "paths"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let range = s.ranges.of(MaterialKind::Conductor);
        scatter_paths(s, range, |surf, u| match surf.material {
            Material::Conductor { alpha, reflectance } => {
                conductor::sample(alpha, reflectance, surf.wo_local, u)
            }
            _ => None,
        })
    }
}
