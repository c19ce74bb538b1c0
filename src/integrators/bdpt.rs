//! Bidirectional path tracing (`--integrator bdpt`, Veach 1997): every sample traces a camera
//! subpath and a light subpath, then joins them by every strategy (s, t), weighting each by
//! multiple importance sampling (power heuristic by default, computed by the ratio walk of
//! `crate::path`).
//!
//! Its graph, built from the scene: `stagelight graph SCENE --integrator bdpt` prints it with
//! each system's columns, and docs/architecture.md shows it for `door_ajar`.
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
use crate::integrators::driver::render_waves_of;
use crate::integrators::{
    Budget, Control, IntegratorState, RenderOutcome, RenderSettings, SceneData, Wave, WaveState,
};
use crate::path::PathContext;
use crate::pipeline::{Graph, Node, Stats};
use crate::sampling::Sampler;
use crate::systems::{connect, gather, generate, shade, trace};
use glam::{DVec3, Vec3};
use std::collections::BTreeMap;
use std::sync::Arc;

pub use crate::components::subpaths::*;

impl From<&RenderSettings> for BdptSettings {
    fn from(s: &RenderSettings) -> BdptSettings {
        BdptSettings {
            mis: s.mis,
            sampler: s.sampler,
            strategy_images: s.strategy_images,
            light_vertex_cache: s.light_vertex_cache,
            lanes: s.lanes.unwrap_or_else(crate::lanes::LaneWidth::widest),
            ..BdptSettings::new(s.seed, s.max_depth)
        }
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
    /// Where each sample's camera ray left the film (raster position of the rendered image),
    /// for a filter wider than a pixel.
    pub sample_raster: Vec<glam::Vec2>,
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
    /// The wave's light vertices that camera vertices merge with (VCM, BPM).
    pub light_grid: LightVertexGrid,
}

/// The default first-pass merge radius of VCM and BPM, in pixel footprints
/// (`photon_mapping::pixel_footprint`): the disc is a few pixels wide where the camera looks.
pub const MERGE_RADIUS_PIXELS: f32 = 1.5;

/// The default radius reduction of VCM and BPM (Georgiev et al. 2012 use 0.75).
pub const DEFAULT_MERGE_ALPHA: f32 = 0.75;

/// Merge radius where the camera sees nothing, as a fraction of the scene's diagonal (no
/// merge can reach the image there anyway).
const BLIND_MERGE_RADIUS_FRACTION: f32 = 1e-3;

/// The settings of VCM (`connect` and `merge`), BPM (merges only) or VCM's connections alone,
/// from the command line's: `--radius` (default `MERGE_RADIUS_PIXELS` pixel footprints) and
/// `--alpha` (default `DEFAULT_MERGE_ALPHA`).
pub fn vcm_settings(
    data: &SceneData,
    s: &RenderSettings,
    connect: bool,
    merge: bool,
) -> BdptSettings {
    let radius = s.photons.radius.unwrap_or_else(|| {
        crate::components::photon_mapping::pixel_footprint(data).map_or_else(
            || {
                let sc = &data.scene;
                BLIND_MERGE_RADIUS_FRACTION * (sc.bounds_max - sc.bounds_min).length()
            },
            |footprint| MERGE_RADIUS_PIXELS * footprint,
        )
    });
    BdptSettings {
        light_vertex_cache: 0,
        merging: Some(VertexMerging {
            radius,
            alpha: s.photons.alpha.unwrap_or(DEFAULT_MERGE_ALPHA),
            connect,
            merge,
        }),
        ..BdptSettings::from(s)
    }
}

/// Light subpaths traced before an LVC render to count the vertices a light subpath leaves
/// in the cache: MIS needs that mean as a constant (see `LightVertexCache`).
pub const PILOT_SUBPATHS: usize = 1 << 13;

/// Salt of the pilot's seed: its light subpaths are not the render's.
const PILOT_SEED_SALT: u64 = 0x6c76_635f_7069_6c6f;

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
            sample_raster: vec![glam::Vec2::ZERO; capacity],
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
            light_grid: LightVertexGrid::default(),
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

/// The graph of vertex connection and merging (`merging` set): BDPT's, and after the
/// connections the wave's light vertices gathered into a hash grid and each camera vertex's
/// merges with those within the radius (BPM: the same graph, only s = 0 connecting; VCM's
/// connections alone: BDPT's graph, VCM's weights).
pub fn vcm_graph(merge: bool) -> Graph<BdptState> {
    let mut nodes = subpath_nodes();
    nodes.extend([
        Node::system(connect::strategies::ConnectStrategies),
        Node::system(trace::shadow::TraceShadow),
        Node::system(connect::weights::WeighConnections),
    ]);
    if merge {
        nodes.extend([
            Node::system(gather::light_vertex_grid::BuildLightVertexGrid),
            Node::system(gather::merges::MergeLightVertices),
        ]);
    }
    nodes.push(Node::system(gather::connections::AccumulateConnections));
    Graph::new("vcm", nodes)
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
        if let Some(merging) = settings.merging {
            vcm_graph(merging.merge)
        } else if settings.light_vertex_cache > 0 {
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
    /// Not where the image depends on the waves' size (VCM and BPM merge with the light
    /// subpaths of their own wave, LVC-BDPT joins those of its wave's groups of samples), nor
    /// with strategy images (their f64 sums round by how the waves were grouped).
    fn waves_side_by_side(settings: &BdptSettings) -> bool {
        settings.merging.is_none() && settings.light_vertex_cache == 0 && !settings.strategy_images
    }
    fn notes(&self) -> Vec<(&'static str, String)> {
        if let Some(m) = self.settings.merging {
            let footprint = crate::components::photon_mapping::pixel_footprint(&self.data);
            let pixels = footprint.map_or(String::new(), |f| {
                format!(" ({:.2} pixel footprints of {f:.4e})", m.radius / f)
            });
            let techniques = match (m.connect, m.merge) {
                (true, true) => "connections and merges",
                (false, _) => "merges and emitters hit (bpm)",
                (true, false) => "connections alone",
            };
            return vec![(
                "vertex merging",
                format!(
                    "{techniques}; first-pass radius {:.4e}{pixels}, alpha {}",
                    m.radius, m.alpha
                ),
            )];
        }
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
    let wavefront = default_wavefront(&settings);
    render_waves_of::<BdptState>(data, settings, budget, control, None, wavefront)
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

/// The systems of its graphs bound to the columns of `BdptState`.
mod bindings {
    use super::BdptState;
    use crate::systems::*;

    crate::bind! {
        BdptState:
        connect::cached_strategies::ConnectThroughCache {
            read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels,
                multiplex, chosen_s, sample_pixel, light_cache;
            write connection_start, connections_len, shadow, connections, sample_radiance,
                cache_pick;
        }
        connect::cached_weights::WeighCachedConnections {
            read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels,
                multiplex, connection_start, connections_len, connections, light_cache, cache_pick;
            write shadow;
        }
        connect::light_vertex_cache::CacheLightVertices {
            read wave, capacity, subpath_len, data, vertices;
            write light_cache;
        }
        connect::strategies::ConnectStrategies {
            read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels,
                multiplex, chosen_s, sample_pixel;
            write connection_start, connections_len, shadow, connections, sample_radiance;
        }
        connect::weights::WeighConnections {
            read wave, capacity, settings, numbers = sampler, subpath_len, data, vertices, pixels,
                multiplex, connection_start, connections_len, connections;
            write shadow;
        }
        gather::light_vertex_grid::BuildLightVertexGrid {
            read wave, capacity, settings, pixels, subpath_len, data, vertices;
            write light_grid;
        }
        gather::merges::MergeLightVertices {
            read wave, settings, pixels, subpath_len, data, vertices, light_grid;
            write sample_radiance;
        }
        gather::connections::AccumulateConnections {
            read wave, shadow, connections, connection_start, connections_len, pixels,
                sample_raster, strategy_images = settings.strategy_images;
            write sample_radiance, film, strategy_sums;
        }
        generate::subpaths::StartSubpaths {
            read wave, data, pixels, numbers = sampler, capacity, settings;
            write vertices, walkers, rays, subpath_len, active, depth, sample_pixel,
                sample_raster, chosen_s, multiplex;
        }
        shade::compact_subpaths::CompactSubpaths {
            write walkers, rays, active, depth, scratch;
        }
        shade::extend_subpaths::ExtendSubpaths {
            read scene = data.scene, settings, numbers = sampler, capacity, hits, active, depth,
                multiplex, chosen_s;
            write vertices, subpath_len, walkers, rays;
        }
        trace::closest::TraceClosest {
            read accel = data.accel, rays, live = active;
            write hits;
        }
        trace::shadow::TraceShadow {
            read accel = data.accel, len = connections_len;
            write shadow;
        }
    }
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
