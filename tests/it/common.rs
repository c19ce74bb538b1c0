//! Helpers shared by the tests: small renders (small images, few samples), and running the
//! `stagelight` binary (temporary folders, shrunken scenes, interrupting a run once it has
//! made progress).

use stagelight::film::Image;
use stagelight::integrators::{Budget, Control, RenderOutcome, SceneData, pt};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

pub fn scene_path(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
}

/// Loads one of the test's own scenes (tests/scenes/), at its own size.
pub fn load_test_scene(name: &str) -> stagelight::scene::PreparedScene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/scenes")
        .join(name);
    stagelight::scene::load(&path).expect("scene loads")
}

/// Loads a scene from scenes/ and shrinks its image to `size` x `size`.
pub fn load_small(name: &str, size: u32) -> stagelight::scene::PreparedScene {
    let mut scene = stagelight::scene::load(&scene_path(name)).expect("scene loads");
    let (w, h) = (size, size);
    scene.camera.resize(w, h);
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
        pt::PtSettings::new(seed, max_depth),
        Budget::SamplesPerPixel(spp),
        &control,
    )
}

/// A render by any integrator at `spp` samples per pixel (never stopped early).
pub fn render_with(
    kind: stagelight::integrators::IntegratorKind,
    data: Arc<SceneData>,
    settings: &stagelight::integrators::RenderSettings,
    spp: u64,
) -> Image {
    render_outcome_with(kind, data, settings, spp).film.image()
}

/// `render_with`'s whole outcome (its film with exact sums, its counts).
pub fn render_outcome_with(
    kind: stagelight::integrators::IntegratorKind,
    data: Arc<SceneData>,
    settings: &stagelight::integrators::RenderSettings,
    spp: u64,
) -> RenderOutcome {
    let stop = AtomicBool::new(false);
    let control = Control {
        stop: &stop,
        progress: &|_, _| {},
    };
    stagelight::integrators::render(kind, data, settings, Budget::SamplesPerPixel(spp), &control)
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

/// `block_luminance_stats` of eight PT renders (seeds 300..308) of a scene in tests/scenes:
/// the reference the block tests of other integrators compare with.
pub fn pt_block_reference(scene: &str, spp: u64) -> Vec<(f64, f64)> {
    let pt: Vec<Image> = (0..8)
        .map(|seed| {
            render_pt(load_test_scene(scene), spp, 300 + seed, u32::MAX)
                .film
                .image()
        })
        .collect();
    block_luminance_stats(&pt)
}

/// Per 16x16 block, the luminance mean over renders (one per seed) and its standard error.
pub fn block_luminance_stats(images: &[Image]) -> Vec<(f64, f64)> {
    block_luminance_stats_of(images, 16)
}

/// `block_luminance_stats` over `block` x `block` blocks (at least one block).
pub fn block_luminance_stats_of(images: &[Image], block: usize) -> Vec<(f64, f64)> {
    assert!(
        images[0].width >= block && images[0].height >= block,
        "no whole {block}x{block} block"
    );
    let blocks: Vec<Vec<f64>> = images
        .iter()
        .map(|img| {
            block_means(img, block)
                .iter()
                .map(|b| 0.2126 * b[0] + 0.7152 * b[1] + 0.0722 * b[2])
                .collect()
        })
        .collect();
    let n = images.len() as f64;
    (0..blocks[0].len())
        .map(|i| {
            let mean = blocks.iter().map(|b| b[i]).sum::<f64>() / n;
            let var = blocks.iter().map(|b| (b[i] - mean).powi(2)).sum::<f64>() / (n - 1.0);
            (mean, (var / n).sqrt())
        })
        .collect()
}

/// Asserts that every block of `images` (one render per seed) agrees with the same block of
/// `reference` (`block_luminance_stats` of the reference's renders) within `z` combined standard
/// errors, and that each block's standard error is below `max_error` of its value (so the test
/// can fail). Seeds are compared, not pixels: MLT's pixels are correlated within a render.
pub fn assert_blocks_agree(
    what: &str,
    images: &[Image],
    reference: &[(f64, f64)],
    max_error: f64,
    z: f64,
) {
    for (i, ((m, s), (rm, rs))) in block_luminance_stats(images)
        .into_iter()
        .zip(reference)
        .enumerate()
    {
        let se = (s * s + rs * rs).sqrt();
        assert!(
            se < max_error * rm,
            "{what} block {i}: standard error {se} too large ({m} vs {rm})"
        );
        assert!(
            (m - rm).abs() <= z * se,
            "{what} block {i}: {m} against {rm}, {:.2} standard errors",
            (m - rm).abs() / se
        );
    }
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

/// The `stagelight` binary, run in the repository root (where `scenes/` is).
pub fn stagelight_command() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_stagelight"));
    command.current_dir(env!("CARGO_MANIFEST_DIR"));
    command
}

/// Runs `stagelight` with `args` to the end.
pub fn stagelight(args: &[&str]) -> Output {
    stagelight_command()
        .args(args)
        .output()
        .expect("stagelight runs")
}

/// Starts `command` with stdout and stderr captured, for `interrupt`.
pub fn spawn(command: &mut Command) -> Child {
    command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("stagelight starts")
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh, empty folder under the temp dir, named after `name` and this process, removed
/// with what it holds when the value is dropped (at the test's end, passed or failed).
pub fn temp_dir(name: &str) -> TempDir {
    let dir = std::env::temp_dir().join(format!("stagelight-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    TempDir(dir)
}

/// `temp_dir`'s folder: a path while it lives.
pub struct TempDir(PathBuf);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The shipped scene `name` (a file stem of scenes/) at `size` x `size`, written as `to`.
pub fn shrunk_scene(name: &str, size: u32, to: &Path) -> PathBuf {
    let text = std::fs::read_to_string(scene_path(&format!("{name}.ron"))).unwrap();
    let text = text.replacen(
        "camera: (",
        &format!("camera: (\n        width: {size},\n        height: {size},"),
        1,
    );
    std::fs::write(to, text).unwrap();
    to.to_path_buf()
}

/// Polls `ready` until it holds, however slow the machine (up to two minutes); panics if the
/// child ends first, and kills it on a timeout.
pub fn wait_until(child: &mut Child, what: &str, mut ready: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !ready() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("stagelight ended before {what}: {status}");
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            panic!("timed out waiting for {what}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until the child catches Ctrl-C (its handler is installed, so SIGINT stops it instead
/// of killing it) and has then spent `cpu_seconds` of CPU time, user and system: progress a
/// loaded machine delays but does not fake, as it would a sleep's. Commands that print no
/// progress (`--quiet`, or stderr not a terminal) leave nothing else to watch; give them few
/// threads, so idle workers spinning add little CPU time. Without /proc (not Linux), sleeps.
pub fn wait_for_progress(child: &mut Child, cpu_seconds: f64) {
    let pid = child.id();
    if !Path::new(&format!("/proc/{pid}/status")).exists() {
        std::thread::sleep(Duration::from_secs_f64(2.5 * cpu_seconds));
        return;
    }
    wait_until(child, "the Ctrl-C handler", || catches_sigint(pid));
    wait_until(child, "its CPU seconds", || {
        cpu_seconds_of(pid) >= cpu_seconds
    });
}

/// Sends Ctrl-C (SIGINT) to the child and waits for it to end.
pub fn interrupt(child: Child) -> Output {
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(killed.success());
    child.wait_with_output().unwrap()
}

/// Whether the process catches SIGINT (bit 2 of SigCgt in /proc/PID/status).
fn catches_sigint(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|status| {
            let mask = status.lines().find_map(|l| l.strip_prefix("SigCgt:"))?;
            u64::from_str_radix(mask.trim(), 16).ok()
        })
        .is_some_and(|mask| mask & (1 << (2 - 1)) != 0)
}

/// CPU seconds (utime + stime, fields 14 and 15 of /proc/PID/stat, in 1/100 s) of a process.
fn cpu_seconds_of(pid: u32) -> f64 {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return 0.0;
    };
    let fields: Vec<f64> = stat
        .rsplit_once(')')
        .map_or("", |(_, rest)| rest)
        .split_whitespace()
        .map(|f| f.parse().unwrap_or(0.0))
        .collect();
    (fields.get(11).unwrap_or(&0.0) + fields.get(12).unwrap_or(&0.0)) / 100.0
}
