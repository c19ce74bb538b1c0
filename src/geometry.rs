//! Geometry every part of the renderer shares, below both the scene and the accelerator (as
//! pbrt's interaction.h): the prepared triangles as columns, surface points with their
//! floating-point error bounds, and spawning rays off surfaces without self-intersection.

use crate::math::gamma;
use glam::{Vec3, Vec3A};

/// Marks a triangle that emits nothing (`TriangleColumns::emitter`).
/// Coordinates (of every vertex after its transforms, and of the camera) must stay below this
/// magnitude: beyond it, bounding-box areas, squared distances and the tree's costs overflow
/// f32 (a quad of half-size 1e19 broke the BVH build).
pub const MAX_COORDINATE: f64 = 1e12;

pub const NO_EMITTER: u32 = u32::MAX;
/// Marks a flat-shaded triangle (`TriangleColumns::smooth`).
pub const FLAT: u32 = u32::MAX;

/// Every triangle of the scene as structure-of-arrays columns, indexed by triangle id.
#[derive(Clone, Debug, Default)]
pub struct TriangleColumns {
    pub p0: Vec<Vec3>,
    pub p1: Vec<Vec3>,
    pub p2: Vec<Vec3>,
    /// Unit geometric normal, from the winding: (p1 - p0) x (p2 - p0), normalised.
    pub normal: Vec<Vec3>,
    /// Index into `PreparedScene::materials`.
    pub material: Vec<u32>,
    /// Index into `PreparedScene::emitters`, or `NO_EMITTER`.
    pub emitter: Vec<u32>,
    /// Index into `vertex_normals`, or `FLAT`: only meshes that have normals pay for them.
    pub smooth: Vec<u32>,
    /// Unit shading normals at (p0, p1, p2) of each smooth triangle.
    pub vertex_normals: Vec<[Vec3; 3]>,
}

impl TriangleColumns {
    /// Moves the columns to memory the kernel is asked to back with huge pages (see
    /// `cpu::advise_huge_pages`): each hit's surface point reads them at a random triangle,
    /// and a random read of a column thousands of 4 KiB pages long misses the TLB as well.
    pub fn move_to_huge_pages(&mut self) {
        fn moved<T: Copy>(v: &mut Vec<T>) {
            if std::mem::size_of_val(v.as_slice()) < (4 << 20) {
                return;
            }
            let mut fresh = Vec::with_capacity(v.len());
            crate::cpu::advise_huge_pages(&fresh);
            fresh.extend_from_slice(v);
            *v = fresh;
        }
        moved(&mut self.p0);
        moved(&mut self.p1);
        moved(&mut self.p2);
        moved(&mut self.normal);
        moved(&mut self.material);
        moved(&mut self.emitter);
        moved(&mut self.smooth);
        moved(&mut self.vertex_normals);
    }

    pub fn len(&self) -> usize {
        self.p0.len()
    }
    pub fn is_empty(&self) -> bool {
        self.p0.is_empty()
    }

    /// Bytes the columns hold.
    pub fn memory_bytes(&self) -> usize {
        fn bytes<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        bytes(&self.p0)
            + bytes(&self.p1)
            + bytes(&self.p2)
            + bytes(&self.normal)
            + bytes(&self.material)
            + bytes(&self.emitter)
            + bytes(&self.smooth)
            + bytes(&self.vertex_normals)
    }
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

/// The surface point of a hit, with its error bound and normals.
#[inline(always)]
pub fn surface_point(tris: &TriangleColumns, triangle: u32, b1: f32, b2: f32) -> SurfacePoint {
    let i = triangle as usize;
    let (p0, p1, p2) = (tris.p0[i], tris.p1[i], tris.p2[i]);
    // b0 from f64, so that its only error is the final rounding to f32 (relative, covered by
    // the bound below).
    let b0 = (1.0 - f64::from(b1) - f64::from(b2)) as f32;
    let (w0, w1, w2) = (b0 * p0, b1 * p1, b2 * p2);
    let p = w0 + w1 + w2;
    let p_error = gamma(7) * (w0.abs() + w1.abs() + w2.abs());
    let ng = tris.normal[i];
    let ns = match tris.smooth[i] {
        FLAT => ng,
        k => {
            let n = tris.vertex_normals[k as usize];
            let ns = (b0 * n[0] + b1 * n[1] + b2 * n[2]).normalize_or_zero();
            if ns == Vec3::ZERO { ng } else { ns }
        }
    };
    SurfacePoint { p, p_error, ng, ns }
}

/// Moves `p` off the surface along the geometric normal, on the side of `w`, just far enough
/// that a ray leaving towards `w` cannot re-hit the surface it starts on.
#[inline]
pub fn offset_ray_origin(p: Vec3, p_error: Vec3, ng: Vec3, w: Vec3) -> Vec3 {
    offset_origin(p.into(), p_error.into(), ng.into(), w.into()).into()
}

/// `offset_ray_origin` on four-lane vectors: lane by lane the same operations (the dot
/// products add in the same order), so the same bits.
#[inline(always)]
fn offset_origin(p: Vec3A, p_error: Vec3A, ng: Vec3A, w: Vec3A) -> Vec3A {
    let d = ng.abs().dot(p_error);
    let mut offset = d * ng;
    if w.dot(ng) < 0.0 {
        offset = -offset;
    }
    let po = p + offset;
    // The addition rounded to nearest, possibly back towards p: move each component on by
    // |po| * 2^-23, which is at least one ulp of po (and never less than the smallest normal
    // float), in the direction of the offset. Branch-free, so it vectorises.
    let bump = (po.abs() * f32::EPSILON).max(Vec3A::splat(f32::MIN_POSITIVE));
    let away = Vec3A::select(offset.cmpgt(Vec3A::ZERO), bump, Vec3A::ZERO)
        - Vec3A::select(offset.cmplt(Vec3A::ZERO), bump, Vec3A::ZERO);
    po + away
}

/// How much of a shadow ray's length is left unchecked at its far end (pbrt's value).
pub const SHADOW_EPSILON: f32 = 1e-4;

/// A shadow ray between two surface points: `(origin, dir, t_max)` for `any_hit`, both ends
/// moved off their surfaces (towards each other), the far end short by `SHADOW_EPSILON`, so
/// that neither surface occludes the ray itself.
pub fn spawn_ray_to(
    p_from: Vec3,
    err_from: Vec3,
    n_from: Vec3,
    p_to: Vec3,
    err_to: Vec3,
    n_to: Vec3,
) -> (Vec3, Vec3, f32) {
    let (p_from, p_to) = (Vec3A::from(p_from), Vec3A::from(p_to));
    let origin = offset_origin(p_from, err_from.into(), n_from.into(), p_to - p_from);
    let target = offset_origin(p_to, err_to.into(), n_to.into(), origin - p_to);
    (
        origin.into(),
        (target - origin).into(),
        1.0 - SHADOW_EPSILON,
    )
}
