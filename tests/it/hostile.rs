//! Hostile inputs (issue 18): each reproducer runs through the binary and must end in a
//! correct render, or in exit 1 with one line naming the file at fault; never a panic, an
//! abort, a silent black image or a lost output.
//!
//! `STAGELIGHT_BIN=/path/to/an/older/stagelight cargo nextest run hostile` runs them against
//! another build (to see which of them an older binary fails).

use crate::common::{stderr, stdout, temp_dir};
use stagelight::film::Image;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The binary under test: `STAGELIGHT_BIN` or this build's.
fn binary() -> Command {
    let bin = std::env::var("STAGELIGHT_BIN")
        .unwrap_or_else(|_| env!("CARGO_BIN_EXE_stagelight").to_string());
    let mut command = Command::new(bin);
    command.current_dir(env!("CARGO_MANIFEST_DIR"));
    command
}

/// Runs stagelight to the end, or kills it after two minutes (an older binary may render
/// for hours what this one refuses at once).
fn run(args: &[&str]) -> Output {
    let mut child = binary()
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("stagelight runs");
    let deadline = Instant::now() + Duration::from_secs(120);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!("still running after 2 minutes: {args:?}\n{}", stderr(&o));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Exit 1 and exactly one line on stderr besides warnings, naming `file` and saying each of
/// `words`.
#[track_caller]
fn refused(o: &Output, file: &str, words: &[&str]) -> String {
    let err = stderr(o);
    assert_eq!(
        o.status.code(),
        Some(1),
        "stderr: {err}\nstdout: {}",
        stdout(o)
    );
    assert!(!err.contains("panicked"), "{err}");
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| !l.starts_with("warning:") && !l.trim().is_empty())
        .collect();
    // clap's own errors add a "For more information, try '--help'." line.
    let lines: Vec<&str> = lines
        .into_iter()
        .filter(|l| !l.starts_with("For more information"))
        .collect();
    assert_eq!(lines.len(), 1, "one line expected: {err}");
    let line = lines[0];
    assert!(line.contains(file), "{line:?} does not name {file}");
    for w in words {
        assert!(line.contains(w), "{line:?} does not say {w:?}");
    }
    line.to_string()
}

#[track_caller]
fn rendered(o: &Output) {
    assert_eq!(o.status.code(), Some(0), "{}", stderr(o));
    assert!(!stderr(o).contains("panicked"));
}

const CAMERA: &str =
    "camera: (position: (0, 1, -4), look_at: (0, 1, 0), fov: 50, width: 16, height: 16),";
const MATERIALS: &str = "materials: {\"white\": Diffuse(reflectance: (0.5, 0.5, 0.5))},";
const FLOOR: &str =
    "(shape: Quad((-2, 0, -2), (-2, 0, 2), (2, 0, 2), (2, 0, -2)), material: \"white\"),";
const LIGHT: &str = "(shape: Quad((-0.5, 2, -0.5), (0.5, 2, -0.5), (0.5, 2, 0.5), (-0.5, 2, 0.5)), material: \"white\", emission: Some((4, 4, 4))),";

/// A scene with the standard camera and materials and these objects (one per line, the first
/// on line 4).
fn scene_text(objects: &[&str]) -> String {
    format!(
        "Scene(\n{CAMERA}\n{MATERIALS}\nobjects: [\n{}\n],\n)\n",
        objects.join("\n")
    )
}

fn write_scene(dir: &Path, name: &str, objects: &[&str]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, scene_text(objects)).unwrap();
    path
}

fn render_args<'a>(scene: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["render", scene, "--quiet", "-o", out];
    args.extend_from_slice(extra);
    args
}

// 1 ---------------------------------------------------------------------------------------

#[test]
fn huge_coordinates_are_refused_at_the_object() {
    let dir = temp_dir("hostile-huge");
    let scene = write_scene(
        &dir,
        "huge.ron",
        &[
            "(shape: Quad((-1e19, 0, -1e19), (-1e19, 0, 1e19), (1e19, 0, 1e19), (1e19, 0, -1e19)), material: \"white\"),",
            LIGHT,
        ],
    );
    let out = dir.join("out.exr");
    let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
    refused(&o, "huge.ron:5:1", &["must stay below"]);

    let scene = write_scene(
        &dir,
        "far.ron",
        &[
            FLOOR,
            LIGHT,
            "(shape: Box(min: (0, 0, 0), max: (1, 1, 1)), material: \"white\", transform: [Translate((0, 1.8e38, 0))]),",
        ],
    );
    let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
    refused(&o, "far.ron:7:1", &["must stay below"]);

    std::fs::write(
        dir.join("far.obj"),
        "v 3e38 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n",
    )
    .unwrap();
    let scene = write_scene(
        &dir,
        "obj.ron",
        &[
            FLOOR,
            LIGHT,
            "(shape: Obj(\"far.obj\"), material: \"white\"),",
        ],
    );
    let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
    refused(&o, "obj.ron:7:1", &["must stay below"]);
}

// 2 ---------------------------------------------------------------------------------------

#[test]
fn a_light_too_small_for_f32_is_refused_not_a_panic() {
    let dir = temp_dir("hostile-tiny");
    let scene = write_scene(
        &dir,
        "tiny.ron",
        &[
            FLOOR,
            "(shape: Quad((0, 1, 0), (2e-23, 1, 0), (2e-23, 1, 2e-23), (0, 1, 2e-23)), material: \"white\", emission: Some((1, 1, 1))),",
        ],
    );
    let out = dir.join("out.exr");
    for integrator in ["pt", "bdpt", "sppm"] {
        let mut args = vec!["--spp", "1", "--integrator", integrator];
        if integrator == "sppm" {
            args.extend(["--photons-per-pass", "1000"]);
        }
        let o = run(&render_args(s(&scene), s(&out), &args));
        refused(&o, "tiny.ron:6:1", &["degenerate light"]);
    }
}

// 3 ---------------------------------------------------------------------------------------

/// A 256 x 256 EXR (as a render writes it) and the offset of its dataWindow's four i32s.
fn exr_with_data_window(dir: &Path) -> (PathBuf, Vec<u8>, usize) {
    let path = dir.join("good.exr");
    let mut image = Image::new(256, 256);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        *p = glam::Vec3::splat((i % 7) as f32);
    }
    image.write_exr(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let name = b"dataWindow\0box2i\0";
    let at = bytes
        .windows(name.len())
        .position(|w| w == name)
        .expect("a dataWindow attribute")
        + name.len()
        + 4; // the attribute's size
    (path, bytes, at)
}

#[test]
fn a_damaged_exr_header_is_an_error_not_a_huge_allocation() {
    let dir = temp_dir("hostile-exr");
    let (good, bytes, at) = exr_with_data_window(&dir);
    // One damaged byte: xMin becomes 8323072, a width of 8 million (a 25 GB allocation).
    let mut damaged = bytes.clone();
    damaged[at + 2] = 0x7f;
    let bad = dir.join("damaged.exr");
    std::fs::write(&bad, &damaged).unwrap();
    let o = run(&["diff", s(&bad), s(&good)]);
    refused(&o, "damaged.exr", &["damaged"]);

    // 300 bytes that claim 100000 x 100000 pixels.
    let mut claim = bytes.clone();
    claim[at..at + 16].copy_from_slice(
        &[0i32, 0, 99_999, 99_999]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    );
    claim.truncate(300);
    let huge = dir.join("huge.exr");
    std::fs::write(&huge, &claim).unwrap();
    let o = run(&["diff", s(&good), s(&huge)]);
    refused(&o, "huge.exr", &[]);

    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let o = run(&[
        "compare",
        s(&scene),
        "--reference",
        s(&bad),
        "--integrators",
        "pt",
        "--budget-unit",
        "spp",
        "--budgets",
        "1",
        "--quiet",
        "-o",
        s(&dir.join("report")),
    ]);
    refused(&o, "damaged.exr", &["damaged"]);
}

// 4 ---------------------------------------------------------------------------------------

#[test]
fn samples_beyond_a_u64_are_refused() {
    let dir = temp_dir("hostile-spp");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let out = dir.join("out.exr");
    // 2^56 spp x 256 pixels = 2^64: wrapped to 0 passes and a black image.
    let o = run(&render_args(
        s(&scene),
        s(&out),
        &["--spp", "72057594037927936"],
    ));
    refused(&o, "--spp", &["72057594037927936"]);
    assert!(!out.exists());
    let o = run(&[
        "bench",
        s(&scene),
        "--spp",
        "72057594037927936",
        "--runs",
        "1",
    ]);
    refused(&o, "--spp", &[]);
}

// 5 ---------------------------------------------------------------------------------------

#[cfg(unix)]
#[test]
fn an_output_that_is_a_symbolic_link_is_refused() {
    let dir = temp_dir("hostile-link");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let precious = dir.join("precious.txt");
    std::fs::write(&precious, "keep me").unwrap();
    let link = dir.join("out.exr");
    std::os::unix::fs::symlink(&precious, &link).unwrap();
    let o = run(&render_args(s(&scene), s(&link), &["--spp", "1"]));
    refused(&o, "out.exr", &["symbolic link"]);
    assert_eq!(std::fs::read_to_string(&precious).unwrap(), "keep me");
}

#[test]
fn two_renders_to_one_path_leave_a_whole_image() {
    let dir = temp_dir("hostile-race");
    // Large enough that writing the EXR takes a while: writers in place interleave.
    let scene = dir.join("s.ron");
    std::fs::write(
        &scene,
        scene_text(&[FLOOR, LIGHT]).replace("width: 16, height: 16", "width: 384, height: 384"),
    )
    .unwrap();
    let out = dir.join("out.exr");
    for _ in 0..4 {
        let children: Vec<Child> = (0..3)
            .map(|seed| {
                binary()
                    .args(render_args(
                        s(&scene),
                        s(&out),
                        &["--spp", "1", "--seed", &seed.to_string(), "--threads", "1"],
                    ))
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for mut c in children {
            assert!(c.wait().unwrap().success());
        }
        let image = Image::read_exr(&out).expect("a whole EXR");
        assert_eq!((image.width, image.height), (384, 384));
        let png = std::fs::read(dir.join("out.png")).unwrap();
        let decoder = png::Decoder::new(std::io::Cursor::new(png));
        let mut reader = decoder.read_info().expect("a whole PNG");
        let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut buffer).expect("a whole PNG");
    }
    // No temporary file is left behind.
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.ends_with(".tmp")), "{names:?}");
}

// 6 ---------------------------------------------------------------------------------------

/// Runs stagelight with its address space limited to `kib` KiB (`ulimit -v`).
fn run_limited(kib: u64, args: &[&str]) -> Output {
    let bin = std::env::var("STAGELIGHT_BIN")
        .unwrap_or_else(|_| env!("CARGO_BIN_EXE_stagelight").to_string());
    let mut command = Command::new("bash");
    command
        .arg("-c")
        .arg(format!("ulimit -v {kib} && exec \"$0\" \"$@\""))
        .arg(bin)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"));
    command.output().unwrap()
}

#[test]
fn requests_beyond_the_machines_memory_are_refused_before_allocating() {
    let dir = temp_dir("hostile-memory");
    let out = dir.join("out.exr");
    let limit = 3 << 20; // 3 GiB of address space
    let big = dir.join("big.ron");
    std::fs::write(
        &big,
        scene_text(&[FLOOR, LIGHT]).replace("width: 16, height: 16", "width: 16384, height: 16384"),
    )
    .unwrap();
    let o = run_limited(limit, &render_args(s(&big), s(&out), &["--spp", "1"]));
    refused(&o, "big.ron", &["needs ~", "GB", "ulimit -v allows"]);

    let torus = write_scene(
        &dir,
        "torus.ron",
        &[
            LIGHT,
            "(shape: Torus(major_radius: 1, minor_radius: 0.2, nu: 4096, nv: 4096), material: \"white\"),",
        ],
    );
    let o = run_limited(limit, &render_args(s(&torus), s(&out), &["--spp", "1"]));
    refused(&o, "torus.ron:6:1", &["needs ~13.4 GB"]);

    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let o = run_limited(
        limit,
        &render_args(
            s(&scene),
            s(&out),
            &["--spp", "1", "--integrator", "pm", "--k", "4294967295"],
        ),
    );
    refused(&o, "--k 4294967295", &["--photons"]);
    let o = run_limited(
        limit,
        &render_args(
            s(&scene),
            s(&out),
            &[
                "--spp",
                "1",
                "--integrator",
                "pm",
                "--photons",
                "1000000000000",
            ],
        ),
    );
    refused(&o, "s.ron", &["needs ~", "photons"]);
}

// 7, 8 ------------------------------------------------------------------------------------

#[test]
fn absurd_thread_counts_and_checkpoint_intervals_are_refused() {
    let dir = temp_dir("hostile-threads");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let out = dir.join("out.exr");
    let o = run(&render_args(
        s(&scene),
        s(&out),
        &["--spp", "1", "--threads", "18446744073709551615"],
    ));
    refused(&o, "--threads", &["at most"]);
    let o = run(&[
        "reference",
        s(&scene),
        "--spp",
        "1",
        "--quiet",
        "-o",
        s(&out),
        "--checkpoint-every",
        "1e20",
    ]);
    refused(&o, "--checkpoint-every", &["at most"]);
}

// 9, SIGTERM, SIGHUP ----------------------------------------------------------------------

/// Whether the process catches `signal` (its bit in SigCgt of /proc/PID/status).
fn catches(pid: u32, signal: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|status| {
            let mask = status.lines().find_map(|l| l.strip_prefix("SigCgt:"))?;
            u64::from_str_radix(mask.trim(), 16).ok()
        })
        .is_some_and(|mask| mask & (1 << (signal - 1)) != 0)
}

fn wait_for(child: &mut Child, what: &str, mut ready: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !ready() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("stagelight ended before {what}: {status}");
        }
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn signal(child: &Child, name: &str) {
    let sent = Command::new("kill")
        .args([&format!("-{name}"), &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
}

#[cfg(target_os = "linux")]
#[test]
fn ctrl_c_before_the_first_pass_keeps_the_old_output() {
    let dir = temp_dir("hostile-early-stop");
    // One pass of 2048 x 2048 takes seconds.
    let scene = dir.join("big.ron");
    std::fs::write(
        &scene,
        scene_text(&[FLOOR, LIGHT]).replace("width: 16, height: 16", "width: 2048, height: 2048"),
    )
    .unwrap();
    let out = dir.join("out.exr");
    std::fs::write(&out, "the previous render").unwrap();
    let mut child = binary()
        .args(render_args(
            s(&scene),
            s(&out),
            &["--spp", "64", "--threads", "1"],
        ))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    wait_for(&mut child, "the Ctrl-C handler", || catches(pid, 2));
    signal(&child, "INT");
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(stdout(&o).contains("nothing written"), "{}", stdout(&o));
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "the previous render"
    );
}

#[cfg(target_os = "linux")]
#[test]
fn sigterm_and_sighup_stop_a_render_as_ctrl_c_does() {
    let dir = temp_dir("hostile-term");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    for name in ["TERM", "HUP"] {
        let out = dir.join(format!("{name}.exr"));
        let mut child = binary()
            .args(render_args(
                s(&scene),
                s(&out),
                &["--spp", "100000000", "--threads", "1"],
            ))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let pid = child.id();
        let number = if name == "TERM" { 15 } else { 1 };
        wait_for(&mut child, "the signal handler", || catches(pid, number));
        // Some passes finish (the first wave is 1024 passes of 16 x 16 pixels).
        crate::common::wait_for_progress(&mut child, 1.5);
        signal(&child, name);
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(130), "SIG{name}: {}", stderr(&o));
        assert!(
            stdout(&o).contains("interrupted: saved the"),
            "{}",
            stdout(&o)
        );
        let image = Image::read_exr(&out).expect("the finished passes were written");
        assert!(image.channel_means().x > 0.0);
    }
}

// 10, 18, 19 (the output's path) ---------------------------------------------------------

#[test]
fn unwritable_outputs_are_found_before_rendering() {
    let dir = temp_dir("hostile-unwritable");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    // A render that would take hours: the error must come at once.
    let long = ["--spp", "100000000"];
    let folder = dir.join("x.exr");
    std::fs::create_dir_all(&folder).unwrap();
    let start = Instant::now();
    let o = run(&render_args(s(&scene), s(&folder), &long));
    refused(&o, "x.exr", &["folder"]);

    std::fs::write(dir.join("file"), "").unwrap();
    let under_file = dir.join("file").join("out.exr");
    let o = run(&render_args(s(&scene), s(&under_file), &long));
    let line = refused(&o, "out.exr", &["is a file, not a folder"]);
    assert!(!line.contains("os error 17"), "{line}");

    let out = dir.join("out.exr");
    let file = dir.join("file");
    let mut args = render_args(s(&scene), s(&out), &long);
    args.extend(["--integrator", "bdpt", "--strategy-images", s(&file)]);
    let o = run(&args);
    refused(&o, "file", &[]);
    assert!(start.elapsed() < Duration::from_secs(60));
}

#[test]
fn an_output_that_is_the_scene_is_refused() {
    let dir = temp_dir("hostile-same");
    let text = scene_text(&[FLOOR, LIGHT]);
    // A scene file named like an image: the EXR, or its PNG preview, would replace it.
    let exr_scene = dir.join("scene.exr");
    std::fs::write(&exr_scene, &text).unwrap();
    let o = run(&render_args(s(&exr_scene), s(&exr_scene), &["--spp", "1"]));
    refused(&o, "scene.exr", &["input"]);
    assert_eq!(std::fs::read_to_string(&exr_scene).unwrap(), text);

    let png_scene = dir.join("view.png");
    std::fs::write(&png_scene, &text).unwrap();
    let o = run(&render_args(
        s(&png_scene),
        s(&dir.join("view.exr")),
        &["--spp", "1"],
    ));
    refused(&o, "view.png", &["input"]);
    assert_eq!(std::fs::read_to_string(&png_scene).unwrap(), text);
}

// 11, 12 ----------------------------------------------------------------------------------

#[test]
fn forty_thousand_objects_load_in_linear_time() {
    let dir = temp_dir("hostile-many");
    let n = 40_000;
    let mut text = format!(
        "Scene(\n{CAMERA}\nmaterials: {{\n\"white\": Diffuse(reflectance: (0.5, 0.5, 0.5)),\n"
    );
    for i in 0..n {
        text += &format!("\"m{i}\": Diffuse(reflectance: (0.5, 0.5, 0.5)),\n");
    }
    text += "},\nobjects: [\n";
    text += LIGHT;
    text += "\n";
    for i in 0..n {
        let x = (i % 200) as f32 * 0.02 - 2.0;
        let z = (i / 200) as f32 * 0.02 - 2.0;
        text += &format!(
            "(shape: Triangle(({x}, 0, {z}), ({}, 0, {z}), ({x}, 0, {})), material: \"m{i}\"),\n",
            x + 0.01,
            z + 0.01
        );
    }
    text += "],\n)\n";
    let scene = dir.join("many.ron");
    std::fs::write(&scene, text).unwrap();
    let start = Instant::now();
    let o = run(&render_args(
        s(&scene),
        s(&dir.join("out.exr")),
        &["--spp", "1"],
    ));
    rendered(&o);
    // Quadratic loading took over two minutes (linear: 3 s, more on a loaded machine).
    assert!(
        start.elapsed() < Duration::from_secs(75),
        "{:?}",
        start.elapsed()
    );
}

#[test]
fn a_polygon_of_100000_vertices_loads_fast() {
    let dir = temp_dir("hostile-disc");
    let n = 100_000;
    let mut obj = String::new();
    for i in 0..n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        obj += &format!("v {} 0 {}\n", a.cos(), -a.sin());
    }
    obj += "f";
    for i in 1..=n {
        obj += &format!(" {i}");
    }
    obj += "\n";
    std::fs::write(dir.join("disc.obj"), obj).unwrap();
    let scene = write_scene(
        &dir,
        "disc.ron",
        &[LIGHT, "(shape: Obj(\"disc.obj\"), material: \"white\"),"],
    );
    let start = Instant::now();
    let out = dir.join("out.exr");
    let o = run(&render_args(s(&scene), s(&out), &["--spp", "4"]));
    rendered(&o);
    // The fan of slivers took 53 s (halving: about 1 s).
    assert!(
        start.elapsed() < Duration::from_secs(30),
        "{:?}",
        start.elapsed()
    );
    // The disc is lit: the light above it shows on it.
    assert!(Image::read_exr(&out).unwrap().channel_means().x > 0.01);
}

// 13 --------------------------------------------------------------------------------------

/// Emission that would overflow f32 light transport is refused with its line named. Below
/// that, whatever the scene's units, the film's unit follows its brightest light (2^-64 times
/// its power of two), so light of 2^96 and of 2^-64 renders the image of emission 4, scaled,
/// with no sample rejected (a film in units of 2^-64 rejects every sample of the first and
/// rounds the second to black).
#[test]
fn emission_that_overflows_f32_is_refused_and_any_other_renders_linearly() {
    let dir = temp_dir("hostile-emission");
    let out = dir.join("out.exr");
    for too in ["(1e34, 1e34, 1e34)", "(2e30, 0, 0)"] {
        let light = LIGHT.replace("(4, 4, 4)", too);
        let scene = write_scene(&dir, "bright.ron", &[FLOOR, &light]);
        let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
        refused(&o, "bright.ron:6", &["too large", "1e30"]);
    }
    let render = |emission: &str, integrator: &str| {
        let light = LIGHT.replace("(4, 4, 4)", emission);
        let scene = write_scene(&dir, "light.ron", &[FLOOR, &light]);
        let mut args = vec!["--spp", "4", "--integrator", integrator];
        if integrator == "sppm" {
            args.extend(["--photons-per-pass", "10000"]);
        }
        let o = run(&render_args(s(&scene), s(&out), &args));
        rendered(&o);
        assert!(
            !stderr(&o).contains("beyond the film's range") && !stderr(&o).contains("NaN"),
            "{integrator} at {emission}: {}",
            stderr(&o)
        );
        Image::read_exr(&out).unwrap()
    };
    for integrator in ["pt", "bdpt", "sppm"] {
        let base = render("(4, 4, 4)", integrator);
        // Powers of two: f32 products by them are exact, so only the light's own f32
        // arithmetic could differ; compare to a relative 1e-5.
        for (emission, scale) in [
            (
                "(7.922816251426434e28, 7.922816251426434e28, 7.922816251426434e28)",
                2f64.powi(96) / 4.0,
            ),
            (
                "(1.8446744073709552e19, 1.8446744073709552e19, 1.8446744073709552e19)",
                2f64.powi(64) / 4.0,
            ),
            (
                "(5.421010862427522e-20, 5.421010862427522e-20, 5.421010862427522e-20)",
                2f64.powi(-64) / 4.0,
            ),
        ] {
            let image = render(emission, integrator);
            let (mut lit, mut worst) = (0, 0.0f64);
            for (p, q) in image.pixels.iter().zip(&base.pixels) {
                for c in 0..3 {
                    let expected = q[c] as f64 * scale;
                    if expected > 0.0 {
                        lit += 1;
                        worst = worst.max((p[c] as f64 - expected).abs() / expected);
                    }
                }
            }
            assert!(lit > 100, "{integrator}: only {lit} lit channels");
            assert!(
                worst < 1e-5,
                "{integrator} at {emission}: off the scaled image by {worst:e}"
            );
        }
    }
}

// 14, 15 ----------------------------------------------------------------------------------

#[test]
fn an_edited_checkpoint_header_is_refused() {
    let dir = temp_dir("hostile-checkpoint");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let out = dir.join("ref.exr");
    let args = [
        "reference",
        s(&scene),
        "--spp",
        "2",
        "--quiet",
        "-o",
        s(&out),
    ];
    rendered(&run(&args));
    let checkpoint = dir.join("ref.exr.checkpoint");
    let good = std::fs::read(&checkpoint).unwrap();
    let text = String::from_utf8_lossy(&good).into_owned();
    let header_end = good.iter().skip(25).position(|&b| b == b'\n').unwrap() + 25;
    let header = String::from_utf8(good[..header_end].to_vec()).unwrap();
    assert!(text.contains("seconds:"));
    for edited in [
        regex_replace(&header, "seconds:", "seconds:NaN,was:"),
        header.replace("passes:2", "passes:3"),
        header.replace("nonfinite:0", "nonfinite:0,extra:1"),
    ] {
        let mut bytes = edited.into_bytes();
        bytes.extend_from_slice(&good[header_end..]);
        std::fs::write(&checkpoint, &bytes).unwrap();
        let o = run(&[
            "reference",
            s(&scene),
            "--spp",
            "4",
            "--quiet",
            "-o",
            s(&out),
        ]);
        refused(&o, "ref.exr.checkpoint", &["damaged"]);
    }
    std::fs::write(&checkpoint, &good).unwrap();
    rendered(&run(&[
        "reference",
        s(&scene),
        "--spp",
        "4",
        "--quiet",
        "-o",
        s(&out),
    ]));
}

/// `text` with the first `from` and the number after it replaced by `to`.
fn regex_replace(text: &str, from: &str, to: &str) -> String {
    let at = text.find(from).unwrap();
    let rest = &text[at + from.len()..];
    let end = rest.find([',', ')']).unwrap();
    format!("{}{to}{}", &text[..at], &rest[end..])
        .replace("was:,", "")
        .replace("was:)", ")")
}

#[cfg(target_os = "linux")]
#[test]
fn a_second_reference_run_on_one_output_is_refused() {
    let dir = temp_dir("hostile-lock");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let out = dir.join("ref.exr");
    let args = [
        "reference",
        s(&scene),
        "--spp",
        "100000000",
        "--quiet",
        "--threads",
        "1",
        "-o",
        s(&out),
    ];
    let mut first = binary()
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = first.id();
    wait_for(&mut first, "the first run's lock", || {
        catches(pid, 2) && dir.join("ref.exr.lock").exists()
    });
    let second = run(&args);
    refused(&second, "ref.exr", &["another stagelight run"]);
    signal(&first, "INT");
    let o = first.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(!dir.join("ref.exr.lock").exists());
}

// 16, 17 ----------------------------------------------------------------------------------

#[test]
fn a_camera_beyond_f32_is_refused() {
    let dir = temp_dir("hostile-camera");
    let path = dir.join("cam.ron");
    std::fs::write(
        &path,
        scene_text(&[FLOOR, LIGHT]).replace("position: (0, 1, -4)", "position: (0, 1, -1e39)"),
    )
    .unwrap();
    let o = run(&render_args(
        s(&path),
        s(&dir.join("o.exr")),
        &["--spp", "1"],
    ));
    refused(&o, "cam.ron:2", &["camera position"]);
}

#[test]
fn a_byte_order_mark_is_skipped() {
    let dir = temp_dir("hostile-bom");
    let path = dir.join("bom.ron");
    let mut bytes = "\u{feff}".as_bytes().to_vec();
    bytes.extend(scene_text(&[FLOOR, LIGHT]).bytes());
    std::fs::write(&path, bytes).unwrap();
    rendered(&run(&render_args(
        s(&path),
        s(&dir.join("o.exr")),
        &["--spp", "1"],
    )));
}

// 19, 20 ----------------------------------------------------------------------------------

#[test]
fn messages_say_what_is_wrong_in_one_short_line() {
    let dir = temp_dir("hostile-messages");
    let scene = write_scene(&dir, "s.ron", &[FLOOR, LIGHT]);
    let out = dir.join("o.exr");
    // A too-large spp budget is not "not a whole number".
    let o = run(&[
        "compare",
        s(&scene),
        "--budget-unit",
        "spp",
        "--budgets",
        "1e30",
        "-o",
        s(&dir.join("report")),
    ]);
    let line = refused(&o, "--budgets", &["too large"]);
    assert!(!line.contains("whole number"), "{line}");
    // A 300-digit number is not echoed whole.
    let digits = "9".repeat(300);
    for args in [
        render_args(s(&scene), s(&out), &["--spp", &digits]),
        render_args(s(&scene), s(&out), &["--threads", &digits]),
    ] {
        let o = run(&args);
        let line = refused(&o, "--", &[]);
        assert!(line.len() < 200, "{line}");
    }
    let o = run(&[
        "compare",
        s(&scene),
        &format!("--budgets=-{digits}"),
        "-o",
        s(&dir.join("report")),
    ]);
    let line = refused(&o, "--budgets", &[]);
    assert!(line.len() < 200, "{line}");
    // A scene that is not UTF-8 gets a position.
    let latin1 = dir.join("latin1.ron");
    let mut bytes = scene_text(&[FLOOR, LIGHT]).into_bytes();
    let at = bytes.len() - 4;
    bytes.insert(at, 0xe9);
    std::fs::write(&latin1, bytes).unwrap();
    let o = run(&render_args(s(&latin1), s(&out), &["--spp", "1"]));
    refused(&o, "latin1.ron:", &["UTF-8", "byte offset"]);
}

#[test]
fn echoed_names_are_cut_short() {
    let dir = temp_dir("hostile-long-name");
    let name = "m".repeat(1 << 20);
    let object =
        format!("(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"{name}\"),");
    let scene = write_scene(&dir, "long.ron", &[FLOOR, LIGHT, &object]);
    let o = run(&render_args(
        s(&scene),
        s(&dir.join("o.exr")),
        &["--spp", "1"],
    ));
    let line = refused(&o, "long.ron:7:1", &["unknown material"]);
    assert!(line.len() < 500, "{} bytes", line.len());
    // A name with a line break stays on one line.
    let object = "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"a\\nb\"),";
    let scene = write_scene(&dir, "newline.ron", &[FLOOR, LIGHT, object]);
    let o = run(&render_args(
        s(&scene),
        s(&dir.join("o.exr")),
        &["--spp", "1"],
    ));
    refused(&o, "newline.ron:7:1", &["unknown material"]);
}

// 21 --------------------------------------------------------------------------------------

#[test]
fn obj_faces_of_one_or_two_vertices_are_malformed_and_bad_normals_warn() {
    let dir = temp_dir("hostile-obj");
    let out = dir.join("o.exr");
    for (file, face) in [("two.obj", "f 1 2"), ("one.obj", "f 3")] {
        std::fs::write(
            dir.join(file),
            format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n{face}\n"),
        )
        .unwrap();
        let scene = write_scene(
            &dir,
            "mesh.ron",
            &[
                FLOOR,
                LIGHT,
                &format!("(shape: Obj(\"{file}\"), material: \"white\"),"),
            ],
        );
        let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
        refused(&o, "mesh.ron:7:1", &[file, "line 5", "malformed"]);
    }
    std::fs::write(
        dir.join("nan.obj"),
        "v -1 0.5 0\nv 1 0.5 0\nv 0 1.5 0\nvn nan 0 -1\nvn 0 0 -1\nf 1//1 2//2 3//2\n",
    )
    .unwrap();
    let scene = write_scene(
        &dir,
        "nan.ron",
        &[
            FLOOR,
            LIGHT,
            "(shape: Obj(\"nan.obj\"), material: \"white\"),",
        ],
    );
    let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
    rendered(&o);
    let err = stderr(&o);
    assert!(
        err.contains("warning:") && err.contains("nan.obj line 4") && err.contains("flat"),
        "{err}"
    );
}

// 22 --------------------------------------------------------------------------------------

/// A binary PLY cut anywhere is one line naming the mesh file, at the object; the whole file
/// renders.
#[test]
fn a_truncated_binary_ply_is_refused_and_the_whole_one_renders() {
    let dir = temp_dir("hostile-ply");
    let out = dir.join("o.exr");
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
                    property float y\nproperty float z\nelement face 1\n\
                    property list uchar uint vertex_indices\nend_header\n"
        .to_vec();
    for v in [-1.0f32, 0.5, 0.0, 1.0, 0.5, 0.0, 0.0, 1.5, 0.0] {
        ply.extend(v.to_le_bytes());
    }
    ply.push(3);
    for i in [0u32, 1, 2] {
        ply.extend(i.to_le_bytes());
    }
    let scene = write_scene(
        &dir,
        "ply.ron",
        &[
            FLOOR,
            LIGHT,
            "(shape: Ply(\"cut.ply\"), material: \"white\"),",
        ],
    );
    for cut in [ply.len() - 1, ply.len() - 13, 40] {
        std::fs::write(dir.join("cut.ply"), &ply[..cut]).unwrap();
        let o = run(&render_args(s(&scene), s(&out), &["--spp", "1"]));
        refused(&o, "ply.ron:7:1", &["cut.ply"]);
    }
    std::fs::write(dir.join("cut.ply"), &ply).unwrap();
    rendered(&run(&render_args(s(&scene), s(&out), &["--spp", "1"])));
}
