//! Integrators: one file each, with its graph of systems and its parameters.

pub mod bdpt;
pub mod pt;

use crate::accel::Accel;
use crate::scene::PreparedScene;

/// A prepared scene with its acceleration structure: everything systems read while rendering.
pub struct SceneData {
    pub scene: PreparedScene,
    pub accel: Accel,
}

impl SceneData {
    pub fn new(scene: PreparedScene) -> SceneData {
        let accel = Accel::build(&scene.triangles);
        SceneData { scene, accel }
    }
}

use crate::film::Film;
use crate::pipeline::Stats;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long a render runs: samples per pixel, or wall seconds (whole passes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    SamplesPerPixel(u64),
    Seconds(f64),
}

/// What a render produced.
pub struct RenderOutcome {
    pub film: Film,
    pub stats: Stats,
    /// Completed passes (one sample in every pixel each).
    pub passes: u64,
    pub samples: u64,
    pub wall: Duration,
    pub interrupted: bool,
    /// Systems of the graph, in order.
    pub systems: Vec<&'static str>,
    pub bytes_per_path: usize,
    pub wavefront: usize,
}

impl RenderOutcome {
    pub fn closest_rays(&self) -> u64 {
        self.stats.get("trace_closest").map_or(0, |s| s.taken)
    }
    pub fn shadow_rays(&self) -> u64 {
        self.stats.get("trace_shadow").map_or(0, |s| s.taken)
    }
}

/// Progress callbacks and the stop flag of a render.
pub struct Control<'a> {
    /// Set (e.g. by Ctrl-C) to stop after the passes in flight.
    pub stop: &'a AtomicBool,
    /// Called after each wave with (passes done, total passes if known).
    pub progress: &'a (dyn Fn(u64, Option<u64>) + Sync),
}

impl Control<'_> {
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Plans waves over the global sample ids: whole passes per wave when a pass fits in the
/// wavefront, else a pass split into wavefront-sized waves. Stops only at pass boundaries.
pub(crate) struct WavePlan {
    pub pixels: u64,
    pub wave_len: u64,
    pub total: Option<u64>,
    pub next: u64,
    start: Instant,
    budget: Budget,
}

impl WavePlan {
    pub fn new(pixels: u64, budget: Budget, wavefront: usize) -> WavePlan {
        let wave_len = if pixels <= wavefront as u64 {
            (wavefront as u64 / pixels) * pixels
        } else {
            wavefront as u64
        };
        let total = match budget {
            Budget::SamplesPerPixel(spp) => Some(spp * pixels),
            Budget::Seconds(_) => None,
        };
        let wave_len = total.map_or(wave_len, |t| wave_len.min(t));
        WavePlan {
            pixels,
            wave_len,
            total,
            next: 0,
            start: Instant::now(),
            budget,
        }
    }

    /// Slots the state needs.
    pub fn capacity(&self) -> usize {
        self.wave_len as usize
    }

    /// The next wave (first sample id, length), or None when the budget is spent or a stop
    /// was asked for at a pass boundary.
    pub fn next_wave(&mut self, control: &Control) -> Option<(u64, usize)> {
        let at_pass_boundary = self.next.is_multiple_of(self.pixels);
        if at_pass_boundary {
            if control.stopped() {
                return None;
            }
            if let Budget::Seconds(s) = self.budget
                && self.start.elapsed().as_secs_f64() >= s
            {
                return None;
            }
        }
        let mut len = self.wave_len;
        if let Some(total) = self.total {
            if self.next >= total {
                return None;
            }
            len = len.min(total - self.next);
        }
        // A wave never crosses a pass boundary in the middle of a split pass.
        if self.wave_len < self.pixels {
            len = len.min(self.pixels - self.next % self.pixels);
        }
        let first = self.next;
        self.next += len;
        Some((first, len as usize))
    }

    /// True when a sample budget has been rendered in full (a time budget never is: it ends
    /// when the time is up).
    pub fn budget_spent(&self) -> bool {
        self.total.is_some_and(|t| self.next >= t)
    }

    pub fn passes_done(&self) -> u64 {
        self.next / self.pixels
    }

    pub fn total_passes(&self) -> Option<u64> {
        self.total.map(|t| t / self.pixels)
    }

    pub fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}
