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

use crate::components::{Connections, Hits, PathVertices, Rays, ShadowRays, Walkers};
use crate::film::{Film, Image};
use crate::integrators::driver::render_waves;
use crate::integrators::{
    Budget, Control, IntegratorState, RenderOutcome, RenderSettings, SceneData, Wave, WaveState,
};
use crate::path::MisHeuristic;
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

/// Connection-stream dimension that picks the strategy s of a multiplexed (MMLT) sample. Only
/// multiplexed samples read it, and they draw from `Numbers::Primary`, where the connection
/// stream has dimensions of its own (under the render's samplers it would be the camera's
/// pixel jitter).
pub const CONNECTION_DIM_STRATEGY: u32 = 0;

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
}

impl From<&RenderSettings> for BdptSettings {
    fn from(s: &RenderSettings) -> BdptSettings {
        BdptSettings {
            mis: s.mis,
            sampler: s.sampler,
            strategy_images: s.strategy_images,
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
        }
    }

    /// Highest vertex index a camera subpath (false) or light subpath (true) may reach: a
    /// path of depth D has D + 2 vertices, at least one on each side.
    #[inline]
    pub fn last_vertex(&self, light: bool) -> usize {
        let d = self.max_depth as usize;
        if light { d } else { d.saturating_add(1) }
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
        2 * per_subpath
            + std::mem::size_of::<usize>()
            + std::mem::size_of::<Vec3>()
            + connections / self.capacity.max(1)
    }
}

/// The BDPT graph (the same for every scene: material code runs only for materials present).
pub fn graph() -> Graph<BdptState> {
    let mut nodes = subpath_nodes();
    nodes.extend([
        Node::system(connect::strategies::ConnectStrategies),
        Node::system(trace::shadow::TraceShadow),
        Node::system(gather::connections::AccumulateConnections),
    ]);
    Graph::new("bdpt", nodes)
}

/// The evaluation part of the graph, without the film: subpaths, connections and their
/// shadow rays. MLT runs it on its chains' proposals and gathers the connections itself.
pub fn evaluation_graph() -> Graph<BdptState> {
    let mut nodes = subpath_nodes();
    nodes.extend([
        Node::system(connect::strategies::ConnectStrategies),
        Node::system(trace::shadow::TraceShadow),
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
    fn graph(_: &SceneData, _: &BdptSettings) -> Graph<BdptState> {
        graph()
    }
}

impl WaveState for BdptState {
    const WAVEFRONT: usize = WAVEFRONT;
    fn new(data: Arc<SceneData>, settings: BdptSettings, capacity: usize) -> BdptState {
        BdptState::new(data, settings, capacity)
    }
    fn begin_wave(&mut self, wave: Wave) {
        self.wave = wave;
    }
    fn film_mut(&mut self) -> &mut Film {
        &mut self.film
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
