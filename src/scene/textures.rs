//! Textures as Mitsuba defines them: `bitmap` (an image looked up at a surface's uv, bilinear or
//! nearest, repeated, mirrored or clamped beyond [0, 1]) and `checkerboard`, each behind a
//! `to_uv` transform. A material's reflectance reads one at the shading point.

use glam::{DMat4, Vec2, Vec3};
use std::path::Path;
use std::sync::Arc;

/// `to_uv`: uv' = A uv + b, the 2D part of Mitsuba's 4x4 transform (rows 0-1, columns 0, 1, 3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    pub matrix: [[f32; 2]; 2],
    pub offset: Vec2,
}

impl UvTransform {
    pub const IDENTITY: UvTransform = UvTransform {
        matrix: [[1.0, 0.0], [0.0, 1.0]],
        offset: Vec2::ZERO,
    };

    pub fn from_mat4(m: &DMat4) -> UvTransform {
        let at = |row: usize, col: usize| m.col(col)[row] as f32;
        UvTransform {
            matrix: [[at(0, 0), at(0, 1)], [at(1, 0), at(1, 1)]],
            offset: Vec2::new(at(0, 3), at(1, 3)),
        }
    }

    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let [[a, b], [c, d]] = self.matrix;
        Vec2::new(a * uv.x + b * uv.y, c * uv.x + d * uv.y) + self.offset
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    Bilinear,
    Nearest,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Repeat,
    Mirror,
    Clamp,
}

impl Wrap {
    /// Texel index `i` of a row or column of `n` texels, as Mitsuba wraps it.
    #[inline]
    fn index(self, i: i64, n: i64) -> usize {
        (match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::Clamp => i.clamp(0, n - 1),
            Wrap::Mirror => {
                let j = i.rem_euclid(2 * n);
                if j < n { j } else { 2 * n - j - 1 }
            }
        }) as usize
    }
}

/// An image in linear RGB, row 0 at v = 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Bitmap {
    pub width: usize,
    pub height: usize,
    pub texels: Arc<Vec<Vec3>>,
    pub filter: Filter,
    pub wrap: Wrap,
}

impl Bitmap {
    #[inline]
    fn texel(&self, x: i64, y: i64) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        self.texels[self.wrap.index(y, h) * self.width + self.wrap.index(x, w)]
    }

    #[inline]
    pub fn eval(&self, uv: Vec2) -> Vec3 {
        let res = Vec2::new(self.width as f32, self.height as f32);
        match self.filter {
            Filter::Nearest => {
                let p = (uv * res).floor();
                self.texel(p.x as i64, p.y as i64)
            }
            Filter::Bilinear => {
                let p = uv * res - 0.5;
                let p0 = p.floor();
                let w1 = p - p0;
                let w0 = Vec2::ONE - w1;
                let (x, y) = (p0.x as i64, p0.y as i64);
                (self.texel(x, y) * w0.x + self.texel(x + 1, y) * w1.x) * w0.y
                    + (self.texel(x, y + 1) * w0.x + self.texel(x + 1, y + 1) * w1.x) * w1.y
            }
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum Pattern {
    Bitmap(Bitmap),
    /// `color0` where the fractional parts of u and v are on the same side of 1/2.
    Checkerboard {
        color0: Vec3,
        color1: Vec3,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub pattern: Pattern,
    pub to_uv: UvTransform,
}

impl Texture {
    /// Width and height in texels (1 x 1 for a pattern without an image, as Mitsuba has it).
    pub fn resolution(&self) -> (usize, usize) {
        match &self.pattern {
            Pattern::Bitmap(b) => (b.width, b.height),
            Pattern::Checkerboard { .. } => (1, 1),
        }
    }
}

impl Texture {
    /// The texture's value at surface uv `uv`.
    #[inline]
    pub fn eval(&self, uv: Vec2) -> Vec3 {
        let uv = self.to_uv.apply(uv);
        match &self.pattern {
            Pattern::Bitmap(b) => b.eval(uv),
            Pattern::Checkerboard { color0, color1 } => {
                let f = uv - uv.floor();
                if (f.x > 0.5) == (f.y > 0.5) {
                    *color0
                } else {
                    *color1
                }
            }
        }
    }
}

impl Texture {
    /// The texture read as one value, as Mitsuba's `eval_1` reads it (a roughness): an image's
    /// luminance, and a checkerboard's `color0` where the cells' parities differ, the other
    /// way round from `eval` (Mitsuba's checkerboard.cpp has it so).
    #[inline]
    pub fn eval_1(&self, uv: Vec2) -> f32 {
        let uv = self.to_uv.apply(uv);
        match &self.pattern {
            Pattern::Bitmap(b) => mitsuba_luminance(b.eval(uv)),
            Pattern::Checkerboard { color0, color1 } => {
                let f = uv - uv.floor();
                mitsuba_luminance(if (f.x > 0.5) != (f.y > 0.5) {
                    *color0
                } else {
                    *color1
                })
            }
        }
    }
}

impl Texture {
    /// The texture's mean as Mitsuba's `mean()` gives it (what a plastic's sampling weight
    /// reads): an image's mean texel luminance, a checkerboard's mean of its two colours'
    /// channel means.
    pub fn mean(&self) -> f32 {
        match &self.pattern {
            Pattern::Bitmap(b) => {
                let sum: f64 = b
                    .texels
                    .iter()
                    .map(|t| f64::from(mitsuba_luminance(*t)))
                    .sum();
                (sum / b.texels.len().max(1) as f64) as f32
            }
            Pattern::Checkerboard { color0, color1 } => {
                0.5 * (color0.element_sum() + color1.element_sum()) / 3.0
            }
        }
    }
}

/// Mitsuba's `luminance` of linear sRGB (its coefficients, which differ from
/// `math::luminance`'s in the fourth digit): what a one-value read of a colour texture gives.
#[inline]
fn mitsuba_luminance(c: Vec3) -> f32 {
    c.x * 0.212_671 + c.y * 0.715_160 + c.z * 0.072_169
}

/// The sRGB transfer function's inverse (8-bit images hold sRGB-encoded values).
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Reads an image file (PNG, JPEG, EXR, Radiance HDR, BMP, TGA or PPM: the formats of Mitsuba's
/// `Bitmap` that `image` decodes, through its memory limits) as linear RGB texels, row 0
/// first: 8-bit and 16-bit images sRGB-decoded unless `raw`, floating-point ones (EXR, HDR)
/// linear; alpha dropped, grey spread to three channels.
pub fn read_image(path: &Path, raw: bool) -> Result<(usize, usize, Vec<Vec3>), String> {
    let image = image::ImageReader::open(path)
        .map_err(|e| format!("cannot open {}: {e}", path.display()))?
        .with_guessed_format()
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?
        .decode()
        .map_err(|e| {
            format!(
                "{} is not an image stagelight reads (PNG, JPEG, EXR, HDR, BMP, TGA, PPM): {e}",
                path.display()
            )
        })?;
    let linear = raw
        || matches!(
            image.color(),
            image::ColorType::Rgb32F | image::ColorType::Rgba32F
        );
    let rgb = image.to_rgb32f();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let decode = |c: f32| if linear { c } else { srgb_to_linear(c) };
    let texels = rgb
        .pixels()
        .map(|p| Vec3::new(decode(p[0]), decode(p[1]), decode(p[2])))
        .collect();
    Ok((w, h, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bitmap(filter: Filter, wrap: Wrap) -> Bitmap {
        // 2 x 2: row 0 (v near 0) red, green; row 1 blue, white.
        Bitmap {
            width: 2,
            height: 2,
            texels: Arc::new(vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE]),
            filter,
            wrap,
        }
    }

    #[test]
    fn nearest_reads_the_texel_under_uv_with_row_zero_at_v_zero() {
        let b = bitmap(Filter::Nearest, Wrap::Repeat);
        assert_eq!(b.eval(Vec2::new(0.25, 0.25)), Vec3::X);
        assert_eq!(b.eval(Vec2::new(0.75, 0.25)), Vec3::Y);
        assert_eq!(b.eval(Vec2::new(0.25, 0.75)), Vec3::Z);
        // Repeat: one period on.
        assert_eq!(b.eval(Vec2::new(1.75, -0.75)), Vec3::Y);
    }

    #[test]
    fn bilinear_is_exact_at_texel_centres_and_halfway_between() {
        let b = bitmap(Filter::Bilinear, Wrap::Clamp);
        assert_eq!(b.eval(Vec2::new(0.25, 0.25)), Vec3::X);
        let mid = b.eval(Vec2::new(0.5, 0.25));
        assert!((mid - Vec3::new(0.5, 0.5, 0.0)).abs().max_element() < 1e-6);
        // Clamped beyond the edge: the edge texel.
        assert_eq!(b.eval(Vec2::new(-3.0, 0.25)), Vec3::X);
    }

    #[test]
    fn mirror_reflects_each_period() {
        let b = bitmap(Filter::Nearest, Wrap::Mirror);
        // u in [1, 2) mirrors [0, 1): texel 2 is texel 1, texel 3 is texel 0.
        assert_eq!(b.eval(Vec2::new(1.25, 0.25)), Vec3::Y);
        assert_eq!(b.eval(Vec2::new(1.75, 0.25)), Vec3::X);
    }

    #[test]
    fn checkerboard_and_to_uv() {
        let t = Texture {
            pattern: Pattern::Checkerboard {
                color0: Vec3::ONE,
                color1: Vec3::ZERO,
            },
            to_uv: UvTransform {
                matrix: [[2.0, 0.0], [0.0, 2.0]],
                offset: Vec2::ZERO,
            },
        };
        // uv (0.1, 0.1) -> (0.2, 0.2): both halves low, color0; (0.3, 0.1) -> (0.6, 0.2): color1.
        assert_eq!(t.eval(Vec2::new(0.1, 0.1)), Vec3::ONE);
        assert_eq!(t.eval(Vec2::new(0.3, 0.1)), Vec3::ZERO);
        assert_eq!(t.eval(Vec2::new(0.3, 0.3)), Vec3::ONE);
    }

    #[test]
    fn srgb_decoding_matches_the_standard() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041_14).abs() < 1e-6);
    }

    /// The formats beyond PNG, JPEG and EXR that Mitsuba's scenes use: 8-bit BMP, TGA and PPM
    /// read as sRGB (so 128 is 0.2158), Radiance HDR as linear radiance (RGBE keeps about
    /// three digits). Files written by `image`'s own encoders, read back through `read_image`.
    #[test]
    fn bmp_tga_ppm_are_srgb_and_hdr_is_linear() {
        let dir = std::env::temp_dir().join(format!("stagelight-formats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let srgb = image::RgbImage::from_fn(3, 2, |x, y| {
            image::Rgb([128, (x * 100) as u8, (y * 255) as u8])
        });
        let expected = |x: usize, y: usize| {
            Vec3::new(
                srgb_to_linear(128.0 / 255.0),
                srgb_to_linear((x * 100) as f32 / 255.0),
                srgb_to_linear((y * 255) as f32 / 255.0),
            )
        };
        for name in ["t.bmp", "t.tga", "t.ppm"] {
            let path = dir.join(name);
            srgb.save(&path).unwrap();
            let (w, h, texels) = read_image(&path, false).unwrap();
            assert_eq!((w, h), (3, 2), "{name}");
            for y in 0..2 {
                for x in 0..3 {
                    let d = (texels[y * 3 + x] - expected(x, y)).abs().max_element();
                    assert!(d < 1e-6, "{name} ({x}, {y}): {}", texels[y * 3 + x]);
                }
            }
            assert!((texels[0].x - 0.215_861).abs() < 1e-5);
        }
        let radiance = image::Rgb32FImage::from_fn(2, 2, |x, y| {
            image::Rgb([0.25 + x as f32, 3.0 * y as f32 + 0.5, 40.0])
        });
        let path = dir.join("t.hdr");
        image::DynamicImage::ImageRgb32F(radiance.clone())
            .save(&path)
            .unwrap();
        let (w, h, texels) = read_image(&path, false).unwrap();
        assert_eq!((w, h), (2, 2));
        for (t, p) in texels.iter().zip(radiance.pixels()) {
            let want = Vec3::new(p[0], p[1], p[2]);
            assert!(
                ((*t - want) / want).abs().max_element() < 0.01,
                "{t} against {want}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
