//! The report page in a real browser: headless Chromium opens a small comparison's
//! index.html from the disk, the page's self-test (`?selftest=`) drives it as a user would
//! (hover, F, the flip button, E, the exposure slider, the wheel, a drag, a click on a
//! side-by-side view, a column heading), and this test checks what it saw against the EXRs,
//! read here with the exr crate, and that a screenshot of it is not blank.
//!
//! Chromium is Debian's `chromium` (`.ci/run` installs it). Where it is missing the test
//! fails, saying so, unless STAGELIGHT_SKIP_BROWSER_TEST=1 skips it on purpose;
//! STAGELIGHT_CHROMIUM names another binary.

use crate::common::{TempDir, stagelight, stderr, temp_dir};
use stagelight::film::Image;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The Chromium to run, or None when the test is skipped on purpose; panics when it is missing
/// and not skipped.
fn chromium() -> Option<PathBuf> {
    if std::env::var("STAGELIGHT_SKIP_BROWSER_TEST").as_deref() == Ok("1") {
        eprintln!("SKIPPED: the browser test (STAGELIGHT_SKIP_BROWSER_TEST=1)");
        return None;
    }
    if let Ok(path) = std::env::var("STAGELIGHT_CHROMIUM") {
        return Some(PathBuf::from(path));
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    for name in ["chromium", "chromium-browser", "google-chrome"] {
        for dir in std::env::split_paths(&path) {
            let candidate = dir.join(name);
            if candidate.is_file() {
                return Some(candidate);
            }
        }
    }
    panic!(
        "the browser test needs Chromium, and none is on PATH (chromium, chromium-browser, \
         google-chrome): install Debian's package (`apt-get install chromium`, as root; \
         .ci/run does), name one with STAGELIGHT_CHROMIUM=/path, or skip this test on purpose \
         with STAGELIGHT_SKIP_BROWSER_TEST=1"
    );
}

/// What one headless Chromium run printed.
struct BrowserRun {
    stdout: String,
    stderr: String,
}

/// Runs headless Chromium on `page` (a file, with `query`) with `extra` arguments, its own
/// profile in `profile`, and a virtual time budget: scripts run until the page is idle.
fn run_chromium(
    chromium: &Path,
    profile: &Path,
    page: &Path,
    query: &str,
    extra: &[&str],
) -> BrowserRun {
    let url = format!(
        "file://{}?{query}",
        page.canonicalize().expect("the page exists").display()
    );
    let mut child = Command::new(chromium)
        .args([
            "--headless",
            // Root in CI: Chromium's sandbox refuses to start as root.
            "--no-sandbox",
            "--disable-gpu",
            "--no-first-run",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--v=0",
            "--window-size=1280,1100",
            "--virtual-time-budget=20000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(&url)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {}: {e}", chromium.display()));
    let out = child.stdout.take().unwrap();
    let err = child.stderr.take().unwrap();
    let read_out = std::thread::spawn(move || std::io::read_to_string(out).unwrap_or_default());
    let read_err = std::thread::spawn(move || std::io::read_to_string(err).unwrap_or_default());
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(90) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{} did not finish {url} in 90 s", chromium.display());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    BrowserRun {
        stdout: read_out.join().unwrap(),
        stderr: read_err.join().unwrap(),
    }
}

/// The text of the element that starts with `open` (up to its closing `close`), unescaped.
fn element_text<'a>(dom: &'a str, open: &str, close: &str) -> Option<(&'a str, String)> {
    let start = dom.find(open)?;
    let tag_end = start + dom[start..].find('>')?;
    let end = tag_end + dom[tag_end..].find(close)?;
    let text = dom[tag_end + 1..end]
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&nbsp;", "\u{a0}")
        .replace("&amp;", "&");
    Some((&dom[start..tag_end], text))
}

fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!("{name}=\"");
    let start = tag.find(&key)? + key.len();
    Some(&tag[start..start + tag[start..].find('"')?])
}

/// The floats the readout showed ("r g b"), each read back as f32.
fn readout_floats(probe: &serde_json::Value) -> Vec<f32> {
    probe["rgb"]
        .as_str()
        .unwrap_or_else(|| panic!("a readout without values: {probe}"))
        .split(' ')
        .map(|v| {
            v.parse::<f32>()
                .unwrap_or_else(|_| panic!("not a float: {v}"))
        })
        .collect()
}

/// Three pixels to read out: distinct non-zero values, at places where a transposed or
/// flipped coordinate would read another value.
fn probe_pixels(image: &Image) -> Vec<(usize, usize)> {
    let (w, h) = (image.width, image.height);
    let at = |x: usize, y: usize| image.pixels[y * w + x];
    let lit: Vec<(usize, usize)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| at(x, y).x > 0.0 && at(x, y).y > 0.0)
        .collect();
    assert!(lit.len() > 10, "the test image is almost black");
    let brightest = *lit
        .iter()
        .max_by(|a, b| at(a.0, a.1).x.total_cmp(&at(b.0, b.1).x))
        .unwrap();
    let mut chosen = vec![brightest, lit[lit.len() / 3], lit[lit.len() - 1]];
    chosen.dedup();
    assert_eq!(chosen.len(), 3, "three distinct pixels: {chosen:?}");
    chosen
}

/// Opens `html` in Chromium with the self-test reading out `probes`; checks that no script
/// failed and that the page decoded `images` images. Returns what the self-test saw.
fn self_test(
    chromium: &Path,
    html: &Path,
    probes: &[(usize, usize)],
    images: usize,
) -> Result<serde_json::Value, String> {
    let query = format!(
        "selftest={}",
        probes
            .iter()
            .map(|(x, y)| format!("{x},{y}"))
            .collect::<Vec<_>>()
            .join(";")
    );
    let profile = html.with_file_name("browser-profile");
    let run = run_chromium(chromium, &profile, html, &query, &["--dump-dom"]);
    if let Some(line) = run.stderr.lines().find(|l| l.contains("Uncaught")) {
        return Err(format!("a script error in the browser's console: {line}"));
    }
    let (status_tag, status_text) = element_text(&run.stdout, "<p id=\"status\"", "</p>")
        .ok_or_else(|| format!("no status line in the page: {:.2000}", run.stdout))?;
    if attribute(status_tag, "data-errors") != Some("0") {
        return Err(format!("the page reported errors: {status_text}"));
    }
    if attribute(status_tag, "data-ready") != Some("1") {
        return Err(format!("the page never finished loading: {status_text}"));
    }
    if attribute(status_tag, "data-decoded") != Some(images.to_string().as_str()) {
        return Err(format!("not every image decoded: {status_tag}"));
    }
    let (_, json) = element_text(&run.stdout, "<pre id=\"selftest\"", "</pre>")
        .ok_or("no #selftest element")?;
    let seen: serde_json::Value =
        serde_json::from_str(&json).map_err(|e| format!("the self-test wrote {json:?}: {e}"))?;
    if seen["errors"].as_array().is_none_or(|e| !e.is_empty()) {
        return Err(format!("script errors: {}", seen["errors"]));
    }
    Ok(seen)
}

/// Checks that the readout at `probes` showed `image`'s floats, bit for bit.
fn check_readout(
    seen: &serde_json::Value,
    probes: &[(usize, usize)],
    image: &Image,
    name: &str,
) -> Result<(), String> {
    let shown = seen["probes"].as_array().ok_or("no probes")?;
    if shown.len() != probes.len() {
        return Err(format!(
            "{} readouts for {} pixels",
            shown.len(),
            probes.len()
        ));
    }
    for ((x, y), probe) in probes.iter().zip(shown) {
        let exr = image.pixels[y * image.width + x];
        let expected = vec![exr.x, exr.y, exr.z];
        if (probe["x"].as_u64(), probe["y"].as_u64()) != (Some(*x as u64), Some(*y as u64))
            || readout_floats(probe) != expected
        {
            return Err(format!(
                "readout at ({x}, {y}): {probe}, but {name} has {expected:?}"
            ));
        }
    }
    Ok(())
}

/// Everything the page must have done, checked against the report folder `dir` (a compare
/// of pt and bdpt at 1 and 2 spp). Err names the first problem.
fn check_page(chromium: &Path, dir: &Path) -> Result<(), String> {
    let shown = Image::read_exr(&dir.join("runs/pt_1_spp.exr")).map_err(|e| e.to_string())?;
    let reference = Image::read_exr(&dir.join("reference.exr")).map_err(|e| e.to_string())?;
    let probes = probe_pixels(&shown);
    let seen = self_test(chromium, &dir.join("index.html"), &probes, 5)?;

    // Every image decoded to its full float array, with the relMSE of results.csv: the page's
    // floats are the runs' own.
    let csv = std::fs::read_to_string(dir.join("results.csv")).map_err(|e| e.to_string())?;
    let csv_relmse: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(10).unwrap().parse().unwrap())
        .collect();
    let images = seen["images"]
        .as_array()
        .ok_or("no images in the self-test")?;
    let values = (shown.width * shown.height * 3) as u64;
    for (k, image) in images.iter().enumerate() {
        if image["values"].as_u64() != Some(values) {
            return Err(format!("{image}: not {values} floats"));
        }
        if k > 0 {
            let (page, expected) = (image["relmse"].as_f64().unwrap_or(-1.0), csv_relmse[k - 1]);
            if (page - expected).abs() > 1e-9 * expected.max(1e-30) {
                return Err(format!(
                    "{image}: relMSE {page}, results.csv has {expected}"
                ));
            }
        }
    }

    // The readout at the three pixels: the EXR's floats, bit for bit.
    check_readout(&seen, &probes, &shown, "runs/pt_1_spp.exr")?;

    // The flip shows the reference, with its floats, and the button flips back.
    let flip = &seen["flip"];
    if flip["shownWhenFlipped"] != "reference" || flip["shownAfterButton"] != seen["shown"] {
        return Err(format!(
            "the flip did not show the reference and back: {flip}"
        ));
    }
    if flip["image"]["hash"] == flip["flipped"]["hash"] {
        return Err(format!("the flip did not change the shown image: {flip}"));
    }
    let (x, y) = probes[0];
    let r = reference.pixels[y * reference.width + x];
    if readout_floats(&flip["probeWhenFlipped"]) != vec![r.x, r.y, r.z] {
        return Err(format!(
            "the flipped readout {} is not reference.exr's {r}",
            flip["probeWhenFlipped"]
        ));
    }
    for (what, digest) in [
        ("error map", &seen["errorMap"]["digest"]),
        ("exposure", &seen["exposure"]["digest"]),
    ] {
        if digest["hash"] == flip["back"]["hash"] && digest["hash"] == flip["image"]["hash"] {
            return Err(format!("the {what} did not change the image: {seen}"));
        }
    }
    if !seen["errorMap"]["label"]
        .as_str()
        .is_some_and(|l| l.contains("error map"))
    {
        return Err(format!(
            "the error map is not labelled: {}",
            seen["errorMap"]
        ));
    }

    // The wheel zoomed every view together: one zoom, the same pixel at each centre.
    let zoom = &seen["zoom"];
    let centres = zoom["centres"].as_array().ok_or("no zoom centres")?;
    if zoom["after"].as_f64() <= zoom["before"].as_f64()
        || centres.len() != 4
        || centres.iter().any(|c| c != &centres[0])
    {
        return Err(format!(
            "the wheel did not zoom every view together: {zoom}"
        ));
    }
    if zoom["strip"] != serde_json::json!(["image-000", "image-002", "reference"]) {
        return Err(format!(
            "the side-by-side views are not pt, bdpt and the reference: {zoom}"
        ));
    }

    // A drag of (40, 20) screen pixels moved the centre back by that many image pixels over
    // the zoom; a click on bdpt's side-by-side view showed bdpt.
    let pan = &seen["pan"];
    let zoom_now = pan["zoom"].as_f64().unwrap_or(0.0);
    let moved = |k: usize| {
        pan["after"][k].as_f64().unwrap_or(0.0) - pan["before"][k].as_f64().unwrap_or(0.0)
    };
    if (moved(0) + 40.0 / zoom_now).abs() > 1e-9 || (moved(1) + 20.0 / zoom_now).abs() > 1e-9 {
        return Err(format!("the drag did not pan: {pan}"));
    }
    let click = &seen["stripClick"];
    if click["clicked"] != "image-002" || click["shown"] != "image-002" {
        return Err(format!("a click on bdpt's view did not show it: {click}"));
    }

    // The relMSE column sorts ascending on a click.
    let sorted: Vec<f64> = seen["sortedRelmse"]
        .as_array()
        .ok_or("the table was not sorted")?
        .iter()
        .map(|v| v.as_str().unwrap_or("nan").parse().unwrap_or(f64::NAN))
        .collect();
    // NaN (an unreadable cell) fails too: it is not sorted after anything.
    if sorted.len() != 4 || !sorted.is_sorted_by(|a, b| a <= b) {
        return Err(format!("the relMSE column did not sort: {sorted:?}"));
    }

    // A screenshot of the page zoomed in, with a readout: not blank.
    let shot = dir.join("screenshot.png");
    run_chromium(
        chromium,
        &dir.join("browser-profile"),
        &dir.join("index.html"),
        "demo=2",
        &[&format!("--screenshot={}", shot.display())],
    );
    let colours = distinct_colours(&shot)?;
    if colours < 200 {
        return Err(format!(
            "the screenshot {} is nearly blank: {colours} colours",
            shot.display()
        ));
    }
    Ok(())
}

/// The number of distinct colours in a PNG.
fn distinct_colours(path: &Path) -> Result<usize, String> {
    let file = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let mut buffer = vec![0; reader.output_buffer_size().unwrap_or(0)];
    let info = reader
        .next_frame(&mut buffer)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let channels = info.color_type.samples();
    let colours: std::collections::HashSet<&[u8]> =
        buffer[..info.buffer_size()].chunks(channels).collect();
    Ok(colours.len())
}

/// A small comparison's report folder: torus_glass at 48x36 (not square, so that a
/// transposed coordinate reads another pixel), pt and bdpt at 1 and 2 spp; with the folder
/// that holds it, which the caller keeps while it reads the report.
fn small_report(name: &str) -> (TempDir, PathBuf) {
    let dir = temp_dir(name);
    let scene = std::fs::read_to_string(crate::common::scene_path("torus_glass.ron")).unwrap();
    let scene = scene.replacen("camera: (", "camera: (\n width: 48,\n height: 36,", 1);
    std::fs::write(dir.join("scene.ron"), scene).unwrap();
    let report = dir.join("report");
    let out = stagelight(&[
        "compare",
        dir.join("scene.ron").to_str().unwrap(),
        "--integrators",
        "pt,bdpt",
        "--budgets",
        "1,2",
        "--budget-unit",
        "spp",
        "--reference-spp",
        "16",
        "--threads",
        "1",
        "--quiet",
        "-o",
        report.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    (dir, report)
}

#[test]
fn report_page_works_in_chromium() {
    let Some(chromium) = chromium() else { return };
    let (_dir, report) = small_report("report-page");
    if let Err(problem) = check_page(&chromium, &report) {
        panic!("{}/index.html: {problem}", report.display());
    }
}

#[test]
fn broken_report_pages_fail_the_browser_check() {
    let Some(chromium) = chromium() else { return };
    let (_dir, report) = small_report("report-page-broken");
    // A corrupted image: its float data cut short.
    let data = report.join("index_data/image-001.js");
    let text = std::fs::read_to_string(&data).unwrap();
    std::fs::write(&data, &text[..text.len() / 2]).unwrap();
    let problem = check_page(&chromium, &report).expect_err("a cut image passes");
    eprintln!("cut image data: {problem}");
    assert!(problem.contains("error"), "{problem}");
    std::fs::write(&data, text).unwrap();
    check_page(&chromium, &report).expect("the repaired page passes");
    // A script error in the page.
    let html = report.join("index.html");
    let page = std::fs::read_to_string(&html).unwrap();
    std::fs::write(
        &html,
        page.replacen("function fit() {", "function fit() { no_such();", 1),
    )
    .unwrap();
    let problem = check_page(&chromium, &report).expect_err("a script error passes");
    eprintln!("script error: {problem}");
    assert!(problem.contains("no_such"), "{problem}");
}

#[test]
fn view_writes_the_viewer_for_any_images() {
    let Some(chromium) = chromium() else { return };
    let (_dir, report) = small_report("view-page");
    let html = report.join("pages/view.html");
    let out = stagelight(&[
        "view",
        report.join("runs/bdpt_2_spp.exr").to_str().unwrap(),
        report.join("runs/pt_2_spp.exr").to_str().unwrap(),
        "--reference",
        report.join("reference.exr").to_str().unwrap(),
        "-o",
        html.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(report.join("pages/view_data/reference.js").is_file());
    let bdpt = Image::read_exr(&report.join("runs/bdpt_2_spp.exr")).unwrap();
    let probes = probe_pixels(&bdpt);
    let seen = self_test(&chromium, &html, &probes, 3).unwrap_or_else(|e| panic!("{e}"));
    check_readout(&seen, &probes, &bdpt, "runs/bdpt_2_spp.exr").unwrap();
    assert_eq!(seen["flip"]["shownWhenFlipped"], "reference", "{seen}");
    assert_eq!(
        seen["zoom"]["strip"],
        serde_json::json!(["image-000", "image-001", "reference"])
    );
}

#[test]
fn view_refuses_bad_input_naming_the_file() {
    let dir = temp_dir("view-bad-input");
    let small = dir.join("small.exr");
    let big = dir.join("big.exr");
    Image::new(4, 3).write_exr(&small).unwrap();
    Image::new(5, 3).write_exr(&big).unwrap();
    std::fs::write(dir.join("junk.exr"), b"not an exr").unwrap();
    let (junk, missing) = (dir.join("junk.exr"), dir.join("missing.exr"));
    let page = dir.join("page.html");
    let page_arg = page.to_str().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (&[small.to_str().unwrap()], "two images at least"),
        (
            &[small.to_str().unwrap(), big.to_str().unwrap()],
            "big.exr: 5x3, but the reference",
        ),
        (
            &[small.to_str().unwrap(), junk.to_str().unwrap()],
            "junk.exr",
        ),
        (
            &[small.to_str().unwrap(), missing.to_str().unwrap()],
            "missing.exr",
        ),
    ];
    for (images, message) in cases {
        let mut args = vec!["view"];
        args.extend(images);
        args.extend(["-o", page_arg]);
        let out = stagelight(&args);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(message), "{args:?}: {}", stderr(&out));
        assert!(!stderr(&out).contains("panicked"), "{}", stderr(&out));
    }
    assert!(!page.exists());
}
