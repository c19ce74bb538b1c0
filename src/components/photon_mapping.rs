//! What the systems of photon mapping share: the settings of PM, PPM and SPPM.
//! `crate::integrators::{pm, sppm}` assemble them into their states.

use crate::sampling::SamplerKind;
use crate::scene::SceneData;

/// Default photons traced.
pub const DEFAULT_PHOTONS: u64 = 250_000;
/// Default photons per density estimate.
pub const DEFAULT_K: usize = 50;
/// Default largest search radius, as a fraction of the scene's bounding-box diagonal.
pub const DEFAULT_MAX_RADIUS_FRACTION: f32 = 0.02;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PmSettings {
    pub seed: u64,
    pub sampler: SamplerKind,
    pub max_depth: u32,
    pub photons: u64,
    /// Photons per density estimate, at least 2 (the k - 1 nearest over the k-th's disc).
    pub k: usize,
    /// Largest search radius in scene units (`None`: `DEFAULT_MAX_RADIUS_FRACTION` of the
    /// scene diagonal).
    pub max_radius: Option<f32>,
    pub final_gather: bool,
}

impl PmSettings {
    pub fn new(seed: u64) -> PmSettings {
        PmSettings {
            seed,
            sampler: SamplerKind::Independent,
            max_depth: u32::MAX,
            photons: DEFAULT_PHOTONS,
            k: DEFAULT_K,
            max_radius: None,
            final_gather: true,
        }
    }

    pub fn max_radius_in(&self, data: &SceneData) -> f32 {
        self.max_radius.unwrap_or_else(|| {
            let s = &data.scene;
            DEFAULT_MAX_RADIUS_FRACTION * (s.bounds_max - s.bounds_min).length()
        })
    }
}

/// Default photons per pass.
pub const DEFAULT_PHOTONS_PER_PASS: u64 = 250_000;
/// Default alpha: the fraction of new photons a pass keeps.
pub const DEFAULT_ALPHA: f32 = 0.7;
/// SPPM's initial radius, as a fraction of the scene's bounding-box diagonal, where the camera
/// sees nothing (no pixel footprint). Of 0.25%, 0.5%, 1% and 2%, 1% had the least relMSE over
/// cornell_box, torus_glass and door_ajar at 10 s (docs/photons/README.md).
pub const SPPM_RADIUS_FRACTION: f32 = 0.01;
/// PPM's, likewise (its torus_glass curves in docs/photons/README.md are at 0.5%).
pub const PPM_RADIUS_FRACTION: f32 = 0.005;
/// SPPM's default initial radius in pixel footprints (`pixel_footprint`): 1% of the diagonal
/// is 3.2, 5.0 and 11 footprints on cornell_box, door_ajar and torus_glass at 256 x 256, and
/// this is their geometric mean, so those scenes keep about the radius measured best (not
/// re-measured), while a scene with one huge triangle no longer gets a huge radius.
pub const SPPM_RADIUS_PIXELS: f32 = 5.6;
/// PPM's: 0.5% of the diagonal is 1.6, 2.5 and 5.5 footprints there.
pub const PPM_RADIUS_PIXELS: f32 = 2.8;
/// Default eye-ray trees per pixel of PPM.
pub const DEFAULT_EYE_RAYS: u32 = 16;

/// The settings of PPM and SPPM.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProgressiveSettings {
    pub seed: u64,
    pub sampler: SamplerKind,
    /// Maximum number of scattering events of camera chains and photons; `u32::MAX` for
    /// unlimited.
    pub max_depth: u32,
    pub photons_per_pass: u64,
    pub alpha: f32,
    /// Initial gather radius in scene units (`None`: `ProgressiveSettings::radius_in`).
    pub initial_radius: Option<f32>,
    /// SPPM (true): new visible points every pass. PPM (false): pass 0's, kept.
    pub stochastic: bool,
    /// PPM: eye-ray trees per pixel, jittered over it (stratified).
    pub eye_rays: u32,
}

impl ProgressiveSettings {
    pub fn new(seed: u64, stochastic: bool) -> ProgressiveSettings {
        ProgressiveSettings {
            seed,
            sampler: SamplerKind::Independent,
            max_depth: u32::MAX,
            photons_per_pass: DEFAULT_PHOTONS_PER_PASS,
            alpha: DEFAULT_ALPHA,
            initial_radius: None,
            stochastic,
            eye_rays: DEFAULT_EYE_RAYS,
        }
    }

    /// The initial radius in `scene`: `SPPM_RADIUS_PIXELS` or `PPM_RADIUS_PIXELS` pixel
    /// footprints, or where the camera sees nothing a fraction of the scene's diagonal.
    pub fn radius_in(&self, data: &SceneData) -> f32 {
        self.initial_radius.unwrap_or_else(|| {
            let (pixels, fraction) = if self.stochastic {
                (SPPM_RADIUS_PIXELS, SPPM_RADIUS_FRACTION)
            } else {
                (PPM_RADIUS_PIXELS, PPM_RADIUS_FRACTION)
            };
            pixel_footprint(data).map_or_else(
                || {
                    let s = &data.scene;
                    fraction * (s.bounds_max - s.bounds_min).length()
                },
                |footprint| pixels * footprint,
            )
        })
    }
}

/// Camera rays, a grid of this many per side over the image, whose first hits give the
/// pixel footprint.
const FOOTPRINT_RAYS_PER_SIDE: u32 = 32;

/// The width of one pixel where the camera sees the scene: the median over a grid of camera
/// rays of the distance to the first hit times a pixel's angular size (the image plane at
/// distance 1 is `2 tan(fov/2)` tall over `height` pixels). None when no ray hits anything.
/// Unlike a fraction of the scene's bounds, it does not grow with geometry the camera barely
/// sees (one huge ground triangle).
pub fn pixel_footprint(data: &SceneData) -> Option<f32> {
    let frustum = data.scene.camera.frustum();
    if let crate::scene::Projection::Orthographic { half_height, .. } = frustum.projection {
        // Parallel rays: a pixel is as wide at every distance (the near plane's height over
        // the film's rows).
        return Some(2.0 * half_height / frustum.film_height as f32);
    }
    let (w, h) = (frustum.width as f32, frustum.height as f32);
    let n = FOOTPRINT_RAYS_PER_SIDE;
    let mut distances: Vec<f32> = (0..n * n)
        .filter_map(|i| {
            let raster = glam::Vec2::new(
                ((i % n) as f32 + 0.5) / n as f32 * w,
                ((i / n) as f32 + 0.5) / n as f32 * h,
            );
            let dir = frustum.direction(raster);
            let hit = data
                .accel
                .closest_hit(frustum.position, dir, f32::INFINITY)?;
            (hit.t.is_finite() && hit.t > 0.0).then(|| hit.t * dir.length())
        })
        .collect();
    if distances.is_empty() {
        return None;
    }
    distances.sort_by(f32::total_cmp);
    let median = distances[distances.len() / 2];
    Some(median * 2.0 * frustum.tan_half / h)
}
