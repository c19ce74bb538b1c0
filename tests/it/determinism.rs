//! The same scene, seed and sample count give a bit-identical EXR whatever the thread count.

use crate::common::{stagelight_command, stderr, temp_dir};
use std::path::Path;

fn render(threads: u32, seed: u64, out: &Path) {
    let o = stagelight_command()
        .args(["render", "scenes/cornell_box.ron", "--spp", "3", "--quiet"])
        .args(["--seed", &seed.to_string()])
        .args(["--threads", &threads.to_string(), "-o"])
        .arg(out)
        .output()
        .expect("stagelight runs");
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn exr_is_bit_identical_for_one_two_and_three_threads() {
    let dir = temp_dir("determinism");
    let files: Vec<_> = [1, 2, 3]
        .iter()
        .map(|&t| {
            let out = dir.join(format!("t{t}.exr"));
            render(t, 11, &out);
            std::fs::read(&out).expect("EXR written")
        })
        .collect();
    let image = stagelight::film::Image::read_exr(&dir.join("t1.exr")).expect("EXR reads");
    assert_eq!((image.width, image.height), (256, 256));
    assert!(files[0] == files[1], "1 and 2 threads differ");
    assert!(files[0] == files[2], "1 and 3 threads differ");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_different_seed_gives_a_different_image() {
    let dir = temp_dir("seed");
    let (a, b) = (dir.join("a.exr"), dir.join("b.exr"));
    render(2, 11, &a);
    render(2, 12, &b);
    assert!(std::fs::read(&a).unwrap() != std::fs::read(&b).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}
