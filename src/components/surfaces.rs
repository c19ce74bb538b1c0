use glam::Vec3;

crate::soa! {
    /// The surface point of each path's hit, computed once per bounce and read by every
    /// system that shades or samples lights there.
    pub struct Surfaces, SurfacesChunk, SurfacesView, SurfacePoint {
        p: Vec3,
        /// Per-axis absolute error bound of `p`.
        p_error: Vec3,
        /// Unit geometric normal (from the winding).
        ng: Vec3,
        /// Unit shading normal, in the hemisphere of `ng`.
        ns: Vec3,
    }
}
