use crate::sampling::SampleKey;
use glam::Vec3;

/// What a stored photon's path was.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhotonFlags(pub u8);

impl PhotonFlags {
    /// Stored at the first surface the photon met (direct light).
    pub const DIRECT: u8 = 1;
    /// Came from the light through one or more specular (delta) bounces only: L S+ D.
    pub const CAUSTIC: u8 = 2;

    #[inline]
    pub fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }
}

crate::soa! {
    /// Photons stored on non-specular surfaces: what density estimation reads.
    pub struct Photons, PhotonsChunk, PhotonsView, Photon {
        p: Vec3,
        /// Unit direction the photon came from (pointing away from the surface).
        wi: Vec3,
        /// Power carried (flux), before division by the photons emitted.
        power: Vec3,
        /// Unit geometric normal of the surface it landed on, on the side it arrived from
        /// (density estimation keeps to photons on the side and plane of the query).
        ng: Vec3,
        /// Scattering events before it landed.
        depth: u32,
        flags: PhotonFlags,
    }
}

crate::soa! {
    /// Photons in flight, one per slot, compacted as they end.
    pub struct PhotonWalkers, PhotonWalkersChunk, PhotonWalkersView, PhotonWalker {
        key: SampleKey,
        power: Vec3,
        /// Scattering events so far.
        depth: u32,
        /// Every scattering so far was specular (delta).
        specular_chain: bool,
        alive: bool,
    }
}
