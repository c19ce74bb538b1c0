//! Photon tracing, shared by the photon-mapping integrators (PM, PPM, SPPM): the wavefront
//! state of photons in flight and the photons they store. The systems that emit, scatter and
//! compact photons (`systems/generate/photons.rs`, `systems/shade/scatter_photons.rs`,
//! `systems/shade/compact_photons.rs`) run on any integrator state that hands this state out
//! through `PhotonQueue`.
//!
//! Photons leave emitters picked by power from points uniform on them, in cosine-distributed
//! directions, each carrying `Le pi / pdf(point)` (so the mean power of a photon is the
//! emitters' total power). At every non-specular surface a photon is stored; it scatters on by
//! sampling the BSDF (importance transport), and Russian roulette by the sampled weight (the
//! albedo, for a Lambertian surface) keeps its power constant in expectation. Photons of a
//! pass are stored in photon order, whatever the thread count.

pub mod hash_grid;
pub mod kd_tree;
pub mod state;

pub use hash_grid::HashGrid;
pub use kd_tree::{KdTree, Nearest};

use crate::components::{Hits, PhotonFlags, PhotonWalkers, Photons, Rays};
use crate::sampling::Sampler;
use crate::scene::SceneData;
use glam::Vec3;

/// Random-number dimensions of a photon: emitter pick (1), point (2), direction (2), then per
/// bounce a BSDF sample (2) and roulette (1).
pub const DIM_PICK: u32 = 0;
pub const DIM_POINT: u32 = 1;
pub const DIM_DIRECTION: u32 = 3;
pub const DIMS_PER_BOUNCE: u32 = 3;
pub const DIM_BSDF: u32 = 0;
pub const DIM_ROULETTE: u32 = 2;

/// First dimension of bounce `depth` (0 for the first surface met).
#[inline]
pub fn bounce_dim(depth: u32) -> u32 {
    5 + depth * DIMS_PER_BOUNCE
}

/// A photon as `scatter_photons` stores it, before it joins the pass's columns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StoredPhoton {
    pub p: Vec3,
    pub wi: Vec3,
    pub power: Vec3,
    pub ng: Vec3,
    pub depth: u32,
    pub flags: PhotonFlags,
}

/// Photons in flight and the photons stored so far in this pass.
#[derive(Default)]
pub struct PhotonTracing {
    /// The render's sampler: photon `index` of pass `pass` draws from the photon stream.
    pub sampler: Sampler<'static>,
    /// Highest number of scattering events before a photon is stored and ends.
    pub max_depth: u32,
    /// Store photons at the first surface they meet (direct light). Integrators that
    /// sample direct light at their gather points leave them out.
    pub store_direct: bool,
    /// Pass number (the sample index of every photon's random numbers).
    pub pass: u64,
    /// Photons this pass emits in all, and the index of the next one to emit.
    pub photons_per_pass: u64,
    pub next: u64,
    /// Index of the wave's first photon within the pass, and the wave's length.
    pub first: u64,
    pub len: usize,
    pub rays: Rays,
    pub hits: Hits,
    pub walkers: PhotonWalkers,
    /// Live photons occupy slots `0..active`.
    pub active: usize,
    /// Photons stored this pass: slots `0..stored`.
    pub photons: Photons,
    pub stored: usize,
    /// Photons emitted this pass.
    pub emitted: u64,
    /// Per chunk of walkers, the photons it stored this bounce (merged in chunk order).
    pub chunk_photons: Vec<Vec<StoredPhoton>>,
    pub scratch_walkers: PhotonWalkers,
    pub scratch_rays: Rays,
    pub order: Vec<u32>,
}

impl PhotonTracing {
    pub fn new(sampler: Sampler<'static>, max_depth: u32, wavefront: usize) -> PhotonTracing {
        PhotonTracing {
            sampler,
            max_depth,
            store_direct: true,
            rays: Rays::new(wavefront),
            hits: Hits::new(wavefront),
            walkers: PhotonWalkers::new(wavefront),
            scratch_walkers: PhotonWalkers::new(wavefront),
            scratch_rays: Rays::new(wavefront),
            order: Vec::with_capacity(wavefront),
            ..Default::default()
        }
    }

    /// Starts a pass of `photons` photons: none stored or emitted yet.
    pub fn begin_pass(&mut self, pass: u64, photons: u64) {
        self.pass = pass;
        self.photons_per_pass = photons;
        self.next = 0;
        self.stored = 0;
        self.emitted = 0;
    }

    /// Photons of the pass not emitted yet.
    pub fn remaining(&self) -> u64 {
        self.photons_per_pass - self.next
    }

    /// Appends each chunk's photons, in chunk order, to the pass's columns (growing them when
    /// a pass stores more than any before it). The chunks are copied in parallel, each into
    /// the slots after the chunks before it: one serial copy of every stored photon was a
    /// serial stretch of `scatter_photons`.
    pub fn append_chunks(&mut self, chunks: &[Vec<StoredPhoton>]) {
        use rayon::prelude::*;
        let mut starts = Vec::with_capacity(chunks.len());
        let mut needed = self.stored;
        for c in chunks {
            starts.push(needed);
            needed += c.len();
        }
        if self.photons.capacity() < needed {
            let mut grown = Photons::new(needed.max(2 * self.photons.capacity()));
            let order: Vec<u32> = (0..self.stored as u32).collect();
            grown.gather_from(&self.photons, &order);
            self.photons = grown;
        }
        self.photons
            .split_mut(&starts, needed)
            .into_par_iter()
            .zip(chunks)
            .with_max_len(1)
            .for_each(|(p, photons)| {
                for (i, ph) in photons.iter().enumerate() {
                    p.p[i] = ph.p;
                    p.wi[i] = ph.wi;
                    p.power[i] = ph.power;
                    p.ng[i] = ph.ng;
                    p.depth[i] = ph.depth;
                    p.flags[i] = ph.flags;
                }
            });
        self.stored = needed;
    }
}

/// Photons in flight per wave.
pub const WAVEFRONT: usize = 1 << 16;

/// A scene and its photon tracing: the state the photon graph runs on.
pub struct PhotonPass {
    pub data: std::sync::Arc<SceneData>,
    pub tracing: PhotonTracing,
}

/// Columns set before the photon graph runs (`begin_pass` sets the pass).
pub const INPUTS: &[&str] = &["data", "tracing"];

/// The photon graph, one pass (a pass is cut into waves of at most `WAVEFRONT` photons); the
/// photon mappers nest it (`stagelight graph SCENE --integrator sppm` prints it).
pub fn graph() -> crate::pipeline::Graph<PhotonPass> {
    use crate::pipeline::{Graph, Node};
    use crate::systems::{generate, shade, trace};
    Graph::new(
        "photons",
        vec![Node::Loop {
            name: "photon_waves",
            queue_len: |s: &PhotonPass| s.tracing.remaining() as usize,
            body: vec![
                // A stop between chunks of photons drops the pass (nothing kept yet).
                Node::StopPoint,
                Node::system(generate::photons::EmitPhotons),
                Node::Loop {
                    name: "photon_bounces",
                    queue_len: |s: &PhotonPass| s.tracing.active,
                    body: vec![
                        Node::system(trace::closest::TraceClosest),
                        Node::system(shade::scatter_photons::ScatterPhotons),
                        Node::system(shade::compact_photons::CompactPhotons),
                    ],
                },
            ],
        }],
    )
}

impl PhotonPass {
    pub fn new(
        data: std::sync::Arc<SceneData>,
        sampler: Sampler<'static>,
        max_depth: u32,
    ) -> PhotonPass {
        PhotonPass {
            data,
            tracing: PhotonTracing::new(sampler, max_depth, WAVEFRONT),
        }
    }

    /// Traces pass `pass` of `photons` photons in waves; afterwards `tracing.photons` holds
    /// the photons stored (slots `0..tracing.stored`), in photon order.
    pub fn trace(
        &mut self,
        graph: &crate::pipeline::Graph<PhotonPass>,
        pass: u64,
        photons: u64,
        stats: &mut crate::pipeline::Stats,
    ) {
        self.tracing.begin_pass(pass, photons);
        graph.run(self, stats);
    }
}

/// The photon maps of PM: every stored photon (global) and, where the scene has specular
/// surfaces, those whose path was L S+ D (caustic), each with a kd-tree for k-nearest queries.
pub struct PhotonMaps {
    pub photons: crate::components::Photons,
    pub global: KdTree,
    /// The caustic photons' kd-tree, with each tree point's index into `photons`.
    pub caustic: Option<(KdTree, Vec<u32>)>,
    /// Photons emitted to make the maps (the estimates divide by it).
    pub emitted: u64,
}

impl PhotonMaps {
    /// Bytes the maps hold.
    pub fn bytes(&self) -> usize {
        let caustic = self
            .caustic
            .as_ref()
            .map_or(0, |(t, i)| t.bytes() + 4 * i.len());
        self.photons.capacity() * crate::components::Photons::bytes_per_item()
            + self.global.bytes()
            + caustic
    }
}

/// Conductors whose roughness alpha (GGX or Beckmann) is below this are followed by the photon
/// mappers' camera chains (sampled, with light sampled there under MIS, as a path tracer does)
/// instead of gathering photons: on a near-mirror a density estimate needs the photons of a
/// tiny solid angle.
/// Measured at 20 s on docs/mlt/mirror_box.ron (docs/photons/README.md): on its mirror (alpha
/// 0.02) following cut SPPM's and PPM's relMSE 23x; on its rough block (alpha 0.3) gathering
/// was better (SPPM 2.5e-3 against 8.3e-3 following).
pub const FOLLOW_ALPHA: f32 = 0.2;

/// Whether camera chains pass through `material` (sampling it) rather than gather photons on
/// it: smooth dielectrics (thick or thin), rough dielectrics, and conductors smoother than `FOLLOW_ALPHA`. Photons are not stored
/// there (nothing gathers them), and a photon path through them to a diffuse surface is a
/// caustic (PM's caustic map).
#[inline]
pub fn chains_follow(material: &crate::bsdf::Material) -> bool {
    use crate::bsdf::Material;
    match *material {
        // Rough glass at every roughness: a gather disc on a surface that transmits would
        // have to gather the photons of both its sides.
        Material::Dielectric(_) | Material::ThinDielectric(_) | Material::RoughDielectric(_) => {
            true
        }
        Material::Conductor(c) => c.max_alpha() < FOLLOW_ALPHA,
        // The smooth plastic gathers on its diffuse lobe; camera chains follow its delta
        // reflection by a per-chain choice (`extend_camera_chains`).
        Material::Diffuse(_) | Material::RoughPlastic(_) | Material::Plastic(_) => false,
    }
}

/// Whether a scene has a material camera chains follow (and so caustics for PM's map).
pub fn scene_has_followed(data: &SceneData) -> bool {
    used_materials(data).any(chains_follow)
}

/// Whether a scene has a glossy surface camera chains follow (where they sample light).
pub fn scene_has_followed_glossy(data: &SceneData) -> bool {
    used_materials(data).any(|m| !m.kind().is_delta() && chains_follow(m))
}

/// The materials some triangle of the scene uses.
fn used_materials(data: &SceneData) -> impl Iterator<Item = &crate::bsdf::Material> {
    let scene = &data.scene;
    let mut used = vec![false; scene.materials.len()];
    for &m in &scene.triangles.material {
        used[m as usize] = true;
        // A twosided's back material is seen where the triangle is seen from behind.
        if let Some(back) = scene.back[m as usize] {
            used[back as usize] = true;
        }
    }
    scene
        .materials
        .iter()
        .zip(used)
        .filter(|(_, u)| *u)
        .map(|(m, _)| m)
}

/// Least cos between a photon's surface normal (on the side it arrived from) and the query's
/// (on the viewer's side): photons on other planes (round a corner) or on the far side of a
/// two-sided surface do not count.
pub const NORMAL_COSINE: f32 = 0.5;

/// The segment a photon must see its gather point along rises off both surfaces by this
/// fraction of its length: it then clears a convex surface curving away (within the
/// normals' 60 degrees a chord sinks below it by at most length^2 / 8 r, less than length / 4
/// while length < 2 r), and a coplanar floor, while a wall standing between the two points
/// (the zero-thickness wall of two rooms, whose floors meet under it) still cuts it.
pub const VISIBILITY_LIFT: f32 = 0.25;

/// The visibility test's segment starts this fraction of the scene's diagonal behind the
/// gather point. The accelerator rejects hits within the rounding error of a ray's origin
/// (about 1e-7 of the triangle's extent: they may be the surface the ray leaves), so a
/// segment from a point on the floor a hair from a wall would pass the wall unseen; started
/// this far back, it meets the wall well past that margin. Photons are missed only where the
/// point lies within this distance of a surface behind it (1e-5 of the diagonal).
pub const VISIBILITY_MARGIN: f32 = 1e-5;

/// The deepest photon a point `camera_depth` bounces from the camera may gather when paths
/// have at most `max_depth` bounces (pt's count: emission seen directly is depth 0), or None
/// when no photon may. A photon stored after `d` bounces lands on the point itself, which is
/// one more bounce of the path: camera_depth + 1 + d bounces in all.
#[inline]
pub fn photon_depth_limit(max_depth: u32, camera_depth: u32) -> Option<u32> {
    max_depth.checked_sub(camera_depth.checked_add(1)?)
}

/// The deepest photon worth storing under `max_depth`: one gathered at a point the camera
/// sees directly (camera depth 0); deeper ones could never count. (With `max_depth` 0 no
/// photon counts; the cap is then 0.)
#[inline]
pub fn deepest_stored_photon(max_depth: u32) -> u32 {
    photon_depth_limit(max_depth, 0).unwrap_or(0)
}

/// Where a density estimate is made: a point, its normal on the viewer's side, and the BSDF.
pub struct GatherPoint<'a> {
    pub p: Vec3,
    /// Offset off the surface that clears its rounding error (`offset_ray_origin`'s).
    pub clearance: f32,
    /// How far the visibility test starts behind the point (`VISIBILITY_MARGIN` of the
    /// scene's diagonal).
    pub margin: f32,
    pub ng: Vec3,
    pub frame: crate::math::Frame,
    pub wo_local: Vec3,
    pub material: crate::bsdf::Material,
    /// Photons stored after more bounces than this would make the path longer than the
    /// maximum depth (`photon_depth_limit`).
    pub max_photon_depth: u32,
    /// The scene's geometry, to test that a photon sees the point.
    pub accel: &'a crate::accel::Accel,
}

impl<'a> GatherPoint<'a> {
    /// The gather point of slot `i` of `visible`, if it has one and some photon may count
    /// there within `max_depth` bounces.
    #[inline]
    pub fn of(
        data: &'a SceneData,
        visible: &crate::components::VisiblePoints,
        i: usize,
        max_depth: u32,
    ) -> Option<GatherPoint<'a>> {
        let tri = visible.triangle[i];
        if tri == crate::components::NO_VISIBLE_POINT {
            return None;
        }
        let max_photon_depth = photon_depth_limit(max_depth, visible.depth[i])?;
        let scene = &data.scene;
        let frame = crate::math::Frame::from_normal(visible.ns[i]);
        let (p, ng) = (visible.p[i], visible.ng[i]);
        let lifted = crate::geometry::offset_ray_origin(p, visible.p_error[i], ng, ng);
        Some(GatherPoint {
            p,
            clearance: 2.0 * (lifted - p).length(),
            margin: VISIBILITY_MARGIN * (scene.bounds_max - scene.bounds_min).length(),
            ng,
            frame,
            wo_local: frame.to_local(visible.wo[i]),
            material: scene.material_facing(tri, p, visible.wo[i], visible.ns[i]),
            max_photon_depth,
            accel: &data.accel,
        })
    }

    /// f(wo, wi) times the power of photon `k`, or None when the photon is too deep for the
    /// point (its path would pass the maximum depth), lies on another plane, on the other
    /// side of the surface, or out of the point's sight (behind a wall that crosses the
    /// gather disc: without the test, a band as wide as the radius along a thin wall gathers
    /// the next room's photons).
    #[inline]
    pub fn reflected(&self, photons: &crate::components::Photons, k: usize) -> Option<Vec3> {
        if photons.depth[k] > self.max_photon_depth {
            return None;
        }
        let (wi, side) = (photons.wi[k], photons.ng[k]);
        if side.dot(self.ng) < NORMAL_COSINE || wi.dot(self.ng) <= 0.0 {
            return None;
        }
        if !self.sees(photons.p[k], side) {
            return None;
        }
        Some(self.material.eval(self.wo_local, self.frame.to_local(wi)) * photons.power[k])
    }

    /// Whether the segment between the point and `q` (a photon on a surface of normal
    /// `side`), each end lifted off its surface by `VISIBILITY_LIFT` of the distance, meets
    /// no surface.
    #[inline]
    pub fn sees(&self, q: Vec3, side: Vec3) -> bool {
        let lift = VISIBILITY_LIFT * (q - self.p).length() + self.clearance;
        let start = self.p + lift * self.ng;
        let to = q + lift * side;
        let Some(dir) = (to - start).try_normalize() else {
            return true;
        };
        let from = start - self.margin * dir;
        !self.accel.any_hit(from, dir, (to - from).dot(dir))
    }
}

/// The k-nearest density estimate of reflected radiance at `at`, before division by the
/// photons emitted: sum f(wo, wi) power / (pi r^2). When k photons are found within
/// `max_radius`, r is the distance to the k-th and the sum runs over the k - 1 nearer ones: in
/// a uniform photon density those lie uniformly in the disc of radius r, so the estimate is
/// exact in expectation (counting the k-th as well overestimates by k / (k - 1)). With fewer
/// found, r is the maximum radius and all of them count. `nearest` gives k and the maximum
/// radius (and holds the search's scratch); `index` maps tree points to photons; `keep`
/// filters them by flags.
pub fn density_estimate(
    tree: &KdTree,
    index: Option<&[u32]>,
    photons: &crate::components::Photons,
    at: &GatherPoint,
    keep: impl Fn(PhotonFlags) -> bool,
    nearest: &mut Nearest,
) -> Vec3 {
    let (k, max_radius) = (nearest.k(), nearest.max_radius());
    tree.nearest(at.p, k, max_radius, nearest);
    if nearest.found.is_empty() {
        return Vec3::ZERO;
    }
    let (r2, skip) = if nearest.found.len() == k {
        // found[0] is the k-th nearest: it sets the radius and is left out of the sum.
        (nearest.radius2(), 1)
    } else {
        (max_radius * max_radius, 0)
    };
    let mut sum = Vec3::ZERO;
    for &(_, i) in &nearest.found[skip..] {
        let k = index.map_or(i, |m| m[i as usize]) as usize;
        if keep(photons.flags[k])
            && let Some(v) = at.reflected(photons, k)
        {
            sum += v;
        }
    }
    sum / (std::f32::consts::PI * r2.max(f32::MIN_POSITIVE))
}

/// A photon map to estimate from: a kd-tree over (some of) `photons`, with each tree point's
/// index into them (`None`: the tree holds all, in order).
pub struct MapQuery<'a> {
    pub tree: &'a KdTree,
    pub index: Option<&'a [u32]>,
    pub photons: &'a crate::components::Photons,
    pub k: usize,
    pub max_radius: f32,
    /// 1 / photons emitted.
    pub scale: f32,
    /// Bounces a path may have (the photons a point gathers are limited by its depth).
    pub max_depth: u32,
}

impl MapQuery<'_> {
    /// Adds to each pixel's sum in `out` (slot = pixel) the density estimate at its point of
    /// `points`, weighted by the point's throughput; pixels without a point get nothing.
    /// Returns (estimates made, NaN or Inf estimates dropped).
    pub fn add_estimates(
        &self,
        data: &SceneData,
        points: &crate::components::VisiblePoints,
        keep: impl Fn(PhotonFlags) -> bool + Sync,
        out: &mut [glam::DVec3],
    ) -> (usize, u64) {
        use rayon::prelude::*;
        let chunk = crate::components::CHUNK;
        // One chunk per task: a pixel's cost varies over the image (k-nearest searches),
        // and rayon's default split (a few pieces per thread) left a core idle at the end.
        out.par_chunks_mut(chunk)
            .with_max_len(1)
            .enumerate()
            .map(|(c, out)| {
                let mut nearest = Nearest::new(self.k, self.max_radius);
                let (mut made, mut nonfinite) = (0, 0);
                for (j, sum) in out.iter_mut().enumerate() {
                    let pixel = c * chunk + j;
                    let Some(at) = GatherPoint::of(data, points, pixel, self.max_depth) else {
                        continue;
                    };
                    let l = density_estimate(
                        self.tree,
                        self.index,
                        self.photons,
                        &at,
                        &keep,
                        &mut nearest,
                    );
                    let value = points.beta[pixel] * l * self.scale;
                    if value.is_finite() {
                        *sum += value.as_dvec3();
                    } else {
                        nonfinite += 1;
                    }
                    made += 1;
                }
                (made, nonfinite)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    }
}

/// The systems of its graphs bound to the columns of `PhotonPass`.
mod bindings {
    use super::PhotonPass;
    use crate::systems::*;

    crate::bind! {
        PhotonPass:
        generate::photons::EmitPhotons {
            read data;
            write tracing;
        }
        shade::compact_photons::CompactPhotons {
            write tracing;
        }
        shade::scatter_photons::ScatterPhotons {
            read data;
            write tracing;
        }
        trace::closest::TraceClosest {
            read accel = data.accel, rays = tracing.rays, live = tracing.active;
            write hits = tracing.hits;
        }
    }
}
