//! The ray as traversal sees it, and the watertight ray-triangle test of Woop, Benthin and
//! Wald ("Watertight Ray/Triangle Intersection", JCGT 2013).
//!
//! The ray is moved to the origin and sheared so that it runs along +z; each triangle is then
//! tested in 2D with three edge functions. Because every edge function of two triangles that
//! share an edge is computed from the same two transformed vertices, in the same order up to a
//! sign, a ray can never slip between two triangles that share an edge or a vertex. An edge
//! function that rounds to exactly zero is recomputed in double precision, where the products
//! of the (single precision) inputs are exact.

use glam::{Vec3, Vec3A, Vec3Swizzles};

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
    /// The axes that become x, y and z: z is the axis along which the direction is largest in
    /// magnitude, and the vertices are rotated (a cyclic permutation, so handedness is kept).
    k: [usize; 3],
    /// Shear constants: `-d[kx] / d[kz]`, `-d[ky] / d[kz]`, `1 / d[kz]`.
    sx: f32,
    sy: f32,
    sz: f32,
    /// The origin's coordinates along the axes `k`, each in all three lanes.
    o_k: [Vec3A; 3],
}

/// A triangle laid out for the test: for each axis, the coordinates of p0, p1 and p2.
pub type TriangleColumns = [Vec3A; 3];

/// The columns of the triangle `v`.
#[inline]
pub fn columns(v: &[Vec3; 3]) -> TriangleColumns {
    [0, 1, 2].map(|axis| Vec3A::new(v[0][axis], v[1][axis], v[2][axis]))
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
        let k = [(kz + 1) % 3, (kz + 2) % 3, kz];
        let d = dir.to_array();
        let sz = 1.0 / d[kz];
        TraversalRay {
            origin,
            inv_dir: Vec3::ONE / dir,
            neg: [
                dir.x.is_sign_negative(),
                dir.y.is_sign_negative(),
                dir.z.is_sign_negative(),
            ],
            k,
            sx: -d[k[0]] * sz,
            sy: -d[k[1]] * sz,
            sz,
            o_k: k.map(|axis| Vec3A::splat(origin[axis])),
        }
    }

    /// Intersects the triangle `v`: the hit's `(t, b1, b2)` when it lies in `(0, t_max)`.
    #[inline(always)]
    pub fn intersect(&self, cols: &TriangleColumns, t_max: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        // The vertices relative to the origin, rotated so that the ray runs along z: lane i is
        // vertex i. Each lane is computed as the scalar `v[i][k] - origin[k]`.
        let x = cols[kx] - self.o_k[0];
        let y = cols[ky] - self.o_k[1];
        let z = cols[kz] - self.o_k[2];

        // Shear into ray space (the ray becomes the z axis through the origin).
        let x = x + self.sx * z;
        let y = y + self.sy * z;

        // Edge functions: twice the signed areas of the sub-triangles opposite each vertex, so
        // e0, e1, e2 are the (unnormalised) barycentric weights of p0, p1, p2:
        // e0 = cx by - cy bx, e1 = ax cy - ay cx, e2 = bx ay - by ax (no fused multiply-add, so
        // each lane is rounded exactly as the scalar expression would be).
        let e = x.zxy() * y.yzx() - y.zxy() * x.yzx();
        if e.cmplt(Vec3A::ZERO).any() && e.cmpgt(Vec3A::ZERO).any() {
            // On both sides of the edges (a zero edge function cannot change this sign test
            // unless it flips, which only an exact recomputation can decide: see below).
            if !e.cmpeq(Vec3A::ZERO).any() {
                return None;
            }
        }
        let [ax, bx, cx] = x.to_array();
        let [ay, by, cy] = y.to_array();
        let [az, bz, cz] = z.to_array();
        let [mut e0, mut e1, mut e2] = e.to_array();
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
