//! Samplers as components: the one place that decides which number a system gets for
//! (stream, index, sample, dimension).
//!
//! A render picks one [`Sampler`] (a `Copy` value the systems share); a system makes a
//! [`SampleKey`] once per path with [`Sampler::key`], stores it in its path slot, and reads
//! numbers with [`Sampler::get`] / [`Sampler::get2`]. Every number is a pure function of
//! (sampler, stream, index, sample, dimension), so images do not depend on threads or waves.
//!
//! - `Independent`: the hash of (seed, tagged index, sample, dimension), bit-identical to the
//!   keys the systems made with `SampleKey::new` before samplers existed.
//! - `Sobol`: Owen-scrambled Sobol' points in Morton order over the pixels (pbrt-v4's
//!   ZSobolSampler, Ahmed and Wonka 2020): every power-of-two prefix of a pixel's samples is
//!   stratified in each 2D pair, and with a known sample count neighbouring pixels' samples
//!   together are stratified too (see "Unknown sample counts" on [`Sampler::Sobol`]).
//! - `Primary`: numbers read from a primary-sample store (Metropolis chains mutate it).

use super::morton;
use super::sobol::{owen_sobol0, owen_sobol1, reverse_low, shuffle_reversed, to_unit};
use super::{PrimarySamples, SampleKey, mix64};
use glam::Vec2;
use std::fmt;

/// Who draws the numbers. Streams never share numbers:
///
/// - `Independent` tags the index with high bits (today's keys): Camera 0000, FinalGather
///   0001, DirectLight 0010 and Light 1000 in the top four bits, for pixel indices below
///   2^60; Photon 11 in the top two bits, for photon indices below 2^62. The prefixes differ,
///   so two streams' tagged indices never meet ([`Stream::index_limit`]; `key` asserts it in
///   debug builds).
/// - `Sobol` hashes the stream's ordinal into every scramble seed and keeps it in the key's
///   top three bits.
/// - `Primary` gives Camera, Light and Connection their own interleaved store dimensions.
///
/// `Connection` is BDPT's numbers for joining subpaths (the s = 1 light sample). Under
/// `Independent` and `Sobol` it is the camera stream itself: the camera subpath reserves
/// per-vertex dimensions for them (`bdpt::CAMERA_DIMS_PER_VERTEX`), which keeps today's
/// images. Under `Primary` it is a stream of its own, as in pbrt-v4's MLT sampler.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Stream {
    /// Camera paths and BDPT camera subpaths; index = pixel, sample = sample index.
    Camera = 0,
    /// BDPT light subpaths; index = pixel, sample = sample index.
    Light = 1,
    /// BDPT connections; index = pixel, sample = sample index (the camera key, see above).
    Connection = 2,
    /// Photons; index = photon index within the pass, sample = pass.
    Photon = 3,
    /// PM final-gather chains; index = pixel, sample = pass.
    FinalGather = 4,
    /// Direct light at the photon mappers' visible points; index = pixel, sample = pass.
    DirectLight = 5,
}

/// Streams that have primary-sample store dimensions, interleaved: a stream's dimension d is
/// store dimension `d * PRIMARY_STREAMS + ordinal`.
pub const PRIMARY_STREAMS: u32 = 3;

/// Key bits above this hold the stream's ordinal (Sobol, Primary).
const ORDINAL_SHIFT: u32 = 61;

impl Stream {
    pub const ALL: [Stream; 6] = [
        Stream::Camera,
        Stream::Light,
        Stream::Connection,
        Stream::Photon,
        Stream::FinalGather,
        Stream::DirectLight,
    ];

    #[inline]
    pub const fn ordinal(self) -> u64 {
        self as u64
    }

    /// The bits `Independent` ors into the index (today's tags; Connection uses the camera's).
    #[inline]
    pub const fn independent_tag(self) -> u64 {
        match self {
            Stream::Camera | Stream::Connection => 0,
            Stream::Light => 1 << 63,
            Stream::Photon => 3 << 62,
            Stream::DirectLight => 1 << 61,
            Stream::FinalGather => 1 << 60,
        }
    }

    /// Indices below this keep `Independent`'s tags disjoint: 2^62 for photons, 2^60 for the
    /// pixel streams.
    #[inline]
    pub const fn index_limit(self) -> u64 {
        match self {
            Stream::Photon => 1 << 62,
            _ => 1 << 60,
        }
    }

    /// The primary-sample store dimension that holds this stream's dimension `dim`, if any
    /// (Camera, Light and Connection interleave; other streams always hash).
    #[inline]
    pub fn primary_dim(self, dim: u32) -> Option<u32> {
        match self {
            Stream::Camera | Stream::Light | Stream::Connection => {
                dim.checked_mul(PRIMARY_STREAMS)?.checked_add(self as u32)
            }
            _ => None,
        }
    }

    /// The streams whose index is a pixel (everything but photons).
    #[inline]
    const fn is_pixel(self) -> bool {
        !matches!(self, Stream::Photon)
    }
}

/// The sampler a render is asked for (`--sampler independent|sobol`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SamplerKind {
    #[default]
    Independent,
    Sobol,
}

impl SamplerKind {
    pub const ALL: [SamplerKind; 2] = [SamplerKind::Independent, SamplerKind::Sobol];

    pub fn as_str(self) -> &'static str {
        match self {
            SamplerKind::Independent => "independent",
            SamplerKind::Sobol => "sobol",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            SamplerKind::Independent => "a hash per number (uncorrelated, white noise)",
            SamplerKind::Sobol => "Owen-scrambled Sobol' in Morton order (pbrt-v4's ZSobol)",
        }
    }
}

/// An unknown sampler name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown sampler '{0}' (expected independent or sobol)")]
pub struct UnknownSampler(pub String);

impl std::str::FromStr for SamplerKind {
    type Err = UnknownSampler;
    /// Case-insensitive.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        SamplerKind::ALL
            .into_iter()
            .find(|k| k.as_str() == lower)
            .ok_or_else(|| UnknownSampler(s.to_string()))
    }
}

impl fmt::Display for SamplerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// `log2_spp` of a Sobol sampler made without a sample count: 2^16 samples per pixel before
/// the next batch starts. Choose it with [`Sampler::with_samples_per_pixel`] where the count
/// is known.
pub const DEFAULT_LOG2_SPP: u32 = 16;

/// Largest `log2_spp`: a Sobol' index keeps 24 bits (the precision of an `f32` in [0, 1)), so
/// a pixel's block cannot be larger.
pub const MAX_LOG2_SPP: u32 = NET_BITS;

/// Largest `log2_res` (images up to 65536 pixels on a side).
pub const MAX_LOG2_RES: u32 = 16;

/// Bits of a Sobol key's index within its scramble block. An `f32` in [0, 1) keeps 24 bits,
/// and digit j of Sobol' dimension 0 is index bit j, so index bits from 24 up could only
/// matter below the `f32`'s precision: points 2^24 apart would coincide, and pixels whose
/// Morton codes agree in their low 24 - log2_spp bits would draw the same numbers (a pattern
/// repeating every 16 pixels at the default count). Those bits go into the scramble seed
/// instead: each block of 2^24 indices (a square of 2^(24 - log2_spp) pixels) is its own
/// independently scrambled net.
const NET_BITS: u32 = 24;

/// Photon keys (Sobol): photon index below 2^36, pass below 2^25.
const PHOTON_INDEX_BITS: u32 = 36;

const MORTON_SALT: u64 = 0x2c0d_e0f0_12e2_7ab3;
const PACK_MULTIPLIER: u64 = 0xd6e8_feb8_6659_fd93;
const SHUFFLE_SALT: u64 = 0x71d6_7fff_eda6_0000;

/// The number source of a render. `Copy`; the systems read it from the render's settings.
///
/// A key is only meaningful to the sampler that made it: make keys with [`Sampler::key`] and
/// read them with the same sampler's [`Sampler::get`] / [`Sampler::get2`].
#[derive(Clone, Copy)]
pub enum Sampler<'a> {
    /// A hash per number (`SampleKey::new` then `SampleKey::get`). Cost per `get`: one
    /// `mix64`; per `key`: three.
    Independent { seed: u64 },
    /// Owen-scrambled Sobol' with Morton-ordered pixels (ZSobol). Make it with
    /// [`Sampler::new`]: pixel `p` is (p % width, p / width) in a 2^log2_res square, and
    /// sample `s` of a pixel is index `s mod 2^log2_spp` in the pixel's block of
    /// 2^log2_spp Sobol' indices.
    ///
    /// Unknown sample counts: ZSobol must know the count in advance, as neighbouring pixels
    /// own neighbouring blocks. `new` assumes `DEFAULT_LOG2_SPP` (65536 samples per pixel);
    /// samples from 2^log2_spp on start a new batch, an independently scrambled copy of the
    /// whole sequence, so there is no upper limit, and progressive or time-budgeted renders
    /// need nothing else. A pixel's samples are shuffled by a nested permutation, so every
    /// power-of-two prefix of them is stratified whatever the count: per-pixel error is the
    /// same as with the exact count. What a count larger than the real one gives up is the
    /// joint stratification of neighbouring pixels (ZSobol's blue-noise error): with the
    /// exact count ([`Sampler::with_samples_per_pixel`]) a 2x2 square's samples together are
    /// one net, which lowers the error of the square's mean (figures in the tests).
    ///
    /// Cost (`benches/sampler.rs`): per `get` two `mix64`, two Laine-Karras hashes and two
    /// bit reversals, about 14 ns against the independent 1-2 ns; per `get2` one hash and
    /// reversal more, about 18 ns; per `key` one `mix64` per Morton digit, about 45 ns at
    /// 1920 x 1080.
    Sobol {
        seed: u64,
        width: u32,
        /// log2 of the power-of-two square that holds the image.
        log2_res: u32,
        /// log2 of the samples per pixel of one batch (at most `MAX_LOG2_SPP`).
        log2_spp: u32,
    },
    /// Numbers come from a primary-sample column (MLT): slot = the key's index (the sample is
    /// ignored). Camera, Light and Connection dimension d read store dimension
    /// `d * PRIMARY_STREAMS + ordinal` (pbrt-v4's interleaving: a number keeps its meaning
    /// when a subpath's length changes); dimensions beyond `store.dims()` are the hash of
    /// (the slot's tail seed, stream, dimension) (`PrimarySamples`: fresh every proposal, a
    /// symmetric independence proposal), and every dimension of Photon, FinalGather and
    /// DirectLight the hash of (fallback_seed, stream, slot, dimension).
    Primary {
        store: &'a PrimarySamples,
        fallback_seed: u64,
    },
}

impl fmt::Debug for Sampler<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Sampler::Independent { seed } => {
                f.debug_struct("Independent").field("seed", &seed).finish()
            }
            Sampler::Sobol {
                seed,
                width,
                log2_res,
                log2_spp,
            } => f
                .debug_struct("Sobol")
                .field("seed", &seed)
                .field("width", &width)
                .field("log2_res", &log2_res)
                .field("log2_spp", &log2_spp)
                .finish(),
            // The store can be large: its shape only.
            Sampler::Primary {
                store,
                fallback_seed,
            } => f
                .debug_struct("Primary")
                .field("slots", &store.slots())
                .field("dims", &store.dims())
                .field("fallback_seed", &fallback_seed)
                .finish(),
        }
    }
}

/// ceil(log2(n)) for n >= 1.
#[inline]
fn ceil_log2(n: u64) -> u32 {
    if n <= 1 {
        0
    } else {
        64 - (n - 1).leading_zeros()
    }
}

#[inline]
const fn low_bits(n: u32) -> u64 {
    if n >= 64 { u64::MAX } else { (1 << n) - 1 }
}

/// The independent sampler at seed 0 (for stores built before their render's sampler is set).
impl Default for Sampler<'_> {
    fn default() -> Self {
        Sampler::Independent { seed: 0 }
    }
}

impl Sampler<'_> {
    /// The sampler of a `width` x `height` render. `Sobol` assumes `DEFAULT_LOG2_SPP`
    /// samples per pixel (see [`Sampler::Sobol`]).
    pub fn new(kind: SamplerKind, seed: u64, width: u32, height: u32) -> Sampler<'static> {
        match kind {
            SamplerKind::Independent => Sampler::Independent { seed },
            SamplerKind::Sobol => {
                let log2_res = ceil_log2(width.max(height).max(1) as u64);
                assert!(
                    log2_res <= MAX_LOG2_RES,
                    "sobol: {width} x {height} is larger than 2^{MAX_LOG2_RES} on a side"
                );
                Sampler::Sobol {
                    seed,
                    width: width.max(1),
                    log2_res,
                    log2_spp: DEFAULT_LOG2_SPP,
                }
            }
        }
    }

    /// The same sampler for a render that will take `spp` samples per pixel (rounded up to a
    /// power of two, at most 2^`MAX_LOG2_SPP`): under `Sobol`, neighbouring pixels' samples
    /// are then stratified together. Other samplers are unchanged.
    pub fn with_samples_per_pixel(self, spp: u64) -> Self {
        match self {
            Sampler::Sobol {
                seed,
                width,
                log2_res,
                ..
            } => Sampler::Sobol {
                seed,
                width,
                log2_res,
                log2_spp: ceil_log2(spp.max(1)).min(MAX_LOG2_SPP),
            },
            other => other,
        }
    }

    /// The kind this sampler was made from (`None` for `Primary`).
    pub fn kind(&self) -> Option<SamplerKind> {
        match self {
            Sampler::Independent { .. } => Some(SamplerKind::Independent),
            Sampler::Sobol { .. } => Some(SamplerKind::Sobol),
            Sampler::Primary { .. } => None,
        }
    }

    /// The key of `stream`'s numbers for `index` (a pixel, a photon index, or under
    /// `Primary` the slot) and `sample` (the sample index, or the pass). Index ranges:
    /// `Independent`: below [`Stream::index_limit`]; `Sobol`: a pixel of the image with
    /// sample below 2^(61 - max(2 log2_res + log2_spp, 24) + log2_spp) (at least 2^29; 2^39
    /// at 1920 x 1080 by default), or a photon index below 2^36 with pass below 2^25;
    /// `Primary`: a slot of the store. Debug builds assert them.
    #[inline(always)]
    pub fn key(&self, stream: Stream, index: u64, sample: u64) -> SampleKey {
        match *self {
            Sampler::Independent { seed } => {
                debug_assert!(
                    index < stream.index_limit(),
                    "{stream:?} index {index} would overlap another stream's tag"
                );
                SampleKey::new(seed, index | stream.independent_tag(), sample)
            }
            Sampler::Sobol {
                seed,
                width,
                log2_res,
                log2_spp,
            } => sobol_key(seed, width, log2_res, log2_spp, stream, index, sample),
            Sampler::Primary { store, .. } => {
                debug_assert!(
                    index < store.slots() as u64,
                    "primary slot {index} of {}",
                    store.slots()
                );
                SampleKey(stream.ordinal() << ORDINAL_SHIFT | index)
            }
        }
    }

    /// Number `dim` of `key`, in [0, 1).
    #[inline(always)]
    pub fn get(&self, key: SampleKey, dim: u32) -> f32 {
        // The independent hash inlines into every system's loop; the others are calls.
        match *self {
            Sampler::Independent { .. } => key.get(dim),
            _ => self.get_other(key, dim),
        }
    }

    #[inline(never)]
    fn get_other(&self, key: SampleKey, dim: u32) -> f32 {
        match *self {
            Sampler::Independent { .. } => key.get(dim),
            Sampler::Sobol { seed, log2_spp, .. } => {
                let (index, h) = sobol_point(seed, log2_spp, key, dim);
                to_unit(owen_sobol0(index, h as u32))
            }
            Sampler::Primary {
                store,
                fallback_seed,
            } => primary_get(store, fallback_seed, key, dim),
        }
    }

    /// Numbers `dim` and `dim + 1` of `key` as a 2D point: draw every 2D quantity (a pixel
    /// jitter, a BSDF or light sample) with one `get2`, never with two `get`s, because under
    /// `Sobol` only the pair of one `get2` is stratified jointly. `get2(key, d).x` is always
    /// `get(key, d)`; `.y` is `get(key, d + 1)` under `Independent` and `Primary`, and under
    /// `Sobol` the pair's second Sobol' dimension. Treat a `get2` at `d` as using up
    /// dimensions `d` and `d + 1`.
    #[inline(always)]
    pub fn get2(&self, key: SampleKey, dim: u32) -> Vec2 {
        match *self {
            Sampler::Independent { .. } => key.get2(dim),
            _ => self.get2_other(key, dim),
        }
    }

    #[inline(never)]
    fn get2_other(&self, key: SampleKey, dim: u32) -> Vec2 {
        match *self {
            Sampler::Independent { .. } => key.get2(dim),
            Sampler::Sobol { seed, log2_spp, .. } => {
                let (index, h) = sobol_point(seed, log2_spp, key, dim);
                Vec2::new(
                    to_unit(owen_sobol0(index, h as u32)),
                    to_unit(owen_sobol1(index, (h >> 32) as u32)),
                )
            }
            Sampler::Primary {
                store,
                fallback_seed,
            } => Vec2::new(
                primary_get(store, fallback_seed, key, dim),
                primary_get(store, fallback_seed, key, dim + 1),
            ),
        }
    }
}

/// A Sobol key: `ordinal << 61 | batch << batch_shift | index`, where `index` is the ZSobol
/// index (permuted Morton code << log2_spp | sample within the batch) or the photon index,
/// and `batch` the sample's batch (or the pass). The index's low `NET_BITS` bits are the
/// Sobol' index; everything above them only seeds the scramble. The bits that `get` shuffles
/// (the sample within the batch, or a photon index's low 24) are stored bit-reversed, the
/// order the shuffle works in, which saves `get` a bit reversal.
#[inline]
fn sobol_key(
    seed: u64,
    width: u32,
    log2_res: u32,
    log2_spp: u32,
    stream: Stream,
    index: u64,
    sample: u64,
) -> SampleKey {
    debug_assert!(log2_spp <= MAX_LOG2_SPP && log2_res <= MAX_LOG2_RES);
    // Connection numbers are camera-key dimensions.
    let stream = if stream == Stream::Connection {
        Stream::Camera
    } else {
        stream
    };
    let ordinal = stream.ordinal() << ORDINAL_SHIFT;
    if !stream.is_pixel() {
        debug_assert!(
            index >> PHOTON_INDEX_BITS == 0,
            "photon index {index} >= 2^36"
        );
        debug_assert!(
            sample >> (ORDINAL_SHIFT - PHOTON_INDEX_BITS) == 0,
            "photon pass {sample} >= 2^25"
        );
        // Beyond the limits (release builds), passes and indices wrap, never into the ordinal.
        let index = index & low_bits(PHOTON_INDEX_BITS);
        let pass = sample & low_bits(ORDINAL_SHIFT - PHOTON_INDEX_BITS);
        let index = (index & !low_bits(NET_BITS)) | reverse_low(index as u32, NET_BITS) as u64;
        return SampleKey(ordinal | pass << PHOTON_INDEX_BITS | index);
    }
    let (x, y) = (index % width as u64, index / width as u64);
    debug_assert!(y >> log2_res == 0, "pixel {index} outside the image");
    let code = morton::encode(x as u32, y as u32);
    let morton_seed = mix64(mix64(seed ^ MORTON_SALT) ^ stream.ordinal());
    let code = morton::permute_digits(code, log2_res, morton_seed);
    let z = code << log2_spp | reverse_low(sample as u32, log2_spp) as u64;
    let batch = sample >> log2_spp;
    let batch_shift = (2 * log2_res + log2_spp).max(NET_BITS);
    debug_assert!(
        batch >> (ORDINAL_SHIFT - batch_shift) == 0,
        "sample {sample}: too many batches of 2^{log2_spp}"
    );
    SampleKey(ordinal | (batch & low_bits(ORDINAL_SHIFT - batch_shift)) << batch_shift | z)
}

/// The shuffled Sobol' index of dimension `dim` of a Sobol key, and the 64-bit hash whose
/// halves seed the Owen scrambles of the pair's two coordinates.
///
/// The scramble seed hashes (seed, stream, batch, index block, dim) and not the pixel, so
/// all pixels of a block share it and their samples together stay one net. The shuffle of the
/// sample bits hashes the pixel too, so that a prefix of samples is a different sub-block in
/// every pixel, and the dimension, so that two dimensions pair their numbers differently
/// (with one order for all dimensions, Owen scrambles of the same index would agree in their
/// first digit up to a constant flip).
#[inline]
fn sobol_point(seed: u64, log2_spp: u32, key: SampleKey, dim: u32) -> (u32, u64) {
    debug_assert!(dim >> NET_BITS == 0, "dimension {dim} >= 2^24");
    let k = key.0;
    let shuffled_bits = if k >> ORDINAL_SHIFT == Stream::Photon.ordinal() {
        NET_BITS
    } else {
        log2_spp
    };
    let index = (k & low_bits(NET_BITS)) as u32;
    let block = k >> NET_BITS;
    // (block, dim) packed without overlap; the odd multiplier spreads it over all 64 bits, so
    // that xoring the seed (unmixed) cannot cancel it for nearby seeds.
    let h = mix64(seed ^ (block << NET_BITS | dim as u64).wrapping_mul(PACK_MULTIPLIER));
    let pixel = (index >> shuffled_bits) as u64;
    // A full mix: seeds derived by a multiply alone differ between two dimensions by the same
    // offset in every pixel, and the two shuffles then correlate the dimensions image-wide.
    let shuffle_seed = mix64(h ^ SHUFFLE_SALT ^ pixel) as u32;
    let mask = low_bits(shuffled_bits) as u32;
    let within = shuffle_reversed(index & mask, shuffled_bits, shuffle_seed);
    ((index & !mask) | within, h)
}

#[inline]
fn primary_get(store: &PrimarySamples, fallback_seed: u64, key: SampleKey, dim: u32) -> f32 {
    let ordinal = key.0 >> ORDINAL_SHIFT;
    let slot = key.0 & low_bits(ORDINAL_SHIFT);
    if ordinal < PRIMARY_STREAMS as u64 {
        let d = dim as u64 * PRIMARY_STREAMS as u64 + ordinal;
        if d < store.dims() as u64 {
            return store.get(slot as usize, d as u32);
        }
        // Past the stored numbers: the hash of (the slot's tail seed, stream, dim), the same
        // in whichever slot the vector is evaluated (a seed's replay).
        return SampleKey::new(store.tail(slot as usize), ordinal, 0).get(dim);
    }
    // The key holds (stream, slot): the hash of (fallback_seed, stream, slot, dim).
    SampleKey::new(fallback_seed, key.0, 0).get(dim)
}

#[cfg(test)]
mod tests;
