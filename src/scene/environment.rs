//! Lights at infinity (Mitsuba's `constant` and `envmap`): radiance that arrives from every
//! direction alike wherever it is seen from, either one colour or an equirectangular image
//! (latitude-longitude, +y up in the map's frame, Mitsuba's conventions). Paths that leave the
//! scene see it; next-event estimation samples its directions, the image by a piecewise-constant
//! 2D distribution over its texel cells (the density follows luminance times sin(theta), as
//! pbrt-v4 and Mitsuba do), the constant uniformly over the sphere (as Mitsuba does).

use crate::sampling::{UNIFORM_SPHERE_PDF, uniform_sphere};
use glam::{DVec3, Mat3, Vec2, Vec3};
use std::f32::consts::PI;
use std::sync::Arc;

/// The light at infinity of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    pub radiance: EnvironmentRadiance,
    /// World directions to the map's frame, and back (the rotation of Mitsuba's `to_world`).
    pub to_local: Mat3,
    pub to_world: Mat3,
}

/// Where light paths from a light at infinity start (the environment's, a directional
/// light's): on a disk as wide as the scene's bounding sphere, facing the direction they come
/// from, outside the sphere.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SceneDisk {
    pub center: Vec3,
    pub radius: f32,
}

impl SceneDisk {
    /// The density of a light path's origin on the disk (1 / (pi r^2)): it plays the role of
    /// a direction density at the light, turned into an area density at the first surface by
    /// the cosine there alone (parallel rays, no distance falloff).
    #[inline]
    pub fn pdf(&self) -> f32 {
        1.0 / (PI * self.radius * self.radius)
    }

    /// The origin for `u` of a light path arriving from unit direction `towards_light`.
    #[inline]
    pub fn origin(&self, towards_light: Vec3, u: Vec2) -> Vec3 {
        let d = crate::sampling::concentric_disk(u);
        let frame = crate::math::Frame::from_normal(towards_light);
        self.center + self.radius * (towards_light + frame.s * d.x + frame.t * d.y)
    }

    /// A point beyond everything the scene holds, seen from `from` in unit direction `dir`:
    /// where a vertex at infinity sits for connections and shadow rays.
    #[inline]
    pub fn far_point(&self, from: Vec3, dir: Vec3) -> Vec3 {
        from + dir * (2.0 * self.radius.max((from - self.center).length()))
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum EnvironmentRadiance {
    /// Mitsuba's `constant`: the same radiance from every direction.
    Constant(Vec3),
    /// Mitsuba's `envmap`.
    Map(Arc<EnvironmentMap>),
}

/// An equirectangular radiance image: texel (x, y) is seen at map coordinates
/// u = (x + 1/2) / width (longitude, wrapping around) and v = y / (height - 1) (from +y at
/// v = 0 to -y at v = 1), radiance bilinear between texels, as Mitsuba's envmap evaluates.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvironmentMap {
    pub width: usize,
    pub height: usize,
    /// Linear RGB radiance (scale applied), row 0 first.
    pub texels: Vec<Vec3>,
    /// Sampling density over the cells between texel centres: `width` columns (the last one
    /// wrapping from the last texel column to the first) by `height - 1` rows.
    cells: PiecewiseConstant2D,
}

impl EnvironmentMap {
    /// The map of `texels` (`width` x `height`, row 0 first), or a message when it is too small
    /// to hold a latitude-longitude image or holds a negative or non-finite value.
    pub fn new(width: usize, height: usize, texels: Vec<Vec3>) -> Result<EnvironmentMap, String> {
        if width < 2 || height < 2 {
            return Err(format!(
                "envmap: the image is {width} x {height} texels; it needs at least 2 x 2"
            ));
        }
        if let Some(bad) = texels
            .iter()
            .find(|t| !t.is_finite() || t.min_element() < 0.0)
        {
            return Err(format!(
                "envmap: a texel holds {:?}: radiance must be finite and not negative",
                bad.to_array()
            ));
        }
        // A cell's radiance is bilinear in its four corner texels, so the largest of their
        // luminances bounds it: the density is zero only where the radiance is. Weighted by the
        // cell's mean sin(theta), its share of the sphere.
        let rows = height - 1;
        let mut weights = Vec::with_capacity(width * rows);
        for y in 0..rows {
            let (theta0, theta1) = (
                PI * y as f32 / rows as f32,
                PI * (y + 1) as f32 / rows as f32,
            );
            let mean_sin = (theta0.cos() - theta1.cos()) / (theta1 - theta0);
            for x in 0..width {
                let x1 = (x + 1) % width;
                let corners = [
                    texels[y * width + x],
                    texels[y * width + x1],
                    texels[(y + 1) * width + x],
                    texels[(y + 1) * width + x1],
                ];
                let peak = corners
                    .iter()
                    .map(|&c| crate::math::luminance(c))
                    .fold(0.0f32, f32::max);
                weights.push(f64::from(peak * mean_sin.max(0.0)));
            }
        }
        let cells = PiecewiseConstant2D::new(&weights, width, rows)
            .ok_or_else(|| "envmap: the image is black: it emits nothing".to_string())?;
        Ok(EnvironmentMap {
            width,
            height,
            texels,
            cells,
        })
    }

    /// Radiance at map coordinates (u, v) in [0, 1]^2 (u wraps).
    #[inline]
    fn eval_uv(&self, uv: Vec2) -> Vec3 {
        let x = (uv.x - uv.x.floor()) * self.width as f32 - 0.5;
        let y = uv.y.clamp(0.0, 1.0) * (self.height - 1) as f32;
        let (x0, y0) = (x.floor(), y.floor().min((self.height - 2) as f32));
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let col = |c: i64| c.rem_euclid(w) as usize;
        let (c0, c1) = (col(x0 as i64), col(x0 as i64 + 1));
        let r0 = y0 as usize;
        let at = |c: usize, r: usize| self.texels[r * self.width + c];
        let top = at(c0, r0) * (1.0 - fx) + at(c1, r0) * fx;
        let bottom = at(c0, r0 + 1) * (1.0 - fx) + at(c1, r0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Map coordinates of a unit direction in the map's frame (Mitsuba's `direction_to_uv`).
#[inline]
fn direction_to_uv(d: Vec3) -> Vec2 {
    Vec2::new(
        d.x.atan2(-d.z) * (0.5 / PI),
        d.y.clamp(-1.0, 1.0).acos() * (1.0 / PI),
    )
}

/// The unit direction in the map's frame at map coordinates `uv`, with sin(theta).
#[inline]
fn uv_to_direction(uv: Vec2) -> (Vec3, f32) {
    let (theta, phi) = (uv.y * PI, uv.x * 2.0 * PI);
    let (sin_theta, cos_theta) = theta.sin_cos();
    let (sin_phi, cos_phi) = phi.sin_cos();
    (
        Vec3::new(sin_phi * sin_theta, cos_theta, -cos_phi * sin_theta),
        sin_theta,
    )
}

impl Environment {
    /// Radiance arriving along unit world direction `-dir`, that is seen by a ray leaving the
    /// scene in direction `dir`.
    #[inline]
    pub fn eval(&self, dir: Vec3) -> Vec3 {
        match &self.radiance {
            EnvironmentRadiance::Constant(l) => *l,
            EnvironmentRadiance::Map(map) => {
                map.eval_uv(direction_to_uv((self.to_local * dir).normalize()))
            }
        }
    }

    /// A unit world direction towards the environment for `u`, with its solid-angle density
    /// (zero: no direction; the caller sends no ray).
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec3, f32) {
        match &self.radiance {
            EnvironmentRadiance::Constant(_) => (uniform_sphere(u), UNIFORM_SPHERE_PDF),
            EnvironmentRadiance::Map(map) => {
                let (cell, pdf_cells) = map.cells.sample(u);
                let uv = Vec2::new(cell.x + 0.5 / map.width as f32, cell.y);
                let (local, sin_theta) = uv_to_direction(uv);
                if sin_theta <= 0.0 || pdf_cells <= 0.0 {
                    return (Vec3::Z, 0.0);
                }
                let pdf = pdf_cells / (2.0 * PI * PI * sin_theta);
                ((self.to_world * local).normalize(), pdf)
            }
        }
    }

    /// The solid-angle density with which `sample` returns unit world direction `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match &self.radiance {
            EnvironmentRadiance::Constant(_) => UNIFORM_SPHERE_PDF,
            EnvironmentRadiance::Map(map) => {
                let local = (self.to_local * dir).normalize();
                let uv = direction_to_uv(local);
                let sin_theta = (local.x * local.x + local.z * local.z).sqrt();
                if sin_theta <= 0.0 {
                    return 0.0;
                }
                let u = uv.x - 0.5 / map.width as f32;
                let cell = Vec2::new(u - u.floor(), uv.y);
                map.cells.pdf(cell) / (2.0 * PI * PI * sin_theta)
            }
        }
    }

    /// The largest radiance it sends (per channel).
    pub fn peak_radiance(&self) -> Vec3 {
        match &self.radiance {
            EnvironmentRadiance::Constant(l) => *l,
            EnvironmentRadiance::Map(map) => map.texels.iter().fold(Vec3::ZERO, |m, t| m.max(*t)),
        }
    }

    /// The radiance integrated over the sphere of directions (RGB, W/m^2): the power that
    /// crosses a unit area facing every way at once, for picking lights by power.
    pub fn irradiance_over_sphere(&self) -> DVec3 {
        match &self.radiance {
            EnvironmentRadiance::Constant(l) => 4.0 * std::f64::consts::PI * l.as_dvec3(),
            EnvironmentRadiance::Map(map) => {
                // Each cell in four quarters: the radiance at a quarter's centre times the
                // quarter's exact solid angle (dphi times the difference of cos(theta)).
                let (w, rows) = (map.width, map.height - 1);
                let dphi = std::f64::consts::PI / w as f64;
                let mut sum = DVec3::ZERO;
                for y in 0..rows {
                    for half in [0.0, 0.5] {
                        let v0 = (y as f64 + half) / rows as f64;
                        let v1 = v0 + 0.5 / rows as f64;
                        let solid_angle = dphi
                            * ((v0 * std::f64::consts::PI).cos()
                                - (v1 * std::f64::consts::PI).cos());
                        let v = ((v0 + v1) / 2.0) as f32;
                        for x in 0..w {
                            for sx in [0.25, 0.75] {
                                let uv = Vec2::new((x as f32 + sx + 0.5) / w as f32, v);
                                sum += map.eval_uv(uv).as_dvec3() * solid_angle;
                            }
                        }
                    }
                }
                sum
            }
        }
    }
}

/// A density over the unit square, constant on each cell of a `cols` x `rows` grid: a row by
/// its marginal, then a column by the row's conditional distribution (pbrt's
/// PiecewiseConstant2D).
#[derive(Clone, Debug, PartialEq)]
struct PiecewiseConstant2D {
    cols: usize,
    rows: usize,
    /// Per row, the running sum of its cells' weights over the row's sum, ending at 1.
    conditional_cdf: Vec<f32>,
    marginal_cdf: Vec<f32>,
    /// Each cell's density over the unit square (weight x cells / total).
    density: Vec<f32>,
}

impl PiecewiseConstant2D {
    /// The distribution of `weights` (row by row), or None when they sum to zero or are not
    /// finite.
    fn new(weights: &[f64], cols: usize, rows: usize) -> Option<PiecewiseConstant2D> {
        let total: f64 = weights.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let mut conditional_cdf = Vec::with_capacity(weights.len());
        let mut row_sums = Vec::with_capacity(rows);
        for row in weights.chunks(cols) {
            let sum: f64 = row.iter().sum();
            row_sums.push(sum);
            conditional_cdf.extend(running_cdf(row, sum));
        }
        let marginal_cdf = running_cdf(&row_sums, total);
        let scale = (cols * rows) as f64 / total;
        let density = weights.iter().map(|&w| (w * scale) as f32).collect();
        Some(PiecewiseConstant2D {
            cols,
            rows,
            conditional_cdf,
            marginal_cdf,
            density,
        })
    }

    /// A point of the unit square for `u`, with its density.
    #[inline]
    fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (row, v) = sample_segment(&self.marginal_cdf, u.y);
        let cdf = &self.conditional_cdf[row * self.cols..(row + 1) * self.cols];
        let (col, s) = sample_segment(cdf, u.x);
        let p = Vec2::new(
            (col as f32 + s) / self.cols as f32,
            (row as f32 + v) / self.rows as f32,
        );
        (p, self.density[row * self.cols + col])
    }

    /// The density of point `p` of the unit square.
    #[inline]
    fn pdf(&self, p: Vec2) -> f32 {
        let col = ((p.x * self.cols as f32) as usize).min(self.cols - 1);
        let row = ((p.y * self.rows as f32) as usize).min(self.rows - 1);
        self.density[row * self.cols + col]
    }
}

/// The running sums of `weights` over `total`, the last exactly 1.
fn running_cdf(weights: &[f64], total: f64) -> Vec<f32> {
    let mut acc = 0.0;
    let mut cdf: Vec<f32> = weights
        .iter()
        .map(|&w| {
            acc += w;
            (acc / total) as f32
        })
        .collect();
    if total > 0.0
        && let Some(last) = cdf.last_mut()
    {
        *last = 1.0;
    }
    cdf
}

/// The segment of `cdf` that `u` falls in and where in it (0..1).
#[inline]
fn sample_segment(cdf: &[f32], u: f32) -> (usize, f32) {
    let i = crate::sampling::sample_cdf(cdf, u);
    let lo = if i == 0 { 0.0 } else { cdf[i - 1] };
    let width = cdf[i] - lo;
    let t = if width > 0.0 {
        ((u - lo) / width).clamp(0.0, 1.0 - f32::EPSILON / 2.0)
    } else {
        0.5
    };
    (i, t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(width: usize, height: usize, f: impl Fn(usize, usize) -> Vec3) -> Environment {
        let texels = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        let rotation = Mat3::from_rotation_z(0.3) * Mat3::from_rotation_x(-0.7);
        Environment {
            radiance: EnvironmentRadiance::Map(Arc::new(
                EnvironmentMap::new(width, height, texels).unwrap(),
            )),
            to_world: rotation,
            to_local: rotation.transpose(),
        }
    }

    /// Radiance at the texel centres is the texel (Mitsuba's mapping: texel x at
    /// u = (x + 1/2) / width, row y at v = y / (height - 1)).
    #[test]
    fn texel_centres_give_their_texels() {
        let env = map(8, 5, |x, y| Vec3::new(x as f32, y as f32, 1.0));
        let EnvironmentRadiance::Map(m) = &env.radiance else {
            unreachable!()
        };
        for y in 0..5 {
            for x in 0..8 {
                let uv = Vec2::new((x as f32 + 0.5) / 8.0, y as f32 / 4.0);
                let got = m.eval_uv(uv);
                assert!(
                    (got - Vec3::new(x as f32, y as f32, 1.0))
                        .abs()
                        .max_element()
                        < 1e-4,
                    "{x} {y}: {got}"
                );
            }
        }
        // Between the last column and the first, the map wraps.
        let got = m.eval_uv(Vec2::new(0.0, 0.5));
        assert!((got.x - 3.5).abs() < 1e-4, "{got}");
    }

    /// Sampled directions report the density `pdf` gives them, and the density integrates to
    /// one over the sphere (a Monte Carlo estimate with uniform directions).
    #[test]
    fn samples_carry_the_density_pdf_reports_and_it_integrates_to_one() {
        let env = map(16, 9, |x, y| {
            Vec3::splat(if (x + y) % 5 == 0 {
                20.0
            } else {
                0.1 + y as f32
            })
        });
        for i in 0..500 {
            let u = Vec2::new(
                ((i * 37) % 500) as f32 / 500.0 + 0.0007,
                (i as f32 + 0.5) / 500.0,
            );
            let (dir, pdf) = env.sample(u);
            assert!((dir.length() - 1.0).abs() < 1e-4);
            let again = env.pdf(dir);
            assert!(
                (again - pdf).abs() <= 2e-3 * pdf,
                "sample {i}: {pdf} vs {again}"
            );
            assert!(env.eval(dir).max_element() > 0.0);
        }
        let n = 200_000;
        let mut sum = 0.0f64;
        for i in 0..n {
            let u = Vec2::new(
                (i as f32 + 0.5) / n as f32,
                ((i as u64 * 7919) % n as u64) as f32 / n as f32,
            );
            sum += f64::from(env.pdf(uniform_sphere(u)) / UNIFORM_SPHERE_PDF);
        }
        let integral = sum / n as f64;
        assert!((integral - 1.0).abs() < 0.02, "{integral}");
    }

    /// The sphere integral of a constant map is 4 pi times its radiance.
    #[test]
    fn irradiance_over_sphere_of_a_uniform_map() {
        let env = map(12, 7, |_, _| Vec3::new(1.0, 2.0, 0.5));
        let got = env.irradiance_over_sphere();
        let want = 4.0 * std::f64::consts::PI * DVec3::new(1.0, 2.0, 0.5);
        assert!(
            (got - want).abs().max_element() < 2e-3 * want.max_element(),
            "{got}"
        );
    }
}
