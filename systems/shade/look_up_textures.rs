//! Looks up the textures of the materials the paths hit, once per hit, into a column that
//! light sampling and shading read (both need the material at the same point). Only the graphs
//! of scenes with textured materials hold this system: without it, those systems read each
//! material as the scene lists it and run no texture code.

use crate::bsdf::Material;
use crate::components::Surfaces;
use crate::geometry::SurfacePoint;
use crate::pipeline::Flow;
use crate::scene::SceneData;
use crate::systems::shade::material_looked_up;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct LookUpTextures;

crate::system! {
    LookUpTextures = "look_up_textures";
    read data: Arc<SceneData>, triangles: Vec<u32>, dirs: Vec<Vec3>, surfaces: Surfaces,
        live: usize;
    write materials: Vec<Material>;
    run {
        let live = *live;
        // Written in slot order, whatever the thread count (an indexed parallel extend).
        materials.clear();
        materials.par_extend((0..live).into_par_iter().map(|slot| {
            let point = SurfacePoint {
                p: surfaces.p[slot],
                p_error: surfaces.p_error[slot],
                ng: surfaces.ng[slot],
                ns: surfaces.ns[slot],
            };
            material_looked_up(data, triangles[slot], &point, dirs[slot])
        }));
        Flow::new(live, live)
    }
}
