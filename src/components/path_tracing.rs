//! What the systems of path tracing share: the settings, the random-number dimensions of a
//! bounce, the material ranges of a sorted wave and the scratch stores of sorting.
//! `crate::integrators::pt` assembles them into its state.

use crate::bsdf::MaterialKind;
use crate::components::{Hits, Paths, Rays};
use crate::lanes::LaneWidth;
use crate::sampling::SamplerKind;
use std::ops::Range;

/// Random-number dimensions: two for the pixel jitter, then `DIMS_PER_BOUNCE` per bounce.
pub const DIM_PIXEL: u32 = 0;
pub const DIMS_PER_BOUNCE: u32 = 6;
/// Offsets within a bounce's dimensions.
pub const DIM_LIGHT_PICK: u32 = 0;
pub const DIM_LIGHT_POINT: u32 = 1;
pub const DIM_BSDF: u32 = 3;
pub const DIM_ROULETTE: u32 = 5;

/// First random dimension of bounce `depth`.
#[inline]
pub fn bounce_dim(depth: u32) -> u32 {
    2 + depth * DIMS_PER_BOUNCE
}

/// The most paths in flight at once by default (the wavefront's and the megakernel's waves;
/// `--wavefront N` sets another): a few tens of megabytes.
pub const WAVEFRONT: usize = 1 << 18;

/// Paths in flight a thread by default, up to `WAVEFRONT` in all: each thread renders waves on a
/// state of its own, and on a Zen 5 at one and two threads these rendered cornell_box, door_ajar
/// and big_1m 1.06-1.18x as fast as 2^18 in all
/// (docs/measurements/2026-12-02-zen5-sitting-and-vec3-permutes.md).
pub const WAVEFRONT_PER_THREAD: usize = 1 << 14;

/// The wavefront's paths in flight a thread on a scene whose tree and triangles take more than
/// `BIG_SCENE_BYTES`: far beyond the last-level cache, so a wave's columns (280 bytes a path)
/// are best small enough to stay in the core's own cache. On the Zen 5 (32 MiB of L3, 1 MiB of
/// L2 a core), against `WAVEFRONT_PER_THREAD`: big_1m (141 MB) 1.11x / 1.12x at one / two
/// threads, big_5m 1.14x / 1.09x; big_100k (19 MB) 1.06x / 0.94x, cornell_box and door_ajar
/// 0.96-1.02x (docs/measurements/2026-12-02-material-index-and-huge-columns.md).
pub const BIG_SCENE_WAVEFRONT_PER_THREAD: usize = 1 << 12;

/// See `BIG_SCENE_WAVEFRONT_PER_THREAD`: between big_100k's 19 MB and big_1m's 141 MB, twice
/// the measured machines' last-level cache.
pub const BIG_SCENE_BYTES: usize = 64 << 20;

/// PT's wavefront's paths in flight where `--wavefront` is not given, for a scene whose tree and
/// triangles take `scene_bytes`: `WAVEFRONT_PER_THREAD` (or `BIG_SCENE_WAVEFRONT_PER_THREAD`)
/// for each thread of the current pool, at most `WAVEFRONT`. The image does not depend on it.
pub fn default_wavefront(scene_bytes: usize) -> usize {
    let per_thread = if scene_bytes > BIG_SCENE_BYTES {
        BIG_SCENE_WAVEFRONT_PER_THREAD
    } else {
        WAVEFRONT_PER_THREAD
    };
    crate::integrators::driver::waves_for_threads(per_thread, WAVEFRONT)
}

/// The megakernel's paths in flight where `--wavefront` is not given: `WAVEFRONT_PER_THREAD`
/// for each thread, at most `WAVEFRONT`, whatever the scene (it is the control the wavefront is
/// measured against).
pub fn default_megakernel_wave() -> usize {
    crate::integrators::driver::waves_for_threads(WAVEFRONT_PER_THREAD, WAVEFRONT)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PtSettings {
    pub seed: u64,
    pub sampler: SamplerKind,
    /// Maximum number of scattering events; `u32::MAX` for unlimited.
    pub max_depth: u32,
    /// Paths the lane systems take at a time (`--lanes`); the image is the same.
    pub lanes: LaneWidth,
    /// The film also sums each pixel's sample squares (`Film::variance_image`).
    pub moments: bool,
}

impl PtSettings {
    /// Independent samples, `seed`, at most `max_depth` bounces, lanes as wide as the CPU's.
    pub fn new(seed: u64, max_depth: u32) -> PtSettings {
        PtSettings {
            seed,
            sampler: SamplerKind::Independent,
            max_depth,
            lanes: LaneWidth::widest(),
            moments: false,
        }
    }
}

/// Slots of each material kind after `sort_by_material`, in `MaterialKind` order: non-delta
/// kinds first, so light sampling runs over one contiguous range.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MaterialRanges {
    ends: [usize; MaterialKind::COUNT],
}

impl MaterialRanges {
    /// The ranges of queues holding `counts[kind]` slots each, one after the other.
    pub fn from_counts(counts: &[usize]) -> MaterialRanges {
        let mut ends = [0; MaterialKind::COUNT];
        let mut end = 0;
        for (e, c) in ends.iter_mut().zip(counts) {
            end += c;
            *e = end;
        }
        MaterialRanges { ends }
    }

    pub fn of(&self, kind: MaterialKind) -> Range<usize> {
        let k = kind as usize;
        let start = if k == 0 { 0 } else { self.ends[k - 1] };
        start..self.ends[k]
    }

    /// Slots whose material can be reached by light sampling.
    pub fn non_delta(&self) -> Range<usize> {
        let last = MaterialKind::ALL
            .iter()
            .rfind(|k| !k.is_delta())
            .expect("a non-delta kind");
        0..self.of(*last).end
    }
}

/// The material queues and the dropped paths of `sort_by_material`.
pub const QUEUES: usize = MaterialKind::COUNT + 1;

#[derive(Default)]
pub struct Scratch {
    pub rays: Rays,
    pub hits: Hits,
    pub paths: Paths,
    pub order: Vec<u32>,
    /// Queue of each slot, for sorting.
    pub queue: Vec<u8>,
    /// Slots per queue (three material kinds, then the ended paths) in each chunk, for sorting.
    pub chunk_counts: Vec<[usize; QUEUES]>,
}
