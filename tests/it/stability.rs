//! Numerical stability: the Cornell box moved 1e5 away from the origin along each axis renders
//! the same image within noise (no self-intersection acne, no light leaks).

use crate::common::*;
use glam::Vec3;
use stagelight::scene::PreparedScene;

fn translated(mut scene: PreparedScene, offset: Vec3) -> PreparedScene {
    let t = &mut scene.triangles;
    for p in
        t.p0.iter_mut()
            .chain(t.p1.iter_mut())
            .chain(t.p2.iter_mut())
    {
        *p += offset;
    }
    scene.camera.position += offset;
    scene.bounds_min += offset;
    scene.bounds_max += offset;
    scene
}

/// Renders the Cornell box near the origin and moved 1e5 along each axis with `render`
/// (scene, seed -> film) and compares block by block.
fn far_from_the_origin_renders_the_same(
    render: impl Fn(PreparedScene, u64) -> stagelight::film::Film,
) {
    let (size, block) = (64, 16);
    let base = load_small("cornell_box.ron", size);
    let a1 = render(base.clone(), 1).image();
    let a2 = render(base.clone(), 2).image();
    let (m1, m2) = (block_means(&a1, block), block_means(&a2, block));
    // Noise of one block mean (relative), from two independent renders of the same scene.
    let rel = |x: f64, y: f64| (x - y) / (0.5 * (x + y)).max(1e-3);
    let mut sum_sq = 0.0;
    let mut n = 0.0;
    for (b1, b2) in m1.iter().zip(&m2) {
        for c in 0..3 {
            sum_sq += rel(b1[c], b2[c]).powi(2) / 2.0;
            n += 1.0;
        }
    }
    let block_noise = (sum_sq / n).sqrt();
    assert!(
        block_noise > 0.0 && block_noise < 0.2,
        "noise {block_noise}"
    );

    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        let far = translated(base.clone(), axis * 1e5);
        let film = render(far, 2);
        assert_eq!(film.nonfinite, 0);
        let t = block_means(&film.image(), block);
        for (i, (b1, bt)) in m1.iter().zip(&t).enumerate() {
            for c in 0..3 {
                let d = rel(b1[c], bt[c]);
                // Two independent estimates differ by sqrt(2) block noises; allow 6 of those.
                assert!(
                    d.abs() < 6.0 * 2f64.sqrt() * block_noise,
                    "axis {axis}: block {i} channel {c} differs by {d:.4} (noise {block_noise:.4})"
                );
            }
        }
    }
}

#[test]
fn cornell_box_far_from_the_origin_renders_the_same() {
    far_from_the_origin_renders_the_same(|scene, seed| render_pt(scene, 16, seed, u32::MAX).film);
}

#[test]
fn cornell_box_far_from_the_origin_renders_the_same_with_bdpt() {
    far_from_the_origin_renders_the_same(|scene, seed| {
        let settings = stagelight::integrators::bdpt::BdptSettings::new(seed, u32::MAX);
        render_bdpt(scene, 8, settings).0.film
    });
}
