//! Paths in SIMD lanes: the wavefront's shading systems take their queues `LANES` paths at a
//! time, as columns of `LANES` numbers, so the compiler turns each step into vector
//! instructions (in the systems' AVX2 copies, eight f32 lanes per instruction).
//!
//! Every operation here is the lane-by-lane twin of the scalar code that the megakernel runs
//! (glam's `Vec3`, `Frame`, the BSDFs, the sampler's hash): the same IEEE operations in the
//! same order, no fused multiply-adds, so each lane's result is the scalar result, bit for bit
//! (`tests/it/kernels.rs` renders both kernels and compares the films).

use crate::math::Frame;
use crate::sampling::{SampleKey, Sampler};
use glam::{Vec2, Vec3};
use std::ops::{Add, BitAnd, BitOr, BitXor, Div, Mul, Neg, Not, Sub};

/// Paths shaded together.
pub const LANES: usize = 8;

/// One f32 per lane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F(pub [f32; LANES]);

/// One flag per lane.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct M(pub [bool; LANES]);

/// A vector per lane, as three columns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct V3 {
    pub x: F,
    pub y: F,
    pub z: F,
}

impl F {
    #[inline(always)]
    pub fn splat(v: f32) -> F {
        F([v; LANES])
    }
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> f32) -> F {
        let mut out = [0.0; LANES];
        for (l, v) in out.iter_mut().enumerate() {
            *v = f(l);
        }
        F(out)
    }
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F {
        let mut out = self.0;
        for v in &mut out {
            *v = f(*v);
        }
        F(out)
    }
    #[inline(always)]
    fn zip(self, o: F, f: impl Fn(f32, f32) -> f32) -> F {
        let mut out = self.0;
        for (v, w) in out.iter_mut().zip(o.0) {
            *v = f(*v, w);
        }
        F(out)
    }
    #[inline(always)]
    fn test(self, o: F, f: impl Fn(f32, f32) -> bool) -> M {
        let mut out = [false; LANES];
        for ((m, a), b) in out.iter_mut().zip(self.0).zip(o.0) {
            *m = f(a, b);
        }
        M(out)
    }
    #[inline(always)]
    pub fn sqrt(self) -> F {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    pub fn abs(self) -> F {
        self.map(f32::abs)
    }
    /// `f32::max` lane by lane (a NaN lane takes the other operand, as `f32::max`).
    #[inline(always)]
    pub fn max(self, o: F) -> F {
        self.zip(o, f32::max)
    }
    #[inline(always)]
    pub fn lt(self, o: F) -> M {
        self.test(o, |a, b| a < b)
    }
    #[inline(always)]
    pub fn le(self, o: F) -> M {
        self.test(o, |a, b| a <= b)
    }
    #[inline(always)]
    pub fn gt(self, o: F) -> M {
        self.test(o, |a, b| a > b)
    }
    #[inline(always)]
    pub fn eq(self, o: F) -> M {
        self.test(o, |a, b| a == b)
    }
    /// `1.0f32.copysign(self)` lane by lane.
    #[inline(always)]
    pub fn sign_one(self) -> F {
        self.map(|v| 1.0f32.copysign(v))
    }
}

impl M {
    #[inline(always)]
    pub fn splat(v: bool) -> M {
        M([v; LANES])
    }
    #[inline(always)]
    pub fn all(self) -> bool {
        self.0.iter().all(|&b| b)
    }
    /// `if self { a } else { b }` lane by lane.
    #[inline(always)]
    pub fn select(self, a: F, b: F) -> F {
        let mut out = b.0;
        for ((v, m), a) in out.iter_mut().zip(self.0).zip(a.0) {
            if m {
                *v = a;
            }
        }
        F(out)
    }
    #[inline(always)]
    pub fn select3(self, a: V3, b: V3) -> V3 {
        V3 {
            x: self.select(a.x, b.x),
            y: self.select(a.y, b.y),
            z: self.select(a.z, b.z),
        }
    }
}

impl Not for M {
    type Output = M;
    #[inline(always)]
    fn not(self) -> M {
        let mut out = self.0;
        for v in &mut out {
            *v = !*v;
        }
        M(out)
    }
}

macro_rules! mask_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for M {
            type Output = M;
            #[inline(always)]
            fn $f(self, o: M) -> M {
                let mut out = self.0;
                for (v, w) in out.iter_mut().zip(o.0) {
                    *v $op w;
                }
                M(out)
            }
        }
    };
}
mask_op!(BitAnd, bitand, &=);
mask_op!(BitXor, bitxor, ^=);
mask_op!(BitOr, bitor, |=);

macro_rules! float_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F {
            type Output = F;
            #[inline(always)]
            fn $f(self, o: F) -> F {
                self.zip(o, |a, b| a $op b)
            }
        }
        impl $tr<f32> for F {
            type Output = F;
            #[inline(always)]
            fn $f(self, o: f32) -> F {
                self.map(|a| a $op o)
            }
        }
        impl $tr<F> for f32 {
            type Output = F;
            #[inline(always)]
            fn $f(self, o: F) -> F {
                o.map(|b| self $op b)
            }
        }
        impl $tr for V3 {
            type Output = V3;
            #[inline(always)]
            fn $f(self, o: V3) -> V3 {
                V3 { x: self.x $op o.x, y: self.y $op o.y, z: self.z $op o.z }
            }
        }
        /// Each component with the lane's number (glam's `Vec3 op f32`).
        impl $tr<F> for V3 {
            type Output = V3;
            #[inline(always)]
            fn $f(self, o: F) -> V3 {
                V3 { x: self.x $op o, y: self.y $op o, z: self.z $op o }
            }
        }
    };
}
float_op!(Add, add, +);
float_op!(Sub, sub, -);
float_op!(Mul, mul, *);
float_op!(Div, div, /);

impl Neg for F {
    type Output = F;
    #[inline(always)]
    fn neg(self) -> F {
        self.map(|v| -v)
    }
}

impl Neg for V3 {
    type Output = V3;
    #[inline(always)]
    fn neg(self) -> V3 {
        V3 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// `f32 * Vec3` (each component times the lane's number, the scalar first, as glam).
impl Mul<V3> for F {
    type Output = V3;
    #[inline(always)]
    fn mul(self, v: V3) -> V3 {
        V3 {
            x: self * v.x,
            y: self * v.y,
            z: self * v.z,
        }
    }
}

impl V3 {
    #[inline(always)]
    pub fn splat(v: Vec3) -> V3 {
        V3 {
            x: F::splat(v.x),
            y: F::splat(v.y),
            z: F::splat(v.z),
        }
    }
    /// Lane `l` is `f(l)`.
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> Vec3) -> V3 {
        let mut v = V3::splat(Vec3::ZERO);
        for l in 0..LANES {
            let w = f(l);
            v.x.0[l] = w.x;
            v.y.0[l] = w.y;
            v.z.0[l] = w.z;
        }
        v
    }
    /// The lanes of eight consecutive vectors.
    #[inline(always)]
    pub fn load(s: &[Vec3]) -> V3 {
        let s = &s[..LANES];
        V3::from_fn(|l| s[l])
    }
    #[inline(always)]
    pub fn lane(&self, l: usize) -> Vec3 {
        Vec3::new(self.x.0[l], self.y.0[l], self.z.0[l])
    }
    /// Writes the lanes to eight consecutive vectors.
    #[inline(always)]
    pub fn store(&self, s: &mut [Vec3]) {
        let s = &mut s[..LANES];
        for (l, v) in s.iter_mut().enumerate() {
            *v = self.lane(l);
        }
    }
    /// glam's `Vec3::dot` (and `Vec3A::dot`): (x x' + y y') + z z'.
    #[inline(always)]
    pub fn dot(self, o: V3) -> F {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    pub fn abs(self) -> V3 {
        V3 {
            x: self.x.abs(),
            y: self.y.abs(),
            z: self.z.abs(),
        }
    }
    /// glam's `Vec3::normalize`: times 1 / length.
    #[inline(always)]
    pub fn normalize(self) -> V3 {
        self * (1.0 / self.dot(self).sqrt())
    }
    /// glam's `Vec3::max_element`: max(x, max(y, z)) with max(a, b) = if a > b { a } else { b }.
    #[inline(always)]
    pub fn max_element(self) -> F {
        let max = |a: F, b: F| a.gt(b).select(a, b);
        max(self.x, max(self.y, self.z))
    }
}

/// `Frame` in lanes.
#[derive(Clone, Copy)]
pub struct Frames {
    pub s: V3,
    pub t: V3,
    pub n: V3,
}

impl Frames {
    /// `Frame::from_normal`, lane by lane.
    #[inline(always)]
    pub fn from_normal(n: V3) -> Frames {
        let sign = n.z.sign_one();
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = V3 {
            x: 1.0 + sign * n.x * n.x * a,
            y: sign * b,
            z: -sign * n.x,
        };
        let t = V3 {
            x: b,
            y: sign + n.y * n.y * a,
            z: -n.y,
        };
        Frames { s, t, n }
    }
    #[inline(always)]
    pub fn to_local(&self, v: V3) -> V3 {
        V3 {
            x: v.dot(self.s),
            y: v.dot(self.t),
            z: v.dot(self.n),
        }
    }
    #[inline(always)]
    pub fn to_world(&self, v: V3) -> V3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// The frames agree with `Frame` (used by tests).
impl Frames {
    pub fn lane(&self, l: usize) -> Frame {
        Frame {
            s: self.s.lane(l),
            t: self.t.lane(l),
            n: self.n.lane(l),
        }
    }
}

/// `[f(0), .., f(LANES - 1)]` (a plain loop: `std::array::from_fn` was left out of line).
#[inline(always)]
pub fn lanes_of<T: Copy + Default>(mut f: impl FnMut(usize) -> T) -> [T; LANES] {
    let mut out = [T::default(); LANES];
    for (l, v) in out.iter_mut().enumerate() {
        *v = f(l);
    }
    out
}

/// Number `dims[l]` of `keys[l]` in every lane (`Sampler::get`): the independent sampler's
/// hash runs in vector lanes, the other samplers lane by lane.
#[inline(always)]
pub fn draw(sampler: &Sampler, keys: &[SampleKey; LANES], dims: &[u32; LANES]) -> F {
    match sampler {
        Sampler::Independent { .. } => F(SampleKey::get_lanes(keys, dims)),
        _ => F::from_fn(|l| sampler.get(keys[l], dims[l])),
    }
}

/// Numbers `dims[l]` and `dims[l] + 1` of `keys[l]` in every lane (`Sampler::get2`).
#[inline(always)]
pub fn draw2(sampler: &Sampler, keys: &[SampleKey; LANES], dims: &[u32; LANES]) -> (F, F) {
    match sampler {
        Sampler::Independent { .. } => {
            let next = lanes_of(|l| dims[l] + 1);
            (
                F(SampleKey::get_lanes(keys, dims)),
                F(SampleKey::get_lanes(keys, &next)),
            )
        }
        _ => {
            let u: [Vec2; LANES] = lanes_of(|l| sampler.get2(keys[l], dims[l]));
            (F::from_fn(|l| u[l].x), F::from_fn(|l| u[l].y))
        }
    }
}

/// `offset_ray_origin` in lanes: `p` moved off its surface along `ng`, on the side of `w`.
#[inline(always)]
pub fn offset_origin(p: V3, p_error: V3, ng: V3, w: V3) -> V3 {
    let d = ng.abs().dot(p_error);
    let offset = d * ng;
    let offset = w.dot(ng).lt(F::splat(0.0)).select3(-offset, offset);
    let po = p + offset;
    let bump = V3 {
        x: (po.x.abs() * f32::EPSILON).max(F::splat(f32::MIN_POSITIVE)),
        y: (po.y.abs() * f32::EPSILON).max(F::splat(f32::MIN_POSITIVE)),
        z: (po.z.abs() * f32::EPSILON).max(F::splat(f32::MIN_POSITIVE)),
    };
    let zero = F::splat(0.0);
    let away = |o: F, b: F| o.gt(zero).select(b, zero) - o.lt(zero).select(b, zero);
    V3 {
        x: po.x + away(offset.x, bump.x),
        y: po.y + away(offset.y, bump.y),
        z: po.z + away(offset.z, bump.z),
    }
}

/// `power_heuristic` in lanes.
#[inline(always)]
pub fn power_heuristic(f: F, g: F) -> F {
    let f2 = f * f;
    let g2 = g * g;
    let sum = f2 + g2;
    let ratio = f2 / sum;
    let ratio = f2.eq(F::splat(f32::INFINITY)).select(F::splat(1.0), ratio);
    sum.eq(F::splat(0.0)).select(F::splat(0.0), ratio)
}

/// `Surface` in lanes, for paths on Lambertian surfaces (the common case, and the only kind
/// shaded in lanes): the hit point with its error bound, the geometric normal and shading frame
/// turned to the side the ray came from, wo, and each lane's reflectance.
#[derive(Clone, Copy)]
pub struct DiffuseLanes {
    pub p: V3,
    pub p_error: V3,
    pub ng: V3,
    pub frame: Frames,
    pub wo: V3,
    pub wo_local: V3,
    pub reflectance: V3,
}

impl DiffuseLanes {
    /// The surfaces of slots `i..i + LANES` of a chunk's views (`Surface::at` lane by lane),
    /// or None when one of them is not Lambertian.
    #[inline(always)]
    pub fn at(
        data: &crate::scene::SceneData,
        surfaces: &crate::components::SurfacesView,
        triangles: &[u32],
        dirs: &[Vec3],
        i: usize,
    ) -> Option<DiffuseLanes> {
        let scene = &data.scene;
        let mut reflectance = [Vec3::ZERO; LANES];
        for (l, r) in reflectance.iter_mut().enumerate() {
            let material = scene.triangles.material[triangles[i + l] as usize];
            match scene.materials[material as usize] {
                crate::bsdf::Material::Diffuse { reflectance } => *r = reflectance,
                _ => return None,
            }
        }
        let ng = V3::load(&surfaces.ng[i..]);
        let ns = V3::load(&surfaces.ns[i..]);
        let wo = -V3::load(&dirs[i..]);
        // Lambertian surfaces reflect on both sides: shade from the side the ray came from.
        let flip = wo.dot(ng).lt(F::splat(0.0));
        let ng = flip.select3(-ng, ng);
        let ns = flip.select3(-ns, ns);
        let frame = Frames::from_normal(ns);
        Some(DiffuseLanes {
            p: V3::load(&surfaces.p[i..]),
            p_error: V3::load(&surfaces.p_error[i..]),
            ng,
            frame,
            wo,
            wo_local: frame.to_local(wo),
            reflectance: V3::from_fn(|l| reflectance[l]),
        })
    }
}

/// Whether both cosines lie strictly on the same side (`diffuse::same_side`).
#[inline(always)]
pub fn same_side(cos_o: F, cos_i: F) -> M {
    let zero = F::splat(0.0);
    (cos_o.gt(zero) & cos_i.gt(zero)) | (cos_o.lt(zero) & cos_i.lt(zero))
}
