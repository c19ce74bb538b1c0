use crate::sampling::SampleKey;
use glam::{DVec3, Vec3};

/// `VisiblePoints::triangle` of a pixel whose camera chain found no surface to gather at.
pub const NO_VISIBLE_POINT: u32 = u32::MAX;

crate::soa! {
    /// Camera chains of the photon mappers in flight: a camera ray that follows specular
    /// (delta) bounces until it meets a surface where photons are gathered. Compacted as
    /// they end; each carries its pixel.
    pub struct CameraChains, CameraChainsChunk, CameraChainsView, CameraChain {
        pixel: u32,
        key: SampleKey,
        /// Product of the specular weights since the camera.
        beta: Vec3,
        /// Emission met along the chain, weighted by `beta` at the time (and, after a
        /// glossy bounce, by its MIS weight against the light sample taken there).
        emitted: Vec3,
        /// Solid-angle density of the last bounce's direction: 0 after the camera or a
        /// specular bounce (whose emission no light sample could find).
        bsdf_pdf: f32,
        /// Bounces from the camera so far: 0 until the camera ray's first hit scatters (a
        /// final-gather chain starts one past its visible point's).
        depth: u32,
        alive: bool,
        /// Where the chain ended (`triangle == NO_VISIBLE_POINT`: nowhere to gather).
        p: Vec3,
        p_error: Vec3,
        /// Geometric normal, on the side the chain arrived from (for diffuse surfaces).
        ng: Vec3,
        /// Shading normal, in the hemisphere of `ng`.
        ns: Vec3,
        wo: Vec3,
        triangle: u32,
    }
}

crate::soa! {
    /// Where camera chains met a surface that is not specular, and what they carried there:
    /// one per pixel (slot = pixel), or for PPM's ray tree a list of a pixel's hit points; or
    /// the glossy surfaces chains followed (`CameraWalk::glossy`), where only light is sampled.
    pub struct VisiblePoints, VisiblePointsChunk, VisiblePointsView, VisiblePoint {
        pixel: u32,
        /// The point's rank among its pixel's (0 where a pixel has one; its light sample's
        /// dimensions).
        branch: u32,
        p: Vec3,
        p_error: Vec3,
        ng: Vec3,
        ns: Vec3,
        wo: Vec3,
        /// The surface's triangle, or `NO_VISIBLE_POINT`.
        triangle: u32,
        beta: Vec3,
        /// Emission the chain met on its way (seen directly or through specular surfaces).
        emitted: Vec3,
        /// The chain's bounces before it reached the point (0: the camera ray's first hit), so
        /// a photon gathered here must keep the whole path within the maximum depth
        /// (`photons::photon_depth_limit`).
        depth: u32,
    }
}

crate::soa! {
    /// Per-pixel statistics of progressive photon mapping (slot = pixel): the gather
    /// radius, the photon count N and flux tau of the progressive estimate, and the sum over
    /// passes of the light found without photons (emission seen and direct light sampled).
    pub struct PixelEstimates, PixelEstimatesChunk, PixelEstimatesView, PixelEstimate {
        radius: f32,
        photons: f64,
        flux: DVec3,
        direct: DVec3,
        /// This pass's photons M found within the radius and their flux tau_M.
        pass_photons: u32,
        pass_flux: Vec3,
    }
}
