//! References: long renders that stop and resume without losing or changing a sample.
//!
//! A reference `REF.exr` is rendered in chunks of whole passes. After every chunk, the film's
//! fixed-point sums and sample counts go to a checkpoint beside it, `REF.exr.checkpoint`, together
//! with what produced them (integrator, seed, depth cap, a fingerprint of the prepared scene);
//! then the EXR (float32, with its sample count and seed as header attributes) and a PNG
//! preview are written. Both files are written to a temporary name and renamed, so an
//! interruption at any moment leaves the previous complete pair.
//!
//! Running the same reference again continues from the checkpoint's passes. Samples are a pure
//! function of (seed, pixel, sample index, dimension) and the film's fixed-point sums do not
//! depend on the order of their samples, so the result equals an uninterrupted render bit for bit. A checkpoint made with a
//! different integrator, seed, depth cap or scene is refused rather than mixed in.
//!
//! The checkpoint file: the line `stagelight checkpoint 4`, one line of RON (the header
//! below, unknown fields refused, every value checked), then per pixel, row 0 first, the
//! film's sums of the three channels (each an i128 in units of 2^-64, `film::fixed`), the u64
//! sample count and, when the pixel data's length says so, the splat sums (light tracing's;
//! three more i128), all little-endian, then an FNV-1a 64 checksum of everything before it, the
//! first line and the header included (u64, little-endian). Version 3 files (f64 sums and
//! splat sums, 56 bytes a pixel) and version 2 files (whose checksum covered the pixels only)
//! are still read, their f64 sums rounded to the unit (exact for samples of 2^-41 and more).
//!
//! A checkpoint may hold a range of passes, `first_pass..passes`: the partial film of a
//! shard (`render` or `reference` with `--shard I/N`), which `stagelight merge` adds to the
//! other shards' films (`commands::merge`).
//!
//! While a run makes or continues a reference it holds `REF.exr.lock` (an advisory lock, let
//! go when the process ends however it ends): a second run on the same output is refused
//! instead of mixing its passes in.

use crate::film::fixed::{FIXED_RGB_BYTES, FixedRgb};
use crate::film::{Film, Image};
use crate::integrators::{
    Budget, Control, IntegratorKind, RenderSettings, Resume, SceneData, resume,
};
use crate::sampling::SamplerKind;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

const MAGIC: &str = "stagelight checkpoint 4\n";
/// Version 3: f64 sums, the checksum over the whole file.
const MAGIC_V3: &str = "stagelight checkpoint 3\n";
/// Version 2: f64 sums, the checksum over the pixel data only.
const MAGIC_V2: &str = "stagelight checkpoint 2\n";

/// Bytes per pixel in a version 2 or 3 checkpoint: the sum (3 x f64), the sample count (u64)
/// and the splat sum (3 x f64, light tracing's contributions), little-endian.
const PIXEL_BYTES_V3: usize = 56;

/// The EXR header attribute of a reference: one text attribute holding
/// `spp=N; seed=S; integrator=NAME; maxDepth=D; scene=PATH` (one attribute, because the EXR
/// writer stores custom attributes in hash order: one keeps the file's bytes reproducible).
pub const ATTRIBUTE: &str = "stagelight";

/// The fields of a reference's `stagelight` attribute, by name (empty for other EXRs).
pub fn reference_attributes(
    path: &Path,
) -> Result<std::collections::BTreeMap<String, String>, ReferenceError> {
    let attributes = Image::read_exr_attributes(path).map_err(|e| error(path, e.message))?;
    Ok(attributes
        .get(ATTRIBUTE)
        .map(|text| {
            // The scene comes last: its path may hold anything but a newline.
            text.splitn(5, "; ")
                .filter_map(|field| field.split_once('='))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        })
        .unwrap_or_default())
}

/// The seed references use unless told otherwise: far from the small seeds of ordinary
/// renders, so a render compared against a reference never shares its random numbers.
pub const DEFAULT_REFERENCE_SEED: u64 = 0x5eed_0000_0000_0001;

fn independent_sampler() -> String {
    SamplerKind::Independent.to_string()
}

/// What a checkpoint records besides the film.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointHeader {
    pub integrator: String,
    pub seed: u64,
    /// The sampler (`--sampler`); checkpoints from before samplers were chosen are
    /// `independent`.
    #[serde(default = "independent_sampler")]
    pub sampler: String,
    pub max_depth: u32,
    /// The scene file, as given when the reference was started (for messages only).
    pub scene: String,
    /// `scene_fingerprint` of the prepared scene, as 16 hex digits.
    pub scene_fingerprint: String,
    pub width: usize,
    pub height: usize,
    /// Finished passes (samples per pixel) in the film.
    pub passes: u64,
    /// Wall seconds spent rendering them, over all runs.
    pub seconds: f64,
    /// Non-finite samples rejected so far.
    pub nonfinite: u64,
    /// Non-finite splats (light tracing) rejected so far (absent from version 2 files).
    #[serde(default)]
    pub nonfinite_splats: u64,
    /// Samples and splats rejected as beyond the film's range (`Film::out_of_range`).
    #[serde(default)]
    pub out_of_range: u64,
    /// The first pass in the film: the film holds passes `first_pass..passes` (a shard's
    /// range; 0 for a whole render).
    #[serde(default)]
    pub first_pass: u64,
    /// For a shard: the pass its range ends at (a shard stopped early has `passes` below
    /// it) and the passes of the whole render the shards split.
    #[serde(default)]
    pub shard: Option<ShardRange>,
    /// The command that made it: `reference` or `render` (a render's shard).
    #[serde(default = "reference_command")]
    pub made_by: String,
    /// The integrator's settings that change its image, besides seed, sampler and depth cap,
    /// as text (`integrators::film_settings`; empty when all are defaults).
    #[serde(default)]
    pub settings: String,
    /// The film's sums are in units of 2^(unit_exponent - 64) (`film::fixed`: the power of
    /// two of the scene's brightest emission); 0 in files from before units followed the
    /// scene, which were all in units of 2^-64.
    #[serde(default)]
    pub unit_exponent: i32,
    /// Bytes of the integrator's saved state after the pixels (the photon mappers'
    /// references: `PassState::save`); 0, and not written, for the others.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub state: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// What part of a render a shard makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardRange {
    /// The pass the shard's range ends at (exclusive).
    pub end_pass: u64,
    /// Passes of the whole render.
    pub total_passes: u64,
}

fn reference_command() -> String {
    "reference".into()
}

impl CheckpointHeader {
    /// The header of a render about to start (no passes yet; a shard's at its first pass),
    /// as `reference` makes it (`made_by` is "reference").
    pub fn start(
        scene_path: &Path,
        data: &SceneData,
        integrator: IntegratorKind,
        settings: &RenderSettings,
        shard: Option<PassRange>,
    ) -> CheckpointHeader {
        let cam = data.scene.camera;
        let first_pass = shard.map_or(0, |r| r.first);
        CheckpointHeader {
            integrator: integrator.as_str().to_string(),
            seed: settings.seed,
            sampler: settings.sampler.to_string(),
            max_depth: settings.max_depth,
            scene: scene_path.display().to_string(),
            scene_fingerprint: format!("{:016x}", scene_fingerprint(data)),
            width: cam.width as usize,
            height: cam.height as usize,
            passes: first_pass,
            seconds: 0.0,
            nonfinite: 0,
            nonfinite_splats: 0,
            out_of_range: 0,
            first_pass,
            shard: shard.map(|r| ShardRange {
                end_pass: r.end,
                total_passes: r.total,
            }),
            made_by: reference_command(),
            settings: crate::integrators::film_settings(integrator, settings),
            state: 0,
            unit_exponent: Film::scene_unit_exponent(&data.scene),
        }
    }

    /// Whether the film is of an unbiased integrator: sums of its samples, one per pixel and
    /// pass. A biased integrator's shard (`render --shard`) holds its image times its weight
    /// (MLT: its mutations; the photon mappers: its passes x pixels) in every pixel, with
    /// the weight as every pixel's count, so that adding films averages the shards' images
    /// weighted by it (`commands::merge`).
    pub fn is_unbiased(&self) -> bool {
        IntegratorKind::all()
            .into_iter()
            .any(|k| k.is_unbiased() && k.as_str() == self.integrator)
    }

    /// Checks every value (the checksum vouches for the bytes, this for their sense).
    fn validate(&self) -> Result<(), String> {
        let Some(kind) = IntegratorKind::all()
            .into_iter()
            .find(|k| k.as_str() == self.integrator)
        else {
            return Err(format!(
                "integrator \"{}\" is not one stagelight has",
                crate::scene::echo(&self.integrator)
            ));
        };
        // A biased integrator's film is a render's shard, or a resumable photon reference's.
        let render_shard = self.shard.is_some() && self.made_by == "render";
        let photon_reference = kind.resumes() && self.made_by == "reference";
        if !(kind.is_unbiased() || render_shard || photon_reference) {
            return Err(format!(
                "integrator {kind} is biased and does not resume: its films are only the \
                 shards of a render"
            ));
        }
        if self.state > 0 && (kind.is_unbiased() || !kind.resumes()) {
            return Err(format!("a saved state for {kind}, which keeps none"));
        }
        let max = crate::scene::format::MAX_IMAGE_SIZE as usize;
        if !(1..=max).contains(&self.width) || !(1..=max).contains(&self.height) {
            return Err(format!(
                "image size {}x{} outside 1..={max}",
                self.width, self.height
            ));
        }
        if !(self.seconds.is_finite() && self.seconds >= 0.0) {
            return Err(format!(
                "render seconds {} are not a non-negative number",
                self.seconds
            ));
        }
        if self.scene_fingerprint.len() != 16
            || !self
                .scene_fingerprint
                .bytes()
                .all(|b| b.is_ascii_hexdigit())
        {
            return Err("the scene fingerprint is not 16 hex digits".into());
        }
        if self.first_pass > self.passes {
            return Err(format!(
                "first pass {} after the last, {}",
                self.first_pass, self.passes
            ));
        }
        if let Some(shard) = self.shard
            && !(self.first_pass < shard.end_pass
                && self.passes <= shard.end_pass
                && shard.end_pass <= shard.total_passes)
        {
            return Err(format!(
                "shard range {}..{} of {} passes does not hold passes {}..{}",
                self.first_pass, shard.end_pass, shard.total_passes, self.first_pass, self.passes
            ));
        }
        if !matches!(self.made_by.as_str(), "render" | "reference") {
            return Err(format!(
                "made by \"{}\", not render or reference",
                crate::scene::echo(&self.made_by)
            ));
        }
        if !(-1000..=1000).contains(&self.unit_exponent) {
            return Err(format!(
                "film unit 2^({} - 64), beyond what a film uses",
                self.unit_exponent
            ));
        }
        let samples =
            (self.passes - self.first_pass).checked_mul((self.width * self.height) as u64);
        if self.is_unbiased() && samples.is_none_or(|n| self.nonfinite > n) {
            return Err(format!(
                "{} rejected samples of {} passes",
                self.nonfinite, self.passes
            ));
        }
        Ok(())
    }
}

/// A checkpoint: its header and the film of its passes.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    pub header: CheckpointHeader,
    pub film: Film,
}

/// A reference could not be made, resumed or read.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct ReferenceError {
    pub path: PathBuf,
    pub message: String,
}

fn error(path: &Path, message: impl std::fmt::Display) -> ReferenceError {
    ReferenceError {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// The checkpoint beside a reference EXR: `REF.exr.checkpoint`.
pub fn checkpoint_path(reference: &Path) -> PathBuf {
    let mut name = reference.as_os_str().to_owned();
    name.push(".checkpoint");
    PathBuf::from(name)
}

/// FNV-1a, 64 bits: a small stable hash (std's hasher may change between releases).
#[derive(Clone, Copy)]
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Fnv1a {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
    fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

impl std::fmt::Write for Fnv1a {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.update(s.as_bytes());
        Ok(())
    }
}

/// A fingerprint of what a render depends on in a prepared scene: camera, triangles,
/// materials (sides and textures too) and emitters (their Debug text, which prints floats exactly). A scene edited
/// after a reference was started, mesh files included, gets a different fingerprint.
pub fn scene_fingerprint(data: &SceneData) -> u64 {
    use std::fmt::Write;
    let s = &data.scene;
    let mut hash = Fnv1a::new();
    let _ = write!(
        hash,
        "{:?}{:?}{:?}{:?}{:?}{:?}{:?}{:?}",
        s.camera,
        s.triangles,
        s.materials,
        s.emitters,
        s.black_behind,
        s.varying,
        s.textures,
        s.triangle_uvs
    );
    hash.0
}

impl Checkpoint {
    /// Writes the checkpoint to a temporary file and renames it over `path`.
    pub fn write(&self, path: &Path) -> Result<(), ReferenceError> {
        let bytes = self.to_bytes().map_err(|e| error(path, e))?;
        crate::film::output::write_bytes(path, &bytes).map_err(|e| error(path, e.message))
    }

    /// Writes the checkpoint with an integrator's saved state after its pixels (see
    /// `CheckpointHeader::state`), as `write` does.
    pub fn write_with_state(&self, path: &Path, state: &[u8]) -> Result<(), ReferenceError> {
        let bytes = self
            .to_bytes_with_state(state)
            .map_err(|e| error(path, e))?;
        crate::film::output::write_bytes(path, &bytes).map_err(|e| error(path, e.message))
    }

    /// The checkpoint file's bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, String> {
        self.to_bytes_with_state(&[])
    }

    /// The checkpoint file's bytes with `state` after the pixels (the header's `state` says
    /// how many bytes).
    pub fn to_bytes_with_state(&self, state: &[u8]) -> Result<Vec<u8>, String> {
        let splats = self.film.fixed_splats();
        // The header says the film's unit, whatever it was given, and the state's length.
        let header = CheckpointHeader {
            state: state.len() as u64,
            unit_exponent: self.film.unit_exponent(),
            ..self.header.clone()
        };
        let header = ron::to_string(&header).map_err(|e| e.to_string())?;
        let pixels = self.film.width * self.film.height;
        let per_pixel = FIXED_RGB_BYTES * (1 + usize::from(!splats.is_empty())) + 8;
        let mut bytes = Vec::with_capacity(MAGIC.len() + header.len() + 1 + pixels * per_pixel + 8);
        bytes.extend_from_slice(MAGIC.as_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.push(b'\n');
        let put = |bytes: &mut Vec<u8>, rgb: &FixedRgb| bytes.extend_from_slice(&rgb.to_le_bytes());
        for (i, (sum, &count)) in self
            .film
            .fixed_sums()
            .iter()
            .zip(self.film.sample_counts())
            .enumerate()
        {
            put(&mut bytes, sum);
            bytes.extend_from_slice(&count.to_le_bytes());
            if let Some(splat) = splats.get(i) {
                put(&mut bytes, splat);
            }
        }
        bytes.extend_from_slice(state);
        let mut hash = Fnv1a::new();
        hash.update(&bytes);
        bytes.extend_from_slice(&hash.0.to_le_bytes());
        Ok(bytes)
    }

    /// Reads a checkpoint; a damaged or foreign file is an error naming what is wrong.
    pub fn read(path: &Path) -> Result<Checkpoint, ReferenceError> {
        Ok(Checkpoint::read_with_state(path)?.0)
    }

    /// Reads a checkpoint and the integrator's saved state in it (empty when it has none).
    pub fn read_with_state(path: &Path) -> Result<(Checkpoint, Vec<u8>), ReferenceError> {
        let bytes = std::fs::read(path).map_err(|e| error(path, e))?;
        Checkpoint::from_bytes_with_state(&bytes).map_err(|message| error(path, message))
    }

    /// Reads a checkpoint from its bytes; the message does not name the file.
    pub fn from_bytes(bytes: &[u8]) -> Result<Checkpoint, String> {
        Ok(Checkpoint::from_bytes_with_state(bytes)?.0)
    }

    /// Reads a checkpoint and its saved state from its bytes.
    pub fn from_bytes_with_state(bytes: &[u8]) -> Result<(Checkpoint, Vec<u8>), String> {
        let damaged = |what: &str| {
            format!("damaged checkpoint ({what}); delete it to start the reference over")
        };
        let (version, rest) = if let Some(rest) = bytes.strip_prefix(MAGIC.as_bytes()) {
            (4, rest)
        } else if let Some(rest) = bytes.strip_prefix(MAGIC_V3.as_bytes()) {
            (3, rest)
        } else if let Some(rest) = bytes.strip_prefix(MAGIC_V2.as_bytes()) {
            (2, rest)
        } else {
            return Err("not a stagelight checkpoint".into());
        };
        let newline = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| damaged("no header line"))?;
        let header_text =
            std::str::from_utf8(&rest[..newline]).map_err(|_| damaged("header is not text"))?;
        let header: CheckpointHeader = ron::from_str(header_text).map_err(|e| {
            damaged(&format!(
                "header: {}",
                crate::scene::clip(&e.to_string(), 200)
            ))
        })?;
        if version < 4 && (header.first_pass != 0 || header.shard.is_some() || header.state > 0) {
            return Err(damaged("a version 4 header in an older file"));
        }
        let payload = &rest[newline + 1..];
        let pixels = header
            .width
            .checked_mul(header.height)
            .ok_or_else(|| damaged("image size"))?;
        // Version 4 pixels hold splat sums or not, which their length says.
        let sizes: &[usize] = if version == 4 {
            &[FIXED_RGB_BYTES + 8, 2 * FIXED_RGB_BYTES + 8]
        } else {
            &[PIXEL_BYTES_V3]
        };
        let state_len = usize::try_from(header.state).map_err(|_| damaged("state size"))?;
        let data_len_of = |pixel_bytes: usize| {
            pixels
                .checked_mul(pixel_bytes)
                .and_then(|n| n.checked_add(8))
                .and_then(|n| n.checked_add(state_len))
                .ok_or_else(|| damaged("image size"))
        };
        let Some(&pixel_bytes) = sizes
            .iter()
            .find(|&&b| data_len_of(b).is_ok_and(|n| n == payload.len()))
        else {
            return Err(damaged(&format!(
                "{} bytes of pixel data where {}x{} pixels need {}",
                payload.len(),
                header.width,
                header.height,
                data_len_of(sizes[0])?
            )));
        };
        let has_splats = pixel_bytes == 2 * FIXED_RGB_BYTES + 8;
        let data_len = payload.len() - 8;
        let (data, checksum) = payload.split_at(data_len);
        let (data, state) = data.split_at(data_len - state_len);
        let mut hash = Fnv1a::new();
        // Versions 3 and 4 cover the whole file; version 2 covered the pixel data only.
        hash.update(if version >= 3 {
            &bytes[..bytes.len() - 8]
        } else {
            data
        });
        if hash.0.to_le_bytes() != checksum {
            return Err(damaged("checksum mismatch"));
        }
        header
            .validate()
            .map_err(|what| damaged(&format!("header: {what}")))?;
        let word = |chunk: &[u8], i: usize| -> [u8; 8] {
            let mut w = [0u8; 8];
            w.copy_from_slice(&chunk[i * 8..i * 8 + 8]);
            w
        };
        let mut sum = Vec::with_capacity(pixels);
        let mut samples = Vec::with_capacity(pixels);
        let mut splat = Vec::new();
        if version == 4 {
            const COUNT: usize = FIXED_RGB_BYTES;
            for chunk in data.chunks_exact(pixel_bytes) {
                sum.push(FixedRgb::from_le_bytes(&chunk[..COUNT]));
                samples.push(u64::from_le_bytes(word(&chunk[COUNT..], 0)));
                if has_splats {
                    splat.push(FixedRgb::from_le_bytes(&chunk[COUNT + 8..]));
                }
            }
        } else {
            let fixed = |v: DVec3| {
                FixedRgb::from_dvec3(v, header.unit_exponent)
                    .ok_or_else(|| damaged("a pixel sum beyond the film's range (+-2^63)"))
            };
            for chunk in data.chunks_exact(PIXEL_BYTES_V3) {
                let f = |i| f64::from_le_bytes(word(chunk, i));
                sum.push(fixed(DVec3::new(f(0), f(1), f(2)))?);
                samples.push(u64::from_le_bytes(word(chunk, 3)));
                splat.push(fixed(DVec3::new(f(4), f(5), f(6)))?);
            }
        }
        let in_film = if header.is_unbiased() {
            header.passes - header.first_pass
        } else {
            // A biased shard's weight, the same in every pixel.
            samples.first().copied().unwrap_or(0).max(1)
        };
        if let Some(&n) = samples.iter().find(|&&n| n != in_film) {
            return Err(damaged(&format!(
                "a pixel with {n} samples where {in_film} were recorded",
            )));
        }
        let mut film = Film::from_fixed_parts(
            header.width,
            header.height,
            header.unit_exponent,
            sum,
            samples,
            splat,
            header.nonfinite,
        )
        .ok_or_else(|| damaged("image size"))?;
        film.nonfinite_splats = header.nonfinite_splats;
        film.out_of_range = header.out_of_range;
        Ok((Checkpoint { header, film }, state.to_vec()))
    }
}

/// The lock a run holds on a reference while it makes or continues it.
pub struct ReferenceLock {
    path: PathBuf,
    _file: std::fs::File,
}

/// The lock file beside a reference EXR: `REF.exr.lock`.
pub fn lock_path(reference: &Path) -> PathBuf {
    let mut name = reference.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

impl ReferenceLock {
    /// Takes the lock of `reference`, or says that another run holds it.
    pub fn acquire(reference: &Path) -> Result<ReferenceLock, ReferenceError> {
        let path = lock_path(reference);
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| error(&path, e))?;
        }
        loop {
            let file = std::fs::OpenOptions::new()
                .create(true)
                .truncate(false)
                .write(true)
                .open(&path)
                .map_err(|e| error(&path, format!("cannot make the lock file: {e}")))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => {
                    return Err(error(
                        reference,
                        format!(
                            "another stagelight run is making this reference (it holds {}); \
                             wait for it to finish, or choose another output",
                            path.display()
                        ),
                    ));
                }
                Err(std::fs::TryLockError::Error(e)) => {
                    return Err(error(&path, format!("cannot lock: {e}")));
                }
            }
            // The holder before us may have removed the file between our open and our lock:
            // the lock counts only on the file that is still at the path.
            if same_inode(&file, &path) {
                return Ok(ReferenceLock { path, _file: file });
            }
        }
    }
}

impl Drop for ReferenceLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(unix)]
fn same_inode(file: &std::fs::File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_inode(_: &std::fs::File, path: &Path) -> bool {
    path.exists()
}

/// How long a reference renders, in total over all its runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReferenceBudget {
    SamplesPerPixel(u64),
    Seconds(f64),
}

/// A reference to make or continue.
pub struct ReferenceJob<'a> {
    /// The scene file (for messages and the EXR's attributes).
    pub scene_path: &'a Path,
    pub data: Arc<SceneData>,
    pub integrator: IntegratorKind,
    pub settings: RenderSettings,
    pub budget: ReferenceBudget,
    /// The EXR to write; the checkpoint and a PNG preview go beside it.
    pub output: &'a Path,
    /// Wall time between checkpoints (whole passes; at least one pass per checkpoint).
    pub checkpoint_every: Duration,
    /// Only these passes of the budget's (a shard; the budget is then samples per pixel, the
    /// whole render's passes).
    pub shard: Option<PassRange>,
}

/// The passes a shard renders, `first..end`, of a render of `total` passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PassRange {
    pub first: u64,
    pub end: u64,
    pub total: u64,
}

impl PassRange {
    /// The seed of a shard of a biased integrator (MLT, the photon mappers), which is an
    /// independent run: the render's own seed for the shard that starts at pass 0 (so it is
    /// the plain render of its passes), a hash of the seed and the first pass for the others.
    pub fn independent_seed(&self, seed: u64) -> u64 {
        if self.first == 0 {
            seed
        } else {
            crate::sampling::mix64(seed ^ crate::sampling::mix64(self.first))
        }
    }

    /// Shard `index` of `count` (1-based) of `total` passes: the passes split as evenly as
    /// whole passes allow, earlier shards never larger than later ones.
    pub fn shard(index: u64, count: u64, total: u64) -> Result<PassRange, String> {
        if count == 0 || index == 0 || index > count {
            return Err(format!(
                "--shard {index}/{count}: I/N needs 1 <= I <= N (shard I of N)"
            ));
        }
        if count > total {
            return Err(format!(
                "--shard {index}/{count}: {count} shards of {total} passes would leave some \
                 empty (at most one shard per pass)"
            ));
        }
        let at = |i: u64| (total as u128 * i as u128 / count as u128) as u64;
        Ok(PassRange {
            first: at(index - 1),
            end: at(index),
            total,
        })
    }

    /// An explicit range `first..end` of `total` passes.
    pub fn explicit(first: u64, end: u64, total: u64) -> Result<PassRange, String> {
        if first >= end || end > total {
            return Err(format!(
                "--pass-range {first}..{end}: needs FIRST < END <= the render's passes ({total})"
            ));
        }
        Ok(PassRange { first, end, total })
    }
}

/// What a reference run did.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceOutcome {
    /// Passes found in the checkpoint at the start (0 for a new reference).
    pub passes_before: u64,
    /// Passes in the reference now.
    pub passes: u64,
    /// Render seconds over all runs.
    pub seconds: f64,
    /// Render seconds of this run.
    pub seconds_this_run: f64,
    pub nonfinite: u64,
    pub interrupted: bool,
    /// True when the checkpoint already met the budget and nothing was rendered.
    pub already_complete: bool,
    pub width: usize,
    pub height: usize,
}

/// Makes a reference, or continues one from its checkpoint, until its budget is met or `stop`
/// is set; the files on disk always hold the finished passes. `progress(done, target)` follows
/// the budget's unit (passes or render seconds, over all runs).
pub fn render_reference(
    job: &ReferenceJob,
    stop: &AtomicBool,
    progress: &(dyn Fn(f64, f64) + Sync),
) -> Result<ReferenceOutcome, ReferenceError> {
    let cam = job.data.scene.camera;
    if let crate::film::PixelFilter::Gaussian(_) = cam.filter {
        return Err(error(
            &job.data.scene.source,
            "a reference's checkpoints hold box-filtered sums, not the gaussian rfilter's \
             weights: add <rfilter type=\"box\"/> to the film (or render the image with \
             `stagelight render`)",
        ));
    }
    let _lock = ReferenceLock::acquire(job.output)?;
    let checkpoint_file = checkpoint_path(job.output);
    let (width, height) = (cam.width as usize, cam.height as usize);
    let mut header = CheckpointHeader::start(
        job.scene_path,
        &job.data,
        job.integrator,
        &job.settings,
        job.shard,
    );
    // The photon mappers (the biased integrators `reference` accepts) continue from their
    // saved state; their film is their image weighted by their passes x pixels, as a
    // `render --shard`'s, so that `merge` averages shards alike. Their shard is an
    // independent run of its passes with its own seed (`PassRange::independent_seed`), which
    // counts its passes from 0.
    let keeps_state = !job.integrator.is_unbiased();
    let (settings, offset) = match job.shard {
        Some(range) if keeps_state => (
            RenderSettings {
                seed: range.independent_seed(job.settings.seed),
                ..job.settings
            },
            range.first,
        ),
        _ => (job.settings, 0),
    };
    let mut state = Vec::new();
    let mut film = if checkpoint_file.exists() {
        let (checkpoint, saved) = Checkpoint::read_with_state(&checkpoint_file)?;
        check_compatible(&checkpoint.header, &header, &checkpoint_file)?;
        header = checkpoint.header;
        if keeps_state && header.passes > header.first_pass && saved.is_empty() {
            return Err(error(
                &checkpoint_file,
                format!(
                    "holds the image of {} passes of {} but not its state (a merge of shards?), \
                     so it cannot be continued: choose another output",
                    header.passes - header.first_pass,
                    job.integrator
                ),
            ));
        }
        state = saved;
        checkpoint.film
    } else {
        if job.output.exists() {
            return Err(error(
                job.output,
                format!(
                    "exists without its checkpoint ({}), so it cannot be resumed: delete it or \
                     choose another output",
                    checkpoint_file.display()
                ),
            ));
        }
        Film::for_scene(&job.data)
    };
    let passes_before = header.passes;
    // A shard's budget is its range's end.
    let end_pass = |spp: u64| job.shard.map_or(spp, |r| r.end);
    let done = |h: &CheckpointHeader| match job.budget {
        ReferenceBudget::SamplesPerPixel(spp) => h.passes >= end_pass(spp),
        ReferenceBudget::Seconds(s) => h.seconds >= s,
    };
    let already_complete = done(&header);
    // The checkpoint alone may exist when the previous run stopped between its two renames.
    if already_complete && !job.output.exists() {
        write_images(job, &header, &film)?;
    }

    let mut seconds_this_run = 0.0;
    let mut interrupted = false;
    let mut seconds_per_pass: Option<f64> = None;
    let every = job.checkpoint_every.as_secs_f64();
    while !done(&header) {
        if stop.load(Ordering::SeqCst) {
            interrupted = true;
            break;
        }
        // One pass first to learn the pass time, then about `every` seconds of passes (a
        // time budget too is cut into whole passes, so every chunk makes progress).
        let passes_in =
            |seconds: f64| seconds_per_pass.map_or(1, |t| (seconds / t.max(1e-9)).round() as u64);
        let chunk = match job.budget {
            ReferenceBudget::SamplesPerPixel(spp) => {
                passes_in(every).clamp(1, end_pass(spp) - header.passes)
            }
            ReferenceBudget::Seconds(s) => passes_in((s - header.seconds).min(every)).max(1),
        };
        // The run's own passes (a biased shard counts from its first pass).
        let run_passes = header.passes - offset;
        let from = if !keeps_state {
            Some(Resume {
                film,
                first_pass: header.first_pass,
                passes: header.passes,
                state: None,
            })
        } else {
            (run_passes > 0).then(|| Resume {
                film,
                first_pass: 0,
                passes: run_passes,
                state: Some(std::mem::take(&mut state)),
            })
        };
        let (chunk_start, seconds_before) = (Instant::now(), header.seconds);
        let on_wave = |passes: u64, _: Option<u64>| match job.budget {
            ReferenceBudget::SamplesPerPixel(spp) => progress((passes + offset) as f64, spp as f64),
            ReferenceBudget::Seconds(s) => {
                progress(seconds_before + chunk_start.elapsed().as_secs_f64(), s)
            }
        };
        let control = Control {
            stop,
            progress: &on_wave,
        };
        let budget = Budget::SamplesPerPixel(run_passes + chunk);
        let outcome = match from {
            Some(from) => resume(
                job.integrator,
                job.data.clone(),
                &settings,
                budget,
                &control,
                from,
            ),
            None => crate::integrators::render(
                job.integrator,
                job.data.clone(),
                &settings,
                budget,
                &control,
            ),
        };
        let wall = outcome.wall.as_secs_f64();
        let new_passes = outcome.passes - run_passes;
        if new_passes > 0 {
            seconds_per_pass = Some(wall / new_passes as f64);
        }
        film = if keeps_state {
            state = outcome
                .state
                .expect("the integrators that keep a state save it");
            weighted_film(&outcome.film.image(), outcome.samples, &outcome.film)
        } else {
            outcome.film
        };
        header.passes = outcome.passes + offset;
        header.seconds += wall;
        header.nonfinite = film.nonfinite;
        header.nonfinite_splats = film.nonfinite_splats;
        header.out_of_range = film.out_of_range;
        seconds_this_run += wall;
        if new_passes > 0 {
            Checkpoint {
                header: header.clone(),
                film: film.clone(),
            }
            .write_with_state(&checkpoint_file, &state)?;
            write_images(job, &header, &film)?;
        }
        if outcome.interrupted {
            interrupted = true;
            break;
        }
    }
    Ok(ReferenceOutcome {
        passes_before,
        passes: header.passes,
        seconds: header.seconds,
        seconds_this_run,
        nonfinite: header.nonfinite,
        interrupted,
        already_complete,
        width,
        height,
    })
}

/// A biased integrator's film for a shard or a reference: `image` times `weight` in every
/// pixel, with `weight` as every pixel's count (see `CheckpointHeader::is_unbiased`), and
/// `film`'s rejected counts.
pub fn weighted_film(image: &Image, weight: u64, film: &Film) -> Film {
    let n = image.pixels.len();
    let sums = image
        .pixels
        .iter()
        .map(|p| p.as_dvec3() * weight as f64)
        .collect();
    let mut weighted = Film::from_parts(
        image.width,
        image.height,
        sums,
        vec![weight; n],
        Vec::new(),
        film.nonfinite,
    )
    .expect("one sum and count per pixel");
    weighted.nonfinite_splats = film.nonfinite_splats;
    weighted.out_of_range += film.out_of_range;
    weighted
}

/// A checkpoint continues only the render that made it.
fn check_compatible(
    found: &CheckpointHeader,
    wanted: &CheckpointHeader,
    path: &Path,
) -> Result<(), ReferenceError> {
    let depth = |d: u32| {
        if d == u32::MAX {
            "unlimited".to_string()
        } else {
            d.to_string()
        }
    };
    let mismatch = if found.integrator != wanted.integrator {
        Some(format!(
            "integrator {}, not {} (use --integrator {})",
            found.integrator, wanted.integrator, found.integrator
        ))
    } else if found.seed != wanted.seed {
        Some(format!(
            "seed {}, not {} (use --seed {})",
            found.seed, wanted.seed, found.seed
        ))
    } else if found.sampler != wanted.sampler {
        Some(format!(
            "sampler {}, not {} (use --sampler {})",
            found.sampler, wanted.sampler, found.sampler
        ))
    } else if found.max_depth != wanted.max_depth {
        Some(format!(
            "maximum depth {}, not {}",
            depth(found.max_depth),
            depth(wanted.max_depth)
        ))
    } else if (found.width, found.height) != (wanted.width, wanted.height) {
        Some(format!(
            "an image of {}x{}, not {}x{}",
            found.width, found.height, wanted.width, wanted.height
        ))
    } else if found.settings != wanted.settings {
        Some(format!(
            "settings \"{}\", not \"{}\"",
            found.settings, wanted.settings
        ))
    } else if (found.first_pass, found.shard) != (wanted.first_pass, wanted.shard) {
        let range = |h: &CheckpointHeader| match h.shard {
            Some(r) => format!(
                "the shard of passes {}..{} of {}",
                h.first_pass, r.end_pass, r.total_passes
            ),
            None => "a whole render".to_string(),
        };
        Some(format!("{}, not {}", range(found), range(wanted)))
    } else if found.scene_fingerprint != wanted.scene_fingerprint {
        Some(format!(
            "a different scene ({} as it was then; now {})",
            found.scene, wanted.scene
        ))
    } else {
        None
    };
    match mismatch {
        Some(what) => Err(error(
            path,
            format!(
                "this checkpoint was made with {what}; it cannot continue this render \
                 (delete it and its EXR to start over, or choose another output)"
            ),
        )),
        None => Ok(()),
    }
}

/// The EXR with its provenance attributes, and an sRGB PNG preview beside it.
fn write_images(
    job: &ReferenceJob,
    header: &CheckpointHeader,
    film: &Film,
) -> Result<(), ReferenceError> {
    write_reference_images(job.output, header, film)
}

/// A reference's EXR, with its `stagelight` attribute (the samples per pixel in the film),
/// and its PNG preview (`output` with the extension png).
pub fn write_reference_images(
    output: &Path,
    header: &CheckpointHeader,
    film: &Film,
) -> Result<(), ReferenceError> {
    let image = film.image();
    let depth = if header.max_depth == u32::MAX {
        "unlimited".to_string()
    } else {
        header.max_depth.to_string()
    };
    // The sampler is named only when it is not the default, so references made before
    // samplers were chosen keep their header.
    let sampler = if header.sampler == independent_sampler() {
        String::new()
    } else {
        format!("sampler={}; ", header.sampler)
    };
    let attributes = [(
        ATTRIBUTE,
        format!(
            "spp={}; seed={}; {sampler}integrator={}; maxDepth={depth}; scene={}",
            header.passes - header.first_pass,
            header.seed,
            header.integrator,
            header.scene.replace('\n', " ")
        ),
    )];
    image
        .write_exr_with_attributes(output, &attributes)
        .map_err(|e| error(output, e.message))?;
    let png = output.with_extension("png");
    image.write_png(&png).map_err(|e| error(&png, e.message))
}

/// A reference image with what its header says about it.
pub struct LoadedReference {
    pub image: Image,
    /// Samples per pixel and seed from the header, when it was made by `reference`.
    pub spp: Option<u64>,
    pub seed: Option<u64>,
    pub integrator: Option<String>,
    /// What the reference's own noise adds to a relMSE against it, when its two independent
    /// halves lie beside it as REF.a.exr and REF.b.exr (as ../mitsuba's references do).
    pub noise_relmse: Option<f64>,
}

/// REF.a.exr and REF.b.exr beside REF.exr, when both exist.
fn reference_halves(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let half = |tag: &str| path.with_extension(format!("{tag}.exr"));
    let (a, b) = (half("a"), half("b"));
    (a.is_file() && b.is_file()).then_some((a, b))
}

/// Reads a reference EXR and checks it: every value finite, the size `width` x `height`.
pub fn load_reference(
    path: &Path,
    width: usize,
    height: usize,
) -> Result<LoadedReference, ReferenceError> {
    let image = Image::read_exr(path).map_err(|e| error(path, e.message))?;
    if let Some(i) = image.pixels.iter().position(|p| !p.is_finite()) {
        return Err(error(
            path,
            format!(
                "the reference has a NaN or infinite value at pixel ({}, {})",
                i % image.width,
                i / image.width
            ),
        ));
    }
    if (image.width, image.height) != (width, height) {
        return Err(error(
            path,
            format!(
                "the reference is {}x{} but the scene renders {}x{}",
                image.width, image.height, width, height
            ),
        ));
    }
    let attributes = reference_attributes(path)?;
    let noise_relmse = match reference_halves(path) {
        None => None,
        Some((a_path, b_path)) => {
            let read = |p: &Path| Image::read_exr(p).map_err(|e| error(p, e.message));
            let (a, b) = (read(&a_path)?, read(&b_path)?);
            Some(
                crate::metrics::reference_noise(&image, &a, &b).ok_or_else(|| {
                    error(
                        &a_path,
                        format!(
                            "the halves {} and {} do not match the reference's {}x{} or hold \
                             a NaN or infinite value",
                            a_path.display(),
                            b_path.display(),
                            width,
                            height
                        ),
                    )
                })?,
            )
        }
    };
    Ok(LoadedReference {
        image,
        spp: attributes.get("spp").and_then(|s| s.parse().ok()),
        seed: attributes.get("seed").and_then(|s| s.parse().ok()),
        integrator: attributes.get("integrator").cloned(),
        noise_relmse,
    })
}
