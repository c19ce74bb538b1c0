//! Looks up the textures of the materials the paths hit, once per hit, into a column that
//! light sampling and shading read (both need the material at the same point). Only the graphs
//! of scenes with textured materials hold this system: without it, those systems read each
//! material as the scene lists it and run no texture code.

use crate::bsdf::Material;
use crate::components::{CHUNK, Surfaces};
use crate::geometry::SurfacePoint;
use crate::pipeline::Flow;
use crate::scene::{BLACK, SceneData};
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
        materials.clear();
        materials.resize(live, BLACK);
        materials
            .par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, chunk)| {
                let start = c * CHUNK;
                let surfaces = surfaces.view(start..start + chunk.len());
                for (i, material) in chunk.iter_mut().enumerate() {
                    let point = SurfacePoint {
                        p: surfaces.p[i],
                        p_error: surfaces.p_error[i],
                        ng: surfaces.ng[i],
                        ns: surfaces.ns[i],
                    };
                    let slot = start + i;
                    *material = material_looked_up(data, triangles[slot], &point, dirs[slot]);
                }
            });
        Flow::new(live, live)
    }
}
