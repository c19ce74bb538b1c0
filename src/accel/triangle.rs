//! The ray as traversal sees it, and the watertight ray-triangle test of Woop, Benthin and
//! Wald ("Watertight Ray/Triangle Intersection", JCGT 2013).
//!
//! The ray is moved to the origin and sheared so that it runs along +z; each triangle is then
//! tested in 2D with three edge functions. Because every edge function of two triangles that
//! share an edge is computed from the same two transformed vertices, in the same order up to a
//! sign, a ray can never slip between two triangles that share an edge or a vertex. An edge
//! function that rounds to exactly zero is recomputed in double precision, where the products
//! of the (single precision) inputs are exact.

use crate::math::gamma;
use glam::{Vec3, Vec3A, Vec3Swizzles};

/// A ray prepared once for traversal: its reciprocal direction for the box tests and the
/// permutation and shear of the watertight triangle test.
#[derive(Clone, Copy, Debug)]
pub struct TraversalRay {
    pub origin: Vec3A,
    /// `1 / dir` per axis (IEEE: +-infinity for a zero component).
    pub inv_dir: Vec3A,
    /// Bit `axis` set where the direction component has its sign bit set (matches the sign of
    /// `inv_dir`).
    pub neg: u32,
    /// The axes that become x, y and z: z is the axis along which the direction is largest in
    /// magnitude, and the vertices are rotated (a cyclic permutation, so handedness is kept).
    pub(super) k: [usize; 3],
    /// Shear constants: `-d[kx] / d[kz]`, `-d[ky] / d[kz]`, `1 / d[kz]`.
    pub(super) sx: f32,
    pub(super) sy: f32,
    pub(super) sz: f32,
    /// The origin's coordinates along the axes `k`, each in all three lanes.
    pub(super) o_k: [Vec3A; 3],
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
    #[inline(always)]
    pub fn new(origin: Vec3A, dir: Vec3A) -> TraversalRay {
        let a = dir.abs();
        let kz = if a.x > a.y {
            if a.x > a.z { 0 } else { 2 }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        // The direction and origin with their axes in the order k (lane by lane, so every
        // value below is the same scalar operation on the same inputs as per axis).
        let (k, d, o) = match kz {
            0 => ([1, 2, 0], dir.yzx(), origin.yzx()),
            1 => ([2, 0, 1], dir.zxy(), origin.zxy()),
            _ => ([0, 1, 2], dir, origin),
        };
        let sz = 1.0 / d.z;
        TraversalRay {
            origin,
            inv_dir: Vec3A::ONE / dir,
            neg: dir.is_negative_bitmask(),
            k,
            sx: -d.x * sz,
            sy: -d.y * sz,
            sz,
            o_k: [Vec3A::splat(o.x), Vec3A::splat(o.y), Vec3A::splat(o.z)],
        }
    }

    /// Intersects the triangle `v`: the hit's `(t, b1, b2)` when it lies in `(0, t_max]` (a
    /// hit at exactly `t_max` is returned so that the caller can break the tie, see `closer`).
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
        finish(
            [ax, bx, cx],
            [ay, by, cy],
            [az, bz, cz],
            [e0, e1, e2],
            det,
            t_scaled,
            t_max,
        )
    }
}

/// The end of the test, shared by the one-triangle and the four-triangle versions: the range
/// test of the scaled distance and the error bound of t. `x`, `y` are the sheared vertex
/// coordinates, `z` the scaled ones, `e` the edge functions (on one side), `det` their sum
/// (non-zero) and `t_scaled` the scaled distance.
#[inline(always)]
fn finish(
    [ax, bx, cx]: [f32; 3],
    [ay, by, cy]: [f32; 3],
    [az, bz, cz]: [f32; 3],
    [e0, e1, e2]: [f32; 3],
    det: f32,
    t_scaled: f32,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    {
        if det < 0.0 {
            if t_scaled >= 0.0 || t_scaled < t_max * det * RANGE_MARGIN {
                return None;
            }
        } else if t_scaled <= 0.0 || t_scaled > t_max * det * RANGE_MARGIN {
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
        // Keeps a t equal to t_max (the caller breaks that tie), rejects any NaN.
        if t > delta_t && t <= t_max {
            Some((t, e1 * inv_det, e2 * inv_det))
        } else {
            None
        }
    }
}

/// How much the range test of the scaled distance widens `t_max |det|` before it rejects a
/// hit: enough that no hit whose final `t = t_scaled * (1 / det)` (two roundings) is at most
/// `t_max` is ever rejected by it (`t_max |det|` rounds once more; 2^-20 is over four times
/// those three roundings of 2^-24). So whether a triangle is hit, and at which t, does not
/// depend on the `t_max` it was tested against, only whether that t is taken does: the
/// closest hit is the same whichever order the triangles are tested in.
pub(crate) const RANGE_MARGIN: f32 = 1.0 + 1.0 / (1u32 << 20) as f32;

/// Whether a hit at `t` on the triangle in leaf-order slot `slot` is closer than the best so
/// far (`t_max`, `best`): a nearer t, or the same t on a lower slot. The tie-break by slot
/// makes the closest hit independent of the order in which traversal meets the triangles, so
/// single rays and packets (which visit in different orders) find the same hit. Before the
/// first hit, and in any-hit searches, `best` is 0, so that only t below `t_max` counts.
#[inline(always)]
pub(crate) fn closer(t: f32, slot: u32, t_max: f32, best: u32) -> bool {
    t < t_max || (t == t_max && slot < best)
}

/// Triangles per packet.
pub const LANES: usize = 4;

/// Four triangles laid out for the four-lane test: `v[vertex][axis][lane]`, and each lane's
/// triangle id (`TriangleColumns` index; `u32::MAX` in an unused lane, whose vertices are zeros
/// and never tested: the caller names the lanes). The ids are kept here, in the packet's last
/// cache line, which the test of a hit has just read, rather than in an array of their own:
/// reading a hit's id from there missed the cache for most hits on big_1m (6% of its
/// closest-hit time, `perf record`). 160 bytes aligned to 32: always three cache lines, as
/// the 144 bytes of the vertices alone were at 16.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct TrianglePacket {
    pub v: [[[f32; LANES]; 3]; 3],
    pub ids: [u32; LANES],
}

const _: () = assert!(std::mem::size_of::<TrianglePacket>() == 160);

impl Default for TrianglePacket {
    fn default() -> TrianglePacket {
        TrianglePacket {
            v: [[[0.0; LANES]; 3]; 3],
            ids: [u32::MAX; LANES],
        }
    }
}

impl TrianglePacket {
    /// Puts the triangle `tri` in lane `lane`.
    pub fn set(&mut self, lane: usize, tri: &[Vec3; 3]) {
        for (vertex, p) in tri.iter().enumerate() {
            for axis in 0..3 {
                self.v[vertex][axis][lane] = p[axis];
            }
        }
    }

    /// The columns of the triangle in lane `lane`, for the one-triangle test.
    #[inline(always)]
    pub fn columns(&self, lane: usize) -> TriangleColumns {
        let v = &self.v;
        [0, 1, 2].map(|axis| Vec3A::new(v[0][axis][lane], v[1][axis][lane], v[2][axis][lane]))
    }
}

impl TraversalRay {
    /// Tests the triangles of `packet` (whose lane 0 is leaf-order slot `base`) in the lanes
    /// set in `valid`, exactly as `intersect` would one after another: each hit `closer` than
    /// (`t_max`, `best`) becomes the best; with `ANY`, the first hit ends the test. Returns the
    /// lane and the hit of the last hit taken (the closest one), if any.
    ///
    /// SSE2 (always present on x86_64): the sheared coordinates, edge functions and scaled
    /// distances of the four triangles, lane by lane the same operations in the same order as
    /// the scalar test, so that the result is bit-identical and shared edges stay watertight.
    /// A lane with an edge function of exactly zero is handed to the scalar test (which
    /// recomputes it exactly); lanes that pass the range test finish in scalar code.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub fn intersect4<const ANY: bool>(
        &self,
        packet: &TrianglePacket,
        valid: u32,
        base: u32,
        t_max: &mut f32,
        best: &mut u32,
    ) -> Option<(u32, (f32, f32, f32))> {
        use std::arch::x86_64::*;
        let [kx, ky, kz] = self.k;
        // SAFETY: SSE2 is part of the x86_64 baseline, so these intrinsics are always
        // available; the loads and stores are `_mm_loadu_ps`/`_mm_storeu_ps` on `[f32; 4]`
        // arrays that are borrowed (or owned) for the duration of the call.
        unsafe {
            let ox = _mm_set1_ps(self.o_k[0].x);
            let oy = _mm_set1_ps(self.o_k[1].x);
            let oz = _mm_set1_ps(self.o_k[2].x);
            let sx = _mm_set1_ps(self.sx);
            let sy = _mm_set1_ps(self.sy);
            let sz = _mm_set1_ps(self.sz);
            let vertex = |i: usize| {
                let x = _mm_sub_ps(_mm_loadu_ps(packet.v[i][kx].as_ptr()), ox);
                let y = _mm_sub_ps(_mm_loadu_ps(packet.v[i][ky].as_ptr()), oy);
                let z = _mm_sub_ps(_mm_loadu_ps(packet.v[i][kz].as_ptr()), oz);
                (
                    _mm_add_ps(x, _mm_mul_ps(sx, z)),
                    _mm_add_ps(y, _mm_mul_ps(sy, z)),
                    z,
                )
            };
            let (x0, y0, z0) = vertex(0);
            let (x1, y1, z1) = vertex(1);
            let (x2, y2, z2) = vertex(2);
            let e0 = _mm_sub_ps(_mm_mul_ps(x2, y1), _mm_mul_ps(y2, x1));
            let e1 = _mm_sub_ps(_mm_mul_ps(x0, y2), _mm_mul_ps(y0, x2));
            let e2 = _mm_sub_ps(_mm_mul_ps(x1, y0), _mm_mul_ps(y1, x0));
            let zero = _mm_setzero_ps();
            let any_lt = _mm_or_ps(
                _mm_or_ps(_mm_cmplt_ps(e0, zero), _mm_cmplt_ps(e1, zero)),
                _mm_cmplt_ps(e2, zero),
            );
            let any_gt = _mm_or_ps(
                _mm_or_ps(_mm_cmpgt_ps(e0, zero), _mm_cmpgt_ps(e1, zero)),
                _mm_cmpgt_ps(e2, zero),
            );
            let any_eq = _mm_or_ps(
                _mm_or_ps(_mm_cmpeq_ps(e0, zero), _mm_cmpeq_ps(e1, zero)),
                _mm_cmpeq_ps(e2, zero),
            );
            let exact = _mm_movemask_ps(any_eq) as u32 & valid;
            let both_sides = _mm_movemask_ps(_mm_and_ps(any_lt, any_gt)) as u32;
            let mut lanes = valid & !exact & !both_sides;
            if lanes != 0 {
                let det = _mm_add_ps(_mm_add_ps(e0, e1), e2);
                let az = _mm_mul_ps(sz, z0);
                let bz = _mm_mul_ps(sz, z1);
                let cz = _mm_mul_ps(sz, z2);
                let t_scaled = _mm_add_ps(
                    _mm_add_ps(_mm_mul_ps(e0, az), _mm_mul_ps(e1, bz)),
                    _mm_mul_ps(e2, cz),
                );
                // The range test with the sign of det moved onto both sides (exact): lanes
                // with 0 < t_scaled <= t_max |det| (widened by `RANGE_MARGIN`); also fails for
                // det == 0 and for NaN.
                let sign = _mm_and_ps(det, _mm_set1_ps(-0.0));
                let ts = _mm_xor_ps(t_scaled, sign);
                let limit = _mm_mul_ps(
                    _mm_xor_ps(_mm_mul_ps(_mm_set1_ps(*t_max), det), sign),
                    _mm_set1_ps(RANGE_MARGIN),
                );
                let in_range = _mm_and_ps(_mm_cmpgt_ps(ts, zero), _mm_cmple_ps(ts, limit));
                lanes &= _mm_movemask_ps(in_range) as u32;
                if lanes | exact == 0 {
                    return None;
                }
                // `finish` on all four lanes at once, operation for operation (so bit for bit:
                // the maxima see no NaN in a lane that passed the range test, since a NaN
                // coordinate makes det or t_scaled NaN). The lanes that pass are then taken in
                // order where `closer` than the best so far.
                let abs_mask = _mm_set1_ps(f32::from_bits(0x7fff_ffff));
                let abs = |v: __m128| _mm_and_ps(v, abs_mask);
                let max3 = |a: __m128, b: __m128, c: __m128| {
                    _mm_max_ps(_mm_max_ps(abs(a), abs(b)), abs(c))
                };
                let inv_det = _mm_div_ps(_mm_set1_ps(1.0), det);
                let t = _mm_mul_ps(t_scaled, inv_det);
                let max_z = max3(az, bz, cz);
                let max_x = max3(x0, x1, x2);
                let max_y = max3(y0, y1, y2);
                let g = |n: i32| _mm_set1_ps(gamma(n));
                let delta_z = _mm_mul_ps(g(3), max_z);
                let delta_x = _mm_mul_ps(g(5), _mm_add_ps(max_x, max_z));
                let delta_y = _mm_mul_ps(g(5), _mm_add_ps(max_y, max_z));
                let delta_e = _mm_mul_ps(
                    _mm_set1_ps(2.0),
                    _mm_add_ps(
                        _mm_add_ps(
                            _mm_mul_ps(_mm_mul_ps(g(2), max_x), max_y),
                            _mm_mul_ps(delta_y, max_x),
                        ),
                        _mm_mul_ps(delta_x, max_y),
                    ),
                );
                let max_e = max3(e0, e1, e2);
                let delta_t = _mm_mul_ps(
                    _mm_mul_ps(
                        _mm_set1_ps(3.0),
                        _mm_add_ps(
                            _mm_add_ps(
                                _mm_mul_ps(_mm_mul_ps(g(3), max_e), max_z),
                                _mm_mul_ps(delta_e, max_z),
                            ),
                            _mm_mul_ps(delta_z, max_e),
                        ),
                    ),
                    abs(inv_det),
                );
                let ok = _mm_and_ps(
                    _mm_cmpgt_ps(t, delta_t),
                    _mm_cmple_ps(t, _mm_set1_ps(*t_max)),
                );
                lanes &= _mm_movemask_ps(ok) as u32;
                if lanes | exact == 0 {
                    return None;
                }
                let store = |v: __m128| {
                    let mut a = [0.0f32; 4];
                    _mm_storeu_ps(a.as_mut_ptr(), v);
                    a
                };
                let (t, inv_det) = (store(t), store(inv_det));
                let (e1, e2) = (store(e1), store(e2));
                let mut hit = None;
                let mut left = lanes | exact;
                while left != 0 {
                    let i = left.trailing_zeros() as usize;
                    left &= left - 1;
                    let h = if exact & (1 << i) != 0 {
                        self.intersect(&packet.columns(i), *t_max)
                    } else {
                        Some((t[i], e1[i] * inv_det[i], e2[i] * inv_det[i]))
                    };
                    let slot = base + i as u32;
                    if let Some(h) = h.filter(|h| closer(h.0, slot, *t_max, *best)) {
                        *t_max = h.0;
                        *best = slot;
                        hit = Some((i as u32, h));
                        if ANY {
                            break;
                        }
                    }
                }
                hit
            } else if exact != 0 {
                self.intersect_lanes::<ANY>(packet, exact, base, t_max, best)
            } else {
                None
            }
        }
    }

    /// The four-triangle test (portable version): the scalar test, lane by lane.
    #[cfg(not(target_arch = "x86_64"))]
    #[inline(always)]
    pub fn intersect4<const ANY: bool>(
        &self,
        packet: &TrianglePacket,
        lanes: u32,
        base: u32,
        t_max: &mut f32,
        best: &mut u32,
    ) -> Option<(u32, (f32, f32, f32))> {
        self.intersect_lanes::<ANY>(packet, lanes, base, t_max, best)
    }

    /// The scalar test of the triangles of `packet` in the lanes set in `lanes`, in order.
    #[inline(always)]
    fn intersect_lanes<const ANY: bool>(
        &self,
        packet: &TrianglePacket,
        mut lanes: u32,
        base: u32,
        t_max: &mut f32,
        best: &mut u32,
    ) -> Option<(u32, (f32, f32, f32))> {
        let mut hit = None;
        while lanes != 0 {
            let i = lanes.trailing_zeros();
            lanes &= lanes - 1;
            let slot = base + i;
            if let Some(h) = self
                .intersect(&packet.columns(i as usize), *t_max)
                .filter(|h| closer(h.0, slot, *t_max, *best))
            {
                *t_max = h.0;
                *best = slot;
                hit = Some((i, h));
                if ANY {
                    break;
                }
            }
        }
        hit
    }
}
