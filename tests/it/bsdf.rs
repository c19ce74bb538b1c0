//! BSDF tests: sample/eval/pdf consistency, chi-square goodness of fit of the sampling routines,
//! energy conservation, reciprocity and numerical stability. Every random number comes from
//! `SampleKey` with fixed seeds, so the tests are deterministic.

use glam::{DVec3, Vec2, Vec3};
use stagelight::bsdf::conductor::{ComplexIor, Conductor, Microfacet};
use stagelight::bsdf::dielectric::{Dielectric, ThinDielectric};
use stagelight::bsdf::diffuse::Diffuse;
use stagelight::bsdf::plastic::RoughPlastic;
use stagelight::bsdf::smooth_plastic::{
    FIT_MAX_ETA, SmoothPlastic, fresnel_diffuse_reflectance, internal_reflectance,
};
use stagelight::bsdf::{Bsdf, Material, TransportMode, conductor, dielectric};
use stagelight::sampling::SampleKey;
use std::f64::consts::PI;

mod rough_dielectric;

// ---------------------------------------------------------------------------------------------
// Helpers

/// A unit direction at polar angle `theta` (from +z) and azimuth `phi`, both in degrees.
fn dir_deg(theta: f64, phi: f64) -> Vec3 {
    let (t, p) = (theta.to_radians(), phi.to_radians());
    DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos()).as_vec3()
}

fn u2(seed: u64, stream: u64, i: u64) -> Vec2 {
    SampleKey::new(seed, stream, i).get2(0)
}

fn is_finite3(v: Vec3) -> bool {
    v.is_finite()
}

fn rel_close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1e-30)
}

/// ln Gamma(x) for x > 0: shift up to x >= 10, then Stirling's series (error < 1e-12 there).
fn ln_gamma(mut x: f64) -> f64 {
    let mut shift = 0.0;
    while x < 10.0 {
        shift -= x.ln();
        x += 1.0;
    }
    let x2 = x * x;
    shift + (x - 0.5) * x.ln() - x + 0.5 * (2.0 * PI).ln() + 1.0 / (12.0 * x)
        - 1.0 / (360.0 * x * x2)
        + 1.0 / (1260.0 * x * x2 * x2)
        - 1.0 / (1680.0 * x * x2 * x2 * x2)
}

/// Regularised upper incomplete gamma Q(a, x) = Gamma(a, x) / Gamma(a): the power series of P
/// below x = a + 1, the continued fraction of Q (modified Lentz) above.
fn gamma_q(a: f64, x: f64) -> f64 {
    assert!(a > 0.0 && x >= 0.0);
    if x == 0.0 {
        return 1.0;
    }
    let log_prefactor = -x + a * x.ln() - ln_gamma(a);
    if x < a + 1.0 {
        // P(a, x) = x^a e^-x / Gamma(a + 1) * sum_n x^n / ((a+1)...(a+n)).
        let mut term = 1.0 / a;
        let mut sum = term;
        let mut n = 1.0;
        while term.abs() > sum.abs() * 1e-16 && n < 10_000.0 {
            term *= x / (a + n);
            sum += term;
            n += 1.0;
        }
        (1.0 - sum * log_prefactor.exp()).max(0.0)
    } else {
        // Q(a, x) = x^a e^-x / Gamma(a) * 1 / (x + 1 - a - 1(1-a) / (x + 3 - a - ...)).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        (log_prefactor.exp() * h).clamp(0.0, 1.0)
    }
}

/// Survival function of the chi-square distribution with `dof` degrees of freedom.
fn chi2_p_value(chi2: f64, dof: usize) -> f64 {
    gamma_q(dof as f64 / 2.0, chi2 / 2.0)
}

#[test]
fn chi2_p_value_matches_tables() {
    // Reference survival values computed with mpmath's regularised incomplete gamma.
    let cases = [
        (3.841_459, 1, 0.049_999_994_653_195_8),
        (6.634_897, 1, 0.009_999_997_760_282_47),
        (23.209_251, 10, 0.010_000_000_547_937_3),
        (18.307_038, 10, 0.050_000_000_824_732_3),
        (124.342_113, 100, 0.050_000_002_549_929_9),
        (1_106.969_301, 1000, 0.009_999_829_183_378_36),
        (0.454_936, 1, 0.500_000_199_347_037),
    ];
    for (x, dof, p) in cases {
        let got = chi2_p_value(x, dof);
        assert!(
            (got - p).abs() < 1e-5 * p.max(1e-3),
            "Q({x}, {dof}) = {got}, want {p}"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Chi-square goodness of fit.
//
// Directions are binned in spherical coordinates (theta, phi) about the normal on wo's side, so
// that the horizon, where the pdf jumps to zero, is a bin edge and the pdf is smooth inside
// every bin. To resolve narrow lobes the bin edges follow a mixture of a uniform and a Cauchy
// density centred on the lobe (the mirror direction), which matches GGX's slope tails. Expected
// counts integrate pdf() * sin(theta) over each bin by adaptive Simpson cubature. Two more
// cells hold the samples on the other side (expected zero: both materials only reflect) and the
// samples `sample` refuses (the leftover probability). Cells expected below 5 are pooled.

/// Number of chi-square tests in this file, for the Sidak correction.
const CHI2_TESTS: usize = 3 + 2 * (4 * 3 + 2) + ROUGH_DIELECTRIC_CHI2_TESTS;
/// The rough dielectric's: 14 incident directions.
const ROUGH_DIELECTRIC_CHI2_TESTS: usize = 14;
const CHI2_SAMPLES: u64 = 1_000_000;
const CHI2_BINS: usize = 40;

fn sidak_alpha() -> f64 {
    1.0 - (1.0 - 0.01f64).powf(1.0 / CHI2_TESTS as f64)
}

/// Bin edges on [lo, hi] at equal steps of the CDF of (1 - beta) uniform + beta Cauchy(c, w).
fn mixture_edges(lo: f64, hi: f64, c: f64, w: f64, beta: f64, n: usize) -> Vec<f64> {
    let (a0, a1) = (((lo - c) / w).atan(), ((hi - c) / w).atan());
    let cdf = |x: f64| {
        (1.0 - beta) * (x - lo) / (hi - lo) + beta * (((x - c) / w).atan() - a0) / (a1 - a0)
    };
    (0..=n)
        .map(|j| {
            let target = j as f64 / n as f64;
            let (mut a, mut b) = (lo, hi);
            for _ in 0..80 {
                let m = 0.5 * (a + b);
                if cdf(m) < target { a = m } else { b = m }
            }
            if j == 0 {
                lo
            } else if j == n {
                hi
            } else {
                0.5 * (a + b)
            }
        })
        .collect()
}

fn axis_index(edges: &[f64], x: f64) -> usize {
    edges[1..edges.len() - 1].partition_point(|&e| e <= x)
}

struct Binning {
    /// Normal on wo's side and a tangent frame; phi is measured from the lobe's azimuth.
    pole: DVec3,
    t1: DVec3,
    t2: DVec3,
    phi0: f64,
    theta_edges: Vec<f64>,
    phi_edges: Vec<f64>,
}

impl Binning {
    /// `center`: the lobe's direction; `width`: its angular scale (None: uniform bins).
    fn new(pole_z: f64, center: Vec3, width: Option<f64>) -> Binning {
        let pole = DVec3::new(0.0, 0.0, pole_z);
        let t1 = DVec3::X;
        let t2 = pole.cross(t1);
        let c = center.as_dvec3();
        let (x, y, z) = (c.dot(t1), c.dot(t2), c.dot(pole));
        let theta_c = (x * x + y * y).sqrt().atan2(z);
        let phi0 = y.atan2(x);
        let n = CHI2_BINS;
        let half = 0.5 * PI;
        let (theta_edges, phi_edges) = match width {
            Some(w) if w < 0.5 => {
                let wphi = w / theta_c.sin().max(w);
                let phi_edges = if wphi < 1.5 {
                    mixture_edges(-PI, PI, 0.0, wphi, 0.9, n)
                } else {
                    mixture_edges(-PI, PI, 0.0, 1.0, 0.0, n)
                };
                (mixture_edges(0.0, half, theta_c, w, 0.9, n), phi_edges)
            }
            _ => (
                mixture_edges(0.0, half, 0.0, 1.0, 0.0, n),
                mixture_edges(-PI, PI, 0.0, 1.0, 0.0, n),
            ),
        };
        Binning {
            pole,
            t1,
            t2,
            phi0,
            theta_edges,
            phi_edges,
        }
    }

    /// The same binning with azimuth bins following a Cauchy of width `wphi` instead.
    fn with_phi_width(mut self, wphi: f64) -> Binning {
        self.phi_edges = mixture_edges(-PI, PI, 0.0, wphi, 0.9, CHI2_BINS);
        self
    }

    fn cells(&self) -> usize {
        (self.theta_edges.len() - 1) * (self.phi_edges.len() - 1)
    }

    /// Cell of a direction; `cells()` for the other side of the surface.
    fn bin(&self, d: Vec3) -> usize {
        let d = d.as_dvec3();
        let (x, y, z) = (d.dot(self.t1), d.dot(self.t2), d.dot(self.pole));
        if z <= 0.0 {
            return self.cells();
        }
        // atan2 keeps the polar angle accurate near the pole, where acos would not.
        let theta = (x * x + y * y).sqrt().atan2(z);
        let phi = (y.atan2(x) - self.phi0 + PI).rem_euclid(2.0 * PI) - PI;
        let nphi = self.phi_edges.len() - 1;
        axis_index(&self.theta_edges, theta) * nphi + axis_index(&self.phi_edges, phi)
    }

    fn direction(&self, theta: f64, phi: f64) -> Vec3 {
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = (phi + self.phi0).sin_cos();
        (self.t1 * (st * cp) + self.t2 * (st * sp) + self.pole * ct).as_vec3()
    }

    /// Probability of every cell under `pdf`.
    fn integrate(&self, pdf: &dyn Fn(Vec3) -> f32) -> Vec<f64> {
        let f = |theta: f64, phi: f64| pdf(self.direction(theta, phi)) as f64 * theta.sin();
        let mut out = Vec::with_capacity(self.cells());
        for t in self.theta_edges.windows(2) {
            for p in self.phi_edges.windows(2) {
                out.push(adaptive_simpson_2d(&f, [t[0], t[1], p[0], p[1]], 1e-8));
            }
        }
        out
    }
}

/// Simpson's rule on the 3x3 nodes `v` of a rectangle of area `area`.
fn simpson_3x3(v: &[[f64; 3]; 3], area: f64) -> f64 {
    let w = [1.0, 4.0, 1.0];
    let mut s = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            s += w[i] * w[j] * v[i][j];
        }
    }
    s * area / 36.0
}

/// Adaptive Simpson cubature over rect = [x0, x1, y0, y1]: compares the rule on the rectangle
/// with the sum over its quarters, reusing the parent's nodes, and splits where they disagree.
fn adaptive_simpson_2d(f: &dyn Fn(f64, f64) -> f64, rect: [f64; 4], tol: f64) -> f64 {
    let [x0, x1, y0, y1] = rect;
    let mut v = [[0.0; 3]; 3];
    for (i, row) in v.iter_mut().enumerate() {
        for (j, val) in row.iter_mut().enumerate() {
            *val = f(
                x0 + (x1 - x0) * i as f64 / 2.0,
                y0 + (y1 - y0) * j as f64 / 2.0,
            );
        }
    }
    simpson_node(f, rect, &v, tol, 0)
}

fn simpson_node(
    f: &dyn Fn(f64, f64) -> f64,
    [x0, x1, y0, y1]: [f64; 4],
    v: &[[f64; 3]; 3],
    tol: f64,
    depth: u32,
) -> f64 {
    // The 5x5 nodes: the even ones are the parent's.
    let mut g = [[0.0; 5]; 5];
    for (i, row) in g.iter_mut().enumerate() {
        for (j, val) in row.iter_mut().enumerate() {
            *val = if i % 2 == 0 && j % 2 == 0 {
                v[i / 2][j / 2]
            } else {
                f(
                    x0 + (x1 - x0) * i as f64 / 4.0,
                    y0 + (y1 - y0) * j as f64 / 4.0,
                )
            };
        }
    }
    let area = (x1 - x0) * (y1 - y0);
    let coarse = simpson_3x3(v, area);
    let (xm, ym) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let quarter = |qi: usize, qj: usize| {
        let mut s = [[0.0; 3]; 3];
        for (i, row) in s.iter_mut().enumerate() {
            for (j, val) in row.iter_mut().enumerate() {
                *val = g[2 * qi + i][2 * qj + j];
            }
        }
        s
    };
    let quarters = [
        ([x0, xm, y0, ym], quarter(0, 0)),
        ([x0, xm, ym, y1], quarter(0, 1)),
        ([xm, x1, y0, ym], quarter(1, 0)),
        ([xm, x1, ym, y1], quarter(1, 1)),
    ];
    let fine: f64 = quarters
        .iter()
        .map(|(_, q)| simpson_3x3(q, 0.25 * area))
        .sum();
    if (fine - coarse).abs() <= 15.0 * tol || depth >= 10 {
        return fine + (fine - coarse) / 15.0;
    }
    quarters
        .iter()
        .map(|(r, q)| simpson_node(f, *r, q, 0.5 * tol, depth + 1))
        .sum()
}

struct Chi2Result {
    p_value: f64,
    dof: usize,
    chi2: f64,
    total_probability: f64,
}

/// Draws CHI2_SAMPLES directions from `sample` and tests them against `pdf`.
fn chi2_test(
    binning: &Binning,
    stream: u64,
    sample: &dyn Fn(Vec2) -> Option<Vec3>,
    pdf: &dyn Fn(Vec3) -> f32,
) -> Chi2Result {
    chi2_test_over(&[binning], stream, sample, pdf)
}

/// `chi2_test` over the cells of several binnings (a direction falls in the first that holds
/// it: one per hemisphere for a BSDF that transmits).
fn chi2_test_over(
    binnings: &[&Binning],
    stream: u64,
    sample: &dyn Fn(Vec2) -> Option<Vec3>,
    pdf: &dyn Fn(Vec3) -> f32,
) -> Chi2Result {
    let n = CHI2_SAMPLES;
    let cells: usize = binnings.iter().map(|b| b.cells()).sum();
    let bin = |wi: Vec3| {
        let mut offset = 0;
        for b in binnings {
            let cell = b.bin(wi);
            if cell < b.cells() {
                return offset + cell;
            }
            offset += b.cells();
        }
        cells
    };
    // Cells, then the other side, then the refused samples.
    let mut observed = vec![0.0f64; cells + 2];
    for i in 0..n {
        match sample(u2(0xc41_5eed, stream, i)) {
            Some(wi) => observed[bin(wi)] += 1.0,
            None => observed[cells + 1] += 1.0,
        }
    }
    let mut expected: Vec<f64> = binnings
        .iter()
        .flat_map(|b| b.integrate(pdf))
        .map(|p| p * n as f64)
        .collect();
    let total_probability = expected.iter().sum::<f64>() / n as f64;
    expected.push(0.0);
    expected.push((n as f64 * (1.0 - total_probability)).max(0.0));

    // Pool the sparse cells; a pool still below 5 joins the smallest regular cell.
    let mut kept: Vec<(f64, f64)> = Vec::new();
    let (mut pool_e, mut pool_o) = (0.0, 0.0);
    for (&e, &o) in expected.iter().zip(&observed) {
        if e < 5.0 {
            pool_e += e;
            pool_o += o;
        } else {
            kept.push((e, o));
        }
    }
    if pool_e >= 5.0 {
        kept.push((pool_e, pool_o));
    } else if let Some(smallest) = kept.iter_mut().min_by(|a, b| a.0.total_cmp(&b.0)) {
        smallest.0 += pool_e;
        smallest.1 += pool_o;
    }
    let chi2: f64 = kept.iter().map(|(e, o)| (o - e) * (o - e) / e).sum();
    let dof = kept.len() - 1;
    Chi2Result {
        p_value: chi2_p_value(chi2, dof),
        dof,
        chi2,
        total_probability,
    }
}

#[test]
fn chi2_diffuse() {
    let m = Material::Diffuse(Diffuse {
        reflectance: Vec3::new(0.8, 0.5, 0.2),
    });
    for (stream, (theta, phi)) in [(0.0, 0.0), (89.0, 200.0), (120.0, 45.0)]
        .into_iter()
        .enumerate()
    {
        let wo = dir_deg(theta, phi);
        let side = wo.z.signum() as f64;
        let binning = Binning::new(side, Vec3::new(0.0, 0.0, side as f32), None);
        let r = chi2_test(
            &binning,
            stream as u64,
            &|u| m.sample(wo, u, TransportMode::Radiance).map(|s| s.wi),
            &|wi| m.pdf(wo, wi),
        );
        println!(
            "diffuse wo theta {theta}: chi2 {:.1} dof {} p {:.4} integral {:.6}",
            r.chi2, r.dof, r.p_value, r.total_probability
        );
        assert!(
            (r.total_probability - 1.0).abs() < 1e-4,
            "{}",
            r.total_probability
        );
        assert!(
            r.p_value > sidak_alpha(),
            "diffuse theta {theta}: p = {}",
            r.p_value
        );
    }
}

/// Gold as Mitsuba's RGB variants see it (material "Au").
const GOLD: ComplexIor = ComplexIor {
    eta: Vec3::new(0.143_035_98, 0.375_307_08, 1.442_045_3),
    k: Vec3::new(3.982_997, 2.385_556_5, 1.603_359_2),
};

/// A conductor of `distribution` and `alpha` (gold for Beckmann, Fresnel 1 for GGX: the pdf
/// does not depend on the Fresnel term, so the chi-square tests cover both).
fn conductor_of(distribution: Microfacet, alpha: f32) -> Material {
    Material::Conductor(Conductor::isotropic(
        distribution,
        alpha,
        Vec3::new(1.0, 0.78, 0.34),
        match distribution {
            Microfacet::Ggx => ComplexIor::PERFECT_MIRROR,
            Microfacet::Beckmann => GOLD,
        },
    ))
}

/// A rough plastic of `distribution` and `alpha` (Mitsuba's defaults otherwise: polypropylene
/// over air, specular 1) on an orange base.
fn plastic_of(distribution: Microfacet, alpha: f32) -> Material {
    let diffuse = Vec3::new(0.8, 0.4, 0.1);
    Material::RoughPlastic(RoughPlastic::new(
        distribution,
        alpha,
        1.49 / 1.000_277,
        diffuse,
        diffuse.element_sum() / 3.0,
        Vec3::ONE,
        false,
    ))
}

/// An anisotropic conductor: alpha_u along a tangent turned `degrees` from the frame's first.
fn anisotropic_of(distribution: Microfacet, alpha_u: f32, alpha_v: f32, degrees: f32) -> Material {
    let Material::Conductor(mut c) = conductor_of(distribution, alpha_u) else {
        unreachable!()
    };
    c.alpha_v = alpha_v;
    let a = degrees.to_radians();
    c.axis = Vec2::new(a.cos(), a.sin());
    Material::Conductor(c)
}

/// The anisotropic conductors the consistency tests below run on as well as isotropic ones.
fn anisotropic_conductors() -> Vec<Material> {
    let mut v = Vec::new();
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        v.push(anisotropic_of(distribution, 0.05, 0.5, 0.0));
        v.push(anisotropic_of(distribution, 0.4, 0.1, 30.0));
        v.push(anisotropic_of(distribution, 1e-4, 0.3, -110.0));
    }
    v
}

fn chi2_conductor(distribution: Microfacet, alpha: f32, thetas: &[f64], stream0: u64) {
    chi2_conductor_lobe(conductor_of(distribution, alpha), alpha, thetas, stream0);
}

/// `chi2_conductor` for any conductor `m`, binned for roughness `alpha` (its narrowest).
fn chi2_conductor_lobe(m: Material, alpha: f32, thetas: &[f64], stream0: u64) {
    let Material::Conductor(c) = m else {
        unreachable!()
    };
    let distribution = c.distribution;
    for (i, &theta) in thetas.iter().enumerate() {
        let wo = dir_deg(theta, 10.0 + 97.0 * i as f64);
        let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
        let binning = match distribution {
            Microfacet::Ggx => Binning::new(1.0, mirror, Some(2.0 * alpha as f64)),
            // Beckmann's Gaussian tails are far lighter than GGX's: narrower bins keep enough
            // cells populated. Near the horizon the lobe is also narrow across the plane of
            // incidence (a sideways microfacet tilt turns the reflection by about 2 cos theta
            // times as much), and the azimuth bins follow.
            Microfacet::Beckmann => {
                let binning = Binning::new(1.0, mirror, Some(alpha as f64));
                let cos = theta.to_radians().cos();
                if alpha < 0.5 && cos < 0.5 {
                    binning.with_phi_width(2.0 * alpha as f64 * cos.max(0.01))
                } else {
                    binning
                }
            }
        };
        let r = chi2_test(
            &binning,
            stream0 + i as u64,
            &|u| m.sample(wo, u, TransportMode::Radiance).map(|s| s.wi),
            &|wi| m.pdf(wo, wi),
        );
        println!(
            "conductor {m:?} wo theta {theta}: chi2 {:.1} dof {} p {:.4} integral {:.6}",
            r.chi2, r.dof, r.p_value, r.total_probability
        );
        assert!(r.total_probability <= 1.0 + 1e-4, "{}", r.total_probability);
        assert!(
            r.dof >= 200,
            "too few populated cells ({}) for a test",
            r.dof
        );
        assert!(
            r.p_value > sidak_alpha(),
            "conductor {m:?} theta {theta}: chi2 {} dof {} p = {}",
            r.chi2,
            r.dof,
            r.p_value
        );
    }
}

#[test]
fn chi2_conductor_rough() {
    chi2_conductor(Microfacet::Ggx, 1.0, &[0.0, 45.0, 88.0], 100);
    chi2_conductor(Microfacet::Ggx, 0.5, &[0.0, 45.0, 88.0], 110);
}

#[test]
fn chi2_conductor_glossy() {
    chi2_conductor(Microfacet::Ggx, 0.1, &[0.0, 45.0, 88.0], 120);
    chi2_conductor(Microfacet::Ggx, 0.01, &[0.0, 45.0, 88.0], 130);
}

#[test]
fn chi2_conductor_near_mirror() {
    // alpha = 1e-4 is nearly a mirror; the Cauchy-spaced bins still resolve it.
    chi2_conductor(Microfacet::Ggx, 1e-4, &[0.0, 70.0], 140);
}

#[test]
fn chi2_beckmann_rough() {
    chi2_conductor(Microfacet::Beckmann, 1.0, &[0.0, 45.0, 88.0], 200);
    chi2_conductor(Microfacet::Beckmann, 0.5, &[0.0, 45.0, 88.0], 210);
}

#[test]
fn chi2_beckmann_glossy() {
    chi2_conductor(Microfacet::Beckmann, 0.1, &[0.0, 45.0, 88.0], 220);
    chi2_conductor(Microfacet::Beckmann, 0.01, &[0.0, 45.0, 88.0], 230);
}

#[test]
fn chi2_conductor_anisotropic() {
    chi2_conductor_lobe(
        anisotropic_of(Microfacet::Ggx, 0.1, 0.5, 0.0),
        0.1,
        &[0.0, 45.0, 88.0],
        300,
    );
    chi2_conductor_lobe(
        anisotropic_of(Microfacet::Ggx, 0.6, 0.15, 30.0),
        0.15,
        &[30.0, 70.0],
        310,
    );
    chi2_conductor_lobe(
        anisotropic_of(Microfacet::Beckmann, 0.1, 0.4, 0.0),
        0.1,
        &[0.0, 45.0, 88.0],
        320,
    );
    chi2_conductor_lobe(
        anisotropic_of(Microfacet::Beckmann, 0.5, 0.2, -60.0),
        0.2,
        &[30.0, 70.0],
        330,
    );
}

/// The plastic's two lobes against its pdf: bins around the mirror direction as wide as the
/// glossy lobe, wide enough in the tails for the cosine lobe.
fn chi2_plastic(distribution: Microfacet, alpha: f32, thetas: &[f64], stream0: u64) {
    let m = plastic_of(distribution, alpha);
    for (i, &theta) in thetas.iter().enumerate() {
        let wo = dir_deg(theta, 10.0 + 97.0 * i as f64);
        let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
        let binning = Binning::new(1.0, mirror, Some(2.0 * alpha as f64));
        let r = chi2_test(
            &binning,
            stream0 + i as u64,
            &|u| m.sample(wo, u, TransportMode::Radiance).map(|s| s.wi),
            &|wi| m.pdf(wo, wi),
        );
        println!(
            "plastic {distribution:?} alpha {alpha} wo theta {theta}: chi2 {:.1} dof {} p {:.4} integral {:.6}",
            r.chi2, r.dof, r.p_value, r.total_probability
        );
        assert!(r.total_probability <= 1.0 + 1e-4, "{}", r.total_probability);
        assert!(r.dof >= 200, "too few populated cells ({})", r.dof);
        assert!(
            r.p_value > sidak_alpha(),
            "plastic {distribution:?} alpha {alpha} theta {theta}: chi2 {} dof {} p = {}",
            r.chi2,
            r.dof,
            r.p_value
        );
    }
}

#[test]
fn chi2_rough_plastic() {
    chi2_plastic(Microfacet::Beckmann, 0.1, &[0.0, 45.0, 85.0], 400);
    chi2_plastic(Microfacet::Ggx, 0.3, &[0.0, 45.0, 85.0], 410);
    chi2_plastic(Microfacet::Beckmann, 0.8, &[30.0, 80.0], 420);
}

/// f and pdf against Mitsuba 3.9.1's `roughplastic` (scalar_rgb, `BSDF::eval` over the cosine
/// and `BSDF::pdf`, si.wi our wo): Beckmann alpha 0.2 with Mitsuba's defaults on an orange
/// base, and GGX alpha 0.35, int_ior 1.8, nonlinear, with a specular_reflectance. The coat's
/// tables are our own quadrature of the same integrals; Beckmann's G1 is exact here.
#[test]
fn rough_plastic_matches_mitsuba_eval_and_pdf() {
    let beckmann = RoughPlastic::new(
        Microfacet::Beckmann,
        0.2,
        1.49 / 1.000_277,
        Vec3::new(0.6, 0.3, 0.1),
        1.0 / 3.0,
        Vec3::ONE,
        false,
    );
    let specular = Vec3::new(0.9, 0.8, 0.7);
    let diffuse = Vec3::new(0.2, 0.5, 0.9);
    let ggx = RoughPlastic::new(
        Microfacet::Ggx,
        0.35,
        1.8 / 1.000_277,
        diffuse,
        diffuse.element_sum() / 3.0,
        specular,
        true,
    );
    let cases: [(RoughPlastic, f32, Vec<MitsubaPair>); 2] = [
        (
            beckmann,
            0.01,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [0.244_234_4, 0.154_872_6, 0.095_298_05],
                    0.459_526_1,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [0.273_036_2, 0.184_621_9, 0.125_678_9],
                    0.418_200_4,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [0.487_726_3, 0.406_485_9, 0.352_325_7],
                    0.724_249_8,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [0.139_060_9, 0.081_485_85, 0.043_102_47],
                    0.069_817_1,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.173_881_6, 0.086_941_49, 0.028_981_39],
                    0.193_342_4,
                ),
                (
                    (20.0, 90.0),
                    (75.0, 300.0),
                    [0.145_034_5, 0.072_606_34, 0.024_320_93],
                    0.073_467_96,
                ),
            ],
        ),
        (
            ggx,
            0.005,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [0.061_557, 0.093_144_23, 0.169_331_3],
                    0.349_247_7,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [0.079_862_39, 0.108_232_6, 0.179_829_6],
                    0.300_540_8,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [0.181_110_1, 0.194_516_2, 0.246_837_8],
                    0.345_812_1,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [0.243_541_3, 0.243_229_8, 0.273_963_8],
                    0.214_889_9,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.024_986_7, 0.058_347_8, 0.133_651_5],
                    0.200_079_7,
                ),
                (
                    (20.0, 90.0),
                    (75.0, 300.0),
                    [0.037_236_45, 0.065_212_05, 0.130_459_3],
                    0.083_231_11,
                ),
            ],
        ),
    ];
    for (m, tolerance, pairs) in cases {
        assert_matches_mitsuba(&Material::RoughPlastic(m), tolerance, &pairs);
    }
}

/// A white base under the coat: the albedo from sampling equals Mitsuba 3.9.1's (its
/// `roughplastic`'s own sample weights averaged over 20000 samples in scalar_rgb, int_ior 1.49
/// over ext_ior 1) within 0.01, and never exceeds 1. Rough coats lose much of the light (their
/// masking removes what a single scattering model cannot return), as Mitsuba's do.
#[test]
fn rough_plastic_albedo() {
    let mitsuba = [
        (
            Microfacet::Ggx,
            [
                [0.9774, 0.9774, 0.984],
                [0.9099, 0.9089, 0.8786],
                [0.5441, 0.525, 0.4448],
            ],
        ),
        (
            Microfacet::Beckmann,
            [
                [0.9783, 0.9784, 0.9851],
                [0.9674, 0.9675, 0.9394],
                [0.7445, 0.733, 0.7338],
            ],
        ),
    ];
    for (distribution, by_alpha) in mitsuba {
        for (alpha, by_theta) in [0.01f32, 0.1, 0.5].into_iter().zip(by_alpha) {
            let white = Material::RoughPlastic(RoughPlastic::new(
                distribution,
                alpha,
                1.49,
                Vec3::ONE,
                1.0,
                Vec3::ONE,
                false,
            ));
            for (theta, want) in [0.0, 45.0, 80.0].into_iter().zip(by_theta) {
                let wo = dir_deg(theta, 0.0);
                let n = 100_000;
                let mut sum = 0.0f64;
                for i in 0..n {
                    if let Some(s) = white.sample(wo, u2(17, 0, i), TransportMode::Radiance) {
                        sum += f64::from(s.value.x * s.wi.z / s.pdf);
                    }
                }
                let albedo = sum / n as f64;
                println!(
                    "{distribution:?} alpha {alpha} theta {theta}: albedo {albedo}, Mitsuba's {want}"
                );
                assert!(
                    albedo <= 1.0 && (albedo - want).abs() < 0.01,
                    "{distribution:?} alpha {alpha} theta {theta}: albedo {albedo}, Mitsuba's {want}"
                );
            }
        }
    }
}

#[test]
fn chi2_beckmann_near_mirror() {
    chi2_conductor(Microfacet::Beckmann, 1e-4, &[0.0, 70.0], 240);
}

// ---------------------------------------------------------------------------------------------
// Consistency of sample() with eval() and pdf().

fn test_wos() -> Vec<Vec3> {
    let mut v = vec![Vec3::Z];
    for (i, theta) in [10.0, 30.0, 45.0, 60.0, 75.0, 85.0, 89.0, 89.9, 89.99]
        .into_iter()
        .enumerate()
    {
        v.push(dir_deg(theta, 37.0 * i as f64));
    }
    v
}

#[test]
fn sample_matches_eval_and_pdf() {
    let mut materials = vec![Material::Diffuse(Diffuse {
        reflectance: Vec3::new(0.7, 0.6, 0.5),
    })];
    for alpha in [1e-4, 1e-3, 0.01, 0.1, 0.5, 1.0] {
        for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
            materials.push(conductor_of(distribution, alpha));
        }
    }
    materials.extend(anisotropic_conductors());
    for alpha in [1e-3, 0.1, 0.7] {
        for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
            materials.push(plastic_of(distribution, alpha));
        }
    }
    for (mi, m) in materials.iter().enumerate() {
        for (wi_idx, &wo0) in test_wos().iter().enumerate() {
            // Diffuse reflects on both sides: test below the surface too.
            let sides: &[f32] = if matches!(m, Material::Diffuse(_)) {
                &[1.0, -1.0]
            } else {
                &[1.0]
            };
            for &side in sides {
                let wo = Vec3::new(wo0.x, wo0.y, wo0.z * side);
                let mut accepted = 0;
                for i in 0..2000 {
                    let u = u2(7, (mi * 100 + wi_idx) as u64, i);
                    let Some(s) = m.sample(wo, u, TransportMode::Radiance) else {
                        continue;
                    };
                    accepted += 1;
                    assert!(!s.delta);
                    assert!((s.wi.length() - 1.0).abs() < 1e-5);
                    assert!(s.pdf > 0.0 && s.pdf.is_finite());
                    let f = m.eval(wo, s.wi);
                    let p = m.pdf(wo, s.wi);
                    for c in 0..3 {
                        assert!(
                            rel_close(s.value[c], f[c], 1e-5),
                            "{m:?} wo {wo} wi {}: value {} eval {}",
                            s.wi,
                            s.value,
                            f
                        );
                    }
                    assert!(rel_close(s.pdf, p, 1e-5), "{m:?}: pdf {} vs {p}", s.pdf);
                }
                assert!(accepted > 0, "{m:?} wo {wo}: no sample accepted");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Conductor specifics.

#[test]
fn conductor_tiny_alpha_is_near_mirror() {
    let alpha = 1e-4f32;
    let r = Vec3::new(1.0, 0.78, 0.34);
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        let m = conductor_of(distribution, alpha);
        for (case, theta) in [0.0, 45.0, 75.0].into_iter().enumerate() {
            let wo = dir_deg(theta, 20.0);
            let mirror = Vec3::new(-wo.x, -wo.y, wo.z).as_dvec3();
            let n = 100_000;
            let mut angles = Vec::with_capacity(n);
            for i in 0..n as u64 {
                let s = m
                    .sample(wo, u2(11, case as u64, i), TransportMode::Radiance)
                    .expect("a near-mirror sample is always above the surface here");
                let w = s.value * s.wi.z / s.pdf;
                assert!(is_finite3(s.value) && s.pdf.is_finite() && is_finite3(w));
                assert!(w.cmple(r * 1.000_01).all());
                angles.push(s.wi.as_dvec3().angle_between(mirror));
            }
            angles.sort_by(|a, b| a.partial_cmp(b).unwrap());
            // GGX's slopes have Cauchy-like tails: P(tan theta_h > x alpha) ~ 1 / (1 + x^2) at
            // normal incidence, and the reflected direction turns by about twice theta_h;
            // Beckmann's are Gaussian, narrower still.
            let median = angles[n / 2];
            let q99 = angles[n * 99 / 100];
            let a = alpha as f64;
            println!("{distribution:?} alpha 1e-4 theta {theta}: median {median:e} q99 {q99:e}");
            assert!(median < 4.0 * a, "median deviation {median}");
            assert!(q99 < 40.0 * a, "99% quantile {q99}");
        }
    }
}

/// The albedo of every conductor: each sampled weight is R F G1(wi), so at most R; near the
/// mirror limit at normal incidence nearly R F.
#[test]
fn conductor_albedo() {
    let r = Vec3::new(1.0, 0.78, 0.34);
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        for ior in [ComplexIor::PERFECT_MIRROR, GOLD] {
            for alpha in [1e-4f32, 0.01, 0.1, 0.5, 1.0] {
                let m = Material::Conductor(Conductor::isotropic(distribution, alpha, r, ior));
                for theta in [0.0, 45.0, 80.0, 89.0] {
                    let wo = dir_deg(theta, 0.0);
                    let n = 100_000;
                    let mut sum = Vec3::ZERO.as_dvec3();
                    for i in 0..n {
                        if let Some(s) = m.sample(wo, u2(13, 0, i), TransportMode::Radiance) {
                            let w = s.value * s.wi.z / s.pdf;
                            assert!(w.cmple(r * 1.000_01).all(), "{m:?}: weight {w}");
                            sum += w.as_dvec3();
                        }
                    }
                    let albedo = (sum / n as f64).as_vec3();
                    assert!(albedo.cmple(r * 1.000_01).all(), "{m:?}: albedo {albedo}");
                    if alpha <= 0.1 && theta == 0.0 {
                        let rf = r * conductor::fresnel(1.0, ior);
                        assert!(
                            albedo.cmpgt(0.95 * rf).all(),
                            "{m:?}: albedo {albedo}, R F {rf}"
                        );
                    }
                }
            }
        }
    }
}

/// A near-mirror reflects R F(cos theta) of the light from every direction: the Fresnel term
/// reaches the samples at the angle of incidence (gold's is much lower at normal incidence than
/// at 75 degrees in blue, and higher in red than blue).
#[test]
fn near_mirror_conductor_reflects_its_fresnel_term() {
    let r = Vec3::new(0.9, 0.8, 0.7);
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        let m = Material::Conductor(Conductor::isotropic(distribution, 1e-4, r, GOLD));
        for theta in [0.0f64, 45.0, 75.0] {
            let wo = dir_deg(theta, 30.0);
            let n = 10_000;
            let mut sum = Vec3::ZERO.as_dvec3();
            for i in 0..n {
                let s = m
                    .sample(wo, u2(29, theta as u64, i), TransportMode::Radiance)
                    .expect("a near-mirror sample is above the surface here");
                sum += (s.value * s.wi.z / s.pdf).as_dvec3();
            }
            let albedo = (sum / n as f64).as_vec3();
            let want = r * conductor::fresnel(theta.to_radians().cos() as f32, GOLD);
            assert!(
                ((albedo - want) / want).abs().max_element() < 1e-3,
                "{distribution:?} theta {theta}: albedo {albedo}, R F {want}"
            );
        }
        let f = |theta: f32| conductor::fresnel(theta.to_radians().cos(), GOLD);
        // 0.967 and 0.324 at normal incidence, 0.496 in blue at 75 degrees.
        assert!(f(0.0).x > 0.96 && f(0.0).z < 0.33 && f(75.0).z > 0.49);
    }
}

/// A direction pair (wo, wi as polar and azimuth angles in degrees) with Mitsuba's f (over
/// the cosine) and pdf there.
type MitsubaPair = ((f64, f64), (f64, f64), [f32; 3], f32);

/// `m`'s eval and pdf equal Mitsuba's values at each pair within relative `tolerance`.
fn assert_matches_mitsuba(m: &Material, tolerance: f32, pairs: &[MitsubaPair]) {
    for &(wo, wi, f, pdf) in pairs {
        let (wo, wi) = (dir_deg(wo.0, wo.1), dir_deg(wi.0, wi.1));
        let (got_f, got_pdf) = (m.eval(wo, wi), m.pdf(wo, wi));
        for c in 0..3 {
            assert!(
                rel_close(got_f[c], f[c], tolerance),
                "{m:?} wo {wo} wi {wi}: f {got_f}, Mitsuba's {f:?}"
            );
        }
        assert!(
            rel_close(got_pdf, pdf, tolerance),
            "{m:?} wo {wo} wi {wi}: pdf {got_pdf}, Mitsuba's {pdf}"
        );
    }
}

/// Anisotropic f and pdf against Mitsuba 3.9.1's `roughconductor` (scalar_rgb, `BSDF::eval`
/// over the cosine and `BSDF::pdf`, alpha_u along the frame's first tangent, si.wi our wo):
/// gold with GGX (alpha_u 0.1, alpha_v 0.4) and copper with Beckmann (0.3, 0.05). Pairs where
/// Mitsuba's value is exactly 0 or below 1e-8 (its rational G1 there) are left out.
#[test]
fn anisotropic_conductor_matches_mitsuba_eval_and_pdf() {
    let copper = ComplexIor {
        eta: Vec3::new(0.201_005_47, 0.923_749_5, 1.102_215_4),
        k: Vec3::new(3.913_262_1, 2.453_045_1, 2.142_089_8),
    };
    let mut ggx = Conductor::isotropic(Microfacet::Ggx, 0.1, Vec3::ONE, GOLD);
    ggx.alpha_v = 0.4;
    let mut beckmann = Conductor::isotropic(Microfacet::Beckmann, 0.3, Vec3::ONE, copper);
    beckmann.alpha_v = 0.05;
    let cases: [(Conductor, f32, Vec<MitsubaPair>); 2] = [
        (
            ggx,
            1e-4,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [0.636_137_8, 0.527_774_5, 0.213_293_95],
                    0.648_117_8,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [0.731_485_8, 0.606_714_7, 0.248_314_77],
                    0.581_434_8,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [3.424_423_3, 2.854_452_9, 1.283_122_7],
                    2.054_658_2,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [0.066_897_06, 0.058_095_95, 0.032_915_23],
                    0.028_478_244,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.010_938_934, 0.009_073_695, 0.003_692_021_8],
                    0.008_312_062,
                ),
                (
                    (50.0, 90.0),
                    (48.0, 275.0),
                    [2.619_396_7, 2.174_735_3, 0.927_159_9],
                    1.901_835_7,
                ),
            ],
        ),
        (
            beckmann,
            0.008,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [4.782_764_4, 3.113_705_4, 2.564_937_8],
                    4.947_506_4,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [4.099_677, 2.669_435_5, 2.205_199_7],
                    3.301_150_3,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [0.015_733_415, 0.010_355_524, 0.008_743_508],
                    0.009_529_725,
                ),
                (
                    (50.0, 90.0),
                    (48.0, 275.0),
                    [9.826_771, 6.417_414, 5.351_125_5],
                    6.926_434,
                ),
            ],
        ),
    ];
    for (m, tolerance, pairs) in cases {
        assert_matches_mitsuba(&Material::Conductor(m), tolerance, &pairs);
    }
}

/// A lobe whose axis is turned by phi is the unturned lobe seen from directions turned by
/// -phi: eval, pdf and the sampled directions all turn with the axis.
#[test]
fn anisotropic_conductor_turns_with_its_axis() {
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        let Material::Conductor(straight) = anisotropic_of(distribution, 0.08, 0.5, 0.0) else {
            unreachable!()
        };
        for degrees in [30.0f32, 90.0, -135.0] {
            let mut turned = straight;
            let a = degrees.to_radians();
            turned.axis = Vec2::new(a.cos(), a.sin());
            let unturn = |w: Vec3| {
                let (c, s) = (a.cos(), a.sin());
                Vec3::new(c * w.x + s * w.y, c * w.y - s * w.x, w.z)
            };
            for (i, wo) in test_wos().into_iter().enumerate() {
                for j in 0..200 {
                    let u = u2(23, i as u64, j);
                    let Some(s) = turned.sample(wo, u, TransportMode::Radiance) else {
                        continue;
                    };
                    let (f, p) = (
                        straight.eval(unturn(wo), unturn(s.wi), TransportMode::Radiance),
                        straight.pdf(unturn(wo), unturn(s.wi)),
                    );
                    for c in 0..3 {
                        assert!(
                            rel_close(s.value[c], f[c], 1e-3),
                            "{degrees}: {} vs {f}",
                            s.value
                        );
                    }
                    assert!(rel_close(s.pdf, p, 1e-3), "{degrees}: {} vs {p}", s.pdf);
                }
            }
        }
        // At 90 degrees the roughnesses trade places.
        let mut turned = straight;
        turned.axis = Vec2::Y;
        let mut swapped = straight;
        (swapped.alpha_u, swapped.alpha_v) = (straight.alpha_v, straight.alpha_u);
        for (wo, wi) in [
            (dir_deg(40.0, 10.0), dir_deg(35.0, 200.0)),
            (dir_deg(70.0, 80.0), dir_deg(20.0, 250.0)),
        ] {
            let (a, b) = (
                turned.eval(wo, wi, TransportMode::Radiance),
                swapped.eval(wo, wi, TransportMode::Radiance),
            );
            assert!(
                (a - b).abs().max_element() <= 1e-5 * b.max_element(),
                "{a} vs {b}"
            );
        }
    }
}

/// f and pdf against Mitsuba 3.9.1's `roughconductor` (scalar_rgb, `BSDF::eval` over the cosine
/// and `BSDF::pdf`, its si.wi being our wo) for gold (material "Au", Beckmann, alpha 0.3),
/// copper ("Cu", Beckmann, 0.05) and an rgb eta/k with specular_reflectance (GGX, 0.2). GGX
/// agrees to f32 precision; Beckmann within Mitsuba's rational approximation of G1 (0.35% per
/// factor). Mitsuba gives exact zeros where D * cos < 1e-20; we give D's tiny value.
#[test]
fn conductor_matches_mitsuba_eval_and_pdf() {
    let copper = ComplexIor {
        eta: Vec3::new(0.201_005_47, 0.923_749_5, 1.102_215_4),
        k: Vec3::new(3.913_262_1, 2.453_045_1, 2.142_089_8),
    };
    let beckmann = |alpha, ior| Conductor::isotropic(Microfacet::Beckmann, alpha, Vec3::ONE, ior);
    let ggx = Conductor::isotropic(
        Microfacet::Ggx,
        0.2,
        Vec3::new(0.9, 0.8, 0.7),
        ComplexIor {
            eta: Vec3::new(0.2, 0.9, 1.1),
            k: Vec3::new(3.9, 2.4, 2.1),
        },
    );
    // (conductor, tolerance, [(wo theta, phi), (wi theta, phi), Mitsuba's f, Mitsuba's pdf]).
    let cases: [(Conductor, f32, Vec<MitsubaPair>); 3] = [
        (
            beckmann(0.3, GOLD),
            0.008,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [0.809_405_5, 0.671_526_7, 0.271_389_7],
                    0.824_584_4,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [1.161_391_6, 0.963_290_6, 0.394_253_3],
                    0.920_805_4,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [2.459_690_4, 2.050_292_8, 0.921_639_7],
                    1.465_047_4,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [1.268_608_9, 1.101_708_2, 0.624_191_2],
                    0.455_772_4,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.014_865_44, 0.012_330_68, 0.005_017_26],
                    0.010_876_72,
                ),
            ],
        ),
        (
            beckmann(0.05, copper),
            0.008,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [1.462_458_7, 0.952_099_1, 0.784_298_7],
                    1.512_833,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [0.504_220_4, 0.328_314_6, 0.271_218_1],
                    0.406_009_4,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [0.028_798_34, 0.018_954_68, 0.016_004_06],
                    0.017_443_14,
                ),
            ],
        ),
        (
            ggx,
            1e-4,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [1.237_772_2, 0.711_720_4, 0.506_798_6],
                    1.423_212_3,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [1.578_875, 0.908_253_5, 0.648_725_3],
                    1.422_577_5,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [2.555_191_8, 1.489_189_3, 1.088_612_7],
                    1.754_120_6,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [0.645_502, 0.408_278_8, 0.316_398_8],
                    0.278_766_3,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.041_248_5, 0.023_721_93, 0.016_919_59],
                    0.034_393_86,
                ),
            ],
        ),
    ];
    for (m, tolerance, pairs) in cases {
        assert_matches_mitsuba(&Material::Conductor(m), tolerance, &pairs);
    }
}

#[test]
fn diffuse_albedo_is_reflectance() {
    let r = Vec3::new(0.725, 0.71, 0.68);
    let m = Material::Diffuse(Diffuse { reflectance: r });
    for wo in [dir_deg(0.0, 0.0), dir_deg(70.0, 5.0), dir_deg(150.0, 80.0)] {
        let n = 10_000;
        let mut sum = Vec3::ZERO;
        let mut count = 0;
        for i in 0..n {
            if let Some(s) = m.sample(wo, u2(17, 0, i), TransportMode::Radiance) {
                assert_eq!(s.wi.z.signum(), wo.z.signum());
                sum += s.value * s.wi.z.abs() / s.pdf;
                count += 1;
            }
        }
        assert!(count as f64 > 0.999 * n as f64);
        let albedo = sum / n as f32;
        assert!((albedo - r).abs().max_element() < 2e-3, "albedo {albedo}");
    }
}

#[test]
fn reciprocity_diffuse_and_conductor() {
    let materials = [
        Material::Diffuse(Diffuse {
            reflectance: Vec3::new(0.5, 0.4, 0.3),
        }),
        conductor_of(Microfacet::Ggx, 0.05),
        conductor_of(Microfacet::Ggx, 0.7),
        // Beckmann's D is exactly 0 beyond tan theta_h = 9.3 alpha: 0.05 would leave too few
        // random pairs with a value.
        conductor_of(Microfacet::Beckmann, 0.2),
        conductor_of(Microfacet::Beckmann, 0.7),
        anisotropic_of(Microfacet::Ggx, 0.05, 0.5, 20.0),
        anisotropic_of(Microfacet::Beckmann, 0.6, 0.2, -75.0),
        plastic_of(Microfacet::Ggx, 0.1),
        plastic_of(Microfacet::Beckmann, 0.4),
    ];
    for m in materials {
        let mut nonzero = 0;
        for i in 0..10_000 {
            let k = SampleKey::new(19, 0, i);
            let a = stagelight::sampling::uniform_sphere(k.get2(0));
            // Pairs mostly on the same side, some across.
            let mut b = stagelight::sampling::uniform_sphere(k.get2(2));
            if k.get(4) < 0.8 && a.z * b.z < 0.0 {
                b.z = -b.z;
            }
            let fab = m.eval(a, b);
            let fba = m.eval(b, a);
            // The plastic's Fresnel factor reads wo.h, rounded apart from wi.h.
            let tolerance = if matches!(m, Material::RoughPlastic(_)) {
                3e-5
            } else {
                1e-5
            };
            for c in 0..3 {
                assert!(
                    rel_close(fab[c], fba[c], tolerance),
                    "{m:?}: {fab} vs {fba}"
                );
            }
            if fab.max_element() > 0.0 {
                nonzero += 1;
            }
        }
        assert!(nonzero > 1000);
    }
}

// ---------------------------------------------------------------------------------------------
// Dielectric.

/// Fresnel reflectance from the angle form (Born and Wolf), independent of the cosine form.
fn fresnel_reference(theta_i: f64, n_i: f64, n_t: f64) -> f64 {
    let s = n_i / n_t * theta_i.sin();
    if s >= 1.0 {
        return 1.0;
    }
    if theta_i == 0.0 {
        let r = (n_t - n_i) / (n_t + n_i);
        return r * r;
    }
    let theta_t = s.asin();
    let rs = (theta_i - theta_t).sin() / (theta_i + theta_t).sin();
    let rp = (theta_i - theta_t).tan() / (theta_i + theta_t).tan();
    0.5 * (rs * rs + rp * rp)
}

#[test]
fn fresnel_values() {
    let f0 = dielectric::fresnel(1.0, 1.5);
    assert!((f0 - 0.04).abs() < 1e-6, "F(0) = {f0}");
    assert!((dielectric::fresnel(-1.0, 1.5) - 0.04).abs() < 1e-6);
    for ior in [1.33f32, 1.5, 2.4] {
        for i in 0..=180 {
            let theta = i as f64 * 0.5; // 0 to 90 degrees
            let c = theta.to_radians().cos() as f32;
            let out = dielectric::fresnel(c, ior);
            let inn = dielectric::fresnel(-c, ior);
            let ref_out = fresnel_reference(theta.to_radians(), 1.0, ior as f64);
            let ref_in = fresnel_reference(theta.to_radians(), ior as f64, 1.0);
            assert!(
                (out as f64 - ref_out).abs() < 2e-5,
                "ior {ior} theta {theta}"
            );
            assert!(
                (inn as f64 - ref_in).abs() < 2e-5,
                "ior {ior} theta {theta} inside"
            );
            assert!((0.0..=1.0).contains(&out) && (0.0..=1.0).contains(&inn));
        }
        // Grazing: everything reflects.
        assert_eq!(dielectric::fresnel(0.0, ior), 1.0);
        // Beyond the critical angle from inside: total internal reflection.
        let crit = (1.0 / ior as f64).asin();
        for extra in [1e-3, 0.1, 0.5] {
            let c = -(crit + extra).cos() as f32;
            assert_eq!(dielectric::fresnel(c, ior), 1.0);
        }
    }
}

#[test]
fn dielectric_lobe_frequencies_and_directions() {
    let ior = 1.5f32;
    let m = Material::Dielectric(Dielectric { ior });
    // (theta of wo in degrees; > 90 means inside).
    let thetas = [
        0.0, 30.0, 60.0, 80.0, 89.0, 180.0, 160.0, 140.0, 139.0, 138.5, 120.0,
    ];
    for (case, &theta) in thetas.iter().enumerate() {
        let wo = dir_deg(theta, 33.0 + 40.0 * case as f64);
        let f = dielectric::fresnel(wo.z, ior);
        let (n_o, n_t) = if wo.z > 0.0 { (1.0, ior) } else { (ior, 1.0) };
        let n = 200_000u64;
        let mut reflected = 0u64;
        for i in 0..n {
            let u = SampleKey::new(23, case as u64, i).get(0);
            let s = m
                .sample(wo, Vec2::new(u, 0.5), TransportMode::Importance)
                .unwrap();
            assert!(s.delta);
            assert!((s.wi.length() - 1.0).abs() < 1e-5);
            if s.wi.z * wo.z > 0.0 {
                reflected += 1;
                // The exact mirror direction, chosen with probability F.
                assert_eq!(s.wi, Vec3::new(-wo.x, -wo.y, wo.z));
                assert!((s.pdf - f).abs() < 1e-5);
            } else {
                assert!((s.pdf - (1.0 - f)).abs() < 1e-5);
                // Snell: n_o sin_o = n_t sin_t, in the plane of incidence, azimuth reversed.
                let so = Vec2::new(wo.x, wo.y);
                let st = Vec2::new(s.wi.x, s.wi.y);
                assert!((n_o * so.length() - n_t * st.length()).abs() < 1e-5);
                assert!(so.perp_dot(st).abs() < 1e-5 && so.dot(st) <= 0.0);
            }
        }
        let freq = reflected as f64 / n as f64;
        let sigma = (f as f64 * (1.0 - f as f64) / n as f64).sqrt();
        assert!(
            (freq - f as f64).abs() <= 5.0 * sigma + 1e-6,
            "theta {theta}: reflected {freq}, F = {f}"
        );
    }
}

#[test]
fn dielectric_energy() {
    for ior in [1.5f32, 1.0 / 1.5, 2.4] {
        for i in 0..200 {
            let k = SampleKey::new(29, 0, i);
            let wo = stagelight::sampling::uniform_sphere(k.get2(0));
            let m = Material::Dielectric(Dielectric { ior });
            let (n_o, n_t) = if wo.z >= 0.0 { (1.0, ior) } else { (ior, 1.0) };
            let f = dielectric::fresnel(wo.z, ior);
            // u = 0 picks reflection when F > 0; u just below 1 picks refraction when F < 1.
            let mut total = 0.0;
            for u in [0.0f32, 1.0 - f32::EPSILON / 2.0] {
                let si = m
                    .sample(wo, Vec2::new(u, 0.0), TransportMode::Importance)
                    .unwrap();
                let sr = m
                    .sample(wo, Vec2::new(u, 0.0), TransportMode::Radiance)
                    .unwrap();
                assert_eq!(si.wi, sr.wi);
                let wi_ = si.value * si.wi.z.abs() / si.pdf;
                let wr = sr.value * sr.wi.z.abs() / sr.pdf;
                // Importance weight is exactly one for both lobes.
                assert!((wi_ - Vec3::ONE).abs().max_element() < 1e-5, "weight {wi_}");
                let refracted = si.wi.z * wo.z < 0.0;
                let expect = if refracted { (n_o / n_t).powi(2) } else { 1.0 };
                assert!((wr.x - expect).abs() < 1e-5 * expect, "{wr} vs {expect}");
                // Energy: (value * cos) summed over both lobes is R + T = 1.
                // u = 0 reflects unless F = 0; the largest u refracts unless F rounds to 1.
                let e = si.value.x * si.wi.z.abs();
                if (u == 0.0) != refracted {
                    assert!((si.pdf - if refracted { 1.0 - f } else { f }).abs() < 1e-5);
                    total += e;
                }
            }
            assert!((total - 1.0).abs() < 1e-5, "R + T = {total}");
        }
    }
}

#[test]
fn dielectric_total_internal_reflection() {
    let ior = 1.5f32;
    let m = Material::Dielectric(Dielectric { ior });
    let crit = (1.0 / ior as f64).asin().to_degrees();
    for theta_in in [crit + 1e-4, crit + 0.5, crit + 10.0, 89.0, 89.999] {
        let wo = dir_deg(180.0 - theta_in, 10.0);
        assert!(wo.z < 0.0);
        for i in 0..1000 {
            let u = SampleKey::new(31, 0, i).get(0);
            let s = m
                .sample(wo, Vec2::new(u, 0.0), TransportMode::Radiance)
                .unwrap();
            assert_eq!(s.wi, Vec3::new(-wo.x, -wo.y, wo.z));
            assert_eq!(s.pdf, 1.0);
        }
    }
    // Exactly at the critical angle (in f32): finite either way.
    let c = (1.0 - 1.0 / (ior * ior)).sqrt();
    for dz in [-2e-7f32, 0.0, 2e-7] {
        let z = -(c + dz);
        let wo = Vec3::new((1.0 - z * z).sqrt(), 0.0, z);
        for u in [0.0, 0.5, 0.999, 1.0 - f32::EPSILON / 2.0] {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let s = m.sample(wo, Vec2::new(u, 0.0), mode).unwrap();
                let w = s.value * s.wi.z.abs() / s.pdf;
                assert!(is_finite3(s.value) && s.pdf > 0.0 && is_finite3(w) && s.wi.is_finite());
            }
        }
    }
}

/// Refracts `w` through the interface (u just below 1 selects refraction where F < 1).
fn refract(ior: f32, w: Vec3, mode: TransportMode) -> stagelight::bsdf::BsdfSample {
    let s = dielectric::sample(ior, w, 1.0 - f32::EPSILON / 2.0, mode);
    assert!(s.wi.z * w.z < 0.0, "not refracted");
    s
}

/// Projected solid angle (area of the projection onto the tangent plane) of a triangle of
/// nearby directions.
fn projected_area(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    0.5 * ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)).abs()
}

#[test]
fn dielectric_generalised_reciprocity() {
    // For a refracting pair, with f written as c * delta over projected solid angle,
    // Veach's generalised reciprocity reads f(wo, wi) / n_o^2 = f(wi, wo) / n_i^2, where
    // n_o, n_i are the indices on wo's and wi's sides. The delta in wi becomes one in wo with the
    // Jacobian J = d(sigma_i) / d(sigma_o) of the refraction map, measured here numerically, so
    // the check is c(wo -> wi) / (J n_o^2) = c(wi -> wo) / n_i^2. Importance mode is the adjoint:
    // c_importance(wo -> wi) / J = c_radiance(wi -> wo).
    for ior in [1.5f32, 2.4, 1.0 / 1.33] {
        for theta in [0.0, 10.0, 30.0, 50.0, 70.0, 85.0, 100.0, 130.0, 150.0] {
            let wo = dir_deg(theta, 57.0);
            let (n_o, n_i) = if wo.z > 0.0 {
                (1.0, ior as f64)
            } else {
                (ior as f64, 1.0)
            };
            // Skip total internal reflection.
            if dielectric::fresnel(wo.z, ior) >= 1.0 {
                continue;
            }
            let fwd = refract(ior, wo, TransportMode::Radiance);
            let wi = fwd.wi;
            let bwd = refract(ior, wi, TransportMode::Radiance);
            // The round trip returns to wo, with the same Fresnel transmittance.
            assert!((bwd.wi - wo).length() < 1e-5, "{} vs {wo}", bwd.wi);
            assert!(
                (fwd.pdf - bwd.pdf).abs() < 1e-5,
                "ior {ior} theta {theta}: T {} vs {}",
                fwd.pdf,
                bwd.pdf
            );

            // A small triangle of directions around wo, and its image under refraction.
            let wod = wo.as_dvec3();
            let a = wod.any_orthonormal_vector();
            let b = wod.cross(a);
            let d = 1e-3;
            let wo1 = (wod + d * a).normalize().as_vec3();
            let wo2 = (wod + d * b).normalize().as_vec3();
            let wi1 = refract(ior, wo1, TransportMode::Radiance).wi;
            let wi2 = refract(ior, wo2, TransportMode::Radiance).wi;
            let jac = projected_area(wi, wi1, wi2) / projected_area(wo, wo1, wo2);
            // Etendue: n^2 d(sigma) is conserved, so J = (n_o / n_i)^2.
            assert!((jac - (n_o / n_i).powi(2)).abs() < 1e-3 * jac, "J = {jac}");

            let c_fwd = (fwd.value.x * fwd.wi.z.abs()) as f64;
            let c_bwd = (bwd.value.x * bwd.wi.z.abs()) as f64;
            let lhs = c_fwd / (jac * n_o * n_o);
            let rhs = c_bwd / (n_i * n_i);
            assert!(
                (lhs - rhs).abs() < 2e-3 * rhs,
                "ior {ior} theta {theta}: {lhs} vs {rhs}"
            );
            let imp = refract(ior, wo, TransportMode::Importance);
            let c_imp = (imp.value.x * imp.wi.z.abs()) as f64;
            assert!((c_imp / jac - c_bwd).abs() < 2e-3 * c_bwd);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Smooth plastic.

/// Mitsuba 3.9.1's `plastic` on its defaults (polypropylene in air) over an orange base, and
/// at int_ior 1.8, nonlinear, with a specular_reflectance over a blue one.
fn smooth_plastics() -> [SmoothPlastic; 2] {
    let orange = Vec3::new(0.6, 0.3, 0.1);
    let blue = Vec3::new(0.2, 0.5, 0.9);
    [
        SmoothPlastic::new(
            1.49 / 1.000_277,
            orange,
            orange.element_sum() / 3.0,
            Vec3::ONE,
            false,
        ),
        SmoothPlastic::new(
            1.8 / 1.000_277,
            blue,
            blue.element_sum() / 3.0,
            Vec3::new(0.9, 0.8, 0.7),
            true,
        ),
    ]
}

/// The diffuse lobe's f and pdf against Mitsuba's `plastic` (scalar_rgb, `BSDF::eval` over the
/// cosine and `BSDF::pdf`, si.wi our wo): the fit of the coat's internal reflectance, the two
/// Fresnel factors and the lobe's share of the sampling as Mitsuba's.
#[test]
fn smooth_plastic_matches_mitsuba_eval_and_pdf() {
    let [linear, nonlinear] = smooth_plastics();
    let cases: [(SmoothPlastic, Vec<MitsubaPair>); 2] = [
        (
            linear,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [0.194_235_6, 0.097_117_78, 0.032_372_59],
                    0.279_716_3,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [0.192_794_1, 0.096_397_06, 0.032_132_35],
                    0.216_637_8,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [0.178_736_8, 0.089_368_41, 0.029_789_47],
                    0.141_805_9,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [0.107_246_4, 0.053_623_18, 0.017_874_39],
                    0.037_731_71,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.190_172_8, 0.095_086_38, 0.031_695_46],
                    0.195_064_6,
                ),
                (
                    (20.0, 90.0),
                    (75.0, 300.0),
                    [0.151_280_7, 0.075_640_33, 0.025_213_44],
                    0.073_456_95,
                ),
            ],
        ),
        (
            nonlinear,
            vec![
                (
                    (0.0, 0.0),
                    (10.0, 180.0),
                    [0.019_429_11, 0.065_411_07, 0.218_934_7],
                    0.276_626_3,
                ),
                (
                    (30.0, 20.0),
                    (40.0, 190.0),
                    [0.019_246_76, 0.064_797_14, 0.216_879_9],
                    0.214_548_9,
                ),
                (
                    (60.0, 0.0),
                    (55.0, 170.0),
                    [0.017_651_89, 0.059_427_76, 0.198_908_2],
                    0.148_043_8,
                ),
                (
                    (80.0, 45.0),
                    (70.0, 240.0),
                    [0.010_510_31, 0.035_384_57, 0.118_434_2],
                    0.052_327_69,
                ),
                (
                    (45.0, 0.0),
                    (45.0, 90.0),
                    [0.018_929_71, 0.063_729_74, 0.213_307_2],
                    0.194_936_9,
                ),
                (
                    (20.0, 90.0),
                    (75.0, 300.0),
                    [0.014_955_33, 0.050_349_38, 0.168_522_4],
                    0.072_662_67,
                ),
            ],
        ),
    ];
    for (m, pairs) in cases {
        assert_matches_mitsuba(&Material::Plastic(m), 1e-4, &pairs);
    }
}

/// The delta lobe against Mitsuba's `plastic` (`BSDF::sample` with sample1 = 0, si.wi our wo
/// at azimuth 20 degrees): its probability and weight (specular F / probability) at five
/// polar angles; the direction is the mirror's and the sample says `delta`.
#[test]
fn smooth_plastic_specular_lobe_matches_mitsuba() {
    let [linear, nonlinear] = smooth_plastics();
    // (wo's polar angle, the lobe's probability, its weight) per material.
    type Lobe = (f64, f32, [f32; 3]);
    let cases: [(SmoothPlastic, [Lobe; 5]); 2] = [
        (
            linear,
            [
                (0.0, 0.107_689_1, [0.359_115_2; 3]),
                (30.0, 0.111_555_8, [0.360_115_35; 3]),
                (60.0, 0.223_301_1, [0.391_634_97; 3]),
                (85.0, 0.825_301_2, [0.741_071_4; 3]),
                (89.0, 0.965_771_6, [0.935_929_3; 3]),
            ],
        ),
        (
            nonlinear,
            [
                (0.0, 0.117_546_4, [0.624_467_9, 0.555_082_6, 0.485_697_27]),
                (30.0, 0.120_122_4, [0.625_026_5, 0.555_579_1, 0.486_131_73]),
                (60.0, 0.189_134_3, [0.640_372_1, 0.569_219_65, 0.498_067_17]),
                (85.0, 0.718_100_3, [0.788_816_4, 0.701_170_15, 0.613_523_9]),
                (89.0, 0.936_058_3, [0.872_117_64, 0.775_215_7, 0.678_313_73]),
            ],
        ),
    ];
    for (m, by_theta) in cases {
        let material = Material::Plastic(m);
        for (theta, pdf, weight) in by_theta {
            let wo = dir_deg(theta, 20.0);
            let s = material
                .sample(wo, Vec2::new(0.0, 0.5), TransportMode::Radiance)
                .unwrap();
            let w = s.value * s.wi.z.abs() / s.pdf;
            assert!(s.delta, "theta {theta}: {s:?}");
            assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
            assert!(
                rel_close(s.pdf, pdf, 2e-4),
                "theta {theta}: probability {}, Mitsuba's {pdf}",
                s.pdf
            );
            for c in 0..3 {
                assert!(
                    rel_close(w[c], weight[c], 2e-4),
                    "theta {theta}: weight {w}, Mitsuba's {weight:?}"
                );
            }
            // The other choice is the diffuse lobe, as eval and pdf describe it.
            let d = material
                .sample(wo, Vec2::new(0.999_9, 0.3), TransportMode::Radiance)
                .unwrap();
            assert!(!d.delta);
            assert!(rel_close(d.pdf, material.pdf(wo, d.wi), 1e-5));
            assert!((d.value - material.eval(wo, d.wi)).abs().max_element() < 1e-6);
        }
    }
}

/// Albedo from sampling (100000 samples) against Mitsuba 3.9.1's (its own sample weights
/// averaged over 40000 samples, base 0.8, int_ior over ext_ior 1) within 0.01, and against
/// quadrature: specular F (the delta lobe's analytic part) plus the diffuse lobe's integral
/// over the hemisphere, within 0.005.
#[test]
fn smooth_plastic_albedo() {
    let mitsuba = [
        (1.49f32, false, [0.808_42, 0.810_98, 0.878_12]),
        (1.49, true, [0.636_66, 0.640_01, 0.766_96]),
        (1.8, false, [0.815_9, 0.818_24, 0.883_41]),
        (1.8, true, [0.556_1, 0.562_04, 0.718_37]),
    ];
    for (eta, nonlinear, by_theta) in mitsuba {
        let p = SmoothPlastic::new(eta, Vec3::splat(0.8), 0.8, Vec3::ONE, nonlinear);
        let m = Material::Plastic(p);
        for (theta, want) in [0.0, 45.0, 80.0].into_iter().zip(by_theta) {
            let wo = dir_deg(theta, 0.0);
            let n = 100_000;
            let mut sum = 0.0f64;
            for i in 0..n {
                if let Some(s) = m.sample(wo, u2(23, 0, i), TransportMode::Radiance) {
                    sum += f64::from(s.value.x * s.wi.z / s.pdf);
                }
            }
            let albedo = sum / n as f64;
            // The diffuse lobe depends on wi's cosine alone: 2 pi int f(mu) mu dmu.
            let k = 20_000;
            let diffuse: f64 = (0..k)
                .map(|j| {
                    let mu = (j as f64 + 0.5) / k as f64;
                    let wi = Vec3::new((1.0 - mu * mu).sqrt() as f32, 0.0, mu as f32);
                    2.0 * PI * f64::from(m.eval(wo, wi).x) * mu / k as f64
                })
                .sum();
            let quadrature = f64::from(dielectric::fresnel(wo.z, eta)) + diffuse;
            println!(
                "eta {eta} nonlinear {nonlinear} theta {theta}: albedo {albedo}, quadrature {quadrature}, Mitsuba's {want}"
            );
            assert!(
                (albedo - want).abs() < 0.01 && (albedo - quadrature).abs() < 0.005,
                "eta {eta} nonlinear {nonlinear} theta {theta}: albedo {albedo}, quadrature {quadrature}, Mitsuba's {want}"
            );
        }
    }
}

/// The diffuse lobe's samples against its pdf; the delta lobe's samples are counted with
/// those `sample` refuses, whose expected share is what the pdf leaves of 1: the probability
/// of the reflection.
#[test]
fn chi2_smooth_plastic() {
    for (k, m) in smooth_plastics().into_iter().enumerate() {
        let m = Material::Plastic(m);
        for (i, theta) in [0.0f64, 45.0, 85.0].into_iter().enumerate() {
            let wo = dir_deg(theta, 10.0 + 97.0 * i as f64);
            let binning = Binning::new(1.0, Vec3::Z, None);
            let r = chi2_test(
                &binning,
                500 + 10 * k as u64 + i as u64,
                &|u| {
                    m.sample(wo, u, TransportMode::Radiance)
                        .filter(|s| !s.delta)
                        .map(|s| s.wi)
                },
                &|wi| m.pdf(wo, wi),
            );
            println!(
                "smooth plastic {k} wo theta {theta}: chi2 {:.1} dof {} p {:.4} integral {:.6}",
                r.chi2, r.dof, r.p_value, r.total_probability
            );
            assert!(r.total_probability <= 1.0 + 1e-4, "{}", r.total_probability);
            assert!(r.dof >= 100, "too few populated cells ({})", r.dof);
            assert!(
                r.p_value > sidak_alpha(),
                "smooth plastic {k} theta {theta}: chi2 {} dof {} p = {}",
                r.chi2,
                r.dof,
                r.p_value
            );
        }
    }
}

/// The coat's internal reflectance: Mitsuba's fit up to eta 3, the integral beyond (where the
/// fit reaches 1 near 3.85 and Mitsuba's diffuse lobe turns negative), both close to the
/// integral where the fit is good.
#[test]
fn smooth_plastic_internal_reflectance() {
    // 2 int_0^1 F_inside(mu) mu dmu, by fine midpoints in f64 (Python, the exact Fresnel term).
    for (eta, exact) in [
        (1.49f32, 0.590_238_1f32),
        (1.8, 0.732_710_2),
        (2.4, 0.862_845_8),
        (4.0, 0.960_336_4),
    ] {
        let got = internal_reflectance(eta);
        let tolerance = if eta <= FIT_MAX_ETA { 0.005 } else { 2e-4 };
        assert!(
            (got - exact).abs() < tolerance,
            "eta {eta}: {got}, exact {exact}"
        );
    }
    assert_eq!(
        internal_reflectance(1.49),
        fresnel_diffuse_reflectance(1.0 / 1.49)
    );
    // Mitsuba's fit past its range: at 4 it exceeds 1.
    assert!(fresnel_diffuse_reflectance(0.25) > 1.0);
}

// ---------------------------------------------------------------------------------------------
// Thin dielectric.

/// Mitsuba 3.9.1's `thindielectric` (scalar_rgb, `BSDF::sample` with sample1 0 and 0.999, si.wi
/// our wo at azimuth 20 degrees, int_ior bk7 and 1.33 over air): the reflection's probability
/// at each polar angle of wo (from both sides); both lobes weigh 1 and the transmitted
/// direction is -wo.
#[test]
fn thin_dielectric_matches_mitsuba_sample() {
    let cases: [(f32, [(f64, f32); 6]); 2] = [
        (
            1.5046,
            [
                (0.0, 0.077_914_33),
                (30.0, 0.080_739_05),
                (60.0, 0.164_935_4),
                (85.0, 0.760_275_5),
                (120.0, 0.164_935_4),
                (170.0, 0.077_943_13),
            ],
        ),
        (
            1.33,
            [
                (0.0, 0.039_255_84),
                (30.0, 0.041_275_78),
                (60.0, 0.111_525_9),
                (85.0, 0.736_280_6),
                (120.0, 0.111_525_9),
                (170.0, 0.039_275_76),
            ],
        ),
    ];
    for (int_ior, by_theta) in cases {
        let m = Material::ThinDielectric(ThinDielectric {
            ior: int_ior / 1.000_277,
        });
        for (theta, r) in by_theta {
            let wo = dir_deg(theta, 20.0);
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let reflected = m.sample(wo, Vec2::new(0.0, 0.5), mode).unwrap();
                let through = m.sample(wo, Vec2::new(0.999, 0.5), mode).unwrap();
                assert!(reflected.delta && through.delta);
                assert!(
                    rel_close(reflected.pdf, r, 1e-4) && rel_close(through.pdf, 1.0 - r, 1e-4),
                    "ior {int_ior} theta {theta}: R' {} and {}, Mitsuba's {r}",
                    reflected.pdf,
                    through.pdf
                );
                let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
                assert!((reflected.wi - mirror).length() < 1e-6, "{reflected:?}");
                assert!((through.wi + wo).length() < 1e-6, "{through:?}");
                for s in [reflected, through] {
                    let weight = s.value * s.wi.z.abs() / s.pdf;
                    assert!((weight - Vec3::ONE).abs().max_element() < 1e-5, "{s:?}");
                }
                // Not reachable by evaluation: a pure delta material.
                assert_eq!(m.eval(wo, through.wi), Vec3::ZERO);
                assert_eq!(m.pdf(wo, reflected.wi), 0.0);
            }
        }
    }
}

/// R' is the sum of the sheet's internal bounces, R + T R T + T R^3 T + ..., summed here term
/// by term from the single-face Fresnel term; lobe frequencies follow it.
#[test]
fn thin_dielectric_sums_its_internal_reflections() {
    for ior in [1.0001f32, 1.33, 1.5, 2.4, 4.0] {
        for theta in [0.0f64, 20.0, 45.0, 70.0, 85.0, 89.0] {
            let cos = theta.to_radians().cos() as f32;
            let r = f64::from(dielectric::fresnel(cos, ior));
            let t = 1.0 - r;
            let series: f64 = r + (0..200).map(|k| t * t * r.powi(2 * k + 1)).sum::<f64>();
            let got = f64::from(dielectric::thin_reflectance(cos, ior));
            let from_behind = f64::from(dielectric::thin_reflectance(-cos, ior));
            assert!(
                (got - series).abs() < 2e-6 && got == from_behind,
                "ior {ior} theta {theta}: R' {got}, series {series}, from behind {from_behind}"
            );
            // One choice in [0, 1): reflection below R', straight through above.
            let m = Material::ThinDielectric(ThinDielectric { ior });
            let wo = dir_deg(theta, 0.0);
            let n = 20_000u64;
            let reflected = (0..n)
                .filter(|&i| {
                    let u = (i as f32 + 0.5) / n as f32;
                    m.sample(wo, Vec2::new(u, 0.5), TransportMode::Radiance)
                        .unwrap()
                        .wi
                        .z
                        > 0.0
                })
                .count();
            let frequency = reflected as f64 / n as f64;
            assert!(
                (frequency - got).abs() < 1e-4,
                "ior {ior} theta {theta}: {frequency} against {got}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Stability.

fn edge_directions() -> Vec<Vec3> {
    let mut v = vec![Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.6, 0.8, 0.0)];
    for z in [1e-30f32, 1e-20, 1e-10, 1e-7, 1e-4, 1e-2, 0.5, 1.0 - 1e-7] {
        let r = (1.0 - z * z).max(0.0).sqrt();
        v.push(Vec3::new(r * 0.8, r * 0.6, z));
        v.push(Vec3::new(-r * 0.6, r * 0.8, -z));
    }
    v
}

fn edge_us() -> Vec<Vec2> {
    let e = [0.0, 1e-7, 0.25, 0.5, 0.75, 1.0 - f32::EPSILON / 2.0];
    let mut v = Vec::new();
    for a in e {
        for b in e {
            v.push(Vec2::new(a, b));
        }
    }
    v
}

fn check_material_finite(m: Material) {
    for wo in edge_directions() {
        for wi in edge_directions() {
            let f = m.eval(wo, wi);
            let p = m.pdf(wo, wi);
            assert!(
                is_finite3(f) && f.cmpge(Vec3::ZERO).all(),
                "{m:?} {wo} {wi}: f {f}"
            );
            assert!(p.is_finite() && p >= 0.0, "{m:?} {wo} {wi}: pdf {p}");
        }
        for u in edge_us() {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                if let Some(s) = m.sample(wo, u, mode) {
                    let w = s.value * s.wi.z.abs() / s.pdf;
                    assert!(
                        s.wi.is_finite() && is_finite3(s.value) && s.pdf.is_finite(),
                        "{m:?} wo {wo} u {u}: {s:?}"
                    );
                    assert!(s.pdf > 0.0 && is_finite3(w), "{m:?} wo {wo} u {u}: {s:?}");
                    assert!((s.wi.length() - 1.0).abs() < 1e-4, "{m:?} wo {wo}: {s:?}");
                }
            }
        }
    }
}

#[test]
fn stability_all_materials() {
    check_material_finite(Material::Diffuse(Diffuse {
        reflectance: Vec3::splat(0.5),
    }));
    for ior in [1.0f32, 1.5, 2.4, 1.0 / 1.5] {
        check_material_finite(Material::Dielectric(Dielectric { ior }));
    }
    for ior in [1.0f32, 1.0001, 1.5, 4.0, 1.0 / 1.5] {
        check_material_finite(Material::ThinDielectric(ThinDielectric { ior }));
    }
    for eta in [1.0001f32, 1.49, 4.0, 1.0 / 1.5] {
        for nonlinear in [false, true] {
            for diffuse in [Vec3::ZERO, Vec3::new(1.0, 0.5, 0.0)] {
                let p = SmoothPlastic::new(
                    eta,
                    diffuse,
                    diffuse.element_sum() / 3.0,
                    Vec3::ONE,
                    nonlinear,
                );
                check_material_finite(Material::Plastic(p));
            }
        }
    }
    for alpha in [0.0f32, 1e-6, 1e-4, 1e-3, 0.01, 0.3, 1.0, 1e4] {
        for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
            check_material_finite(conductor_of(distribution, alpha));
            // The other roughness at its extremes, the axis off the frame's.
            for other in [1e-4f32, 1.0] {
                check_material_finite(anisotropic_of(distribution, alpha, other, 33.0));
            }
            // The coat's tables take a second each: the extremes and one between.
            if [0.0, 0.3, 1e4].contains(&alpha) {
                check_material_finite(plastic_of(distribution, alpha));
            }
        }
    }
    // Near-mirror pairs at tiny alpha stay finite: the peak of D at grazing angles.
    for z in [1.0f32, 0.5, 1e-3, 1e-6] {
        let r = (1.0 - z * z).sqrt();
        let wo = Vec3::new(r, 0.0, z);
        let wi = Vec3::new(-r, 0.0, z);
        for alpha in [1e-4f32, 1e-3, 1.0] {
            for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
                let m = Conductor::isotropic(distribution, alpha, Vec3::ONE, GOLD);
                let (f, p) = (m.eval(wo, wi, TransportMode::Radiance), m.pdf(wo, wi));
                assert!(
                    f.is_finite() && p.is_finite() && p > 0.0,
                    "{distribution:?} alpha {alpha} z {z}"
                );
            }
        }
    }
}

#[test]
fn dielectric_grazing_is_finite() {
    for ior in [1.5f32, 1.0 / 1.5] {
        for z in [0.0f32, -0.0, 1e-30, -1e-30, 1e-7, -1e-7, 1e-3, -1e-3] {
            let r = (1.0 - z * z).sqrt();
            let wo = Vec3::new(r, 0.0, z);
            for u in [0.0f32, 0.5, 0.999_999, 1.0 - f32::EPSILON / 2.0] {
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let s = dielectric::sample(ior, wo, u, mode);
                    let w = s.value * s.wi.z.abs() / s.pdf;
                    assert!(
                        s.wi.is_finite() && s.value.is_finite(),
                        "z {z} u {u}: {s:?}"
                    );
                    assert!(s.pdf > 0.0 && s.pdf <= 1.0 && w.is_finite(), "z {z}: {s:?}");
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Lane forms

/// The bits of a number, NaN as one value (the film counts any NaN alike).
fn bits(x: f32) -> u32 {
    if x.is_nan() { u32::MAX } else { x.to_bits() }
}

fn bits3(v: Vec3) -> [u32; 3] {
    [bits(v.x), bits(v.y), bits(v.z)]
}

/// `B::sample_lanes` and `B::eval_pdf_lanes` over `N` lanes holding `materials` (cycled, so
/// neighbouring lanes differ) give, lane by lane, the bits of `sample` and `eval_pdf` for one
/// path: directions above, below and grazing the surface, numbers across [0, 1).
fn assert_lane_form_is_one_path<B: Bsdf + std::fmt::Debug, const N: usize>(
    materials: &[B],
    stream: u64,
) {
    use stagelight::lanes::{F, Mask, V3};
    let lanes: [B; N] = std::array::from_fn(|l| materials[l % materials.len()]);
    let direction = |i: u64| {
        let u = u2(91, stream, i);
        // Cosines across [-1, 1], a few within 1e-4 of grazing.
        let z = if i.is_multiple_of(7) {
            (u.x - 0.5) * 2e-4
        } else {
            2.0 * u.x - 1.0
        };
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * std::f32::consts::PI * u.y;
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    for trial in 0..400u64 {
        let wo: [Vec3; N] = std::array::from_fn(|l| direction(trial * 64 + l as u64));
        let wi: [Vec3; N] = std::array::from_fn(|l| direction(trial * 64 + 32 + l as u64));
        let u: [Vec2; N] = std::array::from_fn(|l| u2(92, stream, trial * 64 + l as u64));
        let wo_lanes = V3::<F<N>>::from_fn(|l| wo[l]);
        let sampled = B::sample_lanes(
            &lanes,
            wo_lanes,
            F::from_fn(|l| u[l].x),
            F::from_fn(|l| u[l].y),
        );
        let (f, pdf) = B::eval_pdf_lanes(&lanes, wo_lanes, V3::from_fn(|l| wi[l]));
        for l in 0..N {
            let what = format!("{:?} lane {l} of {N}, wo {} u {}", lanes[l], wo[l], u[l]);
            match lanes[l].sample(wo[l], u[l], TransportMode::Radiance) {
                Some(s) => {
                    assert!(sampled.valid.lane(l), "{what}: lanes drew no sample");
                    assert_eq!(bits3(sampled.wi.lane(l)), bits3(s.wi), "{what}");
                    assert_eq!(bits3(sampled.value.lane(l)), bits3(s.value), "{what}");
                    assert_eq!(bits(sampled.pdf.0[l]), bits(s.pdf), "{what}");
                    assert!(!s.delta, "{what}");
                }
                None => assert!(!sampled.valid.lane(l), "{what}: lanes drew a sample"),
            }
            let (f1, pdf1) = lanes[l].eval_pdf(wo[l], wi[l], TransportMode::Radiance);
            assert_eq!(bits3(f.lane(l)), bits3(f1), "{what} wi {}", wi[l]);
            assert_eq!(bits(pdf.0[l]), bits(pdf1), "{what} wi {}", wi[l]);
            assert_eq!(
                bits3(f1),
                bits3(lanes[l].eval(wo[l], wi[l], TransportMode::Radiance)),
                "{what}"
            );
            assert_eq!(bits(pdf1), bits(lanes[l].pdf(wo[l], wi[l])), "{what}");
        }
    }
}

/// Each material with a lane form (`Bsdf::IN_LANES`) samples and evaluates in lanes exactly as
/// for one path, in lanes that mix its parameters (GGX and Beckmann, roughnesses from 1e-4 to
/// 1, anisotropic axes, Fresnel indices, linear and nonlinear bases) and in lanes that share
/// them, at both widths: the wavefront's lanes then render the megakernel's image (which
/// `kernels.rs` checks on whole scenes).
#[test]
fn lane_forms_compute_the_one_path_bits() {
    let diffuse: Vec<Diffuse> = [0.0, 0.3, 0.9]
        .iter()
        .map(|&r| Diffuse {
            reflectance: Vec3::new(r, 0.5, 0.25),
        })
        .collect();
    let mut conductors: Vec<Conductor> = Vec::new();
    for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
        for alpha in [1e-4, 0.05, 0.3, 1.0] {
            let Material::Conductor(c) = conductor_of(distribution, alpha) else {
                unreachable!()
            };
            conductors.push(c);
        }
    }
    for m in anisotropic_conductors() {
        let Material::Conductor(c) = m else {
            unreachable!()
        };
        conductors.push(c);
    }
    let mut plastics: Vec<RoughPlastic> = Vec::new();
    for (distribution, alpha, nonlinear) in [
        (Microfacet::Ggx, 0.1, false),
        (Microfacet::Beckmann, 0.1, true),
        (Microfacet::Ggx, 0.6, true),
        (Microfacet::Beckmann, 0.02, false),
    ] {
        let diffuse = Vec3::new(0.8, 0.4, 0.1);
        plastics.push(RoughPlastic::new(
            distribution,
            alpha,
            1.49,
            diffuse,
            diffuse.element_sum() / 3.0,
            Vec3::new(1.0, 0.9, 0.8),
            nonlinear,
        ));
    }
    const { assert!(Diffuse::IN_LANES && Conductor::IN_LANES && RoughPlastic::IN_LANES) };
    assert_lane_form_is_one_path::<Diffuse, 8>(&diffuse, 1);
    assert_lane_form_is_one_path::<Diffuse, 16>(&diffuse, 2);
    assert_lane_form_is_one_path::<Conductor, 8>(&conductors, 3);
    assert_lane_form_is_one_path::<Conductor, 16>(&conductors, 4);
    assert_lane_form_is_one_path::<RoughPlastic, 8>(&plastics, 5);
    assert_lane_form_is_one_path::<RoughPlastic, 16>(&plastics, 6);
    // Lanes that share one material take the branches a single path takes.
    for (i, c) in conductors.iter().enumerate() {
        assert_lane_form_is_one_path::<Conductor, 8>(&[*c], 10 + i as u64);
    }
    for (i, p) in plastics.iter().enumerate() {
        assert_lane_form_is_one_path::<RoughPlastic, 16>(&[*p], 40 + i as u64);
    }
}
