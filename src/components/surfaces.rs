use glam::Vec3;

crate::soa! {
    /// The surface point of each path's hit, computed once per bounce and read by every
    /// system that shades or samples lights there.
    pub struct Surfaces, SurfacesChunk, SurfacesView, HitSurface {
        p: Vec3,
        /// Per-axis absolute error bound of `p`.
        p_error: Vec3,
        /// Unit geometric normal (from the winding).
        ng: Vec3,
        /// Unit shading normal, in the hemisphere of `ng`.
        ns: Vec3,
        /// The material the hit sees, as `PreparedScene::uniform_material_index_seen` gives
        /// it; written only where the scene has no textures (else the hit's material is
        /// looked up with them, `look_up_textures`).
        material: u32,
    }
}
