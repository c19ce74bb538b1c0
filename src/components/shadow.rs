use glam::Vec3;

crate::soa! {
    /// Shadow rays of next-event estimation, slot for slot with the paths that cast them.
    /// A ray with `t_max == 0` is absent (no light sample was taken).
    pub struct ShadowRays, ShadowRaysChunk, ShadowRaysView, ShadowRay {
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        /// Radiance the path receives if the ray is unoccluded (MIS weight included).
        contribution: Vec3,
        unoccluded: bool,
    }
}
