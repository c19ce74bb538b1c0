//! Numbers one path at a time or many paths in SIMD lanes, behind one trait, so that the maths
//! of a material (or any per-path step) is written once and serves both the megakernel's single
//! path and the wavefront's lanes (docs/architecture.md, "Writing a material once for one path
//! and for lanes").
//!
//! [`Real`] is implemented by `f32` (masks are `bool`) and by [`F<N>`], `N` paths as a column of
//! `N` numbers (masks are [`M<N>`]); [`V3`] is a 3-vector over either. Code generic over `Real`
//! compiles, for `f32`, to the plain scalar code, and for `F<N>` to loops over `N` lanes that
//! the compiler turns into vector instructions: `N = 8` fills AVX2's registers and `N = 16`
//! AVX-512's ([`LaneWidth`] picks one at run time, [`run_lanes`] runs a kernel in the copy
//! compiled for the CPU).
//!
//! Every lane operation is the lane-by-lane twin of the scalar one (glam's `Vec3` included):
//! the same IEEE operations in the same order, never fused, so each lane's result is the scalar
//! result bit for bit (`tests/it/kernels.rs` renders the megakernel and the wavefront at each
//! width and compares the films).

use glam::Vec3;
use std::ops::{Add, BitAnd, BitOr, BitXor, Div, Mul, Neg, Not, Sub};

/// Per-lane flags: `bool` for one path, [`M<N>`] for lanes.
pub trait Mask:
    Copy + BitAnd<Output = Self> + BitOr<Output = Self> + BitXor<Output = Self> + Not<Output = Self>
{
    fn splat(v: bool) -> Self;
    /// A flag per lane from `f(l)`.
    fn lanes(f: impl FnMut(usize) -> bool) -> Self;
    /// Lane `l`'s flag.
    fn lane(self, l: usize) -> bool;
    /// Whether every lane is set.
    fn all(self) -> bool;
    /// Whether some lane is set.
    fn any(self) -> bool;
}

/// A number per path: `f32` for one path, [`F<N>`] for `N` paths in lanes. The operations are
/// those of `f32` (`max` is `f32::max`), lane by lane.
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f32, Output = Self>
    + Sub<f32, Output = Self>
    + Mul<f32, Output = Self>
    + Div<f32, Output = Self>
{
    type Mask: Mask;
    /// `v` in every lane.
    fn splat(v: f32) -> Self;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    /// `f32::max`: a NaN lane takes the other operand.
    fn max(self, o: Self) -> Self;
    /// `f32::min`: a NaN lane takes the other operand.
    fn min(self, o: Self) -> Self;
    /// `1.0f32.copysign(self)`.
    fn sign_one(self) -> Self;
    fn less(self, o: Self) -> Self::Mask;
    fn less_eq(self, o: Self) -> Self::Mask;
    fn greater(self, o: Self) -> Self::Mask;
    fn equal(self, o: Self) -> Self::Mask;
    /// `if m { a } else { b }`, lane by lane.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    fn floor(self) -> Self;
    /// 2^self, exactly, for an integer-valued `self` within [-126, 127] (written straight
    /// into the exponent's bits).
    fn pow2(self) -> Self;

    /// Something per lane: `[R; 1]` for one path, `[R; N]` for lanes. Where a step has no
    /// vector form (a table look-up, an iterative inversion), the generic code runs the
    /// scalar step lane by lane through it (`Real::lanes`, `Real::lane`).
    type Each<R: Copy>: Copy + std::ops::Index<usize, Output = R>;
    /// `f(l)` for every lane `l`.
    fn each<R: Copy>(f: impl FnMut(usize) -> R) -> Self::Each<R>;
    /// A number per lane from `f(l)`.
    fn lanes(f: impl FnMut(usize) -> f32) -> Self;
    /// Lane `l`'s number.
    fn lane(self, l: usize) -> f32;

    /// `if m { a() } else { b() }` lane by lane, computing only what some lane takes: for one
    /// path a branch, for lanes both sides where the mask is mixed.
    #[inline(always)]
    fn select_with(m: Self::Mask, a: impl FnOnce() -> Self, b: impl FnOnce() -> Self) -> Self {
        if m.all() {
            a()
        } else if !m.any() {
            b()
        } else {
            Self::select(m, a(), b())
        }
    }

    /// Sine and cosine of 2 pi `self` for `self` within [0, 1]: the quarter turn nearest
    /// `self` taken off (exactly: the difference is within an eighth of a turn of a multiple
    /// of a quarter, Sterbenz's lemma), `sin_cos_quarter` of the rest, and the quarter's
    /// rotation by swapping and negating. Within 2e-7 (`tests::turn_sine_and_cosine_are_accurate`).
    #[inline(always)]
    fn sin_cos_turn(self) -> (Self, Self) {
        let quarter = (self * 4.0 + 0.5).floor();
        let r = (self - quarter * 0.25) * std::f32::consts::TAU;
        let (sin, cos) = r.sin_cos_quarter();
        let (q1, q2, q3) = (
            quarter.equal(Self::splat(1.0)),
            quarter.equal(Self::splat(2.0)),
            quarter.equal(Self::splat(3.0)),
        );
        (
            Self::select(q1, cos, Self::select(q2, -sin, Self::select(q3, -cos, sin))),
            Self::select(q1, -sin, Self::select(q2, -cos, Self::select(q3, sin, cos))),
        )
    }

    /// Sine and cosine of an angle within [-pi/4, pi/4] (the concentric disk map's), by
    /// Cephes' single-precision minimax polynomials in z = x^2: within 1.2e-7 of the exact
    /// values there (`tests::quarter_sine_and_cosine_are_accurate`). Plain multiplies and adds
    /// in one order, so lanes vectorise (libm's sin and cos ran a call per lane) and every
    /// lane gives the scalar bits.
    #[inline(always)]
    fn sin_cos_quarter(self) -> (Self, Self) {
        let z = self * self;
        let sin = ((z * -1.951_529_6e-4 + 8.332_161e-3) * z - 1.666_665_5e-1) * z * self + self;
        let cos =
            ((z * 2.443_315_7e-5 - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - z * 0.5 + 1.0;
        (sin, cos)
    }

    /// `floor(self)` for |self| < 2^22, by adding and taking off 1.5 * 2^23 (which rounds to
    /// the nearest integer) and stepping down where that went up: the same bits as `floor`
    /// for every such f32 but -0 (which gives +0), in adds, a compare and a select. `floor`
    /// is one instruction in the AVX2 lane code but a libm call per lane in code compiled
    /// without SSE4.1: the one-path megakernel, and the lane code's out-of-line closures
    /// (`select_with`'s sides: Beckmann's D and G1, whose `exp` needs it).
    #[inline(always)]
    fn floor_small(self) -> Self {
        const ROUND: f32 = 12_582_912.0;
        let nearest = (self + ROUND) - ROUND;
        nearest - Self::select(nearest.greater(self), Self::splat(1.0), Self::splat(0.0))
    }

    /// e^self: Cody and Waite's reduction self = n ln 2 + r with ln 2 in two parts (the first
    /// has few enough bits that n times it is exact), Cephes' single-precision minimax
    /// polynomial for e^r on |r| <= ln 2 / 2, and 2^n put into the exponent. Within 1.2e-7 of
    /// e^x relatively on [-87.3, 88.7] (8.1e-8 measured; `tests::exp_and_erf_are_accurate`);
    /// 0 below, where e^x is under f32's least normal number, +inf above, NaN kept. Plain
    /// multiplies and adds, the same bits for one path and in every lane.
    #[inline(always)]
    fn exp(self) -> Self {
        const LOWEST: f32 = -87.336_55;
        const HIGHEST: f32 = 88.722_83;
        let x = self.max(Self::splat(LOWEST)).min(Self::splat(HIGHEST));
        // Within [-126, 129], and never -0 (a sum is -0 only where both terms are).
        let n = (x * std::f32::consts::LOG2_E + 0.5).floor_small();
        let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4;
        let p = (((((r * 1.987_569_2e-4 + 1.398_199_9e-3) * r + 8.333_452e-3) * r
            + 4.166_579_6e-2)
            * r
            + 1.666_666_5e-1)
            * r
            + 0.5)
            * (r * r)
            + r
            + 1.0;
        // n reaches 128 at the top of the range: 2^127 times 2.
        let top = n.greater(Self::splat(127.0));
        let e = p
            * (n - Self::select(top, Self::splat(1.0), Self::splat(0.0))).pow2()
            * Self::select(top, Self::splat(2.0), Self::splat(1.0));
        let e = Self::select(self.less(Self::splat(LOWEST)), Self::splat(0.0), e);
        let e = Self::select(
            self.greater(Self::splat(HIGHEST)),
            Self::splat(f32::INFINITY),
            e,
        );
        // max and min took a NaN to a bound.
        Self::select(self.equal(self), e, self)
    }

    /// erf(self): for |x| < 1/2 its Taylor series to x^11 (the next term is under 2e-8 of
    /// erf there), beyond 1 - erfc(|x|) by Numerical Recipes' Chebyshev fit of erfc (relative
    /// error under 1.2e-7) over `exp`; odd. Within 2.5e-7 of erf, absolutely and below 1/2
    /// relatively (1.7e-7 and 1.8e-7 measured; `tests::exp_and_erf_are_accurate`),
    /// and the same bits for one path and in every lane, where libm's erff was a call per lane.
    #[inline(always)]
    fn erf(self) -> Self {
        let one = Self::splat(1.0);
        let z = self.abs();
        let z2 = z * z;
        // 2/sqrt(pi) (x - x^3/3 + x^5/10 - x^7/42 + x^9/216 - x^11/1320)
        let series = ((((z2 * (-1.0 / 1320.0) + 1.0 / 216.0) * z2 - 1.0 / 42.0) * z2 + 0.1) * z2
            - 1.0 / 3.0)
            * z2
            + 1.0;
        let near = series * z * std::f32::consts::FRAC_2_SQRT_PI;
        let t = one / (z * 0.5 + 1.0);
        let fit = ((((((((t * 0.170_872_77 - 0.822_152_23) * t + 1.488_515_9) * t - 1.135_204)
            * t
            + 0.278_868_07)
            * t
            - 0.186_288_06)
            * t
            + 0.096_784_18)
            * t
            + 0.374_091_96)
            * t
            + 1.000_023_7)
            * t
            - 1.265_512_2;
        let far = one - t * (fit - z2).exp();
        Self::select(z.less(Self::splat(0.5)), near, far) * self.sign_one()
    }
}

impl Mask for bool {
    #[inline(always)]
    fn splat(v: bool) -> bool {
        v
    }
    #[inline(always)]
    fn lanes(mut f: impl FnMut(usize) -> bool) -> bool {
        f(0)
    }
    #[inline(always)]
    fn lane(self, _l: usize) -> bool {
        self
    }
    #[inline(always)]
    fn all(self) -> bool {
        self
    }
    #[inline(always)]
    fn any(self) -> bool {
        self
    }
}

impl Real for f32 {
    type Mask = bool;
    #[inline(always)]
    fn splat(v: f32) -> f32 {
        v
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> f32 {
        f32::abs(self)
    }
    #[inline(always)]
    fn max(self, o: f32) -> f32 {
        f32::max(self, o)
    }
    #[inline(always)]
    fn min(self, o: f32) -> f32 {
        f32::min(self, o)
    }
    #[inline(always)]
    fn sign_one(self) -> f32 {
        1.0f32.copysign(self)
    }
    #[inline(always)]
    fn less(self, o: f32) -> bool {
        self < o
    }
    #[inline(always)]
    fn less_eq(self, o: f32) -> bool {
        self <= o
    }
    #[inline(always)]
    fn greater(self, o: f32) -> bool {
        self > o
    }
    #[inline(always)]
    fn equal(self, o: f32) -> bool {
        self == o
    }
    #[inline(always)]
    fn select(m: bool, a: f32, b: f32) -> f32 {
        if m { a } else { b }
    }
    #[inline(always)]
    fn floor(self) -> f32 {
        f32::floor(self)
    }
    #[inline(always)]
    fn pow2(self) -> f32 {
        f32::from_bits(((self as i32 + 127) as u32) << 23)
    }
    type Each<R: Copy> = [R; 1];
    #[inline(always)]
    fn each<R: Copy>(mut f: impl FnMut(usize) -> R) -> [R; 1] {
        [f(0)]
    }
    #[inline(always)]
    fn lanes(mut f: impl FnMut(usize) -> f32) -> f32 {
        f(0)
    }
    #[inline(always)]
    fn lane(self, _l: usize) -> f32 {
        self
    }
}

/// One f32 per lane, `N` lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F<const N: usize>(pub [f32; N]);

/// One flag per lane, `N` lanes: all bits set (true) or none, the width of an f32 lane, as
/// vector compares give them. As `[bool; N]` the flags were bytes, and every compare and
/// select went through conversions between byte and word lanes and their shuffles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct M<const N: usize>([u32; N]);

/// A flag's lane bits.
#[inline(always)]
fn flag_bits(v: bool) -> u32 {
    (v as u32).wrapping_neg()
}

impl<const N: usize> F<N> {
    /// Lane `l` is `f(l)`.
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> f32) -> F<N> {
        let mut out = [0.0; N];
        for (l, v) in out.iter_mut().enumerate() {
            *v = f(l);
        }
        F(out)
    }
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F<N> {
        let mut out = self.0;
        for v in &mut out {
            *v = f(*v);
        }
        F(out)
    }
    #[inline(always)]
    fn zip(self, o: F<N>, f: impl Fn(f32, f32) -> f32) -> F<N> {
        let mut out = self.0;
        for (v, w) in out.iter_mut().zip(o.0) {
            *v = f(*v, w);
        }
        F(out)
    }
    #[inline(always)]
    fn test(self, o: F<N>, f: impl Fn(f32, f32) -> bool) -> M<N> {
        let mut out = [0; N];
        for ((m, a), b) in out.iter_mut().zip(self.0).zip(o.0) {
            *m = flag_bits(f(a, b));
        }
        M(out)
    }
}

impl<const N: usize> Real for F<N> {
    type Mask = M<N>;
    #[inline(always)]
    fn splat(v: f32) -> F<N> {
        F([v; N])
    }
    #[inline(always)]
    fn sqrt(self) -> F<N> {
        self.map(f32::sqrt)
    }
    #[inline(always)]
    fn abs(self) -> F<N> {
        self.map(f32::abs)
    }
    #[inline(always)]
    fn max(self, o: F<N>) -> F<N> {
        self.zip(o, f32::max)
    }
    #[inline(always)]
    fn min(self, o: F<N>) -> F<N> {
        self.zip(o, f32::min)
    }
    #[inline(always)]
    fn sign_one(self) -> F<N> {
        self.map(|v| 1.0f32.copysign(v))
    }
    #[inline(always)]
    fn less(self, o: F<N>) -> M<N> {
        self.test(o, |a, b| a < b)
    }
    #[inline(always)]
    fn less_eq(self, o: F<N>) -> M<N> {
        self.test(o, |a, b| a <= b)
    }
    #[inline(always)]
    fn greater(self, o: F<N>) -> M<N> {
        self.test(o, |a, b| a > b)
    }
    #[inline(always)]
    fn equal(self, o: F<N>) -> M<N> {
        self.test(o, |a, b| a == b)
    }
    #[inline(always)]
    fn select(m: M<N>, a: F<N>, b: F<N>) -> F<N> {
        // By bits: exactly `a` or `b`, and a blend for the compiler.
        let mut out = b.0;
        for ((v, m), a) in out.iter_mut().zip(m.0).zip(a.0) {
            *v = f32::from_bits((a.to_bits() & m) | (v.to_bits() & !m));
        }
        F(out)
    }
    #[inline(always)]
    fn floor(self) -> F<N> {
        self.map(f32::floor)
    }
    #[inline(always)]
    fn pow2(self) -> F<N> {
        self.map(f32::pow2)
    }
    type Each<R: Copy> = [R; N];
    #[inline(always)]
    fn each<R: Copy>(f: impl FnMut(usize) -> R) -> [R; N] {
        lanes_of(f)
    }
    #[inline(always)]
    fn lanes(f: impl FnMut(usize) -> f32) -> F<N> {
        F::from_fn(f)
    }
    #[inline(always)]
    fn lane(self, l: usize) -> f32 {
        self.0[l]
    }
}

impl<const N: usize> Mask for M<N> {
    #[inline(always)]
    fn splat(v: bool) -> M<N> {
        M([flag_bits(v); N])
    }
    #[inline(always)]
    fn lanes(f: impl FnMut(usize) -> bool) -> M<N> {
        let mut f = f;
        M(lanes_of(|l| flag_bits(f(l))))
    }
    #[inline(always)]
    fn lane(self, l: usize) -> bool {
        self.0[l] != 0
    }
    #[inline(always)]
    fn all(self) -> bool {
        self.0.iter().fold(!0, |all, &m| all & m) != 0
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().fold(0, |any, &m| any | m) != 0
    }
}

impl<const N: usize> Not for M<N> {
    type Output = M<N>;
    #[inline(always)]
    fn not(self) -> M<N> {
        let mut out = self.0;
        for v in &mut out {
            *v = !*v;
        }
        M(out)
    }
}

macro_rules! mask_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl<const N: usize> $tr for M<N> {
            type Output = M<N>;
            #[inline(always)]
            fn $f(self, o: M<N>) -> M<N> {
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
        impl<const N: usize> $tr for F<N> {
            type Output = F<N>;
            #[inline(always)]
            fn $f(self, o: F<N>) -> F<N> {
                self.zip(o, |a, b| a $op b)
            }
        }
        impl<const N: usize> $tr<f32> for F<N> {
            type Output = F<N>;
            #[inline(always)]
            fn $f(self, o: f32) -> F<N> {
                self.map(|a| a $op o)
            }
        }
        impl<const N: usize> $tr<F<N>> for f32 {
            type Output = F<N>;
            #[inline(always)]
            fn $f(self, o: F<N>) -> F<N> {
                o.map(|b| self $op b)
            }
        }
        impl<T: Real> $tr for V3<T> {
            type Output = V3<T>;
            #[inline(always)]
            fn $f(self, o: V3<T>) -> V3<T> {
                V3 { x: self.x $op o.x, y: self.y $op o.y, z: self.z $op o.z }
            }
        }
        /// Each component with the lane's number (glam's `Vec3 op f32`).
        impl<T: Real> $tr<T> for V3<T> {
            type Output = V3<T>;
            #[inline(always)]
            fn $f(self, o: T) -> V3<T> {
                V3 { x: self.x $op o, y: self.y $op o, z: self.z $op o }
            }
        }
    };
}
float_op!(Add, add, +);
float_op!(Sub, sub, -);
float_op!(Mul, mul, *);
float_op!(Div, div, /);

impl<const N: usize> Neg for F<N> {
    type Output = F<N>;
    #[inline(always)]
    fn neg(self) -> F<N> {
        self.map(|v| -v)
    }
}

/// A 3-vector of `Real`s: glam's `Vec3` for one path (`V3<f32>`, convertible both ways), three
/// columns for lanes (`V3<F<N>>`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct V3<T> {
    pub x: T,
    pub y: T,
    pub z: T,
}

impl<T: Real> Neg for V3<T> {
    type Output = V3<T>;
    #[inline(always)]
    fn neg(self) -> V3<T> {
        V3 {
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// `f32 * Vec3` (each component times the lane's number, the scalar first, as glam).
impl<const N: usize> Mul<V3<F<N>>> for F<N> {
    type Output = V3<F<N>>;
    #[inline(always)]
    fn mul(self, v: V3<F<N>>) -> V3<F<N>> {
        V3 {
            x: self * v.x,
            y: self * v.y,
            z: self * v.z,
        }
    }
}

/// `f32 * Vec3`, as glam.
impl Mul<V3<f32>> for f32 {
    type Output = V3<f32>;
    #[inline(always)]
    fn mul(self, v: V3<f32>) -> V3<f32> {
        V3 {
            x: self * v.x,
            y: self * v.y,
            z: self * v.z,
        }
    }
}

impl<T: Real> V3<T> {
    #[inline(always)]
    pub fn new(x: T, y: T, z: T) -> V3<T> {
        V3 { x, y, z }
    }
    /// `v` in every lane.
    #[inline(always)]
    pub fn splat(v: Vec3) -> V3<T> {
        V3 {
            x: T::splat(v.x),
            y: T::splat(v.y),
            z: T::splat(v.z),
        }
    }
    /// glam's `Vec3::dot` (and `Vec3A::dot`): (x x' + y y') + z z'.
    #[inline(always)]
    pub fn dot(self, o: V3<T>) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    #[inline(always)]
    pub fn abs(self) -> V3<T> {
        V3 {
            x: self.x.abs(),
            y: self.y.abs(),
            z: self.z.abs(),
        }
    }
    /// glam's `Vec3::normalize`: times 1 / length.
    #[inline(always)]
    pub fn normalize(self) -> V3<T> {
        self * (T::splat(1.0) / self.dot(self).sqrt())
    }
    /// glam's `Vec3::length`.
    #[inline(always)]
    pub fn length(self) -> T {
        self.dot(self).sqrt()
    }
    /// glam's `Vec3::normalize_or`: `fallback` where 1 / length is not finite and positive.
    #[inline(always)]
    pub fn normalize_or(self, fallback: V3<T>) -> V3<T> {
        let rcp = T::splat(1.0) / self.length();
        let fine = rcp.greater(T::splat(0.0)) & rcp.less(T::splat(f32::INFINITY));
        V3::select(fine, self * rcp, fallback)
    }
    /// glam's `Vec3::cross`.
    #[inline(always)]
    pub fn cross(self, o: V3<T>) -> V3<T> {
        V3 {
            x: self.y * o.z - o.y * self.z,
            y: self.z * o.x - o.z * self.x,
            z: self.x * o.y - o.x * self.y,
        }
    }
    /// A vector per lane from `f(l)`.
    #[inline(always)]
    pub fn lanes(f: impl FnMut(usize) -> Vec3) -> V3<T> {
        let v = T::each(f);
        V3 {
            x: T::lanes(|l| v[l].x),
            y: T::lanes(|l| v[l].y),
            z: T::lanes(|l| v[l].z),
        }
    }
    /// Lane `l`'s vector.
    #[inline(always)]
    pub fn lane_of(self, l: usize) -> Vec3 {
        Vec3::new(self.x.lane(l), self.y.lane(l), self.z.lane(l))
    }
    /// `if m { a() } else { b() }` lane by lane, computing only what some lane takes.
    #[inline(always)]
    pub fn select_with(m: T::Mask, a: impl FnOnce() -> V3<T>, b: impl FnOnce() -> V3<T>) -> V3<T> {
        if m.all() {
            a()
        } else if !m.any() {
            b()
        } else {
            V3::select(m, a(), b())
        }
    }

    /// glam's `Vec3::max_element`: max(x, max(y, z)) with max(a, b) = if a > b { a } else { b }.
    #[inline(always)]
    pub fn max_element(self) -> T {
        let max = |a: T, b: T| T::select(a.greater(b), a, b);
        max(self.x, max(self.y, self.z))
    }
    /// Whether every component is zero (`v == Vec3::ZERO`).
    #[inline(always)]
    pub fn is_zero(self) -> T::Mask {
        let zero = T::splat(0.0);
        self.x.equal(zero) & self.y.equal(zero) & self.z.equal(zero)
    }
    /// `if m { a } else { b }`, lane by lane.
    #[inline(always)]
    pub fn select(m: T::Mask, a: V3<T>, b: V3<T>) -> V3<T> {
        V3 {
            x: T::select(m, a.x, b.x),
            y: T::select(m, a.y, b.y),
            z: T::select(m, a.z, b.z),
        }
    }
}

impl From<Vec3> for V3<f32> {
    #[inline(always)]
    fn from(v: Vec3) -> V3<f32> {
        V3::new(v.x, v.y, v.z)
    }
}

impl From<V3<f32>> for Vec3 {
    #[inline(always)]
    fn from(v: V3<f32>) -> Vec3 {
        Vec3::new(v.x, v.y, v.z)
    }
}

impl<const N: usize> V3<F<N>> {
    /// Lane `l` is `f(l)`.
    #[inline(always)]
    pub fn from_fn(mut f: impl FnMut(usize) -> Vec3) -> V3<F<N>> {
        let mut v: V3<F<N>> = V3::splat(Vec3::ZERO);
        for l in 0..N {
            let w = f(l);
            v.x.0[l] = w.x;
            v.y.0[l] = w.y;
            v.z.0[l] = w.z;
        }
        v
    }
    /// The lanes of `N` consecutive vectors.
    #[inline(always)]
    pub fn load(s: &[Vec3]) -> V3<F<N>> {
        let s = &s[..N];
        #[cfg(target_arch = "x86_64")]
        if N == 16 && crate::cpu::has_avx512() {
            let mut v: V3<F<N>> = V3::splat(Vec3::ZERO);
            // SAFETY: the CPU has AVX-512 (checked just above); `s` holds sixteen vectors of
            // three f32 each (glam's `Vec3` is `repr(C)`), each lane array sixteen f32.
            unsafe {
                transpose::load16(
                    s.as_ptr().cast(),
                    [v.x.0.as_mut_ptr(), v.y.0.as_mut_ptr(), v.z.0.as_mut_ptr()],
                )
            };
            return v;
        }
        V3::from_fn(|l| s[l])
    }
    #[inline(always)]
    pub fn lane(&self, l: usize) -> Vec3 {
        Vec3::new(self.x.0[l], self.y.0[l], self.z.0[l])
    }
    /// Writes the lanes to `N` consecutive vectors.
    #[inline(always)]
    pub fn store(&self, s: &mut [Vec3]) {
        let s = &mut s[..N];
        #[cfg(target_arch = "x86_64")]
        if N == 16 && crate::cpu::has_avx512() {
            // SAFETY: as in `load`.
            unsafe {
                transpose::store16(
                    [self.x.0.as_ptr(), self.y.0.as_ptr(), self.z.0.as_ptr()],
                    s.as_mut_ptr().cast(),
                )
            };
            return;
        }
        for (l, v) in s.iter_mut().enumerate() {
            *v = self.lane(l);
        }
    }
}

/// `[f(0), .., f(N - 1)]` (a plain loop: `std::array::from_fn` was left out of line).
#[inline(always)]
pub fn lanes_of<T: Copy, const N: usize>(mut f: impl FnMut(usize) -> T) -> [T; N] {
    let first = f(0);
    let mut out = [first; N];
    for (l, v) in out.iter_mut().enumerate().skip(1) {
        *v = f(l);
    }
    out
}

/// How many paths the wavefront's lane systems take at a time (`--lanes`): eight fill AVX2's
/// 256-bit registers, sixteen AVX-512's 512-bit ones. Every width renders the same image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LaneWidth {
    Eight,
    Sixteen,
}

impl LaneWidth {
    /// The widest this CPU's vector registers hold.
    pub fn widest() -> LaneWidth {
        if crate::cpu::has_avx512() {
            LaneWidth::Sixteen
        } else {
            LaneWidth::Eight
        }
    }

    /// `8` or `16`, as `--lanes` takes it.
    pub fn of(n: usize) -> Option<LaneWidth> {
        match n {
            8 => Some(LaneWidth::Eight),
            16 => Some(LaneWidth::Sixteen),
            _ => None,
        }
    }

    pub fn count(self) -> usize {
        match self {
            LaneWidth::Eight => 8,
            LaneWidth::Sixteen => 16,
        }
    }
}

/// A system's work over one chunk, written once for any lane width `N` (`F<N>`, `M<N>`):
/// [`run_lanes`] runs it at the width asked for, in the copy compiled for the CPU.
pub trait LaneKernel {
    type Output;
    /// The work at width `N`; `#[inline(always)]`, so that it is compiled into each copy.
    fn run<const N: usize>(self) -> Self::Output;
}

/// Runs `kernel` at `width` in the copy compiled for the CPU's widest vector instructions
/// (AVX-512, else AVX2 and FMA, else the build's baseline; see `crate::cpu`).
#[inline(always)]
pub fn run_lanes<K: LaneKernel>(width: LaneWidth, kernel: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    {
        if crate::cpu::has_avx512() {
            // SAFETY: the CPU has AVX-512 (F, DQ, VL, BW), AVX2 and FMA (checked just above).
            return unsafe {
                match width {
                    LaneWidth::Eight => run_avx512::<K, 8>(kernel),
                    LaneWidth::Sixteen => run_avx512::<K, 16>(kernel),
                }
            };
        }
        if crate::cpu::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe {
                match width {
                    LaneWidth::Eight => run_avx2::<K, 8>(kernel),
                    LaneWidth::Sixteen => run_avx2::<K, 16>(kernel),
                }
            };
        }
    }
    match width {
        LaneWidth::Eight => kernel.run::<8>(),
        LaneWidth::Sixteen => kernel.run::<16>(),
    }
}

/// Sixteen `Vec3`s (x0 y0 z0 x1 ...) to and from three columns of sixteen lanes, in six
/// two-source permutes of three 512-bit registers: lane by lane the compiler moved the 48
/// numbers one at a time through the stack (a sixteen-lane light sample took twice the time of
/// two eight-lane ones).
#[cfg(target_arch = "x86_64")]
mod transpose {
    use std::arch::x86_64::*;

    /// For each axis, the two permutes that gather lanes `3l + axis` of the 48 numbers `a b c`:
    /// the first from `a b` (indices 0..32, lanes whose number lies in `c` take any), the
    /// second from that and `c` (16 + its index in `c`).
    const fn load_indices(axis: usize) -> ([i32; 16], [i32; 16]) {
        let (mut first, mut second) = ([0; 16], [0; 16]);
        let mut l = 0;
        while l < 16 {
            let e = 3 * l + axis;
            if e < 32 {
                first[l] = e as i32;
                second[l] = l as i32;
            } else {
                second[l] = 16 + (e - 32) as i32;
            }
            l += 1;
        }
        (first, second)
    }

    /// For each sixteen-number block of the output, the two permutes that interleave it:
    /// the first takes its x (index l) and y (16 + l) lanes, the second keeps those and adds
    /// its z lanes (16 + l).
    const fn store_indices(block: usize) -> ([i32; 16], [i32; 16]) {
        let (mut first, mut second) = ([0; 16], [0; 16]);
        let mut j = 0;
        while j < 16 {
            let e = 16 * block + j;
            let (l, axis) = (e / 3, e % 3);
            match axis {
                0 => {
                    first[j] = l as i32;
                    second[j] = j as i32;
                }
                1 => {
                    first[j] = 16 + l as i32;
                    second[j] = j as i32;
                }
                _ => second[j] = 16 + l as i32,
            }
            j += 1;
        }
        (first, second)
    }

    const LOAD: [([i32; 16], [i32; 16]); 3] = [load_indices(0), load_indices(1), load_indices(2)];
    const STORE: [([i32; 16], [i32; 16]); 3] =
        [store_indices(0), store_indices(1), store_indices(2)];

    /// Reads 48 f32 at `from` into sixteen lanes at each of `to`.
    ///
    /// Not marked `#[target_feature]`, so that it inlines into the lane kernels, which are
    /// compiled for AVX-512 (`run_lanes`); marked, it stayed out of line.
    ///
    /// # Safety
    /// The CPU must have AVX-512F; `from` must be readable for 48 f32 and each `to` writable
    /// for 16.
    #[inline(always)]
    pub(super) unsafe fn load16(from: *const f32, to: [*mut f32; 3]) {
        // SAFETY: the caller's guarantees.
        unsafe {
            let (a, b, c) = (
                _mm512_loadu_ps(from),
                _mm512_loadu_ps(from.add(16)),
                _mm512_loadu_ps(from.add(32)),
            );
            for (axis, &out) in to.iter().enumerate() {
                let (first, second) = &LOAD[axis];
                let ab = _mm512_permutex2var_ps(a, _mm512_loadu_epi32(first.as_ptr()), b);
                let v = _mm512_permutex2var_ps(ab, _mm512_loadu_epi32(second.as_ptr()), c);
                _mm512_storeu_ps(out, v);
            }
        }
    }

    /// Writes the sixteen lanes at each of `from` as 48 f32 at `to`, vector by vector.
    ///
    /// # Safety
    /// As for `load16`; each `from` must be readable for 16 f32 and `to` writable for 48.
    #[inline(always)]
    pub(super) unsafe fn store16(from: [*const f32; 3], to: *mut f32) {
        // SAFETY: the caller's guarantees.
        unsafe {
            let (x, y, z) = (
                _mm512_loadu_ps(from[0]),
                _mm512_loadu_ps(from[1]),
                _mm512_loadu_ps(from[2]),
            );
            for (block, (first, second)) in STORE.iter().enumerate() {
                let xy = _mm512_permutex2var_ps(x, _mm512_loadu_epi32(first.as_ptr()), y);
                let v = _mm512_permutex2var_ps(xy, _mm512_loadu_epi32(second.as_ptr()), z);
                _mm512_storeu_ps(to.add(16 * block), v);
            }
        }
    }
}

/// `kernel` compiled for AVX-512 (see `crate::cpu::has_avx512`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx512bw,avx2,fma")]
fn run_avx512<K: LaneKernel, const N: usize>(kernel: K) -> K::Output {
    kernel.run::<N>()
}

/// `kernel` compiled for AVX2 and FMA (see `crate::cpu`): about 15% fewer instructions than
/// the baseline.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_avx2<K: LaneKernel, const N: usize>(kernel: K) -> K::Output {
    kernel.run::<N>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_vectors_load_and_store_as_lane_by_lane() {
        let vs: Vec<Vec3> = (0..20)
            .map(|i| Vec3::new(i as f32, -(i as f32) - 0.5, 1000.0 + i as f32))
            .collect();
        for start in 0..4 {
            let v = V3::<F<16>>::load(&vs[start..]);
            for l in 0..16 {
                assert_eq!(v.lane(l), vs[start + l], "lane {l} from {start}");
            }
            let mut out = vec![Vec3::splat(f32::NAN); 17];
            v.store(&mut out[1..]);
            assert_eq!(&out[1..17], &vs[start..start + 16]);
            assert!(out[0].is_nan(), "nothing written before the slice");
        }
    }

    #[test]
    fn lanes_compute_the_scalar_bits() {
        let xs = [0.0f32, -0.0, 1.5, -2.25, 1e-38, f32::INFINITY, 3.0e7, -7.0];
        let ys = [2.0f32, 0.0, -0.5, 8.0, 1e-3, 1.0, -3.0e7, 0.0];
        // Opaque to the compiler: folded at compile time, max(-0, 0) and NaNs may come out
        // otherwise than the CPU computes them.
        let (xs, ys) = (std::hint::black_box(xs), std::hint::black_box(ys));
        let (x, y) = (F::<8>(xs), F::<8>(ys));
        // The same bits, or both NaN (the film counts any NaN alike).
        let same = |v: F<8>, l: usize, s: f32| {
            let v = v.0[l];
            assert!(
                v.to_bits() == s.to_bits() || (v.is_nan() && s.is_nan()),
                "lane {l}: {v} against {s}"
            );
        };
        for l in 0..8 {
            let (a, b) = std::hint::black_box((xs[l], ys[l]));
            same(x * y + x / y, l, a * b + a / b);
            same(x.max(y) - y.min(x), l, a.max(b) - b.min(a));
            same(x.abs().sqrt(), l, a.abs().sqrt());
            same(x.sign_one(), l, 1.0f32.copysign(a));
            let m = x.less(y);
            assert_eq!(m.lane(l), a < b);
            same(F::select(m, x, y), l, f32::select(a < b, a, b));
            let (q, qa) = (x * 0.1, a * 0.1);
            same(q.sin_cos_quarter().0, l, qa.sin_cos_quarter().0);
            same(q.sin_cos_quarter().1, l, qa.sin_cos_quarter().1);
            let (t, ta) = (x.abs().min(F::splat(1.0)), a.abs().min(1.0));
            same(t.sin_cos_turn().0, l, ta.sin_cos_turn().0);
            same(t.sin_cos_turn().1, l, ta.sin_cos_turn().1);
            same(x.floor(), l, a.floor());
            same((-x.abs()).exp(), l, Real::exp(-a.abs()));
            same(x.erf(), l, Real::erf(a));
        }
    }

    #[test]
    fn turn_sine_and_cosine_are_accurate() {
        let (mut worst_sin, mut worst_cos) = (0.0f64, 0.0f64);
        for i in 0..=400_000 {
            let u = i as f32 / 400_000.0;
            let (s, c) = u.sin_cos_turn();
            let angle = std::f64::consts::TAU * u as f64;
            worst_sin = worst_sin.max((s as f64 - angle.sin()).abs());
            worst_cos = worst_cos.max((c as f64 - angle.cos()).abs());
        }
        assert!(
            worst_sin < 2e-7 && worst_cos < 2e-7,
            "{worst_sin:e} {worst_cos:e}"
        );
        // The quarter turns are exact.
        assert_eq!(0.0f32.sin_cos_turn(), (0.0, 1.0));
        assert_eq!(0.25f32.sin_cos_turn(), (1.0, -0.0));
        assert_eq!(0.5f32.sin_cos_turn(), (-0.0, -1.0));
        assert_eq!(1.0f32.sin_cos_turn(), (0.0, 1.0));
    }

    #[test]
    fn floor_small_is_floor() {
        // Steps of 1/1024 over [-256, 256) (exp's range), then every integer and half over
        // [-2^22, 2^22) (where rounding to the nearest ties), each with its neighbours.
        let fine = (-(1i32 << 18)..(1 << 18)).map(|i| i as f32 / 1024.0);
        let halves = (-(1i32 << 23)..(1 << 23)).map(|i| i as f32 / 2.0);
        for x in fine.chain(halves) {
            for y in [x.next_down(), x, x.next_up()] {
                if y.abs() < 4_194_304.0 {
                    assert_eq!(Real::floor_small(y).to_bits(), y.floor().to_bits(), "{y}");
                }
            }
        }
        // And in lanes.
        let x = F::<8>([-2.5, -0.5, -0.3, 0.0, 0.49999997, 0.5, 1.5, 127.99999]);
        assert_eq!(x.floor_small().0, x.0.map(f32::floor));
    }

    #[test]
    fn exp_and_erf_are_accurate() {
        let (mut worst_exp, mut worst_erf, mut worst_erf_near) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..=2_000_000 {
            let x = (-87.33 + (88.72 + 87.33) * i as f64 / 2_000_000.0) as f32;
            let exact = (x as f64).exp();
            worst_exp = worst_exp.max((Real::exp(x) as f64 - exact).abs() / exact);
        }
        for i in -1_000_000..=1_000_000 {
            let x = (6.0 * i as f64 / 1_000_000.0) as f32;
            let exact = libm::erf(x as f64);
            let error = (Real::erf(x) as f64 - exact).abs();
            worst_erf = worst_erf.max(error);
            if x.abs() < 0.5 && x != 0.0 {
                worst_erf_near = worst_erf_near.max(error / exact.abs());
            }
        }
        assert!(
            worst_exp < 1.2e-7 && worst_erf < 2.5e-7 && worst_erf_near < 2.5e-7,
            "exp {worst_exp:e}, erf {worst_erf:e}, erf relatively below 1/2 {worst_erf_near:e}"
        );
        // Exact and special values.
        assert_eq!(Real::exp(0.0f32), 1.0);
        assert_eq!(Real::erf(0.0f32), 0.0);
        assert_eq!(
            Real::erf(-1e-30f32),
            -1e-30 * std::f32::consts::FRAC_2_SQRT_PI
        );
        assert_eq!(Real::exp(-100.0f32), 0.0);
        assert_eq!(Real::exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(Real::exp(89.0f32), f32::INFINITY);
        assert!(Real::exp(f32::NAN).is_nan() && Real::erf(f32::NAN).is_nan());
        assert_eq!(Real::erf(10.0f32), 1.0);
        assert_eq!(Real::erf(f32::NEG_INFINITY), -1.0);
        assert!((Real::exp(88.7f32) as f64 / f64::from(88.7f32).exp() - 1.0).abs() < 2e-7);
    }

    #[test]
    fn quarter_sine_and_cosine_are_accurate() {
        let quarter = std::f64::consts::FRAC_PI_4;
        let (mut worst_sin, mut worst_cos) = (0.0f64, 0.0f64);
        for i in -100_000..=100_000 {
            let x = (quarter * i as f64 / 100_000.0) as f32;
            let (s, c) = x.sin_cos_quarter();
            worst_sin = worst_sin.max((s as f64 - (x as f64).sin()).abs());
            worst_cos = worst_cos.max((c as f64 - (x as f64).cos()).abs());
        }
        assert!(
            worst_sin < 1.2e-7 && worst_cos < 1.2e-7,
            "{worst_sin:e} {worst_cos:e}"
        );
        // Exact where the disk map needs it to be: the axes.
        assert_eq!(0.0f32.sin_cos_quarter(), (0.0, 1.0));
    }
}
