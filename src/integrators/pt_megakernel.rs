//! The path tracer as a megakernel (`--integrator pt --kernel megakernel`): the comparison
//! the project exists for. Each thread carries one path at a time from the camera to its end
//! (`systems/trace/paths.rs`) with the wavefront PT's own per-path steps, sampler streams and
//! film, so it renders the same image bit for bit; what differs is only how the work is laid
//! out: no queues, no sorting or compaction, one path's state in registers instead of 2^18
//! paths' in memory.
//!
//! Waves stay, as the film's batches: a wave's samples are rendered in parallel chunks and
//! their radiance added to the film in one pass, as the wavefront does.

use crate::components::path_tracing::{PtSettings, WAVEFRONT};
use crate::film::{Film, Image};
use crate::integrators::driver::WaveState;
use crate::integrators::{IntegratorState, SceneData, Wave};
use crate::pipeline::{Graph, Node};
use crate::sampling::Sampler;
use crate::systems::gather::film::AccumulateFilm;
use crate::systems::trace::paths::{RayCounts, TracePaths};
use glam::Vec3;
use std::sync::Arc;

/// The megakernel's state: the wave, each of its samples' radiance, the film.
pub struct MegakernelState {
    pub data: Arc<SceneData>,
    pub settings: PtSettings,
    pub sampler: Sampler<'static>,
    pub pixels: u64,
    pub wave: Wave,
    /// Radiance of each sample of the wave.
    pub sample_radiance: Vec<Vec3>,
    pub film: Film,
    /// Rays traced so far.
    pub traced: RayCounts,
}

impl IntegratorState for MegakernelState {
    type Settings = PtSettings;
    const INPUTS: &'static [&'static str] = &["data", "settings", "sampler", "pixels", "wave"];
    fn graph(_: &SceneData, _: &PtSettings) -> Graph<MegakernelState> {
        Graph::new(
            "pt_megakernel",
            vec![Node::system(TracePaths), Node::system(AccumulateFilm)],
        )
    }
}

impl WaveState for MegakernelState {
    /// The same waves as the wavefront PT's: here they only batch the film's additions.
    const WAVEFRONT: usize = WAVEFRONT;
    fn new(data: Arc<SceneData>, settings: PtSettings, capacity: usize) -> MegakernelState {
        let cam = data.scene.camera;
        MegakernelState {
            sampler: Sampler::new(
                settings.sampler,
                settings.seed,
                cam.crop.film_width,
                cam.crop.film_height,
            ),
            pixels: cam.width as u64 * cam.height as u64,
            film: if settings.moments {
                Film::for_scene(&data).with_moments()
            } else {
                Film::for_scene(&data)
            },
            data,
            settings,
            wave: Wave::default(),
            sample_radiance: vec![Vec3::ZERO; capacity],
            traced: RayCounts::default(),
        }
    }
    fn begin_wave(&mut self, wave: Wave) {
        self.wave = wave;
    }
    fn film_mut(&mut self) -> &mut Film {
        &mut self.film
    }
    /// A sample of the wave keeps only its radiance (12 bytes); the paths in flight are one
    /// per thread, on its stack.
    fn finish(self, _: u64) -> (Film, Vec<(String, Image)>, usize) {
        (self.film, Vec::new(), std::mem::size_of::<Vec3>())
    }
    fn counted_rays(&self) -> Option<(u64, u64)> {
        Some((self.traced.closest, self.traced.shadow))
    }
    fn absorb(&mut self, other: MegakernelState) -> Result<(), String> {
        self.film.add_film(&other.film)?;
        self.traced.closest += other.traced.closest;
        self.traced.shadow += other.traced.shadow;
        Ok(())
    }
    fn notes(&self) -> Vec<(&'static str, String)> {
        vec![(
            "kernel",
            "megakernel: one path in flight per thread; the memory line counts the wave's \
             radiance (12 bytes a sample)"
                .to_string(),
        )]
    }
}

/// The systems of its graphs bound to the columns of `MegakernelState`.
mod bindings {
    use super::MegakernelState;
    use crate::systems::*;

    crate::bind! {
        MegakernelState:
        gather::film::AccumulateFilm {
            read sample_radiance, wave, pixels, camera = data.scene.camera, sampler;
            write film;
        }
        trace::paths::TracePaths {
            read data, settings, sampler, wave, pixels;
            write sample_radiance, traced;
        }
    }
}
