//! Rough dielectric (Mitsuba's `roughdielectric`): its values against Mitsuba's, the sampling
//! of both lobes against its pdf by chi-square on both hemispheres, eval / pdf equal to the
//! sample's weight, the adjoint (importance) BSDF as the transpose of the radiance one, the
//! albedo from sampling against quadrature, and the hard cases.

use super::*;
use stagelight::bsdf::rough_dielectric::RoughDielectric;

fn rough_glass(distribution: Microfacet, alpha: f32, eta: f32) -> Material {
    Material::RoughDielectric(RoughDielectric::isotropic(distribution, alpha, eta))
}

/// An anisotropic interface with its axis 33 degrees off the frame's.
fn anisotropic_glass(distribution: Microfacet, alpha_u: f32, alpha_v: f32) -> Material {
    let mut d = RoughDielectric::isotropic(distribution, alpha_u, 1.5);
    d.alpha_v = alpha_v;
    let a = 33f32.to_radians();
    d.axis = Vec2::new(a.cos(), a.sin());
    Material::RoughDielectric(d)
}

/// The refracted direction of `wo` through the macro-surface, or the mirror one under total
/// internal reflection.
fn macro_refraction(wo: Vec3, eta: f32) -> Vec3 {
    let eta = if wo.z > 0.0 { eta } else { 1.0 / eta };
    let sin2 = (wo.x * wo.x + wo.y * wo.y) / (eta * eta);
    if sin2 >= 1.0 {
        return Vec3::new(-wo.x, -wo.y, wo.z);
    }
    let cos_t = (1.0 - sin2).sqrt();
    Vec3::new(-wo.x / eta, -wo.y / eta, -cos_t * wo.z.signum()).normalize()
}

/// Both lobes against the pdf: one binning per hemisphere, centred on the mirror and the
/// refracted direction.
fn chi2_rough_glass(m: Material, alpha: f32, thetas: &[f64], stream0: u64) {
    let eta = match m {
        Material::RoughDielectric(d) => d.eta,
        _ => unreachable!(),
    };
    for (i, &theta) in thetas.iter().enumerate() {
        let wo = dir_deg(theta, 10.0 + 97.0 * i as f64);
        let side = wo.z.signum() as f64;
        let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
        let width = Some(3.0 * alpha as f64);
        let reflected = Binning::new(side, mirror, width);
        let refracted = Binning::new(-side, macro_refraction(wo, eta), width);
        // The directions sampled do not depend on the transport mode (only their values).
        let mode = TransportMode::Radiance;
        let r = chi2_test_over(
            &[&reflected, &refracted],
            stream0 + i as u64,
            &|u| m.sample(wo, u, mode).map(|s| s.wi),
            &|wi| m.pdf(wo, wi),
        );
        println!(
            "rough glass {m:?} wo theta {theta} {mode:?}: chi2 {:.1} dof {} p {:.4} integral {:.6}",
            r.chi2, r.dof, r.p_value, r.total_probability
        );
        assert!(r.total_probability <= 1.0 + 1e-4, "{}", r.total_probability);
        assert!(r.dof >= 100, "too few populated cells ({})", r.dof);
        assert!(
            r.p_value > sidak_alpha(),
            "{m:?} theta {theta}: chi2 {} dof {} p = {}",
            r.chi2,
            r.dof,
            r.p_value
        );
    }
}

#[test]
fn chi2_rough_dielectric() {
    // From outside and from inside (past the macro-surface's critical angle too: 138 degrees
    // for index 1.5), narrow to wide lobes.
    chi2_rough_glass(
        rough_glass(Microfacet::Beckmann, 0.05, 1.5),
        0.05,
        &[20.0, 70.0, 160.0, 125.0],
        500,
    );
    chi2_rough_glass(
        rough_glass(Microfacet::Ggx, 0.3, 1.5),
        0.3,
        &[0.0, 85.0, 150.0, 100.0],
        510,
    );
    chi2_rough_glass(
        rough_glass(Microfacet::Beckmann, 0.8, 1.33),
        0.8,
        &[45.0, 135.0],
        520,
    );
    chi2_rough_glass(
        anisotropic_glass(Microfacet::Ggx, 0.1, 0.4),
        0.4,
        &[50.0, 140.0],
        530,
    );
}

/// f (over the cosine) against Mitsuba 3.9.1's `roughdielectric` (scalar_rgb, `BSDF::eval`
/// in both transport modes, ext_ior 1, si.wi our wo): reflection and refraction from both
/// sides. Mitsuba samples its lobes in proportion to F(wo.m) and stagelight by the
/// macro-surface's F (see the module's comment), so only f is compared; the pdf is checked
/// against sampling by the chi-square test. Beckmann within Mitsuba's G1 approximation.
#[test]
fn rough_dielectric_matches_mitsuba_eval() {
    type Pair = ((f64, f64), (f64, f64), f32, f32);
    let cases: [(Microfacet, f32, f32, f32, &[Pair]); 2] = [
        (
            Microfacet::Beckmann,
            0.2,
            1.5,
            8e-3,
            &[
                ((30.0, 10.0), (40.0, 200.0), 0.099_372_29, 0.099_372_29),
                ((30.0, 10.0), (160.0, 170.0), 1.869_364, 4.206_068),
                ((60.0, 45.0), (150.0, 200.0), 0.027_719_18, 0.062_368_15),
                ((150.0, 30.0), (120.0, 250.0), 0.070_447_22, 0.070_447_22),
                ((10.0, 0.0), (170.0, 180.0), 15.397_28, 34.643_88),
                ((170.0, 0.0), (5.0, 120.0), 0.270_640_2, 0.120_284_5),
            ],
        ),
        (
            Microfacet::Ggx,
            0.35,
            1.33,
            2e-4,
            &[
                ((30.0, 10.0), (40.0, 200.0), 0.018_031_8, 0.018_031_8),
                ((30.0, 10.0), (160.0, 170.0), 2.142_057, 3.789_084),
                ((60.0, 45.0), (150.0, 200.0), 0.055_401_71, 0.098_000_08),
                ((150.0, 30.0), (120.0, 250.0), 0.023_145_76, 0.023_145_76),
                ((150.0, 30.0), (20.0, 200.0), 0.637_825_7, 0.360_577_6),
                ((10.0, 0.0), (170.0, 180.0), 16.273_87, 28.786_85),
                ((170.0, 0.0), (5.0, 120.0), 2.643_824, 1.494_615),
            ],
        ),
    ];
    for (distribution, alpha, eta, tolerance, pairs) in cases {
        let m = rough_glass(distribution, alpha, eta);
        for &(wo, wi, radiance, importance) in pairs {
            let (wo, wi) = (dir_deg(wo.0, wo.1), dir_deg(wi.0, wi.1));
            for (mode, theirs) in [
                (TransportMode::Radiance, radiance),
                (TransportMode::Importance, importance),
            ] {
                let ours = m.eval_mode(wo, wi, mode);
                assert!(
                    rel_close(ours.x, theirs, tolerance) && ours.x == ours.z,
                    "{m:?} wo {wo} wi {wi} {mode:?}: f {ours}, Mitsuba's {theirs}"
                );
            }
        }
        // A pair whose half-vector one direction sees from behind: zero in both.
        let (wo, wi) = (dir_deg(100.0, 0.0), dir_deg(60.0, 180.0));
        assert_eq!(m.eval(wo, wi), Vec3::ZERO);
    }
    // Anisotropic GGX (alpha_u 0.1 along the frame's first tangent, alpha_v 0.4), radiance.
    let mut d = RoughDielectric::isotropic(Microfacet::Ggx, 0.1, 1.5);
    d.alpha_v = 0.4;
    let m = Material::RoughDielectric(d);
    for (wo, wi, theirs) in [
        ((30.0, 10.0), (40.0, 200.0), 0.057_548_78),
        ((30.0, 80.0), (40.0, 280.0), 0.020_245_87),
        ((30.0, 10.0), (160.0, 170.0), 8.874_216),
        ((30.0, 80.0), (160.0, 260.0), 25.678_17),
        ((150.0, 30.0), (20.0, 200.0), 0.040_187_37),
        ((150.0, 100.0), (20.0, 290.0), 3.331_498),
    ] {
        let (wo, wi) = (dir_deg(wo.0, wo.1), dir_deg(wi.0, wi.1));
        let ours = m.eval(wo, wi).x;
        assert!(
            rel_close(ours, theirs, 2e-4),
            "anisotropic wo {wo} wi {wi}: f {ours}, Mitsuba's {theirs}"
        );
    }
    {
        let (wo, wi) = (dir_deg(100.0, 0.0), dir_deg(60.0, 180.0));
        assert_eq!(m.eval(wo, wi), Vec3::ZERO);
    }
}

/// The BSDF that importance sees is the transpose of radiance's: f*(wo, wi) = f(wi, wo)
/// (Veach's adjoint; refraction's 1/eta^2 goes with radiance only), on random pairs from both
/// sides, so a light path through rough glass carries what a camera path would.
#[test]
fn rough_dielectric_adjoint_is_transpose() {
    let materials = [
        rough_glass(Microfacet::Ggx, 0.2, 1.5),
        rough_glass(Microfacet::Beckmann, 0.6, 2.4),
        anisotropic_glass(Microfacet::Beckmann, 0.05, 0.3),
    ];
    let mut checked = 0;
    for (k, m) in materials.iter().enumerate() {
        for i in 0..20_000u64 {
            let u = u2(11, k as u64, i);
            let v = u2(12, k as u64, i);
            let sphere = |u: Vec2| {
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * std::f32::consts::PI * u.y;
                Vec3::new(r * phi.cos(), r * phi.sin(), z)
            };
            let (wo, wi) = (sphere(u), sphere(v));
            let forward = m.eval_mode(wo, wi, TransportMode::Importance);
            let backward = m.eval_mode(wi, wo, TransportMode::Radiance);
            for c in 0..3 {
                // A wrong eta^2 would be off by 125%.
                assert!(
                    rel_close(forward[c], backward[c], 2e-4)
                        || (forward[c] - backward[c]).abs() < 1e-6,
                    "{m:?} wo {wo} wi {wi}: importance {forward} radiance transposed {backward}"
                );
            }
            checked += usize::from(forward != Vec3::ZERO);
        }
    }
    assert!(checked > 20_000, "too few nonzero pairs: {checked}");
}

/// The albedo sum of f |cos| / pdf over samples equals the quadrature of f |cos| over the
/// sphere, from both sides and in both modes; without the 1/eta^2 of radiance (importance)
/// a smooth-ish interface conserves nearly all the energy.
#[test]
fn rough_dielectric_albedo() {
    for (m, alpha) in [
        (rough_glass(Microfacet::Ggx, 0.1, 1.5), 0.1),
        (rough_glass(Microfacet::Beckmann, 0.5, 1.5), 0.5),
        (rough_glass(Microfacet::Ggx, 1.0, 1.33), 1.0),
    ] {
        for theta in [0.0, 60.0, 85.0, 130.0, 175.0] {
            let wo = dir_deg(theta, 25.0);
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                let n = 400_000u64;
                let (mut sum, mut sum2) = (0.0f64, 0.0f64);
                for i in 0..n {
                    if let Some(s) = m.sample(wo, u2(13, (theta * 10.0) as u64, i), mode) {
                        let w = (s.value.x * s.wi.z.abs() / s.pdf) as f64;
                        sum += w;
                        sum2 += w * w;
                    }
                }
                let mean = sum / n as f64;
                let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
                // Quadrature over both hemispheres, bins following the two lobes.
                let width = Some(3.0 * alpha);
                let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
                let side = wo.z.signum() as f64;
                let Material::RoughDielectric(d) = m else {
                    unreachable!()
                };
                let eta = d.eta;
                let mut quadrature = 0.0;
                for b in [
                    Binning::new(side, mirror, width),
                    Binning::new(-side, macro_refraction(wo, eta), width),
                ] {
                    let f = |wi: Vec3| m.eval_mode(wo, wi, mode).x * wi.z.abs();
                    quadrature += b.integrate(&f).iter().sum::<f64>();
                }
                println!(
                    "{m:?} theta {theta} {mode:?}: sampled {mean:.5} +- {se:.5}, quadrature {quadrature:.5}"
                );
                assert!(
                    (mean - quadrature).abs() <= 4.0 * se + 2e-3 * quadrature,
                    "{m:?} theta {theta} {mode:?}: sampled {mean} +- {se}, quadrature {quadrature}"
                );
                if mode == TransportMode::Importance {
                    assert!(quadrature <= 1.0 + 1e-3, "gains energy: {quadrature}");
                }
            }
        }
    }
}

#[test]
fn rough_dielectric_sample_matches_eval_and_pdf() {
    let mut materials = Vec::new();
    for alpha in [1e-4, 1e-3, 0.01, 0.1, 0.5, 1.0] {
        for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
            materials.push(rough_glass(distribution, alpha, 1.5));
        }
    }
    materials.push(anisotropic_glass(Microfacet::Ggx, 0.02, 0.5));
    for (mi, m) in materials.iter().enumerate() {
        for (wi_idx, &wo0) in test_wos().iter().enumerate() {
            for side in [1.0f32, -1.0] {
                let wo = Vec3::new(wo0.x, wo0.y, wo0.z * side);
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let mut accepted = 0;
                    for i in 0..2000 {
                        let u = u2(17, (mi * 100 + wi_idx) as u64, i);
                        let Some(s) = m.sample(wo, u, mode) else {
                            continue;
                        };
                        accepted += 1;
                        assert!(!s.delta);
                        assert!((s.wi.length() - 1.0).abs() < 1e-5);
                        let (f, p) = (m.eval_mode(wo, s.wi, mode), m.pdf(wo, s.wi));
                        assert!(
                            rel_close(s.value.x, f.x, 1e-5) && rel_close(s.pdf, p, 1e-5),
                            "{m:?} wo {wo} wi {}: sample ({}, {}) eval ({f}, {p})",
                            s.wi,
                            s.value,
                            s.pdf
                        );
                    }
                    assert!(accepted > 0, "{m:?} wo {wo}: no sample accepted");
                }
            }
        }
    }
}

/// Alpha from 1e-4 to 1e4, directions within 1e-30 of grazing, indices 1.0001 and 4: finite,
/// non-negative values and weights.
#[test]
fn rough_dielectric_stability() {
    for eta in [1.0001f32, 1.5, 4.0, 1.0 / 1.5] {
        for alpha in [0.0f32, 1e-4, 1e-2, 0.3, 1.0, 1e4] {
            for distribution in [Microfacet::Ggx, Microfacet::Beckmann] {
                check_material_finite(rough_glass(distribution, alpha, eta));
            }
        }
    }
    check_material_finite(anisotropic_glass(Microfacet::Beckmann, 1e-4, 1.0));
}
