//! Adds the light of emitters that paths hit, weighted by multiple importance sampling against
//! the light sampling that could also have found them.

use crate::components::{MISS, PathFlags};
use crate::geometry::surface_point;
use crate::integrators::pt::PtState;
use crate::pipeline::Flow;
use crate::sampling::power_heuristic;
use crate::scene::NO_EMITTER;
use rayon::prelude::*;

pub struct AddEmittedLight;

crate::system! {
    AddEmittedLight = "add_emitted_light";
    on PtState {
        read data, hits, rays, live = active;
        write paths;
    }
    run {
        let emitters = &data.scene.emitters;
        let tris = &data.scene.triangles;
        let found: usize = paths
            .chunks_mut(0..*live)
            .into_par_iter()
            .map(|p| {
                let mut found = 0;
                let range = p.start..p.start + p.len();
                let (hits, rays) = (hits.view(range.clone()), rays.view(range));
                for i in 0..p.len() {
                    let tri = hits.triangle[i];
                    if tri == MISS {
                        continue;
                    }
                    let e = tris.emitter[tri as usize];
                    if e == NO_EMITTER {
                        continue;
                    }
                    let sp = surface_point(tris, tri, hits.b1[i], hits.b2[i]);
                    let cos_light = -rays.dir[i].dot(sp.ng);
                    if cos_light <= 0.0 {
                        continue; // emitters are one-sided
                    }
                    found += 1;
                    let le = emitters.radiance[e as usize];
                    let weight = if p.flags[i].has(PathFlags::SPECULAR) {
                        1.0
                    } else {
                        let t = hits.t[i];
                        let light_pdf =
                            emitters.pmf[e as usize] / emitters.area[e as usize] * t * t
                                / cos_light;
                        power_heuristic(p.bsdf_pdf[i], light_pdf)
                    };
                    p.radiance[i] += p.throughput[i] * le * weight;
                }
                found
            })
            .sum();
        Flow::new(*live, found)
    }
}
