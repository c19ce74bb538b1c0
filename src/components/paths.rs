use crate::sampling::SampleKey;
use glam::Vec3;

/// Bit flags of a path.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PathFlags(pub u8);

impl PathFlags {
    /// The last scattering was a delta lobe (or the path is a camera ray): emission found
    /// next counts fully, as light sampling could not have found it.
    pub const SPECULAR: u8 = 1;
    /// The path has ended (its BSDF sample carried nothing, or Russian roulette ended it).
    pub const DEAD: u8 = 2;

    #[inline]
    pub fn has(self, bit: u8) -> bool {
        self.0 & bit != 0
    }
    #[inline]
    pub fn set(&mut self, bit: u8, on: bool) {
        if on {
            self.0 |= bit;
        } else {
            self.0 &= !bit;
        }
    }
}

crate::soa! {
    /// The state of camera paths in flight.
    pub struct Paths, PathsChunk, PathsView, Path {
        /// Index of the path's sample in the wave (film position follows from it).
        sample: u32,
        /// Random numbers of this (seed, pixel, sample index).
        key: SampleKey,
        throughput: Vec3,
        radiance: Vec3,
        /// Scattering events so far (0 for a camera ray).
        depth: u32,
        /// Solid-angle pdf of the BSDF sample that made the current ray (for MIS on emitters).
        bsdf_pdf: f32,
        flags: PathFlags,
    }
}
