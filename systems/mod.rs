//! Systems, one file per system, grouped by stage. A system declares the columns it reads and
//! writes by type, never an integrator's state: a state runs it once `bind!` maps those
//! columns to its fields, and an integrator's graph (`src/integrators/`) names it.

/// Making new work: camera rays (and later light paths and photons).
pub mod generate {
    pub mod camera_chains;
    pub mod camera_rays;
    pub mod final_gather_rays;
    pub mod photons;
    pub mod subpaths;
}

/// Ray casting against the scene.
pub mod trace {
    pub mod closest;
    pub mod paths;
    pub mod record_rays;
    pub mod shadow;
}

/// What happens at a surface: emission found, queues by material, scattering, roulette.
pub mod shade {
    pub mod compact_camera_chains;
    pub mod compact_photons;
    pub mod compact_subpaths;
    pub mod emitted_light;
    pub mod extend_camera_chains;
    pub mod extend_subpaths;
    pub mod lanes;
    pub mod look_up_textures;
    pub mod material;
    pub mod order_hit_points;
    pub mod russian_roulette;
    pub mod scatter_photons;
    pub mod sort_by_material;
    mod surface;
    pub use surface::{Scattered, Surface, material_looked_up, scatter};
}

/// Joining paths to lights: light sampling and the shadow rays' contributions.
pub mod connect {
    pub mod apply_shadow;
    pub mod cached_strategies;
    pub mod cached_weights;
    pub mod light_vertex_cache;
    pub mod sample_direct_light;
    pub mod sample_lights;
    pub mod strategies;
    pub mod weights;
}

/// Metropolis chains: the bootstrap and its seeds, proposals, acceptance and splats; for
/// path-space MLT the mutations, one file each, and their acceptance.
pub mod mutate {
    pub mod accept;
    pub mod bidirectional;
    pub mod bootstrap;
    pub mod caustic_perturbation;
    pub mod lens_perturbation;
    pub mod multichain_perturbation;
    pub mod path_accept;
    pub mod path_mutation;
    pub mod path_seeds;
    pub mod propose;
}

/// Collecting finished work into the film.
pub mod gather {
    pub mod caustic_photons;
    pub mod chain_contributions;
    pub mod connections;
    pub mod direct_light;
    pub mod film;
    pub mod global_photons;
    pub mod glossy_light;
    pub mod light_vertex_grid;
    pub mod merges;
    pub mod pass_film;
    pub mod photon_grid;
    pub mod photon_maps;
    pub mod progressive_update;
    pub mod visible_point_photons;
}
