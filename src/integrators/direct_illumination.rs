//! Renders direct illumination (paths of depth 0 and 1: emitters seen, and light reaching the
//! first surface straight from an emitter) apart, by path tracing, for the Metropolis
//! integrators that leave it out of their chains, as Veach's MLT and Mitsuba's `mlt` and
//! `pssmlt` do: path-space mlt at Mitsuba's 16 samples per pixel before the chains, pssmlt and
//! mmlt one sample per pixel more per mutation per pixel the chains take (checked at each
//! pass's start), so that it keeps pace with them under any budget (`DirectIllumination`,
//! `--direct-spp`).
//!
//! Why apart: the chains spend their mutations on indirect light, and light that few paths of
//! depth 1 carry (a small light seen in a mirror or a glass ball) is estimated in every pixel
//! it lights instead of by how often an independent sample of the chains happens on it (issue
//! 42: a light's reflection in a glass sphere that one full BDPT sample in 1e5 finds).
//!
//! It is a system of the Metropolis graphs, but it lives with the integrators: it runs a whole
//! path tracing render (PT's state and driver), which systems/ may not name.

use crate::components::metropolis::DirectIllumination;
use crate::film::{Film, Image};
use crate::integrators::pt::PtSettings;
use crate::integrators::{Budget, Control, Resume, SceneData};
use crate::pipeline::Flow;
use glam::DVec3;
use std::sync::Arc;

pub struct RenderDirectIllumination;

crate::system! {
    RenderDirectIllumination = "render_direct_illumination";
    read data: Arc<SceneData>, seed: u64, schedule: DirectIllumination, mutations: u64,
        pixels: u64;
    write direct: Option<Film>;
    run {
        let want = schedule.samples_after(*mutations, *pixels);
        let pt = path_tracing_settings(*seed);
        // Samples are pure functions of their ids: going on from the film's passes gives the
        // image one render of `want` samples per pixel would.
        let from = direct.take().map(|film| {
            let passes = held(Some(&film));
            Resume { film, first_pass: 0, passes, state: None }
        });
        let outcome = crate::integrators::driver::render_waves_of::<crate::integrators::pt::PtState>(
            data.clone(),
            pt,
            Budget::SamplesPerPixel(want),
            &Control {
                stop: &std::sync::atomic::AtomicBool::new(false),
                progress: &|_, _| {},
            },
            from,
            crate::integrators::pt::default_wavefront(data.geometry_bytes()),
        );
        let n = outcome.film.width * outcome.film.height;
        *direct = Some(outcome.film);
        Flow::new(n, n)
    }
}

/// The path tracer that renders a Metropolis render's direct image for `seed`: depth 1 and
/// its own numbers, apart from the chains'.
pub fn path_tracing_settings(seed: u64) -> PtSettings {
    PtSettings {
        max_depth: 1,
        ..PtSettings::new(crate::sampling::mix64(seed ^ DIRECT_DOMAIN), 1)
    }
}

/// Samples per pixel the direct image holds.
pub fn held(direct: Option<&Film>) -> u64 {
    direct.map_or(0, |film| {
        film.total_samples() / (film.width * film.height).max(1) as u64
    })
}

/// The report's line on where direct illumination comes from.
pub fn report_line(schedule: DirectIllumination, direct: Option<&Film>) -> String {
    if schedule.apart() {
        format!("{} spp of path tracing, added", held(direct))
    } else {
        "in the chains".into()
    }
}

/// Whether the direct image needs more samples by `schedule` after `mutations` steps of the
/// chains over `pixels` pixels.
pub fn due(
    schedule: DirectIllumination,
    mutations: u64,
    pixels: u64,
    direct: Option<&Film>,
) -> bool {
    schedule.samples_after(mutations, pixels) > held(direct)
}

/// Separates the direct image's numbers from the chains'.
const DIRECT_DOMAIN: u64 = 0x6469_7265_6374_5f6c;

/// Adds the direct image, when there is one, to the chains' developed pixel sums; returns its
/// count of non-finite values.
pub fn add_direct_image(sums: &mut [DVec3], direct: Option<&Film>) -> u64 {
    let Some(direct) = direct else { return 0 };
    let image: Image = direct.image();
    for (s, v) in sums.iter_mut().zip(&image.pixels) {
        *s += v.as_dvec3();
    }
    direct.nonfinite
}
