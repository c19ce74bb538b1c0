//! The rays a render traced, kept by bounce (`stagelight rays`): what the recording systems
//! (`systems/trace/record_rays.rs`) append to after each trace system has run.

use glam::Vec3;

/// One traced ray as `stagelight rays` writes it: origin, t_min, direction, t_max (the
/// layout of a row of closest.npy and shadow.npy).
pub type RayRow = [f32; 8];

/// The closest hit a render found for one ray: its distance and triangle id (infinity and
/// `MISS` when nothing was hit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracedHit {
    pub t: f32,
    pub triangle: u32,
}

/// The rays of one bounce, in the order they were traced, and what the renderer found:
/// closest hits for closest-hit rays, occlusion for shadow rays (the other stays empty).
#[derive(Clone, Debug, Default)]
pub struct BounceRays {
    pub rays: Vec<RayRow>,
    pub hits: Vec<TracedHit>,
    pub occluded: Vec<bool>,
}

/// Rays recorded during a render, by bounce: bounce k holds the closest-hit rays of depth
/// k (0: camera rays) and the shadow rays cast from the points those rays found.
#[derive(Clone, Debug, Default)]
pub struct RayRecord {
    pub closest: Vec<BounceRays>,
    pub shadow: Vec<BounceRays>,
    /// The first sample of the wave being recorded, and its bounce: a new wave restarts at
    /// bounce 0.
    pub wave_first: Option<u64>,
    pub bounce: usize,
}

impl RayRecord {
    /// The store of bounce `bounce` in `stores`, created (with those before it) if missing.
    pub fn bounce_store(stores: &mut Vec<BounceRays>, bounce: usize) -> &mut BounceRays {
        if stores.len() <= bounce {
            stores.resize_with(bounce + 1, BounceRays::default);
        }
        &mut stores[bounce]
    }
}

/// A ray row from its parts.
#[inline]
pub fn ray_row(origin: Vec3, t_min: f32, dir: Vec3, t_max: f32) -> RayRow {
    [
        origin.x, origin.y, origin.z, t_min, dir.x, dir.y, dir.z, t_max,
    ]
}
