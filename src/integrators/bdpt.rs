//! Bidirectional path tracing (`--integrator bdpt`, Veach 1997): every sample traces a camera
//! subpath and a light subpath, then joins them by every strategy (s, t), weighting each by
//! multiple importance sampling (power heuristic by default, computed by the ratio walk of
//! `crate::path`).
//!
//! Its graph, built from the scene: `stagelight graph SCENE --integrator bdpt` prints it with
//! each system's columns, and the README shows it for `door_ajar`.
//!
//! Subpath vertices are stored depth by depth (`PathVertices`, one store per depth, slot =
//! subpath), so a bounce writes one store and a store is allocated only the first time any
//! wave reaches its depth. Russian roulette (after `roulette::ROULETTE_DEPTH` vertices) ends subpaths;
//! it is left out of the MIS densities, which keeps every estimator unbiased (its weights still
//! sum to one) at a small cost in weighting quality.
//!
//! With a light-vertex cache (`--light-vertex-cache M`, Davidovic et al. 2014, "Progressive
//! light transport simulation on the GPU", LVC-BDPT), the light subpaths are walked as usual,
//! the connectible vertices past the emitter of each group of `CACHE_GROUP` samples' light
//! subpaths go into the group's cache, and each camera vertex joins M vertices picked
//! uniformly from its group's cache instead of every vertex of its own light subpath: the
//! strategies s >= 2, t >= 2 cost M connections per camera vertex instead of one per light
//! vertex, and join light subpaths other than the sample's own. Each such connection is scaled
//! by V / (N M) (V cached vertices, N light subpaths in the group), so its expectation is that
//! of BDPT's, and MIS counts the connection strategies `LightVertexCache::connection_count` =
//! M / (mean cached vertices per light subpath) times (a constant found before the render
//! from light subpaths of their own, so the weights depend on the path alone and the estimator
//! stays unbiased). Strategies s = 0, s = 1 and t = 1 are BDPT's. Groups are counted from each
//! wave's start, so the image (not its expectation) depends on the wave layout (`--wavefront`,
//! where a resumed render starts), not on the thread count.

use crate::components::{Connections, Hits, PathVertices, Rays, ShadowRays, Walkers};
use crate::film::{Film, Image};
use crate::integrators::driver::render_waves;
use crate::integrators::{
    Budget, Control, IntegratorState, RenderOutcome, RenderSettings, SceneData, Wave, WaveState,
};
use crate::path::{Joint, MisHeuristic, PathContext, Vertex};
use crate::pipeline::{Graph, Node, Stats};
use crate::sampling::{PrimarySamples, SampleKey, Sampler, SamplerKind, Stream};
use crate::systems::{connect, gather, generate, shade, trace};
use glam::{DVec3, Vec3};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Samples per wave. Each holds two subpaths and their connections, about ten times a path
/// tracer's state, so the wave is smaller than PT's.
pub const WAVEFRONT: usize = 1 << 15;

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
}

impl From<&RenderSettings> for BdptSettings {
    fn from(s: &RenderSettings) -> BdptSettings {
        BdptSettings {
            mis: s.mis,
            sampler: s.sampler,
            strategy_images: s.strategy_images,
            light_vertex_cache: s.light_vertex_cache,
            ..BdptSettings::new(s.seed, s.max_depth)
        }
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
    }
}

/// The wavefront state of bidirectional path tracing.
pub struct BdptState {
    pub data: Arc<SceneData>,
    pub settings: BdptSettings,
    pub sampler: Numbers,
    pub pixels: u64,
    /// Multiplexed samples (MMLT): the path depth of each sample of the wave, or empty for
    /// full BDPT. A multiplexed sample uses one strategy (s, t) with s + t = depth + 2, s
    /// picked by its connection stream, its subpaths exactly s and t vertices long, and its
    /// contribution is the MIS-weighted one times depth + 2.
    pub multiplex: Vec<u32>,
    /// The strategy s of each multiplexed sample (written by `start_subpaths`).
    pub chosen_s: Vec<u16>,
    /// The pixel of each sample's camera ray (where strategies with t >= 2 land).
    pub sample_pixel: Vec<u32>,
    pub wave: Wave,
    /// Samples a wave may hold; light subpath k of the wave is subpath `capacity + k`.
    pub capacity: usize,
    /// Rays of the live walkers, slots `0..active`, in increasing subpath order.
    pub rays: Rays,
    pub hits: Hits,
    pub walkers: Walkers,
    pub active: usize,
    /// Index of the vertex the rays in flight will make.
    pub depth: usize,
    /// `vertices[d]` holds vertex d of every subpath (2 x capacity slots).
    pub vertices: Vec<PathVertices>,
    /// Vertices of each subpath.
    pub subpath_len: Vec<u32>,
    /// Connection slots of sample k: `connection_start[k]..connection_start[k + 1]`.
    pub connection_start: Vec<usize>,
    pub connections_len: usize,
    pub shadow: ShadowRays,
    pub connections: Connections,
    /// What each sample's own pixel receives (strategies with t >= 2).
    pub sample_radiance: Vec<Vec3>,
    pub film: Film,
    /// Weighted contribution of each strategy (s, t), summed per pixel.
    pub strategy_sums: BTreeMap<(u16, u16), Vec<DVec3>>,
    pub scratch: Scratch,
    /// The wave's light-vertex cache (empty without `light_vertex_cache`).
    pub light_cache: LightVertexCache,
    /// Per connection slot joined through the cache: the cache index of its light vertex.
    pub cache_pick: Vec<u32>,
}

/// Light subpaths traced before an LVC render to count the vertices a light subpath leaves
/// in the cache: MIS needs that mean as a constant (see `LightVertexCache`).
pub const PILOT_SUBPATHS: usize = 1 << 13;

/// Salt of the pilot's seed: its light subpaths are not the render's.
const PILOT_SEED_SALT: u64 = 0x6c76_635f_7069_6c6f;

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
    /// A cache joining `per_camera_vertex` vertices per camera vertex (0: none), its MIS count
    /// from a pilot run of the scene's light subpaths.
    pub fn new(data: &Arc<SceneData>, settings: &BdptSettings) -> LightVertexCache {
        let m = settings.light_vertex_cache;
        if m == 0 {
            return LightVertexCache::default();
        }
        let pilot = BdptSettings {
            seed: settings.seed ^ PILOT_SEED_SALT,
            light_vertex_cache: 0,
            strategy_images: false,
            ..*settings
        };
        let ctx = PathContext::new(&data.scene);
        let cached: usize = trace_subpaths(data.clone(), pilot, 0, PILOT_SUBPATHS)
            .iter()
            .map(|(_, light)| {
                (1..light.len())
                    .filter(|&d| LightVertexCache::joint(&ctx, light, d).is_some())
                    .count()
            })
            .sum();
        let pilot_mean = cached as f32 / PILOT_SUBPATHS as f32;
        LightVertexCache {
            per_camera_vertex: m,
            // Without cached vertices no connection strategy ever samples: any count will do.
            connection_count: if cached > 0 {
                m as f32 / pilot_mean
            } else {
                m as f32
            },
            pilot_mean,
            groups: Vec::new(),
        }
    }

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

impl BdptState {
    pub fn new(data: Arc<SceneData>, settings: BdptSettings, capacity: usize) -> BdptState {
        let cam = data.scene.camera;
        let pixels = cam.width as u64 * cam.height as u64;
        let subpaths = 2 * capacity;
        let film = Film::for_scene(&data);
        BdptState {
            sampler: Numbers::Render(Sampler::new(
                settings.sampler,
                settings.seed,
                cam.width,
                cam.height,
            )),
            multiplex: Vec::new(),
            chosen_s: vec![0; capacity],
            sample_pixel: vec![0; capacity],
            data,
            settings,
            pixels,
            wave: Wave::default(),
            capacity,
            rays: Rays::new(subpaths),
            hits: Hits::new(subpaths),
            walkers: Walkers::new(subpaths),
            active: 0,
            depth: 0,
            vertices: vec![PathVertices::new(subpaths)],
            subpath_len: vec![0; subpaths],
            connection_start: vec![0; capacity + 1],
            connections_len: 0,
            shadow: ShadowRays::default(),
            connections: Connections::default(),
            sample_radiance: vec![Vec3::ZERO; capacity],
            film,
            strategy_sums: BTreeMap::new(),
            scratch: Scratch {
                rays: Rays::new(subpaths),
                walkers: Walkers::new(subpaths),
                order: Vec::with_capacity(subpaths),
            },
            light_cache: LightVertexCache::default(),
            cache_pick: Vec::new(),
        }
    }

    /// Bytes of wavefront state per sample slot as allocated now: walkers and rays (double
    /// buffered), hits, the vertex stores of every depth reached so far and the largest
    /// connection batch so far.
    pub fn bytes_per_sample(&self) -> usize {
        let per_subpath = 2 * (Rays::bytes_per_item() + Walkers::bytes_per_item())
            + Hits::bytes_per_item()
            + std::mem::size_of::<u32>()
            + self.vertices.len() * PathVertices::bytes_per_item();
        let connections =
            self.shadow.capacity() * (ShadowRays::bytes_per_item() + Connections::bytes_per_item());
        let cached =
            self.light_cache.bytes() + self.cache_pick.capacity() * std::mem::size_of::<u32>();
        2 * per_subpath
            + std::mem::size_of::<usize>()
            + std::mem::size_of::<Vec3>()
            + (connections + cached) / self.capacity.max(1)
    }
}

/// The BDPT graph (the same for every scene: material code runs only for materials present).
pub fn graph() -> Graph<BdptState> {
    let mut nodes = subpath_nodes();
    nodes.extend([
        Node::system(connect::strategies::ConnectStrategies),
        Node::system(trace::shadow::TraceShadow),
        Node::system(connect::weights::WeighConnections),
        Node::system(gather::connections::AccumulateConnections),
    ]);
    Graph::new("bdpt", nodes)
}

/// The graph of LVC-BDPT (`light_vertex_cache` > 0): the light subpaths' vertices go into the
/// wave's cache, and camera vertices join picks from it.
pub fn cached_graph() -> Graph<BdptState> {
    let mut nodes = subpath_nodes();
    nodes.extend([
        Node::system(connect::light_vertex_cache::CacheLightVertices),
        Node::system(connect::cached_strategies::ConnectThroughCache),
        Node::system(trace::shadow::TraceShadow),
        Node::system(connect::cached_weights::WeighCachedConnections),
        Node::system(gather::connections::AccumulateConnections),
    ]);
    Graph::new("bdpt_lvc", nodes)
}

/// The evaluation part of the graph, without the film: subpaths, connections and their
/// shadow rays. MLT runs it on its chains' proposals and gathers the connections itself.
pub fn evaluation_graph() -> Graph<BdptState> {
    let mut nodes = subpath_nodes();
    nodes.extend([
        Node::system(connect::strategies::ConnectStrategies),
        Node::system(trace::shadow::TraceShadow),
        Node::system(connect::weights::WeighConnections),
    ]);
    Graph::new("bdpt_evaluation", nodes)
}

/// The first half of the graph: both subpaths of every sample, walked to their ends.
fn subpath_nodes() -> Vec<Node<BdptState>> {
    vec![
        Node::system(generate::subpaths::StartSubpaths),
        Node::Loop {
            name: "subpath_bounces",
            queue_len: |s: &BdptState| s.active,
            body: vec![
                Node::system(trace::closest::TraceClosest),
                Node::system(shade::extend_subpaths::ExtendSubpaths),
                Node::system(shade::compact_subpaths::CompactSubpaths),
            ],
        },
    ]
}

impl IntegratorState for BdptState {
    type Settings = BdptSettings;
    const INPUTS: &'static [&'static str] = &[
        "data",
        "settings",
        "sampler",
        "pixels",
        "multiplex",
        "wave",
        "capacity",
        "film",
        "strategy_sums",
        "scratch",
    ];
    fn graph(_: &SceneData, settings: &BdptSettings) -> Graph<BdptState> {
        if settings.light_vertex_cache > 0 {
            cached_graph()
        } else {
            graph()
        }
    }
}

impl WaveState for BdptState {
    const WAVEFRONT: usize = WAVEFRONT;
    fn new(data: Arc<SceneData>, settings: BdptSettings, capacity: usize) -> BdptState {
        let mut state = BdptState::new(data, settings, capacity);
        state.light_cache = LightVertexCache::new(&state.data, &settings);
        state
    }
    fn begin_wave(&mut self, wave: Wave) {
        self.wave = wave;
    }
    fn film_mut(&mut self) -> &mut Film {
        &mut self.film
    }
    fn notes(&self) -> Vec<(&'static str, String)> {
        let cache = &self.light_cache;
        if cache.per_camera_vertex == 0 {
            return Vec::new();
        }
        vec![(
            "light-vertex cache",
            format!(
                "{} joins per camera vertex; {:.3} cached vertices per light subpath (pilot), \
                 connection strategies counted {:.4} times",
                cache.per_camera_vertex, cache.pilot_mean, cache.connection_count
            ),
        )]
    }
    /// The strategy images (`s{s}_t{t}`) cover the passes of this run only.
    fn finish(self, new_passes: u64) -> (Film, Vec<(String, Image)>, usize) {
        let (width, height) = (self.film.width, self.film.height);
        let new_passes = new_passes.max(1) as f64;
        let bytes_per_path = self.bytes_per_sample();
        let layers = self
            .strategy_sums
            .iter()
            .map(|(&(s, t), sums)| {
                let image = Image {
                    width,
                    height,
                    pixels: sums.iter().map(|v| (*v / new_passes).as_vec3()).collect(),
                };
                (format!("s{s}_t{t}"), image)
            })
            .collect();
        (self.film, layers, bytes_per_path)
    }
}

/// Renders with BDPT until the budget is spent or a stop is asked for; with
/// `settings.strategy_images`, the outcome's layers hold each strategy's image (`s{s}_t{t}`).
pub fn render(
    data: Arc<SceneData>,
    settings: BdptSettings,
    budget: Budget,
    control: &Control,
) -> RenderOutcome {
    render_waves::<BdptState>(data, settings, budget, control, None)
}

/// The subpaths of samples `first..first + len` (global sample ids), camera and light, as the
/// walk stored them: for studying the path space and for testing the MIS weights.
pub fn trace_subpaths(
    data: Arc<SceneData>,
    settings: BdptSettings,
    first: u64,
    len: usize,
) -> Vec<(Vec<crate::path::Vertex>, Vec<crate::path::Vertex>)> {
    let walk = Graph::new("bdpt_subpaths", subpath_nodes());
    let mut state = BdptState::new(data, settings, len);
    state.wave = Wave { first, len };
    walk.run(&mut state, &mut Stats::default());
    let subpath = |k: usize| {
        (0..state.subpath_len[k] as usize)
            .map(|d| crate::path::Vertex::from_store(&state.vertices[d].view(k..k + 1), 0, d))
            .collect::<Vec<_>>()
    };
    (0..len).map(|k| (subpath(k), subpath(len + k))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tail group's depths are drawn with the probabilities its factor divides by: the
    /// factors' implied probabilities sum to one, and a histogram of drawn depths matches them
    /// (chi-square), with and without a finite max depth.
    #[test]
    fn tail_depths_follow_the_probability_in_their_factor() {
        for max_depth in [u32::MAX, MULTIPLEX_TAIL_DEPTH + 5] {
            let p = |d: u32| (d as f64 + 2.0) / multiplexed_factor(d, max_depth) as f64;
            let last = max_depth.min(MULTIPLEX_TAIL_DEPTH + 400);
            let total: f64 = (MULTIPLEX_TAIL_DEPTH..=last).map(p).sum();
            assert!((total - 1.0).abs() < 1e-5, "{max_depth}: {total}");
            let n = 200_000;
            let bins = 12;
            let mut counts = vec![0u64; bins + 1];
            for i in 0..n {
                let u = (i as f32 + 0.5) / n as f32;
                let d = multiplexed_depth(MULTIPLEX_TAIL_DEPTH, u, max_depth);
                assert!((MULTIPLEX_TAIL_DEPTH..=max_depth).contains(&d));
                counts[((d - MULTIPLEX_TAIL_DEPTH) as usize).min(bins)] += 1;
            }
            for (j, &c) in counts.iter().enumerate().take(bins) {
                let d = MULTIPLEX_TAIL_DEPTH + j as u32;
                let want = if d <= max_depth { p(d) * n as f64 } else { 0.0 };
                assert!(
                    (c as f64 - want).abs() <= 4.0 * want.sqrt() + 2.0,
                    "{max_depth} depth {d}: {c} vs {want}"
                );
            }
            // Below the tail a group is its depth, with its strategy count as its factor.
            assert_eq!(multiplexed_depth(3, 0.7, max_depth), 3);
            assert_eq!(multiplexed_factor(3, max_depth), 5.0);
        }
    }
}
