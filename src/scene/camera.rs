//! The camera's geometry and importance: the mapping between raster positions and rays, and
//! the directional density of a pinhole's rays, which bidirectional methods need to connect
//! light subpaths to the camera and to weigh those connections.
//!
//! A pinhole's image plane sits at distance 1 along `forward` and spans `2 tan(fov/2) aspect`
//! by `2 tan(fov/2)` for the whole film; raster x runs right and raster y down, in pixels of
//! the rendered image (the crop window, whose pixel (0, 0) is the film's (crop.x, crop.y)).
//! An orthographic camera's rays are parallel: their direction is a delta, so no direction
//! from a point in the scene reaches it (`raster_of` is None, `pdf_dir` 0) and the integrators
//! that connect light paths to the camera refuse it.

use super::{Camera, Projection};
use glam::{Vec2, Vec3};

impl Camera {
    /// `tan` of half the vertical field of view.
    #[inline]
    pub fn tan_half_fov(&self) -> f32 {
        (self.fov_y_degrees.to_radians() * 0.5).tan()
    }

    /// The camera's projection with its constants worked out once.
    pub fn frustum(&self) -> Frustum {
        let tan_half = self.tan_half_fov();
        let (film_w, film_h) = (self.crop.film_width, self.crop.film_height);
        let aspect = film_w as f32 / film_h as f32;
        // The crop's share of the film (exactly 1 without a crop).
        let share = (self.width as f32 * self.height as f32) / (film_w as f32 * film_h as f32);
        Frustum {
            position: self.position,
            forward: self.forward,
            right: self.right,
            up: self.up,
            tan_half,
            aspect,
            width: self.width,
            height: self.height,
            film_width: film_w,
            film_height: film_h,
            offset: Vec2::new(self.crop.x as f32, self.crop.y as f32),
            area: 4.0 * tan_half * tan_half * aspect * share,
            projection: self.projection,
        }
    }

    /// The camera rendering the whole film at another size (tests and tools shrink scenes):
    /// any crop window is dropped.
    pub fn resize(&mut self, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        self.crop = super::Crop::whole(width, height);
    }

    /// Whether the camera's rays share one origin (a pinhole): only such a camera can be
    /// reached by a light path's connection (t = 1 strategies, light tracing).
    pub fn is_pinhole(&self) -> bool {
        self.projection == Projection::Perspective
    }
}

/// A camera's projection: built once per render by `Camera::frustum`, used per ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    pub position: Vec3,
    pub forward: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    pub tan_half: f32,
    /// The whole film's width over its height.
    pub aspect: f32,
    /// The rendered image (the crop window).
    pub width: u32,
    pub height: u32,
    /// The whole film, and where the rendered image's pixel (0, 0) lies on it.
    pub film_width: u32,
    pub film_height: u32,
    pub offset: Vec2,
    /// The area of the rendered image on the image plane at distance 1.
    pub area: f32,
    pub projection: Projection,
}

impl Frustum {
    /// The unit direction through raster position `raster` (pixels, y down).
    #[inline]
    pub fn direction(&self, raster: Vec2) -> Vec3 {
        self.direction_on_film(raster + self.offset)
    }

    /// `direction` of a position on the whole film (the crop's offset included).
    #[inline]
    pub fn direction_on_film(&self, r: Vec2) -> Vec3 {
        if let Projection::Orthographic { .. } = self.projection {
            return self.forward;
        }
        let (w, h) = (self.film_width as f32, self.film_height as f32);
        let sx = (2.0 * r.x / w - 1.0) * self.tan_half * self.aspect;
        let sy = (1.0 - 2.0 * r.y / h) * self.tan_half;
        (self.forward + self.right * sx + self.up * sy).normalize()
    }

    /// The origin and unit direction of the ray through raster position `raster`: from the
    /// pinhole, or (orthographic) from the point of the near plane the raster position maps
    /// to, Mitsuba's camera x in [-1, 1] and y in [-1/aspect, 1/aspect] scaled by the sensor's
    /// to_world.
    #[inline]
    pub fn ray(&self, raster: Vec2) -> (Vec3, Vec3) {
        self.ray_on_film(raster + self.offset)
    }

    /// `ray` of a position on the whole film (the crop's offset included).
    #[inline]
    pub fn ray_on_film(&self, r: Vec2) -> (Vec3, Vec3) {
        match self.projection {
            Projection::Perspective => (self.position, self.direction_on_film(r)),
            Projection::Orthographic {
                half_width,
                half_height,
                near,
            } => {
                let (w, h) = (self.film_width as f32, self.film_height as f32);
                let sx = (2.0 * r.x / w - 1.0) * half_width;
                let sy = (1.0 - 2.0 * r.y / h) * half_height;
                let origin = self.position + self.forward * near + self.right * sx + self.up * sy;
                (origin, self.forward)
            }
        }
    }

    /// Pixel `pixel` of the rendered image as a pixel index of the whole film (the same
    /// index without a crop): what keys a sample's random numbers, so that a crop renders
    /// the same samples as the whole film there.
    #[inline]
    pub fn film_pixel(&self, pixel: u64) -> u64 {
        let (w, film_w) = (self.width as u64, self.film_width as u64);
        let (x, y) = (
            pixel % w + self.offset.x as u64,
            pixel / w + self.offset.y as u64,
        );
        y * film_w + x
    }

    /// The raster position a direction from the camera projects to, or `None` when it points
    /// outside the image (or backwards), or the camera is orthographic (no direction from a
    /// point reaches it).
    #[inline]
    pub fn raster_of(&self, dir: Vec3) -> Option<Vec2> {
        if let Projection::Orthographic { .. } = self.projection {
            return None;
        }
        let cos = dir.dot(self.forward);
        if cos <= 0.0 {
            return None;
        }
        let q = dir / cos;
        let (w, h) = (self.film_width as f32, self.film_height as f32);
        let x = (q.dot(self.right) / (self.tan_half * self.aspect) + 1.0) * 0.5 * w - self.offset.x;
        let y = (1.0 - q.dot(self.up) / self.tan_half) * 0.5 * h - self.offset.y;
        let (w, h) = (self.width as f32, self.height as f32);
        ((0.0..w).contains(&x) && (0.0..h).contains(&y)).then_some(Vec2::new(x, y))
    }

    /// The pixel index a direction from the camera lands in, if any.
    #[inline]
    pub fn pixel_of(&self, dir: Vec3) -> Option<usize> {
        let r = self.raster_of(dir)?;
        let (x, y) = (r.x as usize, r.y as usize);
        // Rounding at the far edge can give x == width: that direction is outside.
        (x < self.width as usize && y < self.height as usize).then_some(y * self.width as usize + x)
    }

    /// Solid-angle density of a camera ray's direction `dir` (unit), with the raster position
    /// uniform over the whole image: `1 / (A cos^3)`, A the image plane's area at distance 1.
    /// Zero outside the image.
    #[inline]
    pub fn pdf_dir(&self, dir: Vec3) -> f32 {
        if self.raster_of(dir).is_none() {
            return 0.0;
        }
        self.pdf_dir_inside(dir)
    }

    /// `pdf_dir` for a direction known to be inside the image.
    #[inline]
    fn pdf_dir_inside(&self, dir: Vec3) -> f32 {
        let cos = dir.dot(self.forward);
        1.0 / (self.area * cos * cos * cos)
    }

    /// Where a light vertex seen along `dir` (unit, from the camera) lands and the camera's
    /// importance for it: the pixel, the raster position in it, and what the vertex
    /// contributes per unit of incident radiance and solid angle before division by the light
    /// paths per pixel. For a pinhole the importance equals the direction density
    /// `1 / (A cos^3)` (a filter wider than a pixel spreads it from the raster position, the
    /// film normalising it as it does the camera's samples).
    #[inline]
    pub fn project(&self, dir: Vec3) -> Option<(usize, Vec2, f32)> {
        let r = self.raster_of(dir)?;
        let (x, y) = (r.x as usize, r.y as usize);
        // Rounding at the far edge can give x == width: that direction is outside.
        (x < self.width as usize && y < self.height as usize)
            .then(|| (y * self.width as usize + x, r, self.pdf_dir_inside(dir)))
    }

    /// Whether the camera's rays share one origin (a pinhole): only such a camera can be
    /// reached by a light path's connection; an orthographic camera's direction is a delta.
    #[inline]
    pub fn is_pinhole(&self) -> bool {
        self.projection == Projection::Perspective
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> Camera {
        Camera {
            position: Vec3::ZERO,
            forward: Vec3::Z,
            right: Vec3::NEG_X,
            up: Vec3::Y,
            fov_y_degrees: 40.0,
            width: 64,
            height: 48,
            crop: super::super::Crop::whole(64, 48),
            projection: Projection::Perspective,
            filter: crate::scene::filter::PixelFilter::Box,
        }
    }

    #[test]
    fn raster_round_trips() {
        let c = camera().frustum();
        for &(x, y) in &[(0.5, 0.5), (10.25, 40.75), (63.9, 0.1), (32.0, 24.0)] {
            let r = c.raster_of(c.direction(Vec2::new(x, y))).unwrap();
            assert!(
                (r.x - x).abs() < 1e-3 && (r.y - y).abs() < 1e-3,
                "{r} vs {x},{y}"
            );
        }
        assert!(c.raster_of(-Vec3::Z).is_none());
        assert!(c.raster_of(Vec3::new(0.0, 5.0, 1.0).normalize()).is_none());
    }

    #[test]
    fn pdf_integrates_to_one_over_the_image() {
        // Sum of pdf * solid angle of each raster cell: dw = cos^3 dA on the plane at 1.
        let c = camera().frustum();
        let n = 256;
        let cell = c.area / (n * n) as f32;
        let mut total = 0.0f64;
        for i in 0..n {
            for j in 0..n {
                let raster = Vec2::new(
                    (i as f32 + 0.5) / n as f32 * c.width as f32,
                    (j as f32 + 0.5) / n as f32 * c.height as f32,
                );
                let d = c.direction(raster);
                let cos = d.dot(c.forward);
                total += (c.pdf_dir(d) * cell * cos * cos * cos) as f64;
            }
        }
        assert!((total - 1.0).abs() < 1e-3, "{total}");
    }
}
