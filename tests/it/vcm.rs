//! Vertex connection and merging (`vcm`, `bpm`): its MIS weights sum to one over every
//! connection and merge of a path and equal the weights found by brute force from each
//! technique's full path density, and the constant-time weights from the subpaths' tails
//! equal the ratio walk's; its connections alone under its weights are BDPT's
//! estimator; the furnace gives 2; the image does not depend on the thread count; on a scene
//! of our own with glass and a mirror, every block agrees with PT's.

use crate::bdpt::{assert_agree, halves_over_seeds, split};
use crate::common::{load_small, mean_over_seeds};
use crate::common::{render_bdpt, shrunk_scene, stagelight_command, stderr, temp_dir};
use stagelight::integrators::SceneData;
use stagelight::integrators::bdpt::{self, BdptSettings, StrategyFilter, VertexMerging};
use stagelight::mlt::path_space::PathSpace;
use stagelight::path::{MisHeuristic, PathContext, Techniques, Vertex, VertexKind, towards};
use stagelight::weight_tails::{MergedLight, Side, weight_tails};
use std::sync::Arc;

/// `0 -> 1`, as the ratio walk reads a delta neighbour's zero density.
fn remap0(x: f64) -> f64 {
    if x != 0.0 { x } else { 1.0 }
}

/// Each technique's weight by brute force: the path x_0 (on the emitter) .. x_{n-1} (the
/// camera), each vertex's light-side and camera-side area densities recomputed from its
/// neighbours by path-space MLT's `PathSpace::density` (its own formulation: a specular
/// vertex's density is its Fresnel lobe's probability, converted to area like any other), each
/// technique's density the product over the path (in f64), and the weight h(p) over the sum
/// of h over the techniques the estimator uses. Returns the weights of the connections (by s)
/// and of the merges (by the merged vertex's index, 0 where none).
fn brute_force_weights(
    data: &SceneData,
    camera_first: &[Vertex],
    heuristic: MisHeuristic,
    techniques: Techniques,
) -> (Vec<f64>, Vec<f64>) {
    let space = PathSpace::new(data);
    let ctx = &space.ctx;
    let n = camera_first.len();
    let (_, light_all) = split(ctx, camera_first, 1); // x_0 .. x_{n-2}, light side
    let mut x: Vec<Vertex> = light_all.clone();
    x.push(camera_first[0]);
    PathSpace::fix_kinds(&mut x);
    let delta =
        |i: usize| i + 1 < n && x[i].kind == VertexKind::Surface && !ctx.is_connectible(&x[i]);
    // Light-side density of x_i (i <= n - 2) and camera-side density of x_i (i <= n - 2).
    let p_light: Vec<f64> = (0..n - 1)
        .map(|i| space.density(&x, i.checked_sub(1), i) as f64)
        .collect();
    let p_camera: Vec<f64> = (0..n - 1)
        .map(|i| space.density(&x, Some(i + 1), i) as f64)
        .collect();
    let vc = |s: usize| -> f64 {
        (0..s).map(|i| remap0(p_light[i])).product::<f64>()
            * (s..n - 1).map(|i| remap0(p_camera[i])).product::<f64>()
    };
    let h = |p: f64| match heuristic {
        MisHeuristic::Power => p * p,
        MisHeuristic::Balance => p,
    };
    let eta = techniques.merge_count as f64;
    let mut connections = vec![0.0; n];
    for (s, c) in connections.iter_mut().enumerate() {
        let t = n - s;
        let joint_ok = s == 0 || (!delta(s - 1) && (t == 1 || !delta(s)));
        if t >= 1 && joint_ok && (s == 0 || techniques.connect) {
            *c = h(vc(s));
        }
    }
    let mut merges = vec![0.0; n];
    if eta > 0.0 {
        for (i, m) in merges.iter_mut().enumerate().take(n - 1).skip(1) {
            if !delta(i) {
                *m = h(vc(i) * remap0(p_light[i]) * eta);
            }
        }
    }
    let total: f64 = connections.iter().sum::<f64>() + merges.iter().sum::<f64>();
    (
        connections.iter().map(|c| c / total).collect(),
        merges.iter().map(|m| m / total).collect(),
    )
}

fn check_vcm_weights(scene_name: &str) {
    check_vcm_weights_of(scene_name, load_small(scene_name, 32), true);
}

/// `check_vcm_weights` of a prepared scene; without `brute_force`, the weights from tails
/// against the walk and their sum only (path-space MLT's densities, which the brute force
/// reads, know no light at infinity).
fn check_vcm_weights_of(
    scene_name: &str,
    scene: stagelight::scene::PreparedScene,
    brute_force: bool,
) {
    let data = Arc::new(SceneData::new(scene));
    let ctx = PathContext::new(&data.scene);
    // Small lights are rarely hit by camera subpaths: more samples there.
    let samples = match scene_name {
        "cornell_box.ron" | "furnace.ron" => 1 << 14,
        "door_ajar.ron" => 1 << 17,
        // Most camera subpaths end on the sky.
        "envmap.xml" => 1 << 11,
        _ => 1 << 16,
    };
    let subpaths = bdpt::trace_subpaths(data.clone(), BdptSettings::new(7, u32::MAX), 0, samples);
    let s = &data.scene;
    let diagonal = (s.bounds_max - s.bounds_min).length();
    let (mut checked, mut merges_checked, mut caustic_merges) = (0, 0, 0);
    let (mut camera_tails, mut light_tails) = (Vec::new(), Vec::new());
    let mut fast_checked = 0;
    for (camera, _) in &subpaths {
        for k in 1..camera.len() {
            let z = &camera[k];
            let wo = (camera[k - 1].p - z.p).normalize();
            if ctx.emitted(z, wo) == glam::Vec3::ZERO {
                continue;
            }
            let full = &camera[..=k];
            let n = full.len();
            // As in BDPT's test: paths whose recomputed densities rounding moves too far.
            let ill_conditioned = full.windows(2).skip(1).any(|w| {
                let d = w[1].p - w[0].p;
                let dir = d.normalize();
                let cos = w[0].ng.dot(dir).abs().min(w[1].ng.dot(dir).abs());
                (w[0].p_error + w[1].p_error).length() > 1e-4 * d.length() * cos
            });
            if ill_conditioned {
                continue;
            }
            for heuristic in [MisHeuristic::Power, MisHeuristic::Balance] {
                for scale in [1e-3f32, 1.0, 1e3] {
                    // pi r^2 N for r 1% of the diagonal and N 10^4 light subpaths, scaled.
                    let eta = std::f32::consts::PI * (0.01 * diagonal).powi(2) * 1e4 * scale;
                    for techniques in [
                        Techniques {
                            merge_count: eta,
                            ..Techniques::CONNECTIONS
                        },
                        Techniques {
                            connect: false,
                            merge_count: eta,
                            ..Techniques::CONNECTIONS
                        },
                        Techniques::CONNECTIONS,
                    ] {
                        let (want_vc, want_vm) = if brute_force {
                            brute_force_weights(&data, full, heuristic, techniques)
                        } else {
                            (Vec::new(), Vec::new())
                        };
                        let mut sum = 0.0f64;
                        for t in 1..=n {
                            let s = n - t;
                            let (cam, light) = split(&ctx, full, t);
                            let joint_ok = (s == 0 || ctx.is_connectible(&light[s - 1]))
                                && (t == 1 || s == 0 || ctx.is_connectible(&cam[t - 1]));
                            if !joint_ok || (s >= 1 && !techniques.connect) {
                                continue;
                            }
                            let w =
                                ctx.vcm_weight(&cam, &light, (s, t), None, heuristic, techniques)
                                    as f64;
                            weight_tails(&cam, Side::Camera, heuristic, &mut camera_tails);
                            weight_tails(&light, Side::Light, heuristic, &mut light_tails);
                            let fast = ctx.connection_weight_from_tails(
                                (&cam, &camera_tails),
                                (&light, &light_tails),
                                (s, t),
                                heuristic,
                                techniques,
                            ) as f64;
                            assert!(
                                (fast - w).abs() <= 1e-4 * w + 1e-6,
                                "{scene_name} {heuristic:?} {techniques:?}: connection ({s},{t}) \
                                 of a {n}-vertex path weighs {fast} from tails, {w} by the walk"
                            );
                            fast_checked += 1;
                            assert!(
                                !brute_force || (w - want_vc[s]).abs() < 2e-3,
                                "{scene_name} {heuristic:?} {techniques:?}: connection ({s},{t}) \
                                 of a {n}-vertex path weighs {w}, brute force {}",
                                want_vc[s]
                            );
                            sum += w;
                        }
                        if techniques.merge_count > 0.0 {
                            // Merge at camera vertex z_{t-1} = x_s with the light subpath
                            // y_0..y_s (y_s = x_s).
                            for t in 2..n {
                                let s = n - t;
                                let (cam, _) = split(&ctx, full, t);
                                let (_, light) = split(&ctx, full, t - 1);
                                let merged = light[s];
                                if !ctx.is_connectible(&merged) {
                                    continue;
                                }
                                let w = ctx.vcm_weight(
                                    &cam,
                                    &light[..s],
                                    (s, t),
                                    Some(&merged),
                                    heuristic,
                                    techniques,
                                ) as f64;
                                weight_tails(&cam, Side::Camera, heuristic, &mut camera_tails);
                                weight_tails(&light, Side::Light, heuristic, &mut light_tails);
                                let merged_light = MergedLight::new(&light[..=s], &light_tails);
                                let fast = ctx.merge_weight_from_tails(
                                    (&cam, &camera_tails),
                                    t,
                                    &merged_light,
                                    towards(&merged, &light[s - 1]),
                                    heuristic,
                                    techniques,
                                ) as f64;
                                assert!(
                                    (fast - w).abs() <= 1e-4 * w + 1e-6,
                                    "{scene_name} {heuristic:?} {techniques:?}: merge at x_{s} \
                                     of a {n}-vertex path weighs {fast} from tails, {w} by the \
                                     walk"
                                );
                                fast_checked += 1;
                                assert!(
                                    !brute_force || (w - want_vm[s]).abs() < 2e-3,
                                    "{scene_name} {heuristic:?} {techniques:?}: merge at x_{s} \
                                     of a {n}-vertex path weighs {w}, brute force {}",
                                    want_vm[s]
                                );
                                sum += w;
                                merges_checked += 1;
                                if light[s - 1].delta {
                                    caustic_merges += 1;
                                }
                            }
                        }
                        assert!(
                            (sum - 1.0).abs() < 1e-3,
                            "{scene_name} {heuristic:?} {techniques:?}: weights of a {n}-vertex \
                             path sum to {sum}"
                        );
                    }
                }
            }
            checked += 1;
        }
    }
    assert!(
        checked > 30,
        "{scene_name}: only {checked} paths reached a light"
    );
    assert!(
        fast_checked > 100,
        "{scene_name}: only {fast_checked} weights from tails"
    );
    assert!(
        merges_checked > 100,
        "{scene_name}: only {merges_checked} merges"
    );
    if scene_name == "torus_glass.ron" {
        assert!(
            caustic_merges > 10,
            "only {caustic_merges} merges after glass"
        );
    }
}

/// Paths that end on a light at infinity (an environment map): every technique of VCM and
/// BDPT, light sampling the sky and light subpaths from its disk included, weighs them so
/// that the weights sum to one, and the constant-time weights equal the walk's.
#[test]
fn vcm_weights_sum_to_one_with_a_light_at_infinity() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/scenes/mitsuba/envmap.xml");
    let text = std::fs::read_to_string(&path).unwrap();
    let scene = stagelight::scene::load_mitsuba_from_str(
        &path,
        &text,
        &[],
        &stagelight::scene::Limits::of_this_machine(),
    )
    .unwrap()
    .0;
    check_vcm_weights_of("envmap.xml", scene, false);
}

#[test]
fn vcm_weights_sum_to_one_and_match_brute_force_in_every_scene() {
    for scene in [
        "cornell_box.ron",
        "torus_glass.ron",
        "door_ajar.ron",
        "furnace.ron",
    ] {
        check_vcm_weights(scene);
    }
}

fn merging(connect: bool, merge: bool, radius: f32) -> Option<VertexMerging> {
    Some(VertexMerging {
        radius,
        alpha: bdpt::DEFAULT_MERGE_ALPHA,
        connect,
        merge,
    })
}

#[test]
fn connections_alone_under_vcm_weights_agree_with_bdpt_per_half() {
    let scene = load_small("cornell_box.ron", 24);
    let bd = halves_over_seeds(
        |seed| {
            render_bdpt(scene.clone(), 4, BdptSettings::new(seed, u32::MAX))
                .0
                .film
                .image()
        },
        8,
    );
    let vc = halves_over_seeds(
        |seed| {
            let settings = BdptSettings {
                merging: merging(true, false, 0.01),
                ..BdptSettings::new(100 + seed, u32::MAX)
            };
            render_bdpt(scene.clone(), 4, settings).0.film.image()
        },
        8,
    );
    for (i, name) in ["upper", "lower"].iter().enumerate() {
        assert_agree(
            &format!("vcm connections vs bdpt, {name} half"),
            vc[i],
            bd[i],
            4.5,
        );
    }
}

#[test]
fn the_furnace_gives_two_with_vcm_and_bpm() {
    let scene = load_small("furnace.ron", 16);
    for connect in [true, false] {
        let (mean, se) = mean_over_seeds(
            |seed| {
                let settings = BdptSettings {
                    merging: merging(connect, true, 0.1),
                    ..BdptSettings::new(seed, u32::MAX)
                };
                render_bdpt(scene.clone(), 4, settings).0.film.image()
            },
            8,
        );
        for c in 0..3 {
            assert!(
                (mean[c] - 2.0).abs() <= 5.0 * se[c].max(1e-4) && se[c] < 0.02,
                "connect {connect}: {mean:?} +- {se:?}"
            );
        }
    }
}

#[test]
fn vcm_and_bpm_agree_with_bdpt_on_the_cornell_box_per_half() {
    let scene = load_small("cornell_box.ron", 24);
    let bd = halves_over_seeds(
        |seed| {
            render_bdpt(scene.clone(), 4, BdptSettings::new(seed, u32::MAX))
                .0
                .film
                .image()
        },
        8,
    );
    let data = SceneData::new(scene.clone());
    // A radius of half a pixel footprint at 24 x 24 (the default, 1.5 footprints, is a tenth
    // of the box there: its edge bias is not what this tests; a kernel 1.2 times too high is
    // still 5.1 standard errors off).
    let mut render = stagelight::integrators::RenderSettings::default();
    render.photons.radius = Some(15.0);
    for (name, connect) in [("vcm", true), ("bpm", false)] {
        let settings = bdpt::vcm_settings(&data, &render, connect, true);
        let halves = halves_over_seeds(
            |seed| {
                let s = BdptSettings {
                    seed: 300 + seed,
                    ..settings
                };
                render_bdpt(scene.clone(), 4, s).0.film.image()
            },
            8,
        );
        for (i, half) in ["upper", "lower"].iter().enumerate() {
            assert_agree(
                &format!("{name} vs bdpt, {half} half"),
                halves[i],
                bd[i],
                4.5,
            );
        }
    }
}

#[test]
fn vcm_image_is_bit_identical_for_one_and_two_threads() {
    let dir = temp_dir("vcm_threads");
    let scene = shrunk_scene("door_ajar", 48, &dir.join("door_ajar.ron"));
    let files: Vec<Vec<u8>> = [1, 2]
        .iter()
        .map(|&threads| {
            let out = dir.join(format!("t{threads}.exr"));
            let o = stagelight_command()
                .args(["render", "--integrator", "vcm", "--spp", "4", "--quiet"])
                .args(["--seed", "5", "--threads", &threads.to_string()])
                .arg(&scene)
                .arg("-o")
                .arg(&out)
                .output()
                .expect("stagelight runs");
            assert!(o.status.success(), "{}", stderr(&o));
            std::fs::read(&out).expect("EXR written")
        })
        .collect();
    assert!(files[0] == files[1], "vcm: 1 and 2 threads differ");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The merge and gather radii come from what the camera sees: door_ajar with its floor
/// stretched to 1e10 (a bounding box over 1e9 times door_ajar's) gets door_ajar's radii within 10
/// percent, for PPM, SPPM and VCM, at most six pixel footprints.
#[test]
fn merge_radii_follow_the_pixel_footprint_not_the_scene_bounds() {
    use stagelight::components::photon_mapping::{ProgressiveSettings, pixel_footprint};
    let door = SceneData::new(load_small("door_ajar.ron", 64));
    let mut stretched = crate::common::load_test_scene("stretched_wall.ron");
    let (w, h) = (64, 64);
    stretched.camera.resize(w, h);
    let stretched = SceneData::new(stretched);
    let size = |d: &SceneData| (d.scene.bounds_max - d.scene.bounds_min).length();
    assert!(size(&stretched) > 1e9 * size(&door));
    let (a, b) = (
        pixel_footprint(&door).unwrap(),
        pixel_footprint(&stretched).unwrap(),
    );
    // The stretched floor is seen where door_ajar's was: the same footprint, nearly.
    assert!((b / a - 1.0).abs() < 0.1, "footprints {a} and {b}");
    for stochastic in [false, true] {
        let p = ProgressiveSettings::new(0, stochastic);
        let (ra, rb) = (p.radius_in(&door), p.radius_in(&stretched));
        assert!(
            (rb / ra - 1.0).abs() < 0.1,
            "{stochastic}: radii {ra} and {rb}"
        );
        assert!(rb <= 6.0 * b, "{stochastic}: radius {rb}, footprint {b}");
    }
    let render = stagelight::integrators::RenderSettings::default();
    let radius = |d: &SceneData| {
        bdpt::vcm_settings(d, &render, true, true)
            .merging
            .unwrap()
            .radius
    };
    assert!((radius(&stretched) / radius(&door) - 1.0).abs() < 0.1);
}

/// Merges alone, unweighted, converge to what BDPT's strategies make of the same paths: the
/// merges (s, t) (light subpath y_0..y_s, y_s merged with camera vertex z_{t-1}) of paths of
/// one depth against BDPT's strategy (s, t) alone, per image half (a small radius: the kernel's
/// bias stays under the noise).
#[test]
fn merges_alone_agree_with_bdpt_strategies_alone_per_half() {
    let scene = load_small("cornell_box.ron", 16);
    for (s, t) in [(1u16, 2u16), (2, 2), (1, 3)] {
        let only = StrategyFilter::Only {
            s: Some(s),
            t: Some(t),
        };
        let bd = halves_over_seeds(
            |seed| {
                let settings = BdptSettings {
                    strategies: only,
                    ..BdptSettings::new(seed, u32::MAX)
                };
                render_bdpt(scene.clone(), 16, settings).0.film.image()
            },
            8,
        );
        let merged = halves_over_seeds(
            |seed| {
                let settings = BdptSettings {
                    strategies: only,
                    merging: merging(false, true, 8.0),
                    ..BdptSettings::new(500 + seed, u32::MAX)
                };
                render_bdpt(scene.clone(), 16, settings).0.film.image()
            },
            8,
        );
        for (i, half) in ["upper", "lower"].iter().enumerate() {
            assert_agree(
                &format!("merges ({s},{t}) alone vs bdpt's, {half} half"),
                merged[i],
                bd[i],
                4.5,
            );
        }
    }
}

/// On a scene of our own (tests/scenes/glass_spheres.ron: a glass and a mirror sphere on a
/// diffuse floor under a small light, so caustics seen directly and through the glass), VCM
/// and BPM at their default radius agree with PT in every 16x16 block over independent seeds:
/// merges through specular chains and their MIS weights against the connections keep the
/// light, and the default radius' blur stays below the seeds' spread.
#[test]
fn vcm_and_bpm_agree_with_pt_per_block_on_glass_spheres() {
    use crate::common::{assert_blocks_agree, load_test_scene, pt_block_reference};
    const SCENE: &str = "glass_spheres.ron";
    let reference = pt_block_reference(SCENE, 512);
    let scene = load_test_scene(SCENE);
    let data = SceneData::new(scene.clone());
    let render = stagelight::integrators::RenderSettings::default();
    for (name, connect) in [("vcm", true), ("bpm", false)] {
        let settings = bdpt::vcm_settings(&data, &render, connect, true);
        let images: Vec<_> = (0..12)
            .map(|seed| {
                let s = BdptSettings {
                    seed: 700 + seed,
                    ..settings
                };
                render_bdpt(scene.clone(), 48, s).0.film.image()
            })
            .collect();
        assert_blocks_agree(name, &images, &reference, 0.1, 5.0);
    }
}

/// The joint densities `weigh_connections` finds in lanes (between Lambertian surfaces and
/// area lights) are `PathContext::joint_densities`' bits, at both lane widths, for every
/// connection of random subpaths of scenes with Lambertian and other surfaces, one-sided ones
/// and shading normals; and most of the Cornell box's are found in lanes.
#[test]
fn joint_densities_in_lanes_are_the_scalar_bits() {
    use stagelight::lanes::LaneWidth;
    use stagelight::systems::connect::weights::joint_densities_in_lanes;
    let xml = |name: &str| {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/scenes/mitsuba")
            .join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        stagelight::scene::load_mitsuba_from_str(
            &path,
            &text,
            &[],
            &stagelight::scene::Limits::of_this_machine(),
        )
        .unwrap()
        .0
    };
    let scenes = [
        ("cornell_box.ron", load_small("cornell_box.ron", 32)),
        ("door_ajar.ron", load_small("door_ajar.ron", 32)),
        ("one_sided.xml", xml("one_sided.xml")),
        ("materials_room.xml", xml("materials_room.xml")),
        ("analytic_shapes.xml", xml("analytic_shapes.xml")),
        ("twosided_two.xml", xml("twosided_two.xml")),
    ];
    for (name, scene) in scenes {
        let data = Arc::new(SceneData::new(scene));
        let ctx = PathContext::new(&data.scene);
        let subpaths = bdpt::trace_subpaths(data.clone(), BdptSettings::new(11, u32::MAX), 0, 4096);
        let mut connections = Vec::new();
        for (camera, light) in &subpaths {
            for t in 1..=camera.len() {
                for s in 1..=light.len() {
                    connections.push((&camera[..t], &light[..s], (s, t)));
                }
            }
        }
        let mut in_lanes = 0;
        for width in [LaneWidth::Eight, LaneWidth::Sixteen] {
            let lanes = joint_densities_in_lanes(&data.scene, &connections, width);
            in_lanes = 0;
            for (&(camera, light, st), found) in connections.iter().zip(&lanes) {
                let Some(found) = found else { continue };
                let want = ctx.joint_densities(camera, light, st);
                let bits = |d: &stagelight::weight_tails::JointDensities| {
                    [d.z_rev, d.y_rev].map(|p| p.map(f32::to_bits))
                };
                assert_eq!(
                    bits(found),
                    bits(&want),
                    "{name} {width:?}: connection {st:?} in lanes {found:?}, one at a time {want:?}"
                );
                in_lanes += 1;
            }
        }
        let eligible = connections
            .iter()
            .filter(|c| c.2.0 >= 1 && c.2.1 >= 2)
            .count();
        println!("{name}: {in_lanes} of {eligible} joints with t >= 2 in lanes");
        if name == "cornell_box.ron" {
            assert!(
                in_lanes * 10 >= eligible * 9,
                "{name}: {in_lanes} of {eligible} in lanes"
            );
        } else {
            assert!(in_lanes > 0, "{name}: no joint in lanes");
        }
    }
}
