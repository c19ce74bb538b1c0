//! What the systems of bidirectional path tracing share: the settings, the random-number
//! dimensions of subpath vertices and connections, where a sample's numbers come from, the
//! light-vertex cache and the scratch stores of compaction. `crate::integrators::bdpt`
//! assembles them into its state; the MLT integrators hold that state in turn.

use crate::components::{Rays, Walkers, Wave};
use crate::path::{Joint, MisHeuristic, PathContext, Techniques, Vertex};
use crate::photons::HashGrid;
use crate::sampling::{PrimarySamples, SampleKey, Sampler, SamplerKind, Stream};
use crate::weight_tails::MergedLight;
use glam::Vec3;

/// Samples in flight at most by default (vcm's and bpm's waves; bdpt's are smaller, see
/// `WAVEFRONT_PER_THREAD`). Each holds two subpaths and their connections, about ten times a
/// path tracer's state, so the wave is smaller than PT's.
pub const WAVEFRONT: usize = 1 << 15;

/// BDPT's samples in flight a thread by default (`WAVEFRONT` at most in all; each thread
/// renders whole waves of this many). A sample's subpaths and connections take about 5 KB, so
/// a thread's wave stays in its caches from one system to the next. Against `WAVEFRONT` in all,
/// on an AMD EPYC (Zen 5) at one / two threads, medians of three alternated rounds: cornell_box
/// 1.11x / 1.05x, door_ajar 1.18x / 1.28x, torus_glass 1.73x / 1.23x
/// (docs/measurements/2026-12-03-bdpt-wave-size.md).
pub const WAVEFRONT_PER_THREAD: usize = 1 << 10;

/// BDPT's samples in flight where `--wavefront` is not given: `WAVEFRONT_PER_THREAD` for each
/// thread of the current pool, at most `WAVEFRONT`, where the image does not depend on it;
/// through a light-vertex cache, whose groups are counted from each wave's start (so the image
/// does depend on the waves), `WAVEFRONT` whatever the thread count.
pub fn default_wavefront(settings: &BdptSettings) -> usize {
    if settings.light_vertex_cache > 0 {
        return WAVEFRONT;
    }
    crate::integrators::driver::waves_for_threads(WAVEFRONT_PER_THREAD, WAVEFRONT)
}

/// Samples per chunk of the connection work (much heavier per item than a bounce).
pub const CONNECT_CHUNK: usize = 64;

/// Random-number dimensions of a camera subpath: the pixel jitter, then per vertex z_d
/// (d >= 1) `CAMERA_DIMS_PER_VERTEX` numbers: BSDF sample (2), roulette (1), and the light
/// sample of strategy s = 1 joined at z_d (pick 1, point 2).
pub const CAMERA_DIM_PIXEL: u32 = 0;
pub const CAMERA_DIMS_PER_VERTEX: u32 = 6;
pub const DIM_BSDF: u32 = 0;
pub const DIM_ROULETTE: u32 = 2;
pub const DIM_LIGHT_PICK: u32 = 3;
pub const DIM_LIGHT_POINT: u32 = 4;

/// Light subpaths draw from their own stream: emitter pick (1), point (2), direction (2),
/// then per vertex y_d (d >= 1) a BSDF sample (2) and roulette (1).
pub const LIGHT_DIM_PICK: u32 = 0;
pub const LIGHT_DIM_POINT: u32 = 1;
pub const LIGHT_DIM_DIRECTION: u32 = 3;
pub const LIGHT_DIMS_PER_VERTEX: u32 = 3;

/// Connection-stream dimensions of camera vertex z_d (from `camera_vertex_dim(d)`) that pick
/// its light-cache vertices: two numbers make one 48-bit uniform (the strategy s = 1 light
/// sample reads the same vertex's `DIM_LIGHT_PICK` and `DIM_LIGHT_POINT`, above these).
pub const DIM_CACHE_PICK: u32 = 0;

/// Connection-stream dimension that picks the strategy s of a multiplexed (MMLT) sample. Only
/// multiplexed samples read it, and they draw from `Numbers::Primary`, where the connection
/// stream has dimensions of its own (under the render's samplers it would be the camera's
/// pixel jitter).
pub const CONNECTION_DIM_STRATEGY: u32 = 0;

/// Connection-stream dimension that picks the depth of a multiplexed sample of the tail group
/// (depth `MULTIPLEX_TAIL_DEPTH` or more).
pub const CONNECTION_DIM_TAIL_DEPTH: u32 = 1;

/// Multiplexed samples (MMLT) have one exact depth per group below this; the last group holds
/// every deeper path, each sample's depth drawn from a geometric distribution (so no depth is
/// left out: no cap but the user's `--max-depth`).
pub const MULTIPLEX_TAIL_DEPTH: u32 = 16;

/// The tail group's depth is `MULTIPLEX_TAIL_DEPTH + j` with probability proportional to
/// this^j: high, so deep paths in closed, bright scenes (light bouncing 30+ times) are drawn
/// often enough (the estimator's variance is finite while the light kept per bounce is below
/// sqrt of this, about 0.95).
pub const MULTIPLEX_TAIL_CONTINUE: f64 = 0.9;

/// The depth of a multiplexed sample of group `group` (its depth, or the tail group
/// `MULTIPLEX_TAIL_DEPTH`), drawn for the tail group from `u` by the truncated geometric
/// distribution over `MULTIPLEX_TAIL_DEPTH..=max_depth`.
#[inline]
pub fn multiplexed_depth(group: u32, u: f32, max_depth: u32) -> u32 {
    if group < MULTIPLEX_TAIL_DEPTH {
        return group;
    }
    let q = MULTIPLEX_TAIL_CONTINUE;
    let mass = 1.0 - tail_beyond(max_depth);
    let j = ((1.0 - u as f64 * mass).ln() / q.ln()).floor().max(0.0);
    (MULTIPLEX_TAIL_DEPTH as f64 + j).min(max_depth as f64) as u32
}

/// q^(J + 1), J = max_depth - MULTIPLEX_TAIL_DEPTH: the geometric mass past `max_depth`.
#[inline]
fn tail_beyond(max_depth: u32) -> f64 {
    let j = max_depth.saturating_sub(MULTIPLEX_TAIL_DEPTH) as f64;
    MULTIPLEX_TAIL_CONTINUE.powf(j + 1.0)
}

/// The factor on a multiplexed sample's MIS-weighted contribution at depth `depth`: its
/// strategy count (depth + 2, one strategy picked uniformly), over the probability of its
/// depth in the tail group (1 below it).
#[inline]
pub fn multiplexed_factor(depth: u32, max_depth: u32) -> f32 {
    let strategies = depth as f64 + 2.0;
    if depth < MULTIPLEX_TAIL_DEPTH {
        return strategies as f32;
    }
    let q = MULTIPLEX_TAIL_CONTINUE;
    let j = (depth - MULTIPLEX_TAIL_DEPTH) as f64;
    let p = (1.0 - q) * q.powf(j) / (1.0 - tail_beyond(max_depth));
    (strategies / p) as f32
}

/// Numbers of one stream a sample draws with every depth up to `max_depth`: the camera
/// stream's last is the roulette number at camera vertex `max_depth`, the connection stream's
/// the light point of s = 1 joined at camera vertex `max_depth`; the light stream's are fewer.
/// Finite for a finite cap: what bounds a primary-sample vector (MLT).
pub fn stream_dims(max_depth: u32) -> u32 {
    (camera_vertex_dim(max_depth.max(1) as usize) + DIM_LIGHT_POINT + 2)
        .max(LIGHT_DIM_DIRECTION + 2)
}

/// Where a BDPT state's numbers come from.
pub enum Numbers {
    /// The render's sampler: sample k of a wave is pixel `(first + k) % pixels` at sample
    /// index `(first + k) / pixels`, its camera ray jittered inside that pixel.
    Render(Sampler<'static>),
    /// A primary-sample vector per slot (MLT): sample k reads slot k of `store` (keys index the
    /// slot), and its raster position is the camera stream's first two numbers over the whole
    /// film.
    Primary {
        store: PrimarySamples,
        fallback_seed: u64,
    },
}

impl Numbers {
    /// The sampler the systems draw with.
    #[inline]
    pub fn sampler(&self) -> Sampler<'_> {
        match self {
            Numbers::Render(s) => *s,
            Numbers::Primary {
                store,
                fallback_seed,
            } => Sampler::Primary {
                store,
                fallback_seed: *fallback_seed,
            },
        }
    }

    #[inline]
    pub fn is_primary(&self) -> bool {
        matches!(self, Numbers::Primary { .. })
    }

    /// The key of `stream` for sample `k` of `wave`.
    #[inline]
    pub fn key(
        &self,
        sampler: &Sampler,
        stream: Stream,
        wave: Wave,
        pixels: u64,
        k: usize,
    ) -> SampleKey {
        match self {
            Numbers::Render(_) => {
                let g = wave.first + k as u64;
                sampler.key(stream, g % pixels, g / pixels)
            }
            Numbers::Primary { .. } => sampler.key(stream, k as u64, 0),
        }
    }
}

/// First dimension of camera vertex `d` (d >= 1).
#[inline]
pub fn camera_vertex_dim(d: usize) -> u32 {
    2 + (d as u32 - 1) * CAMERA_DIMS_PER_VERTEX
}

/// First dimension of light vertex `d` (d >= 1).
#[inline]
pub fn light_vertex_dim(d: usize) -> u32 {
    5 + (d as u32 - 1) * LIGHT_DIMS_PER_VERTEX
}

/// Which strategies count, and how.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StrategyFilter {
    /// Every strategy, MIS-weighted.
    #[default]
    All,
    /// Only the strategies matching `s` and `t` (`None` matches any), unweighted: for
    /// studying (and testing) each estimator alone.
    Only { s: Option<u16>, t: Option<u16> },
}

impl StrategyFilter {
    #[inline]
    pub fn keeps(&self, s: usize, t: usize) -> bool {
        match *self {
            StrategyFilter::All => true,
            StrategyFilter::Only { s: fs, t: ft } => {
                fs.is_none_or(|v| v as usize == s) && ft.is_none_or(|v| v as usize == t)
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BdptSettings {
    pub seed: u64,
    pub sampler: SamplerKind,
    /// Maximum number of scattering events (path vertices between camera and light);
    /// `u32::MAX` for unlimited.
    pub max_depth: u32,
    pub mis: MisHeuristic,
    pub strategies: StrategyFilter,
    /// Keep each strategy's weighted contribution as its own image.
    pub strategy_images: bool,
    /// Paths shallower than this are left out (path-space MLT renders them apart).
    pub min_depth: u32,
    /// Light-vertex cache: each camera vertex joins this many vertices picked from the
    /// wave's cache instead of its own light subpath's (0: plain BDPT).
    pub light_vertex_cache: u32,
    /// Vertex merging (VCM, BPM): camera vertices also merge with the wave's light vertices
    /// within a radius, and every weight counts the merges. None: BDPT.
    pub merging: Option<VertexMerging>,
    /// How many connections `weigh_connections` takes at a time (`--lanes`): every width
    /// gives the same weights.
    pub lanes: crate::lanes::LaneWidth,
}

/// How camera vertices merge with light vertices (`--integrator vcm`, `bpm`).
#[derive(Clone, Copy, Debug)]
pub struct VertexMerging {
    /// The merge radius of the first pass, in scene units.
    pub radius: f32,
    /// The radius of pass i (from 0) is `radius (i + 1)^((alpha - 1) / 2)` (Georgiev et al.
    /// 2012, after Knaus and Zwicker): the merges' bias vanishes while their variance grows
    /// slowly enough for the estimate to converge.
    pub alpha: f32,
    /// Connections (strategies s >= 1) take part; false: bidirectional photon mapping (BPM),
    /// merges and s = 0 only.
    pub connect: bool,
    /// Merges take part; false: connections alone, under VCM's weights (BDPT's estimator).
    pub merge: bool,
}

impl PartialEq for VertexMerging {
    fn eq(&self, other: &Self) -> bool {
        self.radius.to_bits() == other.radius.to_bits()
            && self.alpha.to_bits() == other.alpha.to_bits()
            && self.connect == other.connect
            && self.merge == other.merge
    }
}

impl Eq for VertexMerging {}

impl VertexMerging {
    /// The merge radius of pass `pass`.
    #[inline]
    pub fn radius_at(&self, pass: u64) -> f32 {
        (self.radius as f64 * ((pass + 1) as f64).powf((self.alpha as f64 - 1.0) / 2.0)) as f32
    }
}

/// The light vertices a wave's camera vertices merge with (VCM): every light vertex past the
/// emitter (depth >= 1) that is not delta and carries light, in light-subpath order then depth
/// order, and a hash grid over their positions.
#[derive(Default)]
pub struct LightVertexGrid {
    pub p: Vec<Vec3>,
    /// All else a merge reads of the vertex, beside `p` so merges never visit the subpaths.
    pub vertex: Vec<MergeableVertex>,
    /// Over `p`, for queries up to the largest radius of the wave's passes (None: no vertex).
    pub grid: Option<HashGrid>,
}

/// A light vertex as a merge reads it.
#[derive(Clone, Copy, Debug, Default)]
pub struct MergeableVertex {
    pub ng: Vec3,
    /// Unit direction to the vertex before it on its light subpath.
    pub w_light: Vec3,
    pub beta: Vec3,
    /// Its depth and what the merge's MIS weight reads of its subpath.
    pub weight: MergedLight,
}

impl LightVertexGrid {
    pub fn clear(&mut self) {
        self.p.clear();
        self.vertex.clear();
        self.grid = None;
    }
}

impl BdptSettings {
    pub fn new(seed: u64, max_depth: u32) -> BdptSettings {
        BdptSettings {
            seed,
            sampler: SamplerKind::Independent,
            max_depth,
            mis: MisHeuristic::Power,
            strategies: StrategyFilter::All,
            strategy_images: false,
            min_depth: 0,
            light_vertex_cache: 0,
            merging: None,
            lanes: crate::lanes::LaneWidth::widest(),
        }
    }

    /// Whether the strategies s >= 1 run (all but BPM).
    #[inline]
    pub fn connects(&self) -> bool {
        self.merging.is_none_or(|m| m.connect)
    }

    /// Every strategy within the depth bounds runs (no filter to ask).
    #[inline]
    pub fn all_strategies(&self) -> bool {
        self.strategies == StrategyFilter::All && self.connects()
    }

    /// The techniques the MIS weights of sample `k` of `wave` count: with merging, merges
    /// with the wave's light subpaths within the radius of the sample's pass.
    #[inline]
    pub fn techniques(&self, wave: Wave, k: usize, pixels: u64) -> Techniques {
        match self.merging {
            None => Techniques::CONNECTIONS,
            Some(m) => {
                let merge_count = if m.merge {
                    let r = m.radius_at((wave.first + k as u64) / pixels);
                    std::f32::consts::PI * r * r * wave.len as f32
                } else {
                    0.0
                };
                Techniques {
                    connect: m.connect,
                    merge_count,
                    connection_count: 1.0,
                }
            }
        }
    }

    /// Highest vertex index a camera subpath (false) or light subpath (true) may reach: a
    /// path of depth D has D + 2 vertices, at least one on each side.
    #[inline]
    pub fn last_vertex(&self, light: bool) -> usize {
        let d = self.max_depth as usize;
        if light { d } else { d.saturating_add(1) }
    }

    /// The s of the strategies (s, t) within the depth bounds for t camera vertices and at
    /// most `nl` light vertices: those `uses` keeps before the strategy filter.
    #[inline]
    pub fn light_vertices(&self, t: usize, nl: usize) -> std::ops::Range<usize> {
        // s + t >= 2 and min_depth <= s + t - 2 <= max_depth.
        let first = (self.min_depth as usize + 2).max(2).saturating_sub(t);
        let Some(last) = (self.max_depth as usize + 2).checked_sub(t) else {
            return 0..0;
        };
        if t == 0 {
            return 0..0;
        }
        first..last.min(nl) + 1
    }

    /// Whether the light-vertex cache may join some light vertex to camera vertex z_{t-1}:
    /// a strategy (s >= 2, t) is within the depth bounds (its picks past them are wasted).
    #[inline]
    pub fn joins_cache(&self, t: usize) -> bool {
        let s = self.light_vertices(t, usize::MAX);
        self.light_vertex_cache > 0 && t >= 2 && s.end > s.start.max(2)
    }

    /// Whether strategy (s, t) may contribute: a camera vertex, at least two vertices in all,
    /// a path within the depth bounds, and kept by the filter.
    #[inline]
    pub fn uses(&self, s: usize, t: usize) -> bool {
        t >= 1
            && s + t >= 2
            && s + t - 2 <= self.max_depth as usize
            && s + t - 2 >= self.min_depth as usize
            && self.strategies.keeps(s, t)
            && (s == 0 || self.connects())
    }
}

/// Samples whose camera vertices pick from the light vertices of their own light subpaths
/// alone: one cache per group of a wave, small enough (~4k vertices on door_ajar, ~0.5 MB)
/// to stay in a core's L2 while its camera vertices pick from it at random, and built in
/// parallel, group by group.
pub const CACHE_GROUP: usize = 1024;

/// The light-vertex caches of a wave (LVC-BDPT), one per `CACHE_GROUP` samples.
#[derive(Default)]
pub struct LightVertexCache {
    /// Vertices each camera vertex joins (M; 0: no cache).
    pub per_camera_vertex: u32,
    /// How many times as often as each other strategy MIS counts each connection strategy
    /// (s >= 2, t >= 2): M over the mean cached vertices per light subpath. A constant
    /// measured before the render (`PILOT_SUBPATHS` light subpaths of a salted seed): were it
    /// a group's own V / N, the weights would depend on the light subpaths they weigh.
    pub connection_count: f32,
    /// The pilot's mean cached vertices per light subpath.
    pub pilot_mean: f32,
    /// Group g serves the wave's samples `g * CACHE_GROUP..(g + 1) * CACHE_GROUP`.
    pub groups: Vec<CacheGroup>,
}

/// The cache of one group of samples: every connectible light vertex past the emitter
/// (s >= 2) of their light subpaths that carries light, in light-subpath order then depth
/// order, so the cache and the picks into it do not depend on the thread count.
#[derive(Default)]
pub struct CacheGroup {
    /// The group's light subpaths (N).
    pub light_subpaths: usize,
    /// Per cached vertex: its light subpath's slot, its depth (s - 1), the vertex, and the
    /// vertex prepared for joining.
    pub subpath: Vec<u32>,
    pub depth: Vec<u32>,
    pub vertex: Vec<Vertex>,
    pub joint: Vec<Joint>,
}

impl CacheGroup {
    /// Vertices cached (V).
    #[inline]
    pub fn len(&self) -> usize {
        self.vertex.len()
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.vertex.is_empty()
    }

    pub fn clear(&mut self) {
        self.subpath.clear();
        self.depth.clear();
        self.vertex.clear();
        self.joint.clear();
    }

    /// What each connection through the cache is multiplied by, V / (N M) with M
    /// `per_camera_vertex`: a pick is uniform over the V, so M picks so scaled average the
    /// sum over all of them, 1 / N of it (BDPT joins one light subpath per camera path).
    #[inline]
    pub fn scale(&self, per_camera_vertex: u32) -> f32 {
        (self.len() as f64 / (self.light_subpaths as f64 * per_camera_vertex as f64)) as f32
    }

    /// The index of pick `m` of `per_camera_vertex` at a camera vertex whose 48-bit uniform
    /// is `x`: the picks are stratified over the cache, each uniform on its own (which is all
    /// the estimator needs), exactly up to 2^-48. The group must not be empty.
    #[inline]
    pub fn pick(&self, x: u64, m: u32, per_camera_vertex: u32) -> usize {
        // floor((m + x / 2^48) V / M), in integers.
        let at = ((m as u128) << 48) | x as u128;
        (((at * self.len() as u128) >> 48) as u64 / per_camera_vertex as u64) as usize
    }
}

impl LightVertexCache {
    /// Light vertex `d` (>= 1) of `subpath` prepared for joining, if it goes into the cache:
    /// connectible and carrying light.
    #[inline]
    pub fn joint(ctx: &PathContext, subpath: &[Vertex], d: usize) -> Option<Joint> {
        let v = &subpath[d];
        if v.beta == Vec3::ZERO {
            return None;
        }
        ctx.joint(v, crate::path::towards(v, &subpath[d - 1]))
    }

    /// The cache sample `k` of the wave picks from.
    #[inline]
    pub fn group(&self, k: usize) -> &CacheGroup {
        &self.groups[k / CACHE_GROUP]
    }

    /// Bytes the caches hold.
    pub fn bytes(&self) -> usize {
        let per_vertex = std::mem::size_of::<Vertex>() + std::mem::size_of::<Joint>() + 8;
        self.groups
            .iter()
            .map(|g| g.vertex.capacity() * per_vertex)
            .sum()
    }
}

#[derive(Default)]
pub struct Scratch {
    pub rays: Rays,
    pub walkers: Walkers,
    pub order: Vec<u32>,
}
