//! The acceleration structure over the scene's triangles (obvhs), watertight ray-triangle
//! intersection, and robust spawning of rays from surfaces.

use crate::scene::TriangleColumns;
use glam::Vec3;

/// A closest hit: distance along the (unnormalised) direction, triangle id, barycentrics of
/// p1 and p2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
    pub b1: f32,
    pub b2: f32,
}

/// A point on a surface with a conservative bound on its floating-point error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub p: Vec3,
    /// Per-axis absolute error bound of `p`.
    pub p_error: Vec3,
    /// Unit geometric normal, from the winding (p1 - p0) x (p2 - p0).
    pub ng: Vec3,
    /// Unit shading normal (interpolated vertex normal, or `ng` for flat triangles).
    pub ns: Vec3,
}

pub struct Accel {}

impl Accel {
    pub fn build(_triangles: &TriangleColumns) -> Accel {
        todo!("accel helper")
    }
    pub fn closest_hit(&self, _origin: Vec3, _dir: Vec3, _t_max: f32) -> Option<Hit> {
        todo!("accel helper")
    }
    pub fn any_hit(&self, _origin: Vec3, _dir: Vec3, _t_max: f32) -> bool {
        todo!("accel helper")
    }
}

/// The surface point of a hit, with its error bound and normals.
pub fn surface_point(_tris: &TriangleColumns, _triangle: u32, _b1: f32, _b2: f32) -> SurfacePoint {
    todo!("accel helper")
}

/// Moves `p` off the surface along the geometric normal, on the side of `w`, just far enough
/// that a ray leaving towards `w` cannot re-hit the surface it starts on.
pub fn offset_ray_origin(_p: Vec3, _p_error: Vec3, _ng: Vec3, _w: Vec3) -> Vec3 {
    todo!("accel helper")
}
