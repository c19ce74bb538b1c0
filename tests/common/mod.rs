//! Helpers shared by the render tests: small images, few samples.
#![allow(dead_code)]

use stagelight::film::Image;
use stagelight::integrators::{Budget, Control, RenderOutcome, SceneData, pt};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

pub fn scene_path(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
}

/// Loads a scene from scenes/ and shrinks its image to `size` x `size`.
pub fn load_small(name: &str, size: u32) -> stagelight::scene::PreparedScene {
    let mut scene = stagelight::scene::load(&scene_path(name)).expect("scene loads");
    scene.camera.width = size;
    scene.camera.height = size;
    scene
}

pub fn render_pt(
    scene: stagelight::scene::PreparedScene,
    spp: u64,
    seed: u64,
    max_depth: u32,
) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    pt::render(
        Arc::new(SceneData::new(scene)),
        pt::PtSettings { seed, max_depth },
        Budget::SamplesPerPixel(spp),
        &control,
    )
}

/// Mean and standard deviation of one channel over pixels.
pub fn pixel_stats(image: &Image, channel: usize) -> (f64, f64) {
    let n = image.pixels.len() as f64;
    let mean = image.pixels.iter().map(|p| p[channel] as f64).sum::<f64>() / n;
    let var = image
        .pixels
        .iter()
        .map(|p| (p[channel] as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    (mean, var.sqrt())
}

/// Averages `block` x `block` tiles of an image (a coarser image for region-by-region checks).
pub fn block_means(image: &Image, block: usize) -> Vec<[f64; 3]> {
    let (bw, bh) = (image.width / block, image.height / block);
    let mut out = vec![[0.0; 3]; bw * bh];
    for y in 0..bh * block {
        for x in 0..bw * block {
            let p = image.pixels[y * image.width + x];
            let o = &mut out[(y / block) * bw + x / block];
            for c in 0..3 {
                o[c] += p[c] as f64 / (block * block) as f64;
            }
        }
    }
    out
}

pub fn render_bdpt(
    scene: stagelight::scene::PreparedScene,
    spp: u64,
    settings: stagelight::integrators::bdpt::BdptSettings,
) -> (RenderOutcome, Vec<(String, Image)>) {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    let mut outcome = stagelight::integrators::bdpt::render(
        Arc::new(SceneData::new(scene)),
        settings,
        Budget::SamplesPerPixel(spp),
        &control,
    );
    let layers = std::mem::take(&mut outcome.layers);
    (outcome, layers)
}

/// Mean and standard error of each channel's image mean over independent renders (one per
/// seed): the spread between renders, so correlated pixels (splats) cannot fool it.
pub fn mean_over_seeds(render: impl Fn(u64) -> Image, seeds: u64) -> ([f64; 3], [f64; 3]) {
    let means: Vec<[f64; 3]> = (0..seeds)
        .map(|seed| {
            let m = render(seed).channel_means();
            [m.x, m.y, m.z]
        })
        .collect();
    let n = seeds as f64;
    let mut mean = [0.0; 3];
    let mut se = [0.0; 3];
    for c in 0..3 {
        mean[c] = means.iter().map(|m| m[c]).sum::<f64>() / n;
        let var = means.iter().map(|m| (m[c] - mean[c]).powi(2)).sum::<f64>() / (n - 1.0);
        se[c] = (var / n).sqrt();
    }
    (mean, se)
}
