//! Paths in SIMD lanes: the wavefront's shading systems take their queues `N` paths at a time
//! (`--lanes`, see `crate::lanes`), as columns of `N` numbers, so the compiler turns each step
//! into vector instructions (eight f32 lanes per AVX2 instruction, sixteen per AVX-512 one).
//!
//! Every operation here is the lane-by-lane twin of the scalar code that the megakernel runs
//! (glam's `Vec3`, `Frame`, the sampler's hash): the same IEEE operations in the same order, no
//! fused multiply-adds, so each lane's result is the scalar result, bit for bit
//! (`tests/it/kernels.rs` renders both kernels and compares the films). The BSDFs' maths is not
//! here: it is written once over `Real` (`crate::bsdf::diffuse`, `conductor`, `plastic`) and
//! runs in lanes as it is (`Bsdf::sample_lanes`, `Bsdf::eval_pdf_lanes`).

use crate::bsdf::Bsdf;
use crate::lanes::{F, M, Mask, Real, V3, lanes_of};
use crate::math::Frame;
use crate::sampling::{SampleKey, Sampler};
use glam::{Vec2, Vec3};

/// `Frame` in lanes.
#[derive(Clone, Copy)]
pub struct Frames<const N: usize> {
    pub s: V3<F<N>>,
    pub t: V3<F<N>>,
    pub n: V3<F<N>>,
}

impl<const N: usize> Frames<N> {
    /// `Frame::from_normal`, lane by lane.
    #[inline(always)]
    pub fn from_normal(n: V3<F<N>>) -> Frames<N> {
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
    pub fn to_local(&self, v: V3<F<N>>) -> V3<F<N>> {
        V3 {
            x: v.dot(self.s),
            y: v.dot(self.t),
            z: v.dot(self.n),
        }
    }
    #[inline(always)]
    pub fn to_world(&self, v: V3<F<N>>) -> V3<F<N>> {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// The frames agree with `Frame` (used by tests).
impl<const N: usize> Frames<N> {
    pub fn lane(&self, l: usize) -> Frame {
        Frame {
            s: self.s.lane(l),
            t: self.t.lane(l),
            n: self.n.lane(l),
        }
    }
}

/// Number `dims[l]` of `keys[l]` in every lane (`Sampler::get`): the independent sampler's
/// hash runs in vector lanes, the other samplers lane by lane.
#[inline(always)]
pub fn draw<const N: usize>(sampler: &Sampler, keys: &[SampleKey; N], dims: &[u32; N]) -> F<N> {
    match sampler {
        Sampler::Independent { .. } => F(SampleKey::get_lanes(keys, dims)),
        _ => F::from_fn(|l| sampler.get(keys[l], dims[l])),
    }
}

/// Numbers `dims[l]` and `dims[l] + 1` of `keys[l]` in every lane (`Sampler::get2`).
#[inline(always)]
pub fn draw2<const N: usize>(
    sampler: &Sampler,
    keys: &[SampleKey; N],
    dims: &[u32; N],
) -> (F<N>, F<N>) {
    match sampler {
        Sampler::Independent { .. } => {
            let next = lanes_of(|l| dims[l] + 1);
            (
                F(SampleKey::get_lanes(keys, dims)),
                F(SampleKey::get_lanes(keys, &next)),
            )
        }
        _ => {
            let u: [Vec2; N] = lanes_of(|l| sampler.get2(keys[l], dims[l]));
            (F::from_fn(|l| u[l].x), F::from_fn(|l| u[l].y))
        }
    }
}

/// `offset_ray_origin` in lanes: `p` moved off its surface along `ng`, on the side of `w`.
#[inline(always)]
pub fn offset_origin<const N: usize>(
    p: V3<F<N>>,
    p_error: V3<F<N>>,
    ng: V3<F<N>>,
    w: V3<F<N>>,
) -> V3<F<N>> {
    let d = ng.abs().dot(p_error);
    let offset = d * ng;
    let offset = V3::select(w.dot(ng).less(F::splat(0.0)), -offset, offset);
    let po = p + offset;
    let bump = V3 {
        x: (po.x.abs() * f32::EPSILON).max(F::splat(f32::MIN_POSITIVE)),
        y: (po.y.abs() * f32::EPSILON).max(F::splat(f32::MIN_POSITIVE)),
        z: (po.z.abs() * f32::EPSILON).max(F::splat(f32::MIN_POSITIVE)),
    };
    let zero = F::splat(0.0);
    let away =
        |o: F<N>, b: F<N>| F::select(o.greater(zero), b, zero) - F::select(o.less(zero), b, zero);
    V3 {
        x: po.x + away(offset.x, bump.x),
        y: po.y + away(offset.y, bump.y),
        z: po.z + away(offset.z, bump.z),
    }
}

/// `power_heuristic` in lanes.
#[inline(always)]
pub fn power_heuristic<const N: usize>(f: F<N>, g: F<N>) -> F<N> {
    let f2 = f * f;
    let g2 = g * g;
    let sum = f2 + g2;
    let ratio = f2 / sum;
    let ratio = F::select(f2.equal(F::splat(f32::INFINITY)), F::splat(1.0), ratio);
    F::select(sum.equal(F::splat(0.0)), F::splat(0.0), ratio)
}

/// `Surface` in lanes, for `N` paths on materials of one kind with a lane form
/// (`Bsdf::IN_LANES`): the hit points with their error bounds, the geometric normals and
/// shading frames turned as `Surface` turns them (to the side the ray came from where the
/// material reflects on both sides), and wo.
#[derive(Clone, Copy)]
pub struct SurfaceLanes<const N: usize> {
    pub p: V3<F<N>>,
    pub p_error: V3<F<N>>,
    pub ng: V3<F<N>>,
    pub frame: Frames<N>,
    pub wo: V3<F<N>>,
    pub wo_local: V3<F<N>>,
}

impl<const N: usize> SurfaceLanes<N> {
    /// The surfaces of slots `i..i + N` of a chunk's views (`Surface::at` lane by lane) and
    /// their materials, or None when one of them is not of type `B`.
    #[inline(always)]
    pub fn at<B: Bsdf>(
        data: &crate::scene::SceneData,
        surfaces: &crate::components::SurfacesView,
        looked_up: &[crate::bsdf::Material],
        dirs: &[Vec3],
        i: usize,
    ) -> Option<(SurfaceLanes<N>, [B; N])> {
        let first = *B::of(&material_seen(data, looked_up, surfaces, i))?;
        let mut materials = [first; N];
        for (l, m) in materials.iter_mut().enumerate().skip(1) {
            *m = *B::of(&material_seen(data, looked_up, surfaces, i + l))?;
        }
        let ng = V3::load(&surfaces.ng[i..]);
        let ns = V3::load(&surfaces.ns[i..]);
        let wo = -V3::load(&dirs[i..]);
        // As `Surface`: a material that reflects on both sides is shaded from the side the
        // ray came from. `Surface` asks the triangle's material, this the material seen (a
        // constant for the Lambertian kind): the same but for a one-sided surface seen from
        // behind, whose black material ends the path from either side.
        let flip = wo.dot(ng).less(F::splat(0.0)) & M::lanes(|l| materials[l].two_sided());
        let ng = V3::select(flip, -ng, ng);
        let ns = V3::select(flip, -ns, ns);
        let frame = Frames::from_normal(ns);
        Some((
            SurfaceLanes {
                p: V3::load(&surfaces.p[i..]),
                p_error: V3::load(&surfaces.p_error[i..]),
                ng,
                frame,
                wo,
                wo_local: frame.to_local(wo),
            },
            materials,
        ))
    }
}

/// The material that slot `i` of a chunk's surfaces sees: `looked_up[i]` where the scene has
/// textures (`look_up_textures` wrote the chunk's column), else the one `sort_by_material`
/// found for the hit (`Surfaces::material`). Inlined: out of line, its call and the copy of
/// the material it returns took 2% of a Cornell box render.
#[inline(always)]
pub(super) fn material_seen(
    data: &crate::scene::SceneData,
    looked_up: &[crate::bsdf::Material],
    surfaces: &crate::components::SurfacesView,
    i: usize,
) -> crate::bsdf::Material {
    match looked_up.get(i) {
        Some(&material) => material,
        None => data.scene.seen_material(surfaces.material[i]),
    }
}
