//! The ray as traversal sees it, and the watertight ray-triangle test of Woop, Benthin and
//! Wald ("Watertight Ray/Triangle Intersection", JCGT 2013).
//!
//! The ray is moved to the origin and sheared so that it runs along +z; each triangle is then
//! tested in 2D with three edge functions. Because every edge function of two triangles that
//! share an edge is computed from the same two transformed vertices, in the same order up to a
//! sign, a ray can never slip between two triangles that share an edge or a vertex. An edge
//! function that rounds to exactly zero is recomputed in double precision, where the products
//! of the (single precision) inputs are exact.

use glam::{Vec3, Vec3Swizzles};

/// `gamma(n) = n u / (1 - n u)` with `u = f32::EPSILON / 2`: the relative error bound of `n`
/// successive rounded operations (Higham).
#[inline]
pub const fn gamma(n: i32) -> f32 {
    let nu = n as f32 * (f32::EPSILON * 0.5);
    nu / (1.0 - nu)
}

/// A ray prepared once for traversal: its reciprocal direction for the box tests and the
/// permutation and shear of the watertight triangle test.
#[derive(Clone, Copy, Debug)]
pub struct TraversalRay {
    pub origin: Vec3,
    /// `1 / dir` per axis (IEEE: +-infinity for a zero component).
    pub inv_dir: Vec3,
    /// Whether each direction component has its sign bit set (matches the sign of `inv_dir`).
    pub neg: [bool; 3],
    /// The axis along which the direction is largest in magnitude: the vertices are rotated
    /// (a cyclic permutation) so that it becomes z.
    kz: u8,
    /// Shear constants: `-d[kx] / d[kz]`, `-d[ky] / d[kz]`, `1 / d[kz]`.
    sx: f32,
    sy: f32,
    sz: f32,
}

impl TraversalRay {
    /// Prepares a ray. `dir` must be finite and non-zero.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> TraversalRay {
        let a = dir.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let d = rotate(dir, kz);
        let sz = 1.0 / d.z;
        TraversalRay {
            origin,
            inv_dir: Vec3::ONE / dir,
            neg: [
                dir.x.is_sign_negative(),
                dir.y.is_sign_negative(),
                dir.z.is_sign_negative(),
            ],
            kz,
            sx: -d.x * sz,
            sy: -d.y * sz,
            sz,
        }
    }

    /// Intersects the triangle `v`: the hit's `(t, b1, b2)` when it lies in `(0, t_max)`.
    #[inline(always)]
    pub fn intersect(&self, v: &[Vec3; 3], t_max: f32) -> Option<(f32, f32, f32)> {
        let a = rotate(v[0] - self.origin, self.kz);
        let b = rotate(v[1] - self.origin, self.kz);
        let c = rotate(v[2] - self.origin, self.kz);

        // Shear into ray space (the ray becomes the z axis through the origin).
        let (az, bz, cz) = (a.z, b.z, c.z);
        let ax = a.x + self.sx * az;
        let ay = a.y + self.sy * az;
        let bx = b.x + self.sx * bz;
        let by = b.y + self.sy * bz;
        let cx = c.x + self.sx * cz;
        let cy = c.y + self.sy * cz;

        // Edge functions: twice the signed areas of the sub-triangles opposite each vertex, so
        // e0, e1, e2 are the (unnormalised) barycentric weights of p0, p1, p2.
        let mut e0 = cx * by - cy * bx;
        let mut e1 = ax * cy - ay * cx;
        let mut e2 = bx * ay - by * ax;
        if e0 == 0.0 || e1 == 0.0 || e2 == 0.0 {
            // A product of two f32 is exact in f64, so the sign of each difference is exact.
            let f = |px: f32, py: f32, qx: f32, qy: f32| {
                (f64::from(px) * f64::from(qy) - f64::from(py) * f64::from(qx)) as f32
            };
            e0 = f(cx, cy, bx, by);
            e1 = f(ax, ay, cx, cy);
            e2 = f(bx, by, ax, ay);
        }

        // Both sides are hit: the ray must be on the same side of all three edges.
        if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
            return None;
        }
        let det = e0 + e1 + e2;
        if det == 0.0 {
            return None;
        }

        // Scaled hit distance, compared against the range without a division.
        let az = self.sz * az;
        let bz = self.sz * bz;
        let cz = self.sz * cz;
        let t_scaled = e0 * az + e1 * bz + e2 * cz;
        if det < 0.0 {
            if t_scaled >= 0.0 || t_scaled < t_max * det {
                return None;
            }
        } else if t_scaled <= 0.0 || t_scaled > t_max * det {
            return None;
        }

        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;

        // A conservative bound on the error of t: reject hits that may be at t <= 0 (the
        // triangle may pass through the origin, as for a ray leaving the surface it is on).
        let max_z = az.abs().max(bz.abs()).max(cz.abs());
        let max_x = ax.abs().max(bx.abs()).max(cx.abs());
        let max_y = ay.abs().max(by.abs()).max(cy.abs());
        let delta_z = gamma(3) * max_z;
        let delta_x = gamma(5) * (max_x + max_z);
        let delta_y = gamma(5) * (max_y + max_z);
        let delta_e = 2.0 * (gamma(2) * max_x * max_y + delta_y * max_x + delta_x * max_y);
        let max_e = e0.abs().max(e1.abs()).max(e2.abs());
        let delta_t =
            3.0 * (gamma(3) * max_e * max_z + delta_e * max_z + delta_z * max_e) * inv_det.abs();
        // Also rejects a t that rounded up to t_max, and any NaN.
        if t > delta_t && t < t_max {
            Some((t, e1 * inv_det, e2 * inv_det))
        } else {
            None
        }
    }
}

/// Rotates the axes so that axis `kz` becomes z (a cyclic permutation, so handedness is kept).
#[inline(always)]
fn rotate(v: Vec3, kz: u8) -> Vec3 {
    match kz {
        0 => v.yzx(),
        1 => v.zxy(),
        _ => v,
    }
}
