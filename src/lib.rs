//! stagelight: a data-oriented, ECS-style wavefront CPU renderer.
//!
//! The engine (`src/`) knows no particular system: it offers the pipeline (systems, graphs, the
//! scheduler), the structure-of-arrays components, the scene and its preparation, BSDFs,
//! sampling, the acceleration structure and the film. The systems themselves live in
//! `systems/`, one file per system, grouped by stage; each integrator in `src/integrators/`
//! declares its graph of systems in one place.

pub mod accel;
pub mod bsdf;
pub mod cli;
pub mod commands;
pub mod compare;
pub mod components;
pub mod cpu;
pub mod film;
pub mod geometry;
pub mod integrators;
pub mod lanes;
pub mod math;
pub mod metrics;
pub mod mlt;
pub mod npy;
pub mod path;
pub mod photons;
pub mod pipeline;
pub mod reference;
pub mod report;
pub mod sampling;
pub mod scene;
pub mod sysinfo;
pub mod units;
pub mod viewer;
pub mod weight_tails;

#[path = "../systems/mod.rs"]
pub mod systems;
