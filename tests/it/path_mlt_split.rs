//! Path-space MLT's split between the direct image (depth 0 and 1, path traced) and the chains
//! (depth 2 and more), on a scene of our own with a glass and a mirror sphere on a diffuse
//! floor (tests/scenes/glass_spheres.ron): with the split and without it (`--direct-spp 0`),
//! every 16x16 block agrees with PT's within the spread of their seeds. MLT's pixels are
//! correlated within a seed, so seeds are compared, not pixels.

use crate::common::{assert_blocks_agree, load_test_scene, pt_block_reference};
use stagelight::film::Image;
use stagelight::integrators::driver::{PassState, run_passes};
use stagelight::integrators::path_mlt::{PathMltSettings, PathMltState};
use stagelight::integrators::{RenderSettings, SceneData};
use std::sync::Arc;

const SCENE: &str = "glass_spheres.ron";

fn mlt(seed: u64, direct_spp: u32, m: u64) -> Image {
    let data = Arc::new(SceneData::new(load_test_scene(SCENE)));
    let mut r = RenderSettings {
        seed,
        ..RenderSettings::default()
    };
    r.mlt.direct_spp = Some(direct_spp);
    let mut s = PathMltSettings::from_render(&data, &r);
    s.bootstrap.mutations_per_pixel = Some(m);
    let cam = data.scene.camera;
    let passes = s
        .bootstrap
        .passes_for(cam.width as u64 * cam.height as u64, m);
    run_passes::<PathMltState>(data, s, passes)
        .finish(0)
        .0
        .image()
}

#[test]
fn path_mlt_direct_split_agrees_with_pt_per_block_through_glass() {
    // Twelve seeds: in the glass sphere's block the seeds' values are skewed (at 32 mutations
    // per pixel: median 0.295, mean 0.308, PT 0.317, one seed 0.425), so the mean of 4 is
    // usually low: 4 seeds failed here by 6 standard errors, 12 do not.
    const SEEDS: u64 = 12;
    let reference = pt_block_reference(SCENE, 128);
    for direct_spp in [16, 0] {
        let images: Vec<Image> = (0..SEEDS).map(|seed| mlt(seed, direct_spp, 32)).collect();
        let what = format!("direct spp {direct_spp}");
        assert_blocks_agree(&what, &images, &reference, 0.1, 5.0);
    }
}
