//! Joins the camera and light subpaths of every sample by each strategy (s, t): computes the
//! strategy's unweighted contribution, and for every strategy but s = 0 a shadow ray for the
//! segment it adds. A connection that cannot contribute (a zero BSDF at either end, a
//! back-facing light or surface, a light subpath that carries nothing) casts no ray. The MIS
//! weight of a connection with a shadow ray is left to `weigh_connections`, which computes it
//! only for the unoccluded ones (on door_ajar 96% are occluded); s = 0 is weighted here. The
//! connections of a sample take consecutive slots (counted from the subpath lengths first), so
//! the whole wave's shadow rays form one batch in sample order.
//!
//! Strategy s = 1 samples a fresh point on a light for each camera vertex (next-event
//! estimation); t = 1 projects a light vertex onto the image (light tracing: it lands in
//! whichever pixel it projects to).

use crate::components::Wave;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::CONNECT_CHUNK;
use crate::components::subpaths::DIM_CACHE_PICK;
use crate::components::subpaths::DIM_LIGHT_PICK;
use crate::components::subpaths::DIM_LIGHT_POINT;
use crate::components::subpaths::LightVertexCache;
use crate::components::subpaths::Numbers;
use crate::components::subpaths::StrategyFilter;
use crate::components::subpaths::camera_vertex_dim;
use crate::components::{
    Connections, ConnectionsChunk, PathVertices, PathVerticesView, ShadowRays, ShadowRaysChunk,
    split_ranges,
};
use crate::geometry::spawn_ray_to;
use crate::path::{Joint, PathContext, Techniques, Vertex, VertexKind, towards};
use crate::pipeline::Flow;
use crate::sampling::{SampleKey, Sampler, Stream};
use crate::scene::{PreparedScene, SceneData};
use crate::weight_tails::WeightTail;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::Arc;

pub struct ConnectStrategies;

/// Connection slots of a sample with `nc` camera and `nl` light vertices: its strategies
/// (s, t), laid out t outer, s inner; a multiplexed sample keeps only `only`. Through a
/// light-vertex cache (`cached`), the strategies s >= 2, t >= 2 become M picks per camera
/// vertex, after that vertex's s = 0 and s = 1.
#[inline]
fn slot_count(
    settings: &BdptSettings,
    nc: usize,
    nl: usize,
    only: Option<(usize, usize)>,
    cached: bool,
) -> usize {
    match only {
        Some((s, t)) => (s <= nl && t <= nc && settings.uses(s, t)) as usize,
        None if cached => (1..=nc)
            .map(|t| {
                let own = settings
                    .light_vertices(t, nl)
                    .filter(|&s| (t == 1 || s < 2) && settings.uses(s, t))
                    .count();
                let picks = if settings.joins_cache(t) {
                    settings.light_vertex_cache as usize
                } else {
                    0
                };
                own + picks
            })
            .sum(),
        None if settings.all_strategies() => {
            (1..=nc).map(|t| settings.light_vertices(t, nl).len()).sum()
        }
        None => (1..=nc)
            .map(|t| {
                settings
                    .light_vertices(t, nl)
                    .filter(|&s| settings.uses(s, t))
                    .count()
            })
            .sum(),
    }
}

crate::system! {
    ConnectStrategies = "connect_strategies";
    read wave: Wave, capacity: usize, settings: BdptSettings, numbers: Numbers,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>, pixels: u64,
        multiplex: Vec<u32>, chosen_s: Vec<u16>, sample_pixel: Vec<u32>;
    write connection_start: Vec<usize>, connections_len: usize, shadow: ShadowRays,
        connections: Connections, sample_radiance: Vec<Vec3>;
    run {
        let wave_in = WaveInputs {
            wave: *wave,
            capacity: *capacity,
            settings: *settings,
            numbers,
            subpath_len,
            data,
            vertices,
            pixels: *pixels,
            multiplex,
            chosen_s,
            sample_pixel,
        };
        let out = WaveOutputs { connection_start, connections_len, shadow, connections, sample_radiance };
        connect_wave(wave_in, out, None)
    }
}

/// What `connect_wave` reads of a BDPT state.
pub struct WaveInputs<'a> {
    pub wave: Wave,
    pub capacity: usize,
    pub settings: BdptSettings,
    pub numbers: &'a Numbers,
    pub subpath_len: &'a [u32],
    pub data: &'a SceneData,
    pub vertices: &'a [PathVertices],
    pub pixels: u64,
    pub multiplex: &'a [u32],
    pub chosen_s: &'a [u16],
    pub sample_pixel: &'a [u32],
}

/// What `connect_wave` writes.
pub struct WaveOutputs<'a> {
    pub connection_start: &'a mut Vec<usize>,
    pub connections_len: &'a mut usize,
    pub shadow: &'a mut ShadowRays,
    pub connections: &'a mut Connections,
    pub sample_radiance: &'a mut Vec<Vec3>,
}

/// The connections of a wave: every strategy of every sample (`cache` None), or through a
/// light-vertex cache, whose picks are written to `cache.1` per slot (their other slots keep
/// what was there).
pub fn connect_wave(
    input: WaveInputs,
    out: WaveOutputs,
    cache: Option<(&LightVertexCache, &mut Vec<u32>)>,
) -> Flow {
    let WaveInputs {
        wave,
        capacity: cap,
        settings,
        numbers,
        subpath_len,
        data,
        vertices,
        pixels,
        multiplex,
        chosen_s,
        sample_pixel,
    } = input;
    let WaveOutputs {
        connection_start,
        connections_len,
        shadow,
        connections,
        sample_radiance,
    } = out;
    let n = wave.len;
    let sampler = numbers.sampler();
    let sampler = &sampler;
    let cached = cache.is_some();
    debug_assert!(
        !cached || (multiplex.is_empty() && !numbers.is_primary()),
        "the light-vertex cache is for BDPT renders, not MLT's proposals"
    );
    // A multiplexed sample keeps its one strategy, its weight times the strategy count.
    let multiplexed = !multiplex.is_empty();
    let only = |k: usize| {
        multiplexed.then(|| {
            let s = chosen_s[k] as usize;
            (s, multiplex[k] as usize + 2 - s)
        })
    };
    // Slots per sample, then where each sample's begin.
    let lens = subpath_len;
    let counts: Vec<usize> = (0..n)
        .into_par_iter()
        .with_min_len(CONNECT_CHUNK)
        .map(|k| {
            slot_count(
                &settings,
                lens[k] as usize,
                lens[cap + k] as usize,
                only(k),
                cached,
            )
        })
        .collect();
    let starts = &mut *connection_start;
    starts[0] = 0;
    for k in 0..n {
        starts[k + 1] = starts[k] + counts[k];
    }
    let total = starts[n];
    *connections_len = total;
    if shadow.capacity() < total {
        // Grows to the largest wave seen, then is reused.
        *shadow = ShadowRays::new(total);
        *connections = Connections::new(total);
    }

    let ctx = PathContext::new(&data.scene);
    let vertices: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
    let starts = &*connection_start;
    let chunk_starts: Vec<usize> = (0..n).step_by(CONNECT_CHUNK).map(|k| starts[k]).collect();
    let shadow = shadow.split_mut(&chunk_starts, total);
    let conns = connections.split_mut(&chunk_starts, total);
    let radiance = split_ranges(
        sample_radiance,
        &(0..n).step_by(CONNECT_CHUNK).collect::<Vec<_>>(),
        n,
    );
    // Through a cache: its picks per slot, and the cache's MIS count and scale.
    let (cache, picks): (_, Vec<Option<&mut [u32]>>) = match cache {
        Some((cache, picks)) => {
            if picks.len() < total {
                picks.resize(total, 0);
            }
            let pieces = split_ranges(picks, &chunk_starts, total);
            (Some(cache), pieces.into_iter().map(Some).collect())
        }
        None => (None, chunk_starts.iter().map(|_| None).collect()),
    };
    let connection_count = cache.map_or(1.0, |c| c.connection_count);
    let scene = &data.scene;
    let has_light = !scene.emitters.triangle.is_empty();
    // Every strategy within the depth bounds counts (no filter to ask).
    let all = settings.all_strategies();
    let made: usize = shadow
        .into_par_iter()
        .zip(conns)
        .zip(radiance)
        .zip(picks)
        .enumerate()
        .map(|(c, (((mut sh, mut cn), radiance), mut picks))| {
            let mut camera = Subpath::default();
            let mut light = Subpath::default();
            let mut made = 0;
            let first_sample = c * CONNECT_CHUNK;
            for (local, out) in radiance.iter_mut().enumerate() {
                *out = Vec3::ZERO;
                let k = first_sample + local;
                let pixel = sample_pixel[k];
                let strategy_count = if multiplexed {
                    crate::components::subpaths::multiplexed_factor(
                        multiplex[k],
                        settings.max_depth,
                    )
                } else {
                    1.0
                };
                let (nc, nl) = (lens[k] as usize, lens[cap + k] as usize);
                camera.gather(&ctx, &vertices, k, nc);
                light.gather(&ctx, &vertices, cap + k, nl);
                let only = only(k);
                let mut this = starts[k] - sh.start;
                for t in 1..=nc {
                    for s in settings.light_vertices(t, nl) {
                        if !(all || settings.uses(s, t)) || only.is_some_and(|st| st != (s, t)) {
                            continue;
                        }
                        if cached && s >= 2 && t >= 2 {
                            // Joined through the cache below.
                            continue;
                        }
                        let slot = this;
                        this += 1;
                        open_slot(&mut sh, &mut cn, slot, k, pixel, (s, t));
                        let (contribution, segment) = if s == 0 {
                            // The camera subpath found the light by itself: nothing to
                            // test, weighted now; it reaches the sample's own pixel.
                            let z = &camera.vertices[t - 1];
                            let c = ctx.reached_emission(z, &camera.vertices[t - 2]);
                            if c == Vec3::ZERO {
                                continue;
                            }
                            let weight = connection_weight(
                                &ctx,
                                &settings,
                                (&camera.vertices, &light.vertices),
                                (s, t),
                                (strategy_count, connection_count),
                                settings.techniques(wave, k, pixels),
                                None,
                            );
                            let contribution = c * weight;
                            if contribution == Vec3::ZERO {
                                continue;
                            }
                            sh.contribution[slot] = contribution;
                            *out += contribution;
                            continue;
                        } else if t == 1 {
                            // Light tracing: lands where the light vertex projects.
                            let y = &light.vertices[s - 1];
                            if light.joints[s - 1].is_none() {
                                continue;
                            }
                            let Some((c, p, raster)) = ctx.connect_to_camera(y, light.wo[s - 1])
                            else {
                                continue;
                            };
                            cn.pixel[slot] = p as u32;
                            cn.raster[slot] = raster;
                            (c, (*y, camera.vertices[0]))
                        } else {
                            let Some(zj) = &camera.joints[t - 1] else {
                                continue;
                            };
                            let z = &camera.vertices[t - 1];
                            let sampled;
                            let y = if s == 1 {
                                // A fresh light sample at z_{t-1}.
                                if !has_light {
                                    continue;
                                }
                                let key = numbers.key(sampler, Stream::Connection, wave, pixels, k);
                                let v = sampled_light_vertex(scene, sampler, key, t, z);
                                sampled = ctx.joint(&v, Vec3::ZERO).map(|j| (v, j));
                                sampled.as_ref().map(|(v, j)| (v, j))
                            } else {
                                let v = &light.vertices[s - 1];
                                light.joints[s - 1].as_ref().map(|j| (v, j))
                            };
                            let Some(y) = y else {
                                continue;
                            };
                            let Some(c) = ctx.join_prepared(y, (z, zj)) else {
                                continue;
                            };
                            (c, (*y.0, *z))
                        };
                        // Unweighted until the ray is found unoccluded.
                        let (y, z) = segment;
                        sh.contribution[slot] = contribution;
                        let (origin, dir, t_max) =
                            spawn_ray_to(y.p, y.p_error, y.ng, z.p, z.p_error, z.ng);
                        sh.origin[slot] = origin;
                        sh.dir[slot] = dir;
                        sh.t_max[slot] = t_max;
                        made += 1;
                    }
                    let (Some(cache), Some(picks)) = (cache, picks.as_deref_mut()) else {
                        continue;
                    };
                    if !settings.joins_cache(t) {
                        continue;
                    }
                    // M light vertices picked from the sample's group's cache, stratified
                    // over it by one 48-bit uniform of this camera vertex.
                    let group = cache.group(k);
                    let cache_scale = group.scale(cache.per_camera_vertex);
                    let key = numbers.key(sampler, Stream::Connection, wave, pixels, k);
                    let dim = camera_vertex_dim(t - 1) + DIM_CACHE_PICK;
                    let bits =
                        |d: u32| ((sampler.get(key, d) * (1u32 << 24) as f32) as u64) & 0xff_ffff;
                    let x = (bits(dim) << 24) | bits(dim + 1);
                    let z = &camera.vertices[t - 1];
                    for m in 0..cache.per_camera_vertex {
                        let slot = this;
                        this += 1;
                        // s is set once the pick names its light vertex.
                        open_slot(&mut sh, &mut cn, slot, k, pixel, (0, t));
                        if group.is_empty() {
                            continue;
                        }
                        let i = group.pick(x, m, cache.per_camera_vertex);
                        let s = group.depth[i] as usize + 1;
                        picks[slot] = i as u32;
                        cn.s[slot] = s as u16;
                        if !settings.uses(s, t) {
                            continue;
                        }
                        let Some(zj) = &camera.joints[t - 1] else {
                            continue;
                        };
                        let y = &group.vertex[i];
                        let Some(c) = ctx.join_prepared((y, &group.joint[i]), (z, zj)) else {
                            continue;
                        };
                        sh.contribution[slot] = c * cache_scale;
                        let (origin, dir, t_max) =
                            spawn_ray_to(y.p, y.p_error, y.ng, z.p, z.p_error, z.ng);
                        sh.origin[slot] = origin;
                        sh.dir[slot] = dir;
                        sh.t_max[slot] = t_max;
                        made += 1;
                    }
                }
                debug_assert_eq!(this, starts[k + 1] - sh.start);
            }
            made
        })
        .sum();
    Flow::new(n, made)
}

/// Opens connection slot `slot` (of a chunk) for strategy (s, t) of sample `k`: no shadow ray
/// and no contribution until the connection makes them.
#[inline(always)]
fn open_slot(
    sh: &mut ShadowRaysChunk,
    cn: &mut ConnectionsChunk,
    slot: usize,
    k: usize,
    pixel: u32,
    (s, t): (usize, usize),
) {
    sh.t_max[slot] = 0.0;
    sh.contribution[slot] = Vec3::ZERO;
    cn.sample[slot] = k as u32;
    cn.pixel[slot] = pixel;
    cn.raster[slot] = glam::Vec2::NAN;
    cn.s[slot] = s as u16;
    cn.t[slot] = t as u16;
}

/// The light vertex strategy s = 1 joins to camera vertex z_{t-1} (`z`, t >= 2): a point
/// sampled on an emitter with that vertex's numbers, or a direction from the light at infinity
/// (a vertex beyond the scene that way). The scene must have an emitter.
#[inline]
pub fn sampled_light_vertex(
    scene: &PreparedScene,
    sampler: &Sampler,
    key: SampleKey,
    t: usize,
    z: &Vertex,
) -> Vertex {
    let dim = camera_vertex_dim(t - 1);
    let u_pick = sampler.get(key, dim + DIM_LIGHT_PICK);
    if let Some((e, env)) = scene.emitters.environment()
        && crate::sampling::sample_cdf(&scene.emitters.cdf, u_pick) == e
    {
        let (towards_light, pdf_dir) = env.sample(sampler.get2(key, dim + DIM_LIGHT_POINT));
        let pdf = scene.emitters.pmf[e] * pdf_dir;
        return Vertex {
            kind: VertexKind::Light,
            p: scene.emitters.disk.far_point(z.p, towards_light),
            p_error: Vec3::ZERO,
            ng: -towards_light,
            ns: -towards_light,
            triangle: crate::scene::ENVIRONMENT,
            // Zero where the direction has no density: the joint then brings nothing.
            beta: if pdf > 0.0 {
                env.eval(towards_light) / pdf
            } else {
                Vec3::ZERO
            },
            pdf_fwd: pdf,
            pdf_rev: 0.0,
            delta: false,
        };
    }
    let light = scene.sample_emitter(u_pick, sampler.get2(key, dim + DIM_LIGHT_POINT));
    let (e, tri, sp) = (light.emitter, light.triangle, light.point);
    let pdf_origin = light.pdf_area;
    if scene.emitters.is_directional(e) {
        // Its one direction, from beyond the scene.
        let travel = scene.emitters.position[e];
        return Vertex {
            kind: VertexKind::Light,
            p: scene.emitters.disk.far_point(z.p, -travel),
            p_error: Vec3::ZERO,
            ng: travel,
            ns: travel,
            triangle: tri,
            beta: scene.emitters.radiance[e] / pdf_origin,
            pdf_fwd: pdf_origin,
            pdf_rev: 0.0,
            delta: false,
        };
    }
    Vertex {
        kind: VertexKind::Light,
        p: sp.p,
        p_error: sp.p_error,
        ng: sp.ng,
        ns: sp.ng,
        triangle: tri,
        beta: scene.emitters.radiance[e] / pdf_origin,
        pdf_fwd: pdf_origin,
        pdf_rev: 0.0,
        delta: false,
    }
}

/// The factor a connection's unweighted contribution is multiplied by: its MIS weight (when
/// every strategy counts) times `strategy_count`, that of a multiplexed sample (1 otherwise).
/// `connection_count` is how many times as often the connection strategies are sampled as the
/// others (1 but through a light-vertex cache); `techniques` what VCM's weights count (read
/// only with `settings.merging`). With both subpaths' `weight_tails` (`tails`) and no cache,
/// the weight takes constant time; without, it walks the path.
#[inline]
pub fn connection_weight(
    ctx: &PathContext,
    settings: &BdptSettings,
    (camera, light): (&[Vertex], &[Vertex]),
    (s, t): (usize, usize),
    (strategy_count, connection_count): (f32, f32),
    techniques: Techniques,
    tails: Option<(&[WeightTail], &[WeightTail])>,
) -> f32 {
    if settings.strategies != StrategyFilter::All {
        strategy_count
    } else if let Some((camera_tails, light_tails)) = tails.filter(|_| connection_count == 1.0) {
        ctx.connection_weight_from_tails(
            (camera, camera_tails),
            (light, light_tails),
            (s, t),
            settings.mis,
            techniques,
        ) * strategy_count
    } else if settings.merging.is_some() {
        ctx.vcm_weight(camera, light, (s, t), None, settings.mis, techniques) * strategy_count
    } else {
        ctx.mis_weight_counted(camera, light, s, t, settings.mis, connection_count) * strategy_count
    }
}

/// One subpath of a sample as its connections read it: the vertices, and per vertex the unit
/// direction to the previous vertex (zero at the first) and, where a strategy may join there,
/// the vertex prepared for joining, each found once rather than per connection.
#[derive(Default)]
struct Subpath {
    vertices: Vec<Vertex>,
    wo: Vec<Vec3>,
    joints: Vec<Option<Joint>>,
}

impl Subpath {
    /// Subpath `sub`'s first `len` vertices.
    fn gather(&mut self, ctx: &PathContext, stores: &[PathVerticesView], sub: usize, len: usize) {
        self.vertices.clear();
        self.wo.clear();
        self.joints.clear();
        for (d, store) in stores.iter().enumerate().take(len) {
            let v = Vertex::from_store(store, sub, d);
            let wo = match self.vertices.last() {
                Some(prev) => towards(&v, prev),
                None => Vec3::ZERO,
            };
            self.wo.push(wo);
            self.joints.push(ctx.joint(&v, wo));
            self.vertices.push(v);
        }
    }
}
