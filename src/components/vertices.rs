use crate::sampling::SampleKey;
use glam::Vec3;

crate::soa! {
    /// Vertices of bidirectional subpaths at one depth: slot `k` is vertex `depth` of subpath
    /// `k` (camera subpaths first, then light subpaths). Stored depth by depth, so a bounce of
    /// the subpath walk writes one contiguous store.
    pub struct PathVertices, PathVerticesChunk, PathVerticesView, PathVertex {
        p: Vec3,
        /// Per-axis bound on the floating-point error of `p` (for spawning rays).
        p_error: Vec3,
        /// Unit geometric normal as the triangle winds it (the camera's forward axis at a
        /// camera vertex).
        ng: Vec3,
        /// Unit shading normal.
        ns: Vec3,
        /// The triangle the vertex lies on (its material and emitter follow from it);
        /// `CAMERA_VERTEX` at a camera vertex.
        triangle: u32,
        /// Throughput of the subpath up to and including this vertex's sampling density.
        beta: Vec3,
        /// Density (area measure) of sampling this vertex from the previous one of its subpath.
        pdf_fwd: f32,
        /// Density (area measure) of sampling this vertex from the next one, were the subpath
        /// generated in the opposite direction.
        pdf_rev: f32,
        /// The subpath scattered here by a delta lobe.
        delta: bool,
    }
}

/// `PathVertices::triangle` of a camera vertex.
pub const CAMERA_VERTEX: u32 = u32::MAX;

crate::soa! {
    /// Subpaths being extended, one per slot, compacted as they end.
    pub struct Walkers, WalkersChunk, WalkersView, Walker {
        /// The subpath this walker extends (index into the vertex stores).
        subpath: u32,
        key: SampleKey,
        /// Throughput of the ray being traced.
        beta: Vec3,
        /// Solid-angle density of the ray's direction (0 after a delta lobe).
        pdf_dir: f32,
        /// Russian roulette compares `beta` against this (the throughput the walk started
        /// with), so that a light subpath's emitted power does not make it immortal.
        roulette_scale: f32,
        alive: bool,
    }
}

crate::soa! {
    /// Which film position each connection of a wave feeds, slot for slot with its shadow ray.
    pub struct Connections, ConnectionsChunk, ConnectionsView, Connection {
        /// The sample (index in the wave) whose subpaths the connection joins.
        sample: u32,
        /// Pixel the contribution lands in: the sample's own, or for light tracing (t = 1)
        /// the pixel the light vertex projects to.
        pixel: u32,
        /// Light subpath vertices used (s).
        s: u16,
        /// Camera subpath vertices used (t).
        t: u16,
    }
}
