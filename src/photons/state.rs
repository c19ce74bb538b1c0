//! The photon mappers' state after a pass, as bytes a later run continues from (a
//! reference's checkpoint keeps them; `PassState::save` and `restore`). Every random number is
//! a pure function of (seed, pass, index), so the seed stream's position is the pass count,
//! and what photons and camera rays a pass traces needs nothing saved. What is saved:
//!
//! - PPM and SPPM: per visible point (PPM: per hit point) its radius R, photon count N, flux
//!   tau and direct sum D, exactly (their bits), and the photons emitted and NaN/Inf values
//!   dropped so far. PPM's hit points themselves are pass 0's eye rays traced again from the
//!   seed; their number and a hash of their positions are kept to prove it.
//! - PM: its film's fixed-point sums and counts; its photon maps are traced again from the
//!   seed.
//!
//! The bytes: a tag naming the integrator's layout, then little-endian numbers. The
//! checkpoint's checksum and header (scene, seed, settings) vouch for them; a layout or
//! length that does not match is a bug, and `restore` panics with what it found.

use crate::components::{PixelEstimates, VisiblePoints};
use crate::film::Film;
use crate::film::fixed::{FIXED_RGB_BYTES, FixedRgb};
use glam::{DVec3, Vec3};

/// Little-endian writer of a saved state.
#[derive(Default)]
pub struct StateWriter(pub Vec<u8>);

impl StateWriter {
    pub fn new(tag: &[u8; 8]) -> StateWriter {
        StateWriter(tag.to_vec())
    }
    pub fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn dvec3(&mut self, v: DVec3) {
        for c in v.to_array() {
            self.f64(c);
        }
    }
}

/// Reader of what `StateWriter` wrote; a short or foreign state panics (see the module).
pub struct StateReader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> StateReader<'a> {
    pub fn new(bytes: &'a [u8], tag: &[u8; 8]) -> StateReader<'a> {
        assert!(
            bytes.starts_with(tag),
            "a saved state of another layout (expected {:?})",
            String::from_utf8_lossy(tag)
        );
        StateReader { bytes, at: 8 }
    }
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let end = self.at + N;
        assert!(end <= self.bytes.len(), "a saved state cut short");
        let mut out = [0u8; N];
        out.copy_from_slice(&self.bytes[self.at..end]);
        self.at = end;
        out
    }
    pub fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
    }
    pub fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    pub fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
    pub fn dvec3(&mut self) -> DVec3 {
        DVec3::new(self.f64(), self.f64(), self.f64())
    }
    pub fn fixed(&mut self) -> FixedRgb {
        FixedRgb::from_le_bytes(&self.take::<FIXED_RGB_BYTES>())
    }
    /// Panics unless every byte was read.
    pub fn finish(self) {
        assert_eq!(
            self.at,
            self.bytes.len(),
            "a saved state with bytes left over"
        );
    }
}

/// A hash of the visible points' pixels and positions (FNV-1a over their bits): PPM's hit
/// points traced again must be the ones the saved statistics belong to.
pub fn points_hash(visible: &VisiblePoints, points: usize) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut put = |v: u32| {
        for b in v.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for i in 0..points {
        put(visible.pixel[i]);
        let p: Vec3 = visible.p[i];
        for c in p.to_array() {
            put(c.to_bits());
        }
    }
    h
}

/// Layout tag of PPM's and SPPM's state.
pub const PROGRESSIVE_TAG: &[u8; 8] = b"sppm st1";
/// Layout tag of PM's state.
pub const PM_TAG: &[u8; 8] = b"pm stat1";

/// Writes the progressive statistics of `points` visible points.
pub fn write_estimates(w: &mut StateWriter, e: &PixelEstimates, points: usize) {
    for i in 0..points {
        w.f32(e.radius[i]);
        w.f64(e.photons[i]);
        w.dvec3(e.flux[i]);
        w.dvec3(e.direct[i]);
    }
}

/// Reads what `write_estimates` wrote into the first `points` slots of `e`.
pub fn read_estimates(r: &mut StateReader, e: &mut PixelEstimates, points: usize) {
    for i in 0..points {
        e.radius[i] = r.f32();
        e.photons[i] = r.f64();
        e.flux[i] = r.dvec3();
        e.direct[i] = r.dvec3();
    }
}

/// Writes a film's unit, sums, counts and rejected counts (PM; no splats).
pub fn write_film(w: &mut StateWriter, film: &Film) {
    w.u64(film.unit_exponent() as i64 as u64);
    for (sum, &count) in film.fixed_sums().iter().zip(film.sample_counts()) {
        w.0.extend_from_slice(&sum.to_le_bytes());
        w.u64(count);
    }
    w.u64(film.nonfinite);
    w.u64(film.out_of_range);
}

/// Reads what `write_film` wrote, for a `width` x `height` film.
pub fn read_film(r: &mut StateReader, width: usize, height: usize) -> Film {
    let unit_exponent = r.u64() as i64 as i32;
    let pixels = width * height;
    let (mut sums, mut counts) = (Vec::with_capacity(pixels), Vec::with_capacity(pixels));
    for _ in 0..pixels {
        sums.push(r.fixed());
        counts.push(r.u64());
    }
    let nonfinite = r.u64();
    let mut film = Film::from_fixed_parts(
        width,
        height,
        unit_exponent,
        sums,
        counts,
        Vec::new(),
        nonfinite,
    )
    .expect("one sum and count per pixel");
    film.out_of_range = r.u64();
    film
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_come_back_bit_for_bit() {
        let mut e = PixelEstimates::new(3);
        for i in 0..3 {
            e.radius[i] = 0.1 + i as f32 / 7.0;
            e.photons[i] = 1.0 / (i as f64 + 3.0);
            e.flux[i] = DVec3::new(1e-300, f64::MIN_POSITIVE, 1.0 / 3.0);
            e.direct[i] = DVec3::splat(i as f64 * 0.1);
        }
        let mut w = StateWriter::new(PROGRESSIVE_TAG);
        write_estimates(&mut w, &e, 3);
        let mut back = PixelEstimates::new(3);
        let mut r = StateReader::new(&w.0, PROGRESSIVE_TAG);
        read_estimates(&mut r, &mut back, 3);
        r.finish();
        for i in 0..3 {
            assert_eq!(back.radius[i].to_bits(), e.radius[i].to_bits());
            assert_eq!(back.photons[i].to_bits(), e.photons[i].to_bits());
            assert_eq!(back.flux[i], e.flux[i]);
            assert_eq!(back.direct[i], e.direct[i]);
        }
    }

    #[test]
    #[should_panic(expected = "another layout")]
    fn a_foreign_state_is_refused() {
        let w = StateWriter::new(PM_TAG);
        StateReader::new(&w.0, PROGRESSIVE_TAG);
    }
}
