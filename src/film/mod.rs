//! The film: per-pixel sums in fixed point (`fixed`: each sample rounded once to the film's
//! unit, 2^-64 times the power of two of the scene's brightest emission, and summed as an
//! integer, so the sum does not depend on the order of its samples and two films of disjoint
//! samples of one scene add up to the film of all of them, bit for bit), non-finite
//! samples counted and never added, and images written as EXR (float32 linear RGB, unscaled)
//! and PNG (sRGB preview), each under a temporary name and renamed (`output`).
//!
//! A rejected (NaN or infinite) sample still counts in its pixel's sample count: it weighs as
//! black in the pixel's mean, so a pixel with rejected samples is darkened by their share.
//! Every integrator does the same (the photon mappers drop a non-finite estimate as zero),
//! and the reports count them; `stagelight render` warns when their share is large. A sample
//! beyond the film's range (a pixel sum beyond +-2^63 times the film's scale) is rejected the
//! same way and counted apart (`out_of_range`).

pub mod fixed;
pub mod output;

pub use crate::scene::filter::{self, Gaussian, PixelFilter};
use fixed::{FixedRgb, Rejected};

use glam::{DVec3, Vec2, Vec3};
use std::io::{Read, Seek};
use std::path::Path;

/// Pixels per block of the splat sums that `Film::add_splats` gives one task.
pub const SPLAT_BLOCK: usize = 4096;

/// Splats (pixel, value, raster position) gathered by one task, sorted by `SPLAT_BLOCK` block
/// of their pixel, for `Film::add_splats`.
#[derive(Clone, Debug, Default)]
pub struct Splats {
    by_block: Vec<Vec<(u32, Vec3, Vec2)>>,
}

impl Splats {
    /// A splat into `pixel` alone (box filter only: a filtered film needs `push_at`).
    #[inline]
    pub fn push(&mut self, pixel: usize, value: Vec3) {
        self.push_at(pixel, Vec2::NAN, value);
    }

    /// A splat that landed at raster position `at` (pixels of the rendered image, x right, y
    /// down) inside `pixel`: under the gaussian it reaches every pixel of its footprint.
    #[inline]
    pub fn push_at(&mut self, pixel: usize, at: Vec2, value: Vec3) {
        let block = pixel / SPLAT_BLOCK;
        if self.by_block.len() <= block {
            self.by_block.resize_with(block + 1, Vec::new);
        }
        self.by_block[block].push((pixel as u32, value, at));
    }

    pub fn len(&self) -> usize {
        self.by_block.iter().map(Vec::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Accumulated samples of one render.
#[derive(Clone, Debug)]
pub struct Film {
    pub width: usize,
    pub height: usize,
    /// The sums' unit is 2^(unit_exponent - 64) (`fixed::unit_exponent`).
    unit_exponent: i32,
    sum: Vec<FixedRgb>,
    samples: Vec<u64>,
    /// Splatted contributions (light tracing): they land in any pixel, not the one sampled,
    /// and are divided by the number of passes (light paths per pixel), not by the pixel's
    /// own sample count. Empty until the first splat.
    splat: Vec<FixedRgb>,
    /// Samples rejected because a channel was NaN or infinite (they count as black).
    pub nonfinite: u64,
    /// Splats rejected because a channel was NaN or infinite (counted apart from samples).
    pub nonfinite_splats: u64,
    /// Samples and splats rejected because they would take their pixel's sum beyond the
    /// film's range, +-2^(unit_exponent + 63) (samples count as black, splats are dropped).
    pub out_of_range: u64,
    /// How samples reach pixels. With `Gaussian`, `sum` holds each pixel's filter-weighted
    /// sum of the samples splatted into it and `weight` the sum of their weights.
    filter: PixelFilter,
    /// Gaussian only: per pixel, the sum of the filter weights it received (units of 2^-64,
    /// `fixed::weight_units`), rejected samples included (they weigh as black).
    weight: Vec<i128>,
    /// With moments on (`with_moments`): per pixel, the (filter-weighted) sum of the samples'
    /// squares, in units of 2^(2 unit_exponent - 64); empty otherwise.
    square: Vec<FixedRgb>,
    /// Where this film's pixel (0, 0) lies on the whole film (a crop window's offset):
    /// `add_wave_at` takes positions on the whole film.
    origin: (usize, usize),
}

/// The fixed-point parts of one pixel a sample reaches: its value, weight and square sums.
struct PixelSums<'a> {
    sum: &'a mut FixedRgb,
    weight: Option<&'a mut i128>,
    square: Option<&'a mut FixedRgb>,
}

impl PixelSums<'_> {
    /// Adds a sample with filter weight `w` (1 for the box filter); a rejected value still
    /// adds its weight. The value's rejection, if any.
    #[inline]
    fn add(&mut self, value: Vec3, w: f32, exponent: i32) -> Result<(), Rejected> {
        if let Some(weight) = self.weight.as_deref_mut() {
            *weight += fixed::weight_units(w).unwrap_or(0);
        }
        let weighted = if w == 1.0 { value } else { value * w };
        self.sum.add_sample(weighted, exponent)?;
        if let Some(square) = self.square.as_deref_mut() {
            // A square beyond the range drops from the moments alone: the image keeps it.
            let _ = square.add_sample(weighted * value, 2 * exponent);
        }
        Ok(())
    }
}

impl Film {
    /// An empty film in units of 2^-64 (a scene whose brightest light is between 1 and 2;
    /// renders make theirs with `for_scene`).
    pub fn new(width: usize, height: usize) -> Film {
        Film::with_unit(width, height, 0)
    }

    /// An empty film of the scene's camera, in the scene's unit: 2^-64 times the power of two
    /// of its brightest emission channel, so that the film's range and precision follow the
    /// scene's light. Every film of a scene has this unit, so they add.
    pub fn for_scene(data: &crate::scene::SceneData) -> Film {
        let cam = data.scene.camera;
        Film::with_unit(
            cam.width as usize,
            cam.height as usize,
            Film::scene_unit_exponent(&data.scene),
        )
        .with_filter(cam.filter)
        .at_origin(cam.crop.x as usize, cam.crop.y as usize)
    }

    /// The same film lying at (x, y) of a whole film (a crop window): the positions
    /// `add_wave_at` takes are on the whole film.
    pub fn at_origin(mut self, x: usize, y: usize) -> Film {
        self.origin = (x, y);
        self
    }

    /// Where this film's pixel (0, 0) lies on the whole film (a crop window's offset).
    pub fn origin(&self) -> (usize, usize) {
        self.origin
    }

    /// Per pixel, what its splat sum is divided by beyond the splats per pixel: 1 under the
    /// box filter; under the gaussian the integral of the filter over the film about the
    /// pixel (`Gaussian::integral_over_film` along each axis), so that a splat spread over its
    /// footprint estimates the pixel that the camera's filtered samples do.
    pub fn splat_normalisations(filter: PixelFilter, width: usize, height: usize) -> Vec<f64> {
        match filter {
            PixelFilter::Box => vec![1.0; width * height],
            PixelFilter::Gaussian(g) => {
                let columns: Vec<f64> =
                    (0..width).map(|x| g.integral_over_film(x, width)).collect();
                (0..height)
                    .flat_map(|y| {
                        let row = g.integral_over_film(y, height);
                        columns.iter().map(move |c| c * row)
                    })
                    .collect()
            }
        }
    }

    /// The unit exponent of a scene's films (`fixed::unit_exponent` of its brightest
    /// emission channel).
    pub fn scene_unit_exponent(scene: &crate::scene::PreparedScene) -> i32 {
        let brightest = scene
            .emitters
            .radiance
            .iter()
            .map(|r| r.max_element())
            .fold(0.0, f32::max);
        fixed::unit_exponent(brightest)
    }

    /// An empty film in units of 2^(unit_exponent - 64).
    pub fn with_unit(width: usize, height: usize, unit_exponent: i32) -> Film {
        Film {
            width,
            height,
            unit_exponent,
            sum: vec![FixedRgb::ZERO; width * height],
            samples: vec![0; width * height],
            splat: Vec::new(),
            nonfinite: 0,
            nonfinite_splats: 0,
            out_of_range: 0,
            filter: PixelFilter::Box,
            weight: Vec::new(),
            square: Vec::new(),
            origin: (0, 0),
        }
    }

    /// The same empty film with a reconstruction filter (a film with samples keeps its own).
    pub fn with_filter(mut self, filter: PixelFilter) -> Film {
        debug_assert_eq!(
            self.total_samples(),
            0,
            "a filter is chosen before any sample"
        );
        self.filter = filter;
        self.weight = match filter {
            PixelFilter::Box => Vec::new(),
            PixelFilter::Gaussian(_) => vec![0; self.width * self.height],
        };
        self
    }

    /// The same empty film, also summing each pixel's (filter-weighted) sample squares, for
    /// `variance_image`.
    pub fn with_moments(mut self) -> Film {
        self.square = vec![FixedRgb::ZERO; self.width * self.height];
        self
    }

    pub fn filter(&self) -> PixelFilter {
        self.filter
    }

    /// Whether the film sums sample squares (`with_moments`).
    pub fn has_moments(&self) -> bool {
        !self.square.is_empty()
    }

    /// Adds one sample to a pixel; a rejected one (NaN, infinite, out of range) is counted
    /// instead.
    #[inline]
    pub fn add_sample(&mut self, pixel: usize, value: Vec3) {
        debug_assert_eq!(
            self.filter,
            PixelFilter::Box,
            "a filtered sample needs its position"
        );
        self.samples[pixel] += 1;
        let mut sums = PixelSums {
            sum: &mut self.sum[pixel],
            weight: None,
            square: self.square.get_mut(pixel),
        };
        match sums.add(value, 1.0, self.unit_exponent) {
            Ok(()) => {}
            Err(Rejected::NonFinite) => self.nonfinite += 1,
            Err(Rejected::OutOfRange) => self.out_of_range += 1,
        }
    }

    /// Adds a wave of samples: `values[i]` is global sample `first_sample + i`, which lands in
    /// pixel `(first_sample + i) % pixels` (as `add_sample` one by one would add them). Each
    /// pixel's samples are added in sample order, so the pixels are shared out between threads
    /// in fixed blocks and the film is the same for any thread count. Box filter only
    /// (`add_wave_at` takes the samples' film positions for any filter).
    pub fn add_wave(&mut self, first_sample: u64, values: &[Vec3]) {
        use rayon::prelude::*;
        const BLOCK: usize = 1024;
        debug_assert_eq!(
            self.filter,
            PixelFilter::Box,
            "a filtered sample needs its position"
        );
        let pixels = self.sum.len();
        if pixels == 0 {
            return;
        }
        let exponent = self.unit_exponent;
        // Sample i lands in pixel (offset + i) % pixels: pixel p's first sample is
        // (p + pixels - offset) % pixels, then every `pixels` further.
        let offset = (first_sample % pixels as u64) as usize;
        let squares = optional_chunks(&mut self.square, BLOCK);
        let (nonfinite, out_of_range) = self
            .sum
            .par_chunks_mut(BLOCK)
            .zip(self.samples.par_chunks_mut(BLOCK))
            .zip(squares)
            .enumerate()
            .map(|(block, ((sums, counts), mut squares))| {
                let (mut nonfinite, mut out_of_range) = (0, 0);
                // A wave shorter than a pass covers the pixels offset.. offset + len (mod
                // pixels): a block outside them has no sample (small waves, `--wavefront`).
                let first = block * BLOCK;
                let covered = |p: usize| (p + pixels - offset) % pixels < values.len();
                if !covered(first) && !(first..first + sums.len()).contains(&offset) {
                    return (0, 0);
                }
                // The block's first pixel's first sample, then stepped pixel by pixel rather
                // than divided out for each pixel.
                let mut first_sample = (first + pixels - offset) % pixels;
                for (k, (sum, count)) in sums.iter_mut().zip(counts).enumerate() {
                    let mut i = first_sample;
                    first_sample += 1;
                    if first_sample == pixels {
                        first_sample = 0;
                    }
                    let mut pixel = PixelSums {
                        sum,
                        weight: None,
                        square: squares.as_deref_mut().map(|s| &mut s[k]),
                    };
                    while i < values.len() {
                        *count += 1;
                        match pixel.add(values[i], 1.0, exponent) {
                            Ok(()) => {}
                            Err(Rejected::NonFinite) => nonfinite += 1,
                            Err(Rejected::OutOfRange) => out_of_range += 1,
                        }
                        i += pixels;
                    }
                }
                (nonfinite, out_of_range)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        self.nonfinite += nonfinite;
        self.out_of_range += out_of_range;
    }

    /// `add_wave` under the film's filter: `raster(g)` is global sample g's position on the
    /// whole film (pixels, x right, y down; inside pixel `g % pixels` once the film's origin
    /// is added): a crop's weights are then the whole film's, bit for bit. Under the box filter that
    /// is `add_wave`; under the gaussian each sample is splatted into every pixel within the
    /// radius (`Gaussian::footprint`). The film is shared out between threads in bands of
    /// rows, each band taking every sample that reaches it; the sums are exact, so the film
    /// does not depend on the thread count. A sample counts (in `sample_counts`, `nonfinite`)
    /// in its own pixel; a rejected one adds its weights, as black.
    pub fn add_wave_at(
        &mut self,
        first_sample: u64,
        values: &[Vec3],
        raster: &(dyn Fn(u64) -> Vec2 + Sync),
    ) {
        use rayon::prelude::*;
        let PixelFilter::Gaussian(gaussian) = self.filter else {
            return self.add_wave(first_sample, values);
        };
        const BAND_ROWS: usize = 8;
        let (width, height) = (self.width, self.height);
        let pixels = width * height;
        if pixels == 0 || values.is_empty() {
            return;
        }
        let exponent = self.unit_exponent;
        let offset = (first_sample % pixels as u64) as usize;
        let reach = gaussian.reach();
        let (ox, oy) = self.origin;
        let band = BAND_ROWS * width;
        let squares = optional_chunks(&mut self.square, band);
        let (nonfinite, out_of_range) = self
            .sum
            .par_chunks_mut(band)
            .zip(self.weight.par_chunks_mut(band))
            .zip(self.samples.par_chunks_mut(band))
            .zip(squares)
            .enumerate()
            .map(|(b, (((sums, weights), counts), mut squares))| {
                let (mut nonfinite, mut out_of_range) = (0, 0);
                let rows = b * BAND_ROWS..(b * BAND_ROWS + sums.len() / width);
                let (mut wx, mut wy) = (Vec::new(), Vec::new());
                let sample_rows = rows.start.saturating_sub(reach)..(rows.end + reach).min(height);
                for p in sample_rows.start * width..sample_rows.end * width {
                    let own = rows.contains(&(p / width));
                    let mut i = (p + pixels - offset) % pixels;
                    while i < values.len() {
                        let value = values[i];
                        let at = raster(first_sample + i as u64);
                        i += pixels;
                        let xs = gaussian.footprint_in(at.x, ox, width);
                        let ys = gaussian.footprint_in(at.y, oy, height);
                        let ys = ys.start.max(rows.start)..ys.end.min(rows.end).max(rows.start);
                        wx.clear();
                        wx.extend(
                            xs.clone()
                                .map(|x| gaussian.eval((x + ox) as f32 + 0.5 - at.x)),
                        );
                        wy.clear();
                        wy.extend(
                            ys.clone()
                                .map(|y| gaussian.eval((y + oy) as f32 + 0.5 - at.y)),
                        );
                        let mut rejected = None;
                        for (y, &weight_y) in ys.zip(&wy) {
                            for (x, &weight_x) in xs.clone().zip(&wx) {
                                let q = (y - rows.start) * width + x;
                                let mut pixel = PixelSums {
                                    sum: &mut sums[q],
                                    weight: Some(&mut weights[q]),
                                    square: squares.as_deref_mut().map(|s| &mut s[q]),
                                };
                                if let Err(e) = pixel.add(value, weight_x * weight_y, exponent) {
                                    rejected = Some(e);
                                }
                            }
                        }
                        if own {
                            counts[p - rows.start * width] += 1;
                            // Counted once, in the sample's own pixel's band.
                            match FixedRgb::of(value, exponent) {
                                Err(Rejected::NonFinite) => nonfinite += 1,
                                Err(Rejected::OutOfRange) => out_of_range += 1,
                                Ok(_) if rejected == Some(Rejected::OutOfRange) => {
                                    out_of_range += 1
                                }
                                Ok(_) => {}
                            }
                        }
                    }
                }
                (nonfinite, out_of_range)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        self.nonfinite += nonfinite;
        self.out_of_range += out_of_range;
    }

    /// Adds a splat to a pixel; a non-finite one is counted (in `nonfinite_splats`), one out
    /// of range in `out_of_range`, instead.
    #[inline]
    pub fn add_splat(&mut self, pixel: usize, value: Vec3) {
        if !value.is_finite() {
            self.nonfinite_splats += 1;
            return;
        }
        if self.splat.is_empty() {
            self.splat = vec![FixedRgb::ZERO; self.width * self.height];
        }
        match self.splat[pixel].add_sample(value, self.unit_exponent) {
            Ok(()) => {}
            Err(Rejected::NonFinite) => self.nonfinite_splats += 1,
            Err(Rejected::OutOfRange) => self.out_of_range += 1,
        }
    }

    /// Adds batches of splats, as `add_splat` one by one would (the sums are exact, so neither
    /// the order of the splats nor how they were batched changes the film), in parallel: the
    /// splat sums are shared out between threads in blocks of `SPLAT_BLOCK` pixels, and each
    /// batch has sorted its splats by block already (the serial loop over a wave's splats
    /// was a stretch of one busy core in BDPT).
    pub fn add_splats(&mut self, batches: &[Splats]) {
        use rayon::prelude::*;
        if let PixelFilter::Gaussian(gaussian) = self.filter {
            return self.add_filtered_splats(batches, gaussian);
        }
        let finite = batches
            .iter()
            .flat_map(|b| &b.by_block)
            .flatten()
            .any(|(_, v, _)| v.is_finite());
        if finite && self.splat.is_empty() {
            self.splat = vec![FixedRgb::ZERO; self.width * self.height];
        }
        let exponent = self.unit_exponent;
        let (nonfinite, out_of_range) = self
            .splat
            .par_chunks_mut(SPLAT_BLOCK)
            .enumerate()
            .map(|(block, sums)| {
                let (mut nonfinite, mut out_of_range) = (0, 0);
                let first = block * SPLAT_BLOCK;
                for batch in batches {
                    for &(pixel, value, _) in batch.by_block.get(block).into_iter().flatten() {
                        match sums[pixel as usize - first].add_sample(value, exponent) {
                            Ok(()) => {}
                            Err(Rejected::NonFinite) => nonfinite += 1,
                            Err(Rejected::OutOfRange) => out_of_range += 1,
                        }
                    }
                }
                (nonfinite, out_of_range)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        // Without a finite splat the sums were never allocated: every splat was non-finite.
        let unallocated: u64 = if self.splat.is_empty() {
            batches.iter().map(Splats::len).sum::<usize>() as u64
        } else {
            0
        };
        self.nonfinite_splats += nonfinite + unallocated;
        self.out_of_range += out_of_range;
    }

    /// `add_splats` under the gaussian: each splat reaches every pixel whose centre lies
    /// within the radius of where it landed (`Gaussian::footprint`), weighted by the filter
    /// there (not normalised: `image` divides each pixel's splat sum by the integral of the
    /// filter over the film around it, `splat_normalisation`, so that a splat estimates the
    /// pixel the camera's filtered samples do). The sums are shared out between threads in
    /// blocks of `SPLAT_BLOCK` pixels; a block takes the splats of every block whose
    /// footprints reach it, and the sums are exact, so the film does not depend on the thread
    /// count or on how the splats were batched. A non-finite splat is counted once (in its
    /// own pixel's block) and added nowhere.
    fn add_filtered_splats(&mut self, batches: &[Splats], gaussian: Gaussian) {
        use rayon::prelude::*;
        let total: usize = batches.iter().map(Splats::len).sum();
        if total == 0 {
            return;
        }
        if self.splat.is_empty() {
            self.splat = vec![FixedRgb::ZERO; self.width * self.height];
        }
        let (width, height) = (self.width, self.height);
        let exponent = self.unit_exponent;
        // A splat in pixel p reaches pixels at most `reach` rows and columns away.
        let span = gaussian.reach() * (width + 1);
        let blocks = batches.iter().map(|b| b.by_block.len()).max().unwrap_or(0);
        let (nonfinite, out_of_range) = self
            .splat
            .par_chunks_mut(SPLAT_BLOCK)
            .enumerate()
            .map(|(block, sums)| {
                let (mut nonfinite, mut out_of_range) = (0, 0);
                let first = block * SPLAT_BLOCK;
                let end = first + sums.len();
                let from = first.saturating_sub(span) / SPLAT_BLOCK;
                let to = ((end + span) / SPLAT_BLOCK + 1).min(blocks);
                for batch in batches {
                    for source in from..to.min(batch.by_block.len()) {
                        for &(pixel, value, at) in &batch.by_block[source] {
                            let own = (first..end).contains(&(pixel as usize));
                            if !value.is_finite() || !at.is_finite() {
                                nonfinite += own as u64;
                                continue;
                            }
                            let xs = gaussian.footprint(at.x, width);
                            let ys = gaussian.footprint(at.y, height);
                            for y in ys {
                                let row = y * width;
                                if row + xs.end <= first || row + xs.start >= end {
                                    continue;
                                }
                                let wy = gaussian.eval(y as f32 + 0.5 - at.y);
                                for x in xs.clone() {
                                    let q = row + x;
                                    if !(first..end).contains(&q) {
                                        continue;
                                    }
                                    let w = gaussian.eval(x as f32 + 0.5 - at.x) * wy;
                                    if w == 0.0 {
                                        continue;
                                    }
                                    if sums[q - first].add_sample(value * w, exponent).is_err() {
                                        out_of_range += 1;
                                    }
                                }
                            }
                        }
                    }
                }
                (nonfinite, out_of_range)
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        self.nonfinite_splats += nonfinite;
        self.out_of_range += out_of_range;
    }

    /// Adds another film of the same size and unit (samples, splats and rejected counts): the
    /// film of both sets of samples, exactly as if they had been added one by one. An error
    /// when the sizes or units differ or a sum would leave the film's range (this film is
    /// then unchanged).
    pub fn add_film(&mut self, other: &Film) -> Result<(), String> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(format!(
                "a {}x{} film cannot be added to a {}x{} one",
                other.width, other.height, self.width, self.height
            ));
        }
        if self.unit_exponent != other.unit_exponent {
            return Err(format!(
                "a film in units of 2^{} cannot be added to one in units of 2^{} (films of \
                 different scenes, or made by different versions of stagelight)",
                other.unit_exponent - fixed::FRACTION_BITS,
                self.unit_exponent - fixed::FRACTION_BITS
            ));
        }
        if self.filter != other.filter
            || self.has_moments() != other.has_moments()
            || self.origin != other.origin
        {
            return Err(format!(
                "a film made with the {} filter{} cannot be added to one made with the {} \
                 filter{}",
                other.filter.name(),
                if other.has_moments() {
                    " and moments"
                } else {
                    ""
                },
                self.filter.name(),
                if self.has_moments() {
                    " and moments"
                } else {
                    ""
                },
            ));
        }
        let add = |a: &[FixedRgb], b: &[FixedRgb], what: &str| -> Result<Vec<FixedRgb>, String> {
            a.iter()
                .zip(b)
                .enumerate()
                .map(|(i, (x, y))| {
                    x.checked_add(y).ok_or_else(|| {
                        format!(
                            "the {what} of pixel ({}, {}) would leave the film's range \
                             (+-2^{})",
                            i % self.width,
                            i / self.width,
                            self.unit_exponent + 63
                        )
                    })
                })
                .collect()
        };
        let sum = add(&self.sum, &other.sum, "sum")?;
        let splat = match (self.splat.is_empty(), other.splat.is_empty()) {
            (_, true) => None,
            (true, false) => Some(other.splat.clone()),
            (false, false) => Some(add(&self.splat, &other.splat, "splat sum")?),
        };
        // Squares beyond the range drop from the moments alone, as when they are added.
        let square: Vec<FixedRgb> = self
            .square
            .iter()
            .zip(&other.square)
            .map(|(a, b)| a.checked_add(b).unwrap_or(*a))
            .collect();
        self.sum = sum;
        if let Some(splat) = splat {
            self.splat = splat;
        }
        self.square = square;
        for (a, &b) in self.weight.iter_mut().zip(&other.weight) {
            *a += b;
        }
        for (a, &b) in self.samples.iter_mut().zip(&other.samples) {
            *a += b;
        }
        self.nonfinite += other.nonfinite;
        self.nonfinite_splats += other.nonfinite_splats;
        self.out_of_range += other.out_of_range;
        Ok(())
    }

    /// Rebuilds a film from its unit exponent, fixed-point per-pixel sums, sample counts and
    /// splat sums (a checkpoint; `splat` may be empty); None when their lengths do not match
    /// the size.
    pub fn from_fixed_parts(
        width: usize,
        height: usize,
        unit_exponent: i32,
        sum: Vec<FixedRgb>,
        samples: Vec<u64>,
        splat: Vec<FixedRgb>,
        nonfinite: u64,
    ) -> Option<Film> {
        let pixels = width.checked_mul(height)?;
        let splat = if splat.iter().all(FixedRgb::is_zero) {
            Vec::new()
        } else {
            splat
        };
        (sum.len() == pixels
            && samples.len() == pixels
            && (splat.is_empty() || splat.len() == pixels))
            .then_some(Film {
                width,
                height,
                unit_exponent,
                sum,
                samples,
                splat,
                nonfinite,
                nonfinite_splats: 0,
                out_of_range: 0,
                filter: PixelFilter::Box,
                weight: Vec::new(),
                square: Vec::new(),
                origin: (0, 0),
            })
    }

    /// The sums' unit is 2^(this - 64).
    pub fn unit_exponent(&self) -> i32 {
        self.unit_exponent
    }

    /// The same film in units of 2^(unit_exponent - 64), each sum rounded to the new unit
    /// (exact when it is finer); an error naming the pixel when a sum does not fit.
    pub fn in_unit(&self, unit_exponent: i32) -> Result<Film, String> {
        let (from, to) = (self.unit_exponent, unit_exponent);
        let convert = |sums: &[FixedRgb]| -> Result<Vec<FixedRgb>, String> {
            sums.iter()
                .enumerate()
                .map(|(i, s)| {
                    s.rescaled(from, to).ok_or_else(|| {
                        format!(
                            "pixel ({}, {}) does not fit in units of 2^{}",
                            i % self.width.max(1),
                            i / self.width.max(1),
                            to - fixed::FRACTION_BITS
                        )
                    })
                })
                .collect()
        };
        Ok(Film {
            unit_exponent,
            sum: convert(&self.sum)?,
            splat: convert(&self.splat)?,
            // Squares in units of 2^(2E - 64); those that do not fit drop from the moments.
            square: self
                .square
                .iter()
                .map(|s| s.rescaled(2 * from, 2 * to).unwrap_or(FixedRgb::ZERO))
                .collect(),
            ..self.clone()
        })
    }

    /// The fixed-point per-pixel sums, row 0 first.
    pub fn fixed_sums(&self) -> &[FixedRgb] {
        &self.sum
    }

    /// The fixed-point per-pixel splat sums; empty for a film without splats.
    pub fn fixed_splats(&self) -> &[FixedRgb] {
        &self.splat
    }

    /// Builds a film from f64 per-pixel sums, sample counts and splat sums (`splat` may be
    /// empty for a film without splats), in a unit taken from the largest finite sum
    /// (`fixed::unit_exponent_of_sums`: 2^-104 of it), each sum rounded to it; a sum not
    /// finite is taken as 0 and counted in `nonfinite`. None when their lengths do not match
    /// the size. For films made from f64 images (the photon mappers, MLT).
    pub fn from_parts(
        width: usize,
        height: usize,
        sum: Vec<DVec3>,
        samples: Vec<u64>,
        splat: Vec<DVec3>,
        nonfinite: u64,
    ) -> Option<Film> {
        let largest = sum
            .iter()
            .chain(&splat)
            .flat_map(|s| s.to_array())
            .filter(|c| c.is_finite())
            .fold(0.0, |m, c| c.abs().max(m));
        let exponent = fixed::unit_exponent_of_sums(largest);
        let (mut rejected_nonfinite, mut out_of_range) = (0, 0);
        let mut fixed = |v: Vec<DVec3>| -> Vec<FixedRgb> {
            v.into_iter()
                .map(|s| {
                    FixedRgb::from_dvec3(s, exponent).unwrap_or_else(|| {
                        if s.is_finite() {
                            out_of_range += 1;
                        } else {
                            rejected_nonfinite += 1;
                        }
                        FixedRgb::ZERO
                    })
                })
                .collect()
        };
        let (sum, splat) = (fixed(sum), fixed(splat));
        let mut film = Film::from_fixed_parts(
            width,
            height,
            exponent,
            sum,
            samples,
            splat,
            nonfinite + rejected_nonfinite,
        )?;
        film.out_of_range = out_of_range;
        Some(film)
    }

    /// A pixel's splat sum, rounded to f64 (zero for a film without splats).
    pub fn splat_sum(&self, pixel: usize) -> DVec3 {
        self.splat
            .get(pixel)
            .map_or(DVec3::ZERO, |s| s.to_dvec3(self.unit_exponent))
    }

    /// Per-pixel sums of the finite samples, rounded to f64, row 0 first.
    pub fn sums(&self) -> Vec<DVec3> {
        self.sum
            .iter()
            .map(|s| s.to_dvec3(self.unit_exponent))
            .collect()
    }

    /// Per-pixel sample counts (rejected non-finite samples included).
    pub fn sample_counts(&self) -> &[u64] {
        &self.samples
    }

    pub fn total_samples(&self) -> u64 {
        self.samples.iter().sum()
    }

    /// The per-pixel mean as an image, plus the splats divided by the passes (samples per
    /// pixel on average). Under the gaussian filter a pixel is its weighted sum over its
    /// weight sum, and a splat's filter weight is divided by what the weights of one sample per
    /// pixel add up to there on average (`Gaussian::integral_over_film`), so that splats and
    /// samples estimate the same filtered pixel.
    pub fn image(&self) -> Image {
        let passes = self.total_samples() as f64 / (self.width * self.height).max(1) as f64;
        let splat_norm = self.splat_normalisation();
        let pixels = self
            .sum
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let mut v = match self.mean_divisor(i) {
                    Some(d) => s.to_dvec3(self.unit_exponent) / d,
                    None => DVec3::ZERO,
                };
                if let Some(splat) = self.splat.get(i)
                    && passes > 0.0
                {
                    v += splat.to_dvec3(self.unit_exponent) / (passes * splat_norm(i));
                }
                v.as_vec3()
            })
            .collect();
        Image {
            width: self.width,
            height: self.height,
            pixels,
        }
    }

    /// What pixel `i`'s sums are divided by for its mean: its sample count (box) or its
    /// weight sum (gaussian); None when it has none.
    fn mean_divisor(&self, i: usize) -> Option<f64> {
        let d = match self.filter {
            PixelFilter::Box => self.samples[i] as f64,
            PixelFilter::Gaussian(_) => fixed::weight_of_units(self.weight[i]),
        };
        (d > 0.0).then_some(d)
    }

    /// Per pixel, the factor a splat's sum is divided by beyond the passes: 1 under the box
    /// filter, the film-clipped integral of the filter around the pixel under the gaussian.
    fn splat_normalisation(&self) -> impl Fn(usize) -> f64 + '_ {
        let (columns, rows): (Vec<f64>, Vec<f64>) = match self.filter {
            PixelFilter::Box => (Vec::new(), Vec::new()),
            PixelFilter::Gaussian(g) => (
                (0..self.width)
                    .map(|x| g.integral_over_film(x, self.width))
                    .collect(),
                (0..self.height)
                    .map(|y| g.integral_over_film(y, self.height))
                    .collect(),
            ),
        };
        move |i| {
            if columns.is_empty() {
                1.0
            } else {
                columns[i % self.width] * rows[i / self.width]
            }
        }
    }

    /// Per pixel and channel, the sample variance of the per-sample estimate: the (filter-
    /// weighted) mean of the squares less the square of the mean, as Mitsuba's `moment`
    /// integrator gives it (E[x^2] - E[x]^2), at least 0; None for a film without moments.
    /// Splats are not samples of a pixel and take no part.
    pub fn variance_image(&self) -> Option<Image> {
        if !self.has_moments() {
            return None;
        }
        let pixels = (0..self.sum.len())
            .map(|i| match self.mean_divisor(i) {
                Some(d) => {
                    let mean = self.sum[i].to_dvec3(self.unit_exponent) / d;
                    let squares = self.square[i].to_dvec3(2 * self.unit_exponent) / d;
                    (squares - mean * mean).max(DVec3::ZERO).as_vec3()
                }
                None => Vec3::ZERO,
            })
            .collect();
        Some(Image {
            width: self.width,
            height: self.height,
            pixels,
        })
    }
}

/// Parallel chunks of an optional per-pixel column: its chunks, or `None` for every chunk
/// when it is empty (zipped with the film's other columns).
fn optional_chunks<T: Send>(
    column: &mut [T],
    chunk: usize,
) -> impl rayon::iter::IndexedParallelIterator<Item = Option<&mut [T]>> {
    use rayon::prelude::*;
    if column.is_empty() {
        rayon::iter::Either::Left((0..usize::MAX).into_par_iter().map(|_| None))
    } else {
        rayon::iter::Either::Right(column.par_chunks_mut(chunk).map(Some))
    }
}

/// A linear RGB image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Vec3>,
}

/// An image file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {message}", .path.display())]
pub struct ImageError {
    pub path: std::path::PathBuf,
    pub message: String,
}

fn image_error(path: &Path, message: impl std::fmt::Display) -> ImageError {
    ImageError {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

impl Image {
    pub fn new(width: usize, height: usize) -> Image {
        Image {
            width,
            height,
            pixels: vec![Vec3::ZERO; width * height],
        }
    }

    /// Mean of each channel over all pixels, in f64.
    pub fn channel_means(&self) -> DVec3 {
        let sum: DVec3 = self.pixels.iter().map(|p| p.as_dvec3()).sum();
        sum / self.pixels.len().max(1) as f64
    }

    /// Writes float32 linear RGB, unscaled.
    pub fn write_exr(&self, path: &Path) -> Result<(), ImageError> {
        self.write_exr_with_attributes(path, &[])
    }

    /// Writes float32 linear RGB, unscaled, with text attributes in the header (e.g. a
    /// reference's sample count and seed). Non-ASCII characters are written as '?'.
    pub fn write_exr_with_attributes(
        &self,
        path: &Path,
        attributes: &[(&str, String)],
    ) -> Result<(), ImageError> {
        output::write_atomically(path, |file| self.encode_exr(file, attributes))
            .map_err(ImageError::from)
    }

    /// The EXR file's bytes to `out`.
    fn encode_exr(
        &self,
        out: &mut (impl std::io::Write + Seek),
        attributes: &[(&str, String)],
    ) -> Result<(), String> {
        use exr::prelude::*;
        let mut layer_attributes = LayerAttributes::default();
        for (name, value) in attributes {
            let ascii = |s: &str| -> Text {
                let cleaned: String = s
                    .chars()
                    .map(|c| if c.is_ascii() { c } else { '?' })
                    .collect();
                Text::new_or_none(cleaned.as_str()).unwrap_or_default()
            };
            layer_attributes
                .other
                .insert(ascii(name), AttributeValue::Text(ascii(value)));
        }
        let channels = SpecificChannels::rgb(|position: Vec2<usize>| {
            let p = self.pixels[position.y() * self.width + position.x()];
            (p.x, p.y, p.z)
        });
        // Lossless ZIP scanlines in increasing order: the file's bytes depend only on the
        // pixels, never on which compression thread finished first.
        let layer = Layer::new(
            (self.width, self.height),
            layer_attributes,
            Encoding::SMALL_LOSSLESS,
            channels,
        );
        Image::from_layer(layer)
            .write()
            .to_buffered(out)
            .map_err(|e| format!("cannot write EXR: {e}"))
    }

    /// Reads the first RGB(A) layer of an EXR file as linear RGB. The header's image size is
    /// checked against the file's length, `MAX_READ_PIXELS` and this machine's memory before
    /// anything is allocated for it.
    pub fn read_exr(path: &Path) -> Result<Image, ImageError> {
        let file = std::fs::File::open(path).map_err(|e| image_error(path, e))?;
        let len = file.metadata().map_err(|e| image_error(path, e))?.len();
        read_exr_from(
            std::io::BufReader::new(file),
            len,
            crate::sysinfo::memory_limit(),
        )
        .map_err(|message| image_error(path, message))
    }

    /// `read_exr` of a file's bytes; the message does not name a file.
    pub fn read_exr_bytes(
        bytes: &[u8],
        memory: Option<crate::sysinfo::MemoryLimit>,
    ) -> Result<Image, String> {
        read_exr_from(std::io::Cursor::new(bytes), bytes.len() as u64, memory)
    }

    /// The text attributes in the header of an EXR file's first layer, by name.
    pub fn read_exr_attributes(
        path: &Path,
    ) -> Result<std::collections::BTreeMap<String, String>, ImageError> {
        let meta = exr::meta::MetaData::read_from_file(path, false)
            .map_err(|e| image_error(path, format!("cannot read EXR: {}", clip_exr_error(&e))))?;
        let mut attributes = std::collections::BTreeMap::new();
        if let Some(header) = meta.headers.first() {
            for (name, value) in header
                .shared_attributes
                .other
                .iter()
                .chain(&header.own_attributes.other)
            {
                if let exr::meta::attribute::AttributeValue::Text(text) = value {
                    attributes.insert(name.to_string(), text.to_string());
                }
            }
        }
        Ok(attributes)
    }

    /// Writes an 8-bit sRGB preview (values clamped to [0, 1]).
    pub fn write_png(&self, path: &Path) -> Result<(), ImageError> {
        let bytes: Vec<u8> = self
            .pixels
            .iter()
            .flat_map(|p| [srgb8(p.x), srgb8(p.y), srgb8(p.z)])
            .collect();
        output::write_atomically(path, |file| {
            output::encode_rgb_png(file, self.width as u32, self.height as u32, &bytes)
        })
        .map_err(ImageError::from)
    }
}

/// The largest image `read_exr` reads: the largest a scene renders (16384 x 16384).
pub const MAX_READ_PIXELS: u64 = 16384 * 16384;

/// The smallest number of bytes a chunk of an EXR file takes: its entry in the offset table
/// (8) and its header (the y coordinate and the data size, 4 each).
const MIN_CHUNK_BYTES: u64 = 16;

/// Reads the first RGB(A) layer from an EXR file of `len` bytes, after checking every layer's
/// size in the header: at most `MAX_READ_PIXELS`, no more chunks than the file has room for,
/// and the pixels' memory within `memory`.
fn read_exr_from(
    mut reader: impl Read + Seek,
    len: u64,
    memory: Option<crate::sysinfo::MemoryLimit>,
) -> Result<Image, String> {
    let meta = exr::meta::MetaData::read_from_buffered(&mut reader, false)
        .map_err(|e| format!("cannot read EXR: {}", clip_exr_error(&e)))?;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.width(), header.layer_size.height());
        let pixels = (w as u64).saturating_mul(h as u64);
        if pixels > MAX_READ_PIXELS {
            return Err(format!(
                "damaged or unsupported EXR: its header says {w}x{h} pixels, more than the \
                 {MAX_READ_PIXELS} this reads"
            ));
        }
        // No compression packs more than 1:100000 (deflate stops near 1:1032), and a pixel
        // takes at least 2 bytes (one half-float channel).
        if pixels > len.saturating_mul(50_000) {
            return Err(format!(
                "damaged EXR: its header says {w}x{h} pixels, more than a file of {len} bytes \
                 can hold"
            ));
        }
        let needed = (header.chunk_count as u64).saturating_mul(MIN_CHUNK_BYTES);
        if needed > len {
            return Err(format!(
                "damaged EXR: its header says {w}x{h} pixels in {} chunks, which need at \
                 least {needed} bytes, but the file has {len}",
                header.chunk_count
            ));
        }
        // The image, and as much again while the reader decodes it.
        crate::sysinfo::check_memory(
            &format!("reading a {w}x{h} EXR"),
            pixels.saturating_mul(2 * std::mem::size_of::<Vec3>() as u64),
            memory,
        )?;
    }
    reader
        .seek(std::io::SeekFrom::Start(0))
        .map_err(|e| format!("cannot read EXR: {e}"))?;
    use exr::prelude::{ReadChannels, ReadLayers};
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |resolution, _| Image::new(resolution.width(), resolution.height()),
            |image: &mut Image, position, (r, g, b, _a): (f32, f32, f32, f32)| {
                let w = image.width;
                if let Some(p) = image.pixels.get_mut(position.y() * w + position.x()) {
                    *p = Vec3::new(r, g, b);
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(reader)
        .map_err(|e| format!("cannot read EXR: {}", clip_exr_error(&e)))?;
    Ok(image.layer_data.channel_data.pixels)
}

/// The exr crate's message, on one line and at most 300 characters.
fn clip_exr_error(e: &exr::error::Error) -> String {
    crate::scene::clip(&e.to_string(), 300)
}

impl From<output::OutputError> for ImageError {
    fn from(e: output::OutputError) -> ImageError {
        ImageError {
            path: e.path,
            message: e.message,
        }
    }
}

/// Linear to 8-bit sRGB with the exact piecewise transfer function.
pub fn srgb8(linear: f32) -> u8 {
    let c = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonfinite_samples_are_counted_not_added() {
        let mut film = Film::new(2, 1);
        film.add_sample(0, Vec3::ONE);
        film.add_sample(0, Vec3::new(f32::NAN, 0.0, 0.0));
        film.add_sample(1, Vec3::splat(f32::INFINITY));
        assert_eq!(film.nonfinite, 2);
        let img = film.image();
        assert_eq!(img.pixels[0], Vec3::splat(0.5));
        assert_eq!(img.pixels[1], Vec3::ZERO);
    }

    #[test]
    fn a_wave_adds_as_its_samples_one_by_one() {
        let values: Vec<Vec3> = (0..5000)
            .map(|i| match i % 97 {
                0 => Vec3::NAN,
                k => Vec3::new(k as f32 * 0.37, 1.0 / k as f32, -(k as f32)),
            })
            .collect();
        // On the second film (six blocks of pixels) short waves leave blocks without a
        // sample, wrapping past the last pixel or not.
        for (width, first, len) in [
            (37, 0u64, 5000usize),
            (37, 1234, 700),
            (37, 2999, 4001),
            (37, 7, 1),
            (97, 1500, 300),
            (97, 5000, 400),
            (97, 2048, 1024),
            (97, 3977 * 3 + 3976, 2),
        ] {
            let (mut one_by_one, mut wave) = (Film::new(width, 41), Film::new(width, 41));
            for (i, &v) in values[..len].iter().enumerate() {
                one_by_one.add_sample(((first + i as u64) % (width as u64 * 41)) as usize, v);
            }
            wave.add_wave(first, &values[..len]);
            assert_eq!(wave.fixed_sums(), one_by_one.fixed_sums());
            assert_eq!(wave.sample_counts(), one_by_one.sample_counts());
            assert_eq!(wave.nonfinite, one_by_one.nonfinite);
        }
    }

    #[test]
    fn films_in_different_units_do_not_add_until_converted() {
        let mut a = Film::with_unit(2, 1, 4);
        a.add_sample(0, Vec3::splat(3.0));
        let mut b = Film::new(2, 1);
        b.add_sample(0, Vec3::splat(3.0));
        let e = a.add_film(&b).unwrap_err();
        assert!(e.contains("units of 2^-64") && e.contains("2^-60"), "{e}");
        assert_eq!(a.total_samples(), 1, "left as it was");
        a.add_film(&b.in_unit(4).unwrap()).unwrap();
        assert_eq!(a.image().pixels, vec![Vec3::splat(3.0), Vec3::ZERO]);
        // A sum too large for a finer unit is named, not wrapped.
        let mut big = Film::with_unit(2, 1, 40);
        big.add_sample(1, Vec3::splat(1e20));
        let e = big.in_unit(0).unwrap_err();
        assert!(e.contains("pixel (1, 0)"), "{e}");
    }

    #[test]
    fn splat_batches_add_as_their_splats_one_by_one() {
        // 3 x SPLAT_BLOCK pixels and a bit: four blocks, the last one short.
        let (width, height) = (97, 3 * SPLAT_BLOCK / 97 + 2);
        let pixels = width * height;
        let splat = |i: usize| {
            let pixel = (i * 7919) % pixels;
            let value = match i % 89 {
                0 => Vec3::new(0.0, f32::INFINITY, 0.0),
                k => Vec3::new(k as f32 * 0.31, 1.0 / k as f32, 1e-9 * k as f32),
            };
            (pixel, value)
        };
        for (count, batch_len) in [(20000, 1000), (20000, 7), (3, 1), (0, 1)] {
            let (mut one_by_one, mut batched) =
                (Film::new(width, height), Film::new(width, height));
            let mut batches = Vec::new();
            for i in 0..count {
                let (pixel, value) = splat(i);
                one_by_one.add_splat(pixel, value);
                if i % batch_len == 0 {
                    batches.push(Splats::default());
                }
                batches.last_mut().unwrap().push(pixel, value);
            }
            batched.add_splats(&batches);
            assert_eq!(batched.fixed_splats(), one_by_one.fixed_splats());
            assert_eq!(batched.nonfinite_splats, one_by_one.nonfinite_splats);
        }
        // Only non-finite splats: counted, and no sums allocated.
        let mut film = Film::new(3, 3);
        let mut batch = Splats::default();
        batch.push(4, Vec3::NAN);
        film.add_splats(&[batch]);
        assert_eq!(film.nonfinite_splats, 1);
        assert!(film.fixed_splats().is_empty());
    }

    #[test]
    fn srgb_endpoints() {
        assert_eq!(srgb8(0.0), 0);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(0.5), 188);
        assert_eq!(srgb8(f32::NAN), 0);
    }
}
