//! Reflects or refracts paths at smooth dielectrics (choosing by the Fresnel term).

use super::surface::scatter_paths;
use crate::bsdf::{Material, MaterialKind, TransportMode, dielectric};
use crate::integrators::pt::PtState;
use crate::pipeline::{Flow, System};

pub struct ShadeDielectric;

impl System<PtState> for ShadeDielectric {
    fn name(&self) -> &'static str {
        "shade_dielectric"
    }
    fn reads(&self) -> &'static [&'static str] {
        &["hits", "surfaces", "rays.dir", "paths", "material_ranges"]
    }
    fn writes(&self) -> &'static [&'static str] {
        &["rays", "paths"]
    }
    fn run(&self, s: &mut PtState) -> Flow {
        let range = s.ranges.of(MaterialKind::Dielectric);
        scatter_paths(s, range, |surf, u| match surf.material {
            Material::Dielectric { ior } => Some(dielectric::sample(
                ior,
                surf.wo_local,
                u.x,
                TransportMode::Radiance,
            )),
            _ => None,
        })
    }
}
