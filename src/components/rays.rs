use glam::Vec3;

/// `Hits::triangle` of a ray that left the scene.
pub const MISS: u32 = u32::MAX;

crate::soa! {
    /// Rays to trace for closest hits, one per path slot. Directions are unit length.
    pub struct Rays, RaysChunk, RaysView, Ray {
        origin: Vec3,
        dir: Vec3,
    }
}

crate::soa! {
    /// Closest hits of `Rays`, slot for slot: distance, triangle (or `MISS`) and barycentrics.
    pub struct Hits, HitsChunk, HitsView, Hit {
        t: f32,
        triangle: u32,
        b1: f32,
        b2: f32,
    }
}
