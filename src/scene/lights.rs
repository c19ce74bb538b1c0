//! Point lights' emission: a plain point sends its intensity alike in every direction; a spot
//! (Mitsuba's `spot`) only within a cone, at full intensity inside its beam and ramping down
//! linearly in angle to zero at the cutoff; a projector (Mitsuba's `projector`) through a
//! pinhole frustum, an image's irradiance on the plane one unit in front of it.

use crate::sampling::{UNIFORM_SPHERE_PDF, uniform_sphere};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A spot light's cone about its unit `axis`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spot {
    pub axis: Vec3,
    /// Cosine and angle (radians) of the cutoff: no light beyond it.
    pub cos_cutoff: f32,
    pub cutoff: f32,
    /// Cosine of the beam's half-width: full intensity within it.
    pub cos_beam: f32,
    /// 1 / (cutoff - beam width), the slope of the linear ramp in angle.
    pub inv_transition: f32,
    /// A texture projected along the cone (Mitsuba's spot `texture`), if any.
    pub projection: Option<SpotProjection>,
}

/// How a spot projects its texture: a direction `w` in the light's frame (`to_local * w`, +z
/// along the axis) looks up uv = 1/2 + (x, y) / (2 z tan(cutoff)), so the cutoff cone's
/// square of tangents spans the image (Mitsuba's `direction_to_uv`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpotProjection {
    pub to_local: glam::Mat3,
    /// tan(cutoff).
    pub uv_factor: f32,
    /// Index into `Emitters::projected_textures`.
    pub texture: u32,
}

impl SpotProjection {
    /// The texture coordinates unit direction `w` looks up.
    #[inline]
    pub fn uv(&self, w: Vec3) -> Vec2 {
        let local = self.to_local * w;
        let scale = 0.5 / (local.z * self.uv_factor);
        Vec2::new(0.5 + local.x * scale, 0.5 + local.y * scale)
    }
}

impl Spot {
    /// The cone of `cutoff_degrees` with a full beam of `beam_degrees` about `axis`, or an error
    /// message for angles outside (0, 180) (a beam wider than the cutoff is the cutoff).
    pub fn new(axis: Vec3, cutoff_degrees: f64, beam_degrees: f64) -> Result<Spot, String> {
        for (name, angle) in [
            ("cutoff_angle", cutoff_degrees),
            ("beam_width", beam_degrees),
        ] {
            if !(angle > 0.0 && angle < 180.0) {
                return Err(format!("spot: {name} {angle} must lie in (0, 180) degrees"));
            }
        }
        let (cutoff, beam) = (cutoff_degrees.to_radians(), beam_degrees.to_radians());
        Ok(Spot {
            axis: axis.normalize(),
            cos_cutoff: cutoff.cos() as f32,
            cutoff: cutoff as f32,
            cos_beam: beam.cos() as f32,
            inv_transition: (1.0 / (cutoff - beam)) as f32,
            projection: None,
        })
    }

    /// The fraction of the intensity sent towards unit direction `w`.
    #[inline]
    pub fn falloff(&self, w: Vec3) -> f32 {
        let cos = w.dot(self.axis);
        if cos <= self.cos_cutoff {
            0.0
        } else if cos >= self.cos_beam {
            1.0
        } else {
            ((self.cutoff - cos.min(1.0).acos()) * self.inv_transition).clamp(0.0, 1.0)
        }
    }

    /// The solid angle the intensity covers, weighted by the falloff: power = intensity x this.
    pub fn weighted_solid_angle(&self) -> f64 {
        // Midpoint rule in cos(theta) over the cone; the ramp is smooth in it.
        const STEPS: usize = 1 << 14;
        let lo = f64::from(self.cos_cutoff);
        let step = (1.0 - lo) / STEPS as f64;
        let sum: f64 = (0..STEPS)
            .map(|i| {
                let cos = lo + (i as f64 + 0.5) * step;
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let w = self.axis * cos as f32 + any_perpendicular(self.axis) * sin as f32;
                f64::from(self.falloff(w))
            })
            .sum();
        2.0 * std::f64::consts::PI * sum * step
    }

    /// Density of `sample`'s directions inside the cone (uniform in solid angle).
    #[inline]
    fn cone_pdf(&self) -> f32 {
        1.0 / (2.0 * PI * (1.0 - self.cos_cutoff))
    }
}

fn any_perpendicular(axis: Vec3) -> Vec3 {
    crate::math::Frame::from_normal(axis).s
}

/// A projector (Mitsuba's `projector`): a pinhole that casts an image, as a perspective camera
/// sees one, onto the plane one unit in front of it, so that the image's texel is the
/// irradiance there (times the light's intensity, pi x scale). Towards a direction at angle
/// theta off its axis it sends the texel there over cos^3 theta: the plane at distance
/// 1 / cos theta, tilted by theta.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projector {
    /// World to the projector's frame (+z forward; a rotation: to_world is rigid) and back.
    pub to_local: glam::Mat3,
    pub to_world: glam::Mat3,
    /// Half the image's width and height on the plane z = 1: tan of half the fields of view.
    pub tan_x: f32,
    pub tan_y: f32,
    /// Index into `Emitters::projected_textures`, or `NO_TEXTURE` where the irradiance is
    /// one colour (then in the light's intensity).
    pub texture: u32,
}

/// `Projector::texture` of a projector whose irradiance is one colour.
pub const NO_TEXTURE: u32 = u32::MAX;

impl Projector {
    /// The image's area on the plane z = 1: the integral of 1 / cos^3 over the frustum's
    /// solid angle, so power = intensity x this x the image's mean.
    pub fn image_area(&self) -> f32 {
        4.0 * self.tan_x * self.tan_y
    }

    /// Where unit direction `w` crosses the image (Mitsuba's sample space: u grows towards the
    /// frame's -x, v towards its -y, as its perspective camera's pixels) and its cos theta, or
    /// None outside the frustum.
    #[inline]
    pub fn uv(&self, w: Vec3) -> Option<(Vec2, f32)> {
        let local = self.to_local * w;
        if local.z <= 0.0 {
            return None;
        }
        let (x, y) = (local.x / local.z, local.y / local.z);
        let uv = Vec2::new(0.5 - 0.5 * x / self.tan_x, 0.5 - 0.5 * y / self.tan_y);
        let inside = (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y);
        inside.then(|| (uv, local.z / local.length()))
    }
}

/// How a point light sends its intensity out.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum PointProfile {
    /// Alike in every direction (and every emitter that is not a point light).
    #[default]
    Uniform,
    Spot(Spot),
    Projector(Projector),
}

impl PointProfile {
    /// The fraction of the intensity sent towards unit direction `w`, and where a projected
    /// texture is looked up for it (its index and uv), if the light projects one.
    #[inline]
    pub fn towards(&self, w: Vec3) -> (f32, Option<(u32, Vec2)>) {
        match self {
            PointProfile::Uniform => (1.0, None),
            PointProfile::Spot(spot) => {
                let falloff = spot.falloff(w);
                match spot.projection {
                    Some(p) if falloff > 0.0 => (falloff, Some((p.texture, p.uv(w)))),
                    _ => (falloff, None),
                }
            }
            PointProfile::Projector(projector) => match projector.uv(w) {
                Some((uv, cos)) => {
                    let texture =
                        (projector.texture != NO_TEXTURE).then_some((projector.texture, uv));
                    (1.0 / (cos * cos * cos), texture)
                }
                None => (0.0, None),
            },
        }
    }

    /// The solid angle the intensity covers, weighted by the fraction `towards` gives: power =
    /// intensity x this, a projected texture left out (as light selection counts it).
    pub fn weighted_solid_angle(&self) -> f64 {
        match self {
            PointProfile::Uniform => 4.0 * std::f64::consts::PI,
            PointProfile::Spot(spot) => spot.weighted_solid_angle(),
            PointProfile::Projector(projector) => f64::from(projector.image_area()),
        }
    }
}

/// A direction a point light's photon or light subpath leaves by, with its solid-angle density:
/// uniform over the sphere, over a spot's cone, or over a projector's image (uniform in area on
/// its plane, so the density follows 1 / cos^3 as its intensity does).
#[inline]
pub fn sample_direction(profile: &PointProfile, u: Vec2) -> (Vec3, f32) {
    match profile {
        PointProfile::Uniform => (uniform_sphere(u), UNIFORM_SPHERE_PDF),
        PointProfile::Spot(spot) => {
            let cos = 1.0 - u.x * (1.0 - spot.cos_cutoff);
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            let phi = 2.0 * PI * u.y;
            let frame = crate::math::Frame::from_normal(spot.axis);
            let local = Vec3::new(sin * phi.cos(), sin * phi.sin(), cos);
            (frame.to_world(local).normalize(), spot.cone_pdf())
        }
        PointProfile::Projector(projector) => {
            let on_plane = Vec3::new(
                projector.tan_x * (1.0 - 2.0 * u.x),
                projector.tan_y * (1.0 - 2.0 * u.y),
                1.0,
            );
            let length = on_plane.length();
            let cos = 1.0 / length;
            let w = (projector.to_world * (on_plane / length)).normalize();
            (w, 1.0 / (projector.image_area() * cos * cos * cos))
        }
    }
}

/// The density with which `sample_direction` returns unit direction `w`.
#[inline]
pub fn pdf_direction(profile: &PointProfile, w: Vec3) -> f32 {
    match profile {
        PointProfile::Uniform => UNIFORM_SPHERE_PDF,
        PointProfile::Spot(spot) if w.dot(spot.axis) > spot.cos_cutoff => spot.cone_pdf(),
        PointProfile::Spot(_) => 0.0,
        PointProfile::Projector(projector) => match projector.uv(w) {
            Some((_, cos)) => 1.0 / (projector.image_area() * cos * cos * cos),
            None => 0.0,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The weighted solid angle against its closed form: the full cone 2 pi (1 - cos c) when
    /// the beam fills it, and for a ramp, 2 pi times the integral of the linear ramp in angle
    /// times sin(theta) (by parts: a cosine difference over the transition width).
    #[test]
    fn weighted_solid_angle_matches_closed_forms() {
        let spot = Spot::new(Vec3::Z, 30.0, 30.0).unwrap();
        let full = 2.0 * std::f64::consts::PI * (1.0 - 30f64.to_radians().cos());
        assert!((spot.weighted_solid_angle() - full).abs() < 1e-6 * full);
        let (c, b) = (20f64.to_radians(), 15f64.to_radians());
        let spot = Spot::new(Vec3::Y, 20.0, 15.0).unwrap();
        // Integral over [0, b] of sin = 1 - cos b; over [b, c] of (c - t)/(c - b) sin t
        // = (c - b - (sin c - sin b)) / (c - b) ... evaluated: [-(c - t) cos t - sin t]/(c-b).
        let ramp = ((c - b) * b.cos() - (c.sin() - b.sin())) / (c - b);
        let expected = 2.0 * std::f64::consts::PI * (1.0 - b.cos() + ramp);
        let got = spot.weighted_solid_angle();
        assert!(
            (got - expected).abs() < 1e-5 * expected,
            "{got} vs {expected}"
        );
    }

    #[test]
    fn falloff_is_full_in_the_beam_and_zero_past_the_cutoff() {
        let spot = Spot::new(Vec3::Z, 20.0, 15.0).unwrap();
        let at = |deg: f32| {
            let t = deg.to_radians();
            spot.falloff(Vec3::new(t.sin(), 0.0, t.cos()))
        };
        assert_eq!(at(0.0), 1.0);
        assert_eq!(at(14.9), 1.0);
        assert!((at(17.5) - 0.5).abs() < 1e-4);
        assert_eq!(at(20.1), 0.0);
        assert_eq!(at(120.0), 0.0);
        assert!(Spot::new(Vec3::Z, 0.0, 1.0).is_err());
    }

    #[test]
    fn cone_samples_lie_in_the_cone_with_the_density_they_report() {
        let spot = Spot::new(Vec3::new(1.0, 1.0, 0.0), 25.0, 10.0).unwrap();
        let profile = PointProfile::Spot(spot);
        for i in 0..64 {
            let u = Vec2::new((i as f32 + 0.5) / 64.0, ((i * 37) % 64) as f32 / 64.0);
            let (w, pdf) = sample_direction(&profile, u);
            assert!((w.length() - 1.0).abs() < 1e-5);
            assert!(w.dot(spot.axis) >= spot.cos_cutoff - 1e-6);
            assert_eq!(pdf, pdf_direction(&profile, w));
        }
    }

    /// A projector turned so that its +z is world (1, 1, 1) / sqrt 3.
    fn projector() -> Projector {
        let frame = crate::math::Frame::from_normal(Vec3::ONE.normalize());
        let to_world = glam::Mat3::from_cols(frame.s, frame.t, frame.n);
        Projector {
            to_local: to_world.transpose(),
            to_world,
            tan_x: 1.2,
            tan_y: 0.7,
            texture: 0,
        }
    }

    #[test]
    fn projector_samples_lie_in_its_frustum_with_the_density_they_report() {
        let p = projector();
        let profile = PointProfile::Projector(p);
        for i in 0..256 {
            let u = Vec2::new(
                (i as f32 + 0.5) / 256.0,
                ((i * 97) % 256) as f32 / 256.0 + 1e-3,
            );
            let (w, pdf) = sample_direction(&profile, u);
            assert!((w.length() - 1.0).abs() < 1e-5);
            let (uv, _) = p.uv(w).expect("in the frustum");
            // The sample's image position is its uv (u runs against the frame's x).
            assert!((uv - u).abs().max_element() < 1e-4, "{uv} vs {u}");
            let expected = pdf_direction(&profile, w);
            assert!(
                (pdf - expected).abs() < 1e-4 * expected,
                "{pdf} vs {expected}"
            );
        }
        // Behind the pinhole and beside the frustum: nothing.
        assert_eq!(pdf_direction(&profile, -p.to_world.z_axis), 0.0);
        let beside = (p.to_world * Vec3::new(1.3, 0.0, 1.0)).normalize();
        assert_eq!(profile.towards(beside).0, 0.0);
        assert_eq!(
            profile.towards(p.to_world.z_axis),
            (1.0, Some((0, Vec2::splat(0.5))))
        );
    }

    /// The 1 / cos^3 profile integrates over the sphere to the image's area on the plane z = 1
    /// (Monte Carlo over uniform directions, an estimator independent of the frustum sampling).
    #[test]
    fn projector_profile_integrates_to_its_image_area() {
        let profile = PointProfile::Projector(projector());
        let n = 1 << 20;
        let mut sum = 0.0f64;
        let mut sum2 = 0.0f64;
        for i in 0..n {
            let u = Vec2::new(
                (i as f32 + 0.5) / n as f32,
                ((i as u64 * 2_654_435_761) % n as u64) as f32 / n as f32,
            );
            let f = f64::from(profile.towards(uniform_sphere(u)).0) / f64::from(UNIFORM_SPHERE_PDF);
            sum += f;
            sum2 += f * f;
        }
        let mean = sum / n as f64;
        let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
        let area = profile.weighted_solid_angle();
        assert!((area - 4.0 * 1.2 * 0.7).abs() < 1e-5);
        assert!(
            (mean - area).abs() < 4.0 * se + 1e-3 * area,
            "{mean} +- {se} vs {area}"
        );
    }
}
