//! Multiplies each unoccluded connection's contribution by its MIS weight (and a multiplexed
//! sample's strategy count). `connect_strategies` leaves the weight of connections with a
//! shadow ray to this system, run after the rays are traced, so the weight (four densities
//! next to the joint, then the subpaths' tails: `crate::weight_tails`) is paid only by
//! connections that reach the film: on door_ajar 4% of them. The four densities of joints
//! between Lambertian surfaces and area lights are found in vector lanes, `--lanes` joints at
//! a time (`lambertian_joint_densities`); both forms do the arithmetic the connection would
//! have done at once, so the image is the same bit for bit.

use crate::bsdf::diffuse::pdf_cos;
use crate::components::PathVerticesView;
use crate::components::Wave;
use crate::components::subpaths::BdptSettings;
use crate::components::subpaths::CONNECT_CHUNK;
use crate::components::subpaths::LightVertexCache;
use crate::components::subpaths::Numbers;
use crate::components::subpaths::StrategyFilter;
use crate::components::{Connections, PathVertices, ShadowRays};
use crate::lanes::{LaneKernel, LaneWidth, M, Mask, Real, V3, run_lanes};
use crate::path::{MisHeuristic, Techniques, VertexKind};
use crate::path::{PathContext, Vertex};
use crate::pipeline::Flow;
use crate::sampling::Stream;
use crate::scene::PreparedScene;
use crate::scene::SceneData;
use crate::systems::connect::strategies::{connection_weight, sampled_light_vertex};
use crate::weight_tails::{
    JointDensities, Side, WeightTail, append_weight_tails, connection_weight_from_densities,
};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

pub struct WeighConnections;

crate::system! {
    WeighConnections = "weigh_connections";
    read wave: Wave, capacity: usize, settings: BdptSettings, numbers: Numbers,
        subpath_len: Vec<u32>, data: Arc<SceneData>, vertices: Vec<PathVertices>, pixels: u64,
        multiplex: Vec<u32>, connection_start: Vec<usize>, connections_len: usize,
        connections: Connections;
    write shadow: ShadowRays;
    run {
        let input = WeighInputs {
            wave: *wave,
            capacity: *capacity,
            settings: *settings,
            numbers,
            data,
            vertices,
            pixels: *pixels,
            multiplex,
            connection_start,
            connections_len: *connections_len,
            connections,
        };
        weigh_wave(input, shadow, None)
    }
}

/// What `weigh_wave` reads of a BDPT state.
pub struct WeighInputs<'a> {
    pub wave: Wave,
    pub capacity: usize,
    pub settings: BdptSettings,
    pub numbers: &'a Numbers,
    pub data: &'a SceneData,
    pub vertices: &'a [PathVertices],
    pub pixels: u64,
    pub multiplex: &'a [u32],
    pub connection_start: &'a [usize],
    pub connections_len: usize,
    pub connections: &'a Connections,
}

/// Weighs the wave's unoccluded connections; through a light-vertex cache (`cache`: the cache
/// and each slot's pick), the connection strategies (s >= 2, t >= 2) read their picked light
/// vertex's own subpath, and every weight counts the connection strategies as the cache samples
/// them.
pub fn weigh_wave(
    input: WeighInputs,
    shadow: &mut ShadowRays,
    cache: Option<(&LightVertexCache, &[u32])>,
) -> Flow {
    let WeighInputs {
        wave,
        capacity: cap,
        settings,
        numbers,
        data,
        vertices,
        pixels,
        multiplex,
        connection_start: starts,
        connections_len: total,
        connections,
    } = input;
    let n = wave.len;
    let sampler = numbers.sampler();
    let sampler = &sampler;
    let ctx = PathContext::new(&data.scene);
    let scene = &data.scene;
    let vertices: Vec<_> = vertices.iter().map(|v| v.view(0..v.capacity())).collect();
    let connection_count = cache.map_or(1.0, |(c, _)| c.connection_count);
    let through_cache = |s: usize, t: usize| cache.is_some() && s >= 2 && t >= 2;
    // Without a cache every weight is found in constant time from the subpaths' tails and
    // four densities at the joint, and those of joints between Lambertian surfaces (and area
    // lights) are found in lanes.
    let from_tails = cache.is_none() && settings.strategies == StrategyFilter::All;
    let lambertian = scene.lambertian_materials();
    let chunk_starts: Vec<usize> = (0..n).step_by(CONNECT_CHUNK).map(|k| starts[k]).collect();
    let weighed: usize = shadow
        .split_mut(&chunk_starts, total)
        .into_par_iter()
        .enumerate()
        // Each task's buffers serve all its chunks: allocated per chunk, they took about a
        // sixth of this system's time (perf, cornell_box).
        .map_init(WeighBuffers::default, |buffers, (c, sh)| {
            let first_sample = c * CONNECT_CHUNK;
            let last_sample = (first_sample + CONNECT_CHUNK).min(n);
            buffers.clear();
            let WeighBuffers {
                subpaths,
                picked,
                pending,
                joints,
            } = buffers;
            let mut weighed = 0;
            for k in first_sample..last_sample {
                // The vertices the sample's weights read: camera z_0..z_{t-1} and light
                // y_0..y_{s-1} of each unoccluded connection (s = 1 with t >= 2 joins a
                // fresh light sample instead, a connection through the cache its pick's
                // subpath).
                let slots = starts[k]..starts[k + 1];
                let (mut nc, mut nl) = (0, 0);
                for slot in slots.clone() {
                    let this = slot - sh.start;
                    if sh.t_max[this] > 0.0 && sh.unoccluded[this] {
                        let (s, t) = (connections.s[slot] as usize, connections.t[slot] as usize);
                        nc = nc.max(t);
                        if (s >= 2 || t == 1) && !through_cache(s, t) {
                            nl = nl.max(s);
                        }
                    }
                }
                if nc == 0 {
                    continue;
                }
                let sample =
                    subpaths.push(&vertices, (k, cap + k), (nc, nl), from_tails, settings.mis);
                let (camera, light) = subpaths.vertices(sample);
                // VCM's merge factor follows the sample's pass radius (a power): once a sample.
                let techniques = settings.techniques(wave, k, pixels);
                let strategy_count = if multiplex.is_empty() {
                    1.0
                } else {
                    crate::components::subpaths::multiplexed_factor(
                        multiplex[k],
                        settings.max_depth,
                    )
                };
                for slot in slots {
                    let this = slot - sh.start;
                    if sh.t_max[this] <= 0.0 || !sh.unoccluded[this] {
                        continue;
                    }
                    let (s, t) = (connections.s[slot] as usize, connections.t[slot] as usize);
                    let sampled = (s == 1 && t >= 2).then(|| {
                        let key = numbers.key(sampler, Stream::Connection, wave, pixels, k);
                        sampled_light_vertex(scene, sampler, key, t, &camera[t - 1])
                    });
                    let light_side = sampled.as_ref().map_or(light, std::slice::from_ref);
                    if from_tails
                        && joins_in_lanes(&lambertian, scene, (camera, light_side), (s, t))
                    {
                        joints.push((camera, light_side), (s, t));
                        pending.push(Pending {
                            this,
                            sample,
                            s: s as u16,
                            t: t as u16,
                            sampled,
                            techniques,
                            strategy_count,
                        });
                        continue;
                    }
                    let light_side: &[Vertex] =
                        if let Some((cache, picks)) = cache.filter(|_| through_cache(s, t)) {
                            let sub = cache.group(k).subpath[picks[slot] as usize] as usize;
                            picked.clear();
                            for (d, store) in vertices.iter().enumerate().take(s) {
                                picked.push(Vertex::from_store(store, sub, d));
                            }
                            picked
                        } else {
                            light_side
                        };
                    let weight = connection_weight(
                        &ctx,
                        &settings,
                        (camera, light_side),
                        (s, t),
                        (strategy_count, connection_count),
                        techniques,
                        from_tails.then(|| subpaths.tails(sample)),
                    );
                    sh.contribution[this] *= weight;
                    weighed += 1;
                }
            }
            joints.find_densities(settings.lanes);
            for (i, p) in pending.iter().enumerate() {
                let densities = joints.densities(i);
                let (camera, light) = subpaths.vertices(p.sample);
                let (camera_tails, light_tails) = subpaths.tails(p.sample);
                let light_side = p.sampled.as_ref().map_or(light, std::slice::from_ref);
                let weight = connection_weight_from_densities(
                    (camera, camera_tails),
                    (light_side, light_tails),
                    (p.s as usize, p.t as usize),
                    densities,
                    settings.mis,
                    p.techniques,
                ) * p.strategy_count;
                sh.contribution[p.this] *= weight;
                weighed += 1;
            }
            weighed
        })
        .sum();
    Flow::new(total, weighed)
}

/// What a task of `weigh_wave` keeps from chunk to chunk.
#[derive(Default)]
struct WeighBuffers {
    subpaths: ChunkSubpaths,
    picked: Vec<Vertex>,
    pending: Vec<Pending>,
    joints: JointColumns,
}

impl WeighBuffers {
    fn clear(&mut self) {
        self.subpaths.clear();
        self.picked.clear();
        self.pending.clear();
        self.joints.clear();
    }
}

/// A chunk's samples' subpath vertices (and, weighed from tails, their tails), one after
/// another, kept until the chunk's weights are found.
#[derive(Default)]
struct ChunkSubpaths {
    camera: Vec<Vertex>,
    light: Vec<Vertex>,
    camera_tails: Vec<WeightTail>,
    light_tails: Vec<WeightTail>,
    /// Each sample's first camera vertex, light vertex, camera tail and light tail.
    starts: Vec<[usize; 4]>,
}

impl ChunkSubpaths {
    fn clear(&mut self) {
        self.camera.clear();
        self.light.clear();
        self.camera_tails.clear();
        self.light_tails.clear();
        self.starts.clear();
    }

    /// Appends the first `nc` vertices of camera subpath `camera` and the first `nl` of light
    /// subpath `light`, with their tails if `tails`; gives the sample's index here.
    fn push(
        &mut self,
        stores: &[PathVerticesView],
        (camera, light): (usize, usize),
        (nc, nl): (usize, usize),
        tails: bool,
        mis: MisHeuristic,
    ) -> usize {
        let first = [
            self.camera.len(),
            self.light.len(),
            self.camera_tails.len(),
            self.light_tails.len(),
        ];
        for (d, store) in stores.iter().enumerate().take(nc) {
            self.camera.push(Vertex::from_store(store, camera, d));
        }
        for (d, store) in stores.iter().enumerate().take(nl) {
            self.light.push(Vertex::from_store(store, light, d));
        }
        if tails {
            let (c, l) = (&self.camera[first[0]..], &self.light[first[1]..]);
            append_weight_tails(c, Side::Camera, mis, &mut self.camera_tails);
            append_weight_tails(l, Side::Light, mis, &mut self.light_tails);
        }
        self.starts.push(first);
        self.starts.len() - 1
    }

    fn end(&self, sample: usize) -> [usize; 4] {
        self.starts.get(sample + 1).copied().unwrap_or([
            self.camera.len(),
            self.light.len(),
            self.camera_tails.len(),
            self.light_tails.len(),
        ])
    }

    fn vertices(&self, sample: usize) -> (&[Vertex], &[Vertex]) {
        let (a, b) = (self.starts[sample], self.end(sample));
        (&self.camera[a[0]..b[0]], &self.light[a[1]..b[1]])
    }

    fn tails(&self, sample: usize) -> (&[WeightTail], &[WeightTail]) {
        let (a, b) = (self.starts[sample], self.end(sample));
        (
            &self.camera_tails[a[2]..b[2]],
            &self.light_tails[a[3]..b[3]],
        )
    }
}

/// A connection as the subpaths it joins: camera subpath, light subpath, (s, t).
pub type SubpathConnection<'a> = (&'a [Vertex], &'a [Vertex], (usize, usize));

/// The joint densities of `connections` that
/// `weigh_connections` finds in lanes, `width` joints at a time, and None for those it finds one
/// at a time with `PathContext::joint_densities` (tests compare the two).
pub fn joint_densities_in_lanes(
    scene: &PreparedScene,
    connections: &[SubpathConnection],
    width: LaneWidth,
) -> Vec<Option<JointDensities>> {
    let lambertian = scene.lambertian_materials();
    let mut joints = JointColumns::default();
    let taken: Vec<bool> = connections
        .iter()
        .map(|&(camera, light, st)| {
            let taken = joins_in_lanes(&lambertian, scene, (camera, light), st);
            if taken {
                joints.push((camera, light), st);
            }
            taken
        })
        .collect();
    joints.find_densities(width);
    let mut next = 0..;
    taken
        .iter()
        .map(|&taken| taken.then(|| joints.densities(next.next().unwrap())))
        .collect()
}

/// An unoccluded connection whose weight waits for its joint densities from lanes.
struct Pending {
    /// Its slot in the chunk's shadow rays.
    this: usize,
    /// Its sample in `ChunkSubpaths`.
    sample: usize,
    s: u16,
    t: u16,
    /// The light vertex sampled for s = 1, t >= 2.
    sampled: Option<Vertex>,
    techniques: Techniques,
    strategy_count: f32,
}

/// Whether connection (s, t)'s joint densities are found in lanes: t >= 2 and s >= 1, both
/// joined vertices on Lambertian surfaces (the light's, for s = 1, on an area light), and the
/// vertices before them, where a density is read, on surfaces (or, before the light side's,
/// anywhere but at infinity). `JointColumns::densities` then gives `joint_densities`' bits.
fn joins_in_lanes(
    lambertian: &[bool],
    scene: &PreparedScene,
    (camera, light): (&[Vertex], &[Vertex]),
    (s, t): (usize, usize),
) -> bool {
    let lambertian_surface = |v: &Vertex| {
        v.kind == VertexKind::Surface
            && lambertian[scene.triangles.material[v.triangle as usize] as usize]
    };
    if t < 2 || s < 1 || !lambertian_surface(&camera[t - 1]) {
        return false;
    }
    if t >= 3 && !camera[t - 2].is_on_surface() {
        return false;
    }
    let y = &light[s - 1];
    if s == 1 {
        y.kind == VertexKind::Light && y.is_on_surface()
    } else {
        lambertian_surface(y) && !light[s - 2].is_at_infinity()
    }
}

/// The joints of the connections `joins_in_lanes` takes, as columns: camera vertices z_{t-1}
/// and z_{t-2}, light vertices y_{s-1} and y_{s-2} (zero for s = 1).
#[derive(Default)]
struct JointColumns {
    z: Vec<Vec3>,
    z_ng: Vec<Vec3>,
    z_ns: Vec<Vec3>,
    z_prev: Vec<Vec3>,
    z_prev_ng: Vec<Vec3>,
    y: Vec<Vec3>,
    y_ng: Vec<Vec3>,
    y_ns: Vec<Vec3>,
    y_prev: Vec<Vec3>,
    y_prev_ng: Vec<Vec3>,
    /// t >= 3: z_{t-2}'s density is read.
    t3: Vec<bool>,
    /// s = 1: y_0 is on an area light.
    at_light: Vec<bool>,
    /// s >= 2: y_{s-2}'s density is read.
    s2: Vec<bool>,
    /// y_{s-2} is on a surface (its density counts its cosine).
    y_prev_on_surface: Vec<bool>,
    /// What `find_densities` found: z_rev[0], z_rev[1], y_rev[0] and y_rev[1] of each joint,
    /// as columns (stores of consecutive lanes, from which the compiler vectorises; stored
    /// joint by joint, the kernel compiled to scalar instructions).
    found: [Vec<f32>; 4],
}

impl JointColumns {
    fn push(&mut self, (camera, light): (&[Vertex], &[Vertex]), (s, t): (usize, usize)) {
        let (z, z_prev, y) = (&camera[t - 1], &camera[t - 2], &light[s - 1]);
        self.z.push(z.p);
        self.z_ng.push(z.ng);
        self.z_ns.push(z.ns);
        self.z_prev.push(z_prev.p);
        self.z_prev_ng.push(z_prev.ng);
        self.y.push(y.p);
        self.y_ng.push(y.ng);
        self.y_ns.push(y.ns);
        let y_prev = (s >= 2).then(|| &light[s - 2]);
        self.y_prev.push(y_prev.map_or(Vec3::ZERO, |v| v.p));
        self.y_prev_ng.push(y_prev.map_or(Vec3::ZERO, |v| v.ng));
        self.t3.push(t >= 3);
        self.at_light.push(s == 1);
        self.s2.push(s >= 2);
        self.y_prev_on_surface
            .push(y_prev.is_some_and(|v| v.is_on_surface()));
    }

    fn clear(&mut self) {
        self.resize(0);
    }

    /// Every column `len` long (new joints zero, their flags false).
    fn resize(&mut self, len: usize) {
        for column in [
            &mut self.z,
            &mut self.z_ng,
            &mut self.z_ns,
            &mut self.z_prev,
            &mut self.z_prev_ng,
            &mut self.y,
            &mut self.y_ng,
            &mut self.y_ns,
            &mut self.y_prev,
            &mut self.y_prev_ng,
        ] {
            column.resize(len, Vec3::ZERO);
        }
        for column in [
            &mut self.t3,
            &mut self.at_light,
            &mut self.s2,
            &mut self.y_prev_on_surface,
        ] {
            column.resize(len, false);
        }
        for column in &mut self.found {
            column.resize(len, 0.0);
        }
    }

    /// Finds each joint's densities, `width` joints at a time (the last lanes padded).
    fn find_densities(&mut self, width: LaneWidth) {
        let len = self.z.len();
        self.resize(len.div_ceil(width.count()) * width.count());
        let mut found = std::mem::take(&mut self.found);
        run_lanes(
            width,
            JointLanes {
                columns: self,
                out: &mut found,
            },
        );
        self.found = found;
    }

    /// Joint `i`'s densities, once found.
    fn densities(&self, i: usize) -> JointDensities {
        let [z_rev0, z_rev1, y_rev0, y_rev1] = &self.found;
        JointDensities {
            z_rev: [z_rev0[i], z_rev1[i]],
            y_rev: [y_rev0[i], y_rev1[i]],
        }
    }
}

/// `JointColumns::find_densities`' work, for `run_lanes`.
struct JointLanes<'a> {
    columns: &'a JointColumns,
    /// `JointColumns::found`.
    out: &'a mut [Vec<f32>; 4],
}

impl LaneKernel for JointLanes<'_> {
    type Output = ();
    #[inline(always)]
    fn run<const N: usize>(self) {
        let c = self.columns;
        let [z_rev0, z_rev1, y_rev0, y_rev1] = self.out;
        for at in (0..c.z.len()).step_by(N) {
            let [d0, d1, d2, d3] = lambertian_joint_densities(JointVertices {
                z: V3::load(&c.z[at..]),
                z_ng: V3::load(&c.z_ng[at..]),
                z_ns: V3::load(&c.z_ns[at..]),
                z_prev: V3::load(&c.z_prev[at..]),
                z_prev_ng: V3::load(&c.z_prev_ng[at..]),
                y: V3::load(&c.y[at..]),
                y_ng: V3::load(&c.y_ng[at..]),
                y_ns: V3::load(&c.y_ns[at..]),
                y_prev: V3::load(&c.y_prev[at..]),
                y_prev_ng: V3::load(&c.y_prev_ng[at..]),
                t3: mask_of::<N>(&c.t3[at..]),
                at_light: mask_of::<N>(&c.at_light[at..]),
                s2: mask_of::<N>(&c.s2[at..]),
                y_prev_on_surface: mask_of::<N>(&c.y_prev_on_surface[at..]),
            });
            z_rev0[at..at + N].copy_from_slice(&d0.0);
            z_rev1[at..at + N].copy_from_slice(&d1.0);
            y_rev0[at..at + N].copy_from_slice(&d2.0);
            y_rev1[at..at + N].copy_from_slice(&d3.0);
        }
    }
}

/// The first `N` flags as a mask (a function, not a closure, so that it is compiled into the
/// kernel's copy for the CPU).
#[inline(always)]
fn mask_of<const N: usize>(flags: &[bool]) -> M<N> {
    M::lanes(|l| flags[l])
}

/// The vertices about one joint (or lanes of them) as `lambertian_joint_densities` reads
/// them: see `JointColumns`.
pub struct JointVertices<T: Real> {
    pub z: V3<T>,
    pub z_ng: V3<T>,
    pub z_ns: V3<T>,
    pub z_prev: V3<T>,
    pub z_prev_ng: V3<T>,
    pub y: V3<T>,
    pub y_ng: V3<T>,
    pub y_ns: V3<T>,
    pub y_prev: V3<T>,
    pub y_prev_ng: V3<T>,
    pub t3: T::Mask,
    pub at_light: T::Mask,
    pub s2: T::Mask,
    pub y_prev_on_surface: T::Mask,
}

/// `PathContext::joint_densities` of a joint `joins_in_lanes` takes, as
/// [z_rev[0], z_rev[1], y_rev[0], y_rev[1]]: the same operations in the same order (`pdf_area`
/// with `Diffuse::pdf_world` seen through `PathContext::scattering`, or an area light's
/// cosine density), so each lane's numbers are the scalar ones.
#[inline(always)]
pub fn lambertian_joint_densities<T: Real>(j: JointVertices<T>) -> [T; 4] {
    let zero = T::splat(0.0);
    let none = V3::splat(Vec3::ZERO);
    let z_to_y = (j.y - j.z).normalize_or(none);
    let z_to_prev = (j.z_prev - j.z).normalize_or(none);
    let y_to_z = (j.z - j.y).normalize_or(none);
    let y_to_prev = (j.y_prev - j.y).normalize_or(none);
    let always = T::Mask::splat(true);
    let light = y_to_z.dot(j.y_ng).max(zero) * FRAC_1_PI;
    let at_y = T::select(
        j.at_light,
        light,
        lambertian_pdf(j.y_ng, j.y_ns, y_to_prev, y_to_z),
    );
    let z_rev0 = to_area_near(at_y, j.y, j.z, j.z_ng, always);
    let z_rev1 = to_area_near(
        lambertian_pdf(j.z_ng, j.z_ns, z_to_y, z_to_prev),
        j.z,
        j.z_prev,
        j.z_prev_ng,
        always,
    );
    let y_rev0 = to_area_near(
        lambertian_pdf(j.z_ng, j.z_ns, z_to_prev, z_to_y),
        j.z,
        j.y,
        j.y_ng,
        always,
    );
    let y_rev1 = to_area_near(
        lambertian_pdf(j.y_ng, j.y_ns, y_to_z, y_to_prev),
        j.y,
        j.y_prev,
        j.y_prev_ng,
        j.y_prev_on_surface,
    );
    [
        z_rev0,
        T::select(j.t3, z_rev1, zero),
        y_rev0,
        T::select(j.s2, y_rev1, zero),
    ]
}

/// `PathContext::pdf_dir` at a Lambertian surface vertex (geometric normal `ng`, shading
/// normal `ns`): the shading normal turned to `wo`'s side, zero where the geometric surface
/// does not reflect `wo` into `wi` (`scatters_between`).
#[inline(always)]
fn lambertian_pdf<T: Real>(ng: V3<T>, ns: V3<T>, wo: V3<T>, wi: V3<T>) -> T {
    let zero = T::splat(0.0);
    let wo_ng = wo.dot(ng);
    let wi_ng = wi.dot(ng);
    let ns = V3::select(wo_ng.less(zero), -ns, ns);
    let pdf = pdf_cos(wo.dot(ns), wi.dot(ns));
    T::select((wo_ng * wi_ng).greater(zero), pdf, zero)
}

/// `to_area` from `from` to `to`, neither at infinity; the cosine at `to` where `on_surface`.
#[inline(always)]
fn to_area_near<T: Real>(pdf: T, from: V3<T>, to: V3<T>, to_ng: V3<T>, on_surface: T::Mask) -> T {
    let zero = T::splat(0.0);
    let d = to - from;
    let dist2 = d.dot(d);
    let per_area = pdf / dist2;
    let per_area = T::select(
        on_surface,
        per_area * (to_ng.dot(d).abs() / dist2.sqrt()),
        per_area,
    );
    T::select(dist2.equal(zero), zero, per_area)
}
