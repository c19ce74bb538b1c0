//! Fuzzing on stable Rust: a structure-aware mutator drives the targets of
//! `tests/fuzz/targets.rs` from the seed corpus in `tests/fuzz/corpus/<target>/` (and, for
//! scenes, `scenes/`). Inputs whose outcome has a new signature (a new kind of error or of
//! success) join the corpus in memory, a cheap feedback that steers the search past the
//! first error messages.
//!
//! By default each target runs a fixed, seeded number of inputs (what `cargo nextest run`
//! and CI run: a few seconds). For longer runs:
//!
//!     STAGELIGHT_FUZZ_SECONDS=600 STAGELIGHT_FUZZ_SEED=7 cargo nextest run fuzz_ --no-capture
//!
//! A panic (or a broken invariant) fails the test, naming the seed, the input number and the
//! file the input was saved to (`target/tmp/fuzz-findings/`); the input being run is also
//! kept in `<target>-current.bin` there, so an abort (an allocation failure kills the
//! process) leaves it behind too.

use crate::fuzz_targets as targets;
use std::collections::HashSet;
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// A small, fast generator (SplitMix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
    fn chance(&mut self, one_in: usize) -> bool {
        self.below(one_in) == 0
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// Inputs are kept below this size.
const MAX_INPUT: usize = 64 << 10;
/// An input slower than this is a finding (a quadratic path, a near-endless loop).
const SLOW: Duration = Duration::from_secs(10);
/// Inputs kept in memory at most (the seeds always stay).
const MAX_CORPUS: usize = 4000;

type Mutator = fn(&mut Rng, &[u8], &[Vec<u8>]) -> Vec<u8>;

/// Runs `target` on mutants of `seeds` (and the seeds themselves first).
fn fuzz(name: &str, seeds: Vec<Vec<u8>>, mutate: Mutator, target: fn(&[u8]) -> String) {
    assert!(!seeds.is_empty(), "{name}: no seeds");
    let seed: u64 = std::env::var("STAGELIGHT_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(18);
    let seconds: Option<f64> = std::env::var("STAGELIGHT_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok());
    let iterations: usize = std::env::var("STAGELIGHT_FUZZ_ITERATIONS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1500);
    let findings = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-findings");
    std::fs::create_dir_all(&findings).unwrap();
    let current = findings.join(format!("{name}-current.bin"));
    let mut rng = Rng(seed ^ name.bytes().fold(0, |h, b| h * 31 + b as u64));
    let mut corpus = seeds.clone();
    let mut seen: HashSet<String> = HashSet::new();
    let start = Instant::now();
    let mut slowest = (Duration::ZERO, 0usize);
    let mut run = 0usize;
    loop {
        let done = match seconds {
            Some(s) => start.elapsed().as_secs_f64() >= s,
            None => run >= iterations + seeds.len(),
        };
        if done {
            break;
        }
        let input = if run < seeds.len() {
            seeds[run].clone()
        } else {
            let base = rng.pick(&corpus).clone();
            let mut input = mutate(&mut rng, &base, &corpus);
            // A few stacked mutations now and then.
            while rng.chance(3) {
                input = mutate(&mut rng, &input, &corpus);
            }
            input.truncate(MAX_INPUT);
            input
        };
        let _ = std::fs::write(&current, &input);
        let t = Instant::now();
        let outcome = std::panic::catch_unwind(AssertUnwindSafe(|| target(&input)));
        let took = t.elapsed();
        let finding = |what: &str| {
            let file = findings.join(format!("{name}-seed{seed}-input{run}.bin"));
            std::fs::write(&file, &input).unwrap();
            panic!(
                "fuzz target {name}: {what} (seed {seed}, input {run}); the input is in {}",
                file.display()
            );
        };
        match outcome {
            Ok(signature) => {
                if seen.insert(signature) && run >= seeds.len() {
                    if corpus.len() >= MAX_CORPUS {
                        let k = seeds.len() + rng.below(corpus.len() - seeds.len());
                        corpus[k] = input.clone();
                    } else {
                        corpus.push(input.clone());
                    }
                }
            }
            Err(_) => finding("panicked"),
        }
        if took > SLOW {
            finding(&format!("took {took:?}"));
        }
        if took > slowest.0 {
            slowest = (took, run);
        }
        run += 1;
    }
    let _ = std::fs::remove_file(&current);
    eprintln!(
        "fuzz {name}: {run} inputs in {:.1} s, {} outcome kinds, corpus {}, slowest {:?} \
         (input {})",
        start.elapsed().as_secs_f64(),
        seen.len(),
        corpus.len(),
        slowest.0,
        slowest.1
    );
}

/// The seed files of a target.
fn corpus(name: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz/corpus")
        .join(name);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files.iter().map(|f| std::fs::read(f).unwrap()).collect()
}

// ----------------------------------------------------------------------- generic mutations

const INTERESTING_BYTES: &[u8] = b"\0\xff\x7f\x80\n\r\t ()[]{},:\"'/*#-+.0123456789eE\\";

/// A mutation of any bytes: bit flips, interesting bytes, insertions, deletions,
/// duplications, splices with another input, truncation.
fn mutate_bytes(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut v = input.to_vec();
    let len = v.len();
    match rng.below(8) {
        0 if len > 0 => {
            let i = rng.below(len);
            v[i] ^= 1 << rng.below(8);
        }
        1 if len > 0 => {
            let i = rng.below(len);
            v[i] = *rng.pick(INTERESTING_BYTES);
        }
        2 => {
            let i = rng.below(len + 1);
            let n = 1 + rng.below(8);
            for _ in 0..n {
                v.insert(i, rng.next() as u8);
            }
        }
        3 if len > 0 => {
            let i = rng.below(len);
            let n = 1 + rng.below((len - i).min(64));
            v.drain(i..i + n);
        }
        4 if len > 0 => {
            let i = rng.below(len);
            let n = 1 + rng.below((len - i).min(256));
            let piece = v[i..i + n].to_vec();
            let at = rng.below(len + 1);
            v.splice(at..at, piece);
        }
        5 => {
            let other = rng.pick(corpus);
            if !other.is_empty() {
                let i = rng.below(other.len());
                let n = 1 + rng.below((other.len() - i).min(512));
                let at = rng.below(len + 1);
                let cut = rng.below((len - at).min(512) + 1);
                v.splice(at..at + cut, other[i..i + n].iter().copied());
            }
        }
        6 if len > 0 => v.truncate(rng.below(len)),
        _ => {
            let i = rng.below(len + 1);
            v.splice(i..i, rng.pick(NUMBERS).bytes());
        }
    }
    v
}

/// Numbers at the edges: zero, signs, f32 and integer limits, tiny and huge values.
const NUMBERS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "2",
    "3",
    "4",
    "8",
    "0.5",
    "255",
    "4096",
    "4097",
    "16384",
    "16385",
    "65536",
    "4294967295",
    "4294967296",
    "-2147483648",
    "18446744073709551615",
    "18446744073709551616",
    "1e-45",
    "1e-38",
    "2e-23",
    "1e-7",
    "1e12",
    "1e19",
    "1e30",
    "1e34",
    "1e38",
    "3.5e38",
    "1e39",
    "1e300",
    "-1e300",
    "NaN",
    "inf",
    "-inf",
    "1.0e",
    "99999999999999999999999999999999999999999",
];

// ------------------------------------------------------------------------ text mutations

/// Splits text into tokens: numbers, words, strings, and single other bytes.
fn tokens(text: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < text.len() {
        let c = text[i];
        let start = i;
        if c.is_ascii_digit()
            || ((c == b'-' || c == b'.') && i + 1 < text.len() && text[i + 1].is_ascii_digit())
        {
            i += 1;
            while i < text.len()
                && (text[i].is_ascii_digit()
                    || matches!(text[i], b'.' | b'e' | b'E')
                    || ((text[i] == b'-' || text[i] == b'+') && matches!(text[i - 1], b'e' | b'E')))
            {
                i += 1;
            }
        } else if c.is_ascii_alphabetic() || c == b'_' {
            while i < text.len() && (text[i].is_ascii_alphanumeric() || text[i] == b'_') {
                i += 1;
            }
        } else if c == b'"' {
            i += 1;
            while i < text.len() && text[i] != b'"' {
                i += if text[i] == b'\\' { 2 } else { 1 };
            }
            i = (i + 1).min(text.len());
        } else {
            i += 1;
        }
        out.push(start..i);
    }
    out
}

/// The words of the scene format.
const SCENE_WORDS: &[&str] = &[
    "Scene",
    "camera",
    "materials",
    "objects",
    "position",
    "look_at",
    "up",
    "fov",
    "width",
    "height",
    "Diffuse",
    "Dielectric",
    "Conductor",
    "reflectance",
    "ior",
    "alpha",
    "shape",
    "material",
    "emission",
    "transform",
    "flip_normals",
    "name",
    "Quad",
    "Triangle",
    "Box",
    "min",
    "max",
    "Icosphere",
    "level",
    "smooth",
    "Torus",
    "major_radius",
    "minor_radius",
    "nu",
    "nv",
    "Obj",
    "Translate",
    "Rotate",
    "axis",
    "degrees",
    "Scale",
    "Some",
    "None",
    "true",
    "false",
];

const SCENE_STRINGS: &[&str] = &[
    "\"\"",
    "\"white\"",
    "\"light\"",
    "\"a\\nb\"",
    "\"meshes/none.obj\"",
    "\"/dev/zero\"",
    "\"/\"",
    "\"\\u{feff}\"",
];

const SCENE_SNIPPETS: &[&str] = &[
    "#![enable(implicit_some)]\n",
    "\u{feff}",
    "/*",
    "*/",
    "//",
    "(shape: Quad((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), material: \"white\"),",
    "(shape: Triangle((0, 0, 0), (1, 0, 0), (0, 1, 0)), material: \"white\", emission: Some((1, 1, 1))),",
    "(shape: Icosphere(level: 5), material: \"white\", transform: [Scale(1e-20)]),",
    "(shape: Torus(major_radius: 1, minor_radius: 0.5, nu: 200, nv: 200), material: \"white\"),",
    "(shape: Box(min: (-1e11, 0, 0), max: (1e11, 1, 1)), material: \"white\", flip_normals: true),",
    "\"m\": Conductor(alpha: 1e-30, reflectance: (1, 1, 1)),",
    "\"g\": Dielectric(ior: 1e30),",
    "transform: [Rotate(axis: (0, 1e-300, 0), degrees: 1e300)],",
];

/// A mutation of RON text that knows its tokens: numbers swapped for edge values, words for
/// the format's words, strings for awkward ones, parts of the file duplicated or removed,
/// snippets inserted; else a byte-level mutation.
fn mutate_ron(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let toks = tokens(input);
    if toks.is_empty() || rng.chance(4) {
        return mutate_bytes(rng, input, corpus);
    }
    let mut v = input.to_vec();
    let t = toks[rng.below(toks.len())].clone();
    let first = input[t.start];
    match rng.below(6) {
        0 | 1 => {
            // Replace a token of the same kind.
            let with: String = if first.is_ascii_digit() || first == b'-' || first == b'.' {
                rng.pick(NUMBERS).to_string()
            } else if first.is_ascii_alphabetic() {
                rng.pick(SCENE_WORDS).to_string()
            } else if first == b'"' {
                if rng.chance(8) {
                    format!("\"{}\"", "x".repeat(1 + rng.below(20_000)))
                } else {
                    rng.pick(SCENE_STRINGS).to_string()
                }
            } else {
                (*rng.pick(INTERESTING_BYTES) as char).to_string()
            };
            v.splice(t, with.bytes());
        }
        2 => {
            // Duplicate a run of tokens (an object, a field).
            let end = toks
                [(toks.iter().position(|x| *x == t).unwrap() + rng.below(40)).min(toks.len() - 1)]
            .end;
            let piece = input[t.start..end].to_vec();
            let at = toks[rng.below(toks.len())].start;
            v.splice(at..at, piece);
        }
        3 => {
            // Remove a run of tokens.
            let end = toks
                [(toks.iter().position(|x| *x == t).unwrap() + rng.below(20)).min(toks.len() - 1)]
            .end;
            v.drain(t.start..end);
        }
        4 => {
            let at = if rng.chance(4) { 0 } else { t.start };
            v.splice(at..at, rng.pick(SCENE_SNIPPETS).bytes());
        }
        _ => return mutate_bytes(rng, input, corpus),
    }
    v
}

// ------------------------------------------------------------------------- OBJ mutations

const OBJ_LINES: &[&str] = &[
    "f 1 2",
    "f 1",
    "f",
    "f 1 2 3",
    "f -1 -2 -3",
    "f 1/1/1 2/2/2 3/3/3",
    "f 1//1 2//1 3//1",
    "f 1/1 2/1 3/1",
    "f 0 1 2",
    "f 1 2 99999",
    "f -99999 1 2",
    "f 1/2/3/4 2 3",
    "v 3e38 0 0",
    "v nan 0 0",
    "v inf 0 0",
    "v 1e12 0 0",
    "v 1e-40 0 0",
    "v 1 2",
    "v 0 0 0 1 1 1",
    "vn nan 0 0",
    "vn 0 0 0",
    "vn 0 1 0",
    "vn 1e39 0 0",
    "vt 0 0",
    "o x",
    "g",
    "s 1",
    "usemtl m",
    "mtllib x.mtl",
    "l 1 2",
    "p 1",
    "# comment",
    "\\",
    "f 1 2 3 \\",
];

/// A mutation of an OBJ file by lines: numbers swapped for edge values, lines duplicated,
/// removed or inserted (short faces, bad vertices and normals, long polygons); else a
/// byte-level mutation.
fn mutate_obj(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut lines: Vec<Vec<u8>> = input.split(|&b| b == b'\n').map(|l| l.to_vec()).collect();
    if rng.chance(5) {
        return mutate_bytes(rng, input, corpus);
    }
    let i = rng.below(lines.len());
    match rng.below(6) {
        0 => {
            let toks = tokens(&lines[i]);
            let numbers: Vec<_> = toks
                .into_iter()
                .filter(|t| lines[i][t.start].is_ascii_digit() || lines[i][t.start] == b'-')
                .collect();
            if !numbers.is_empty() {
                let t = numbers[rng.below(numbers.len())].clone();
                lines[i].splice(t, rng.pick(NUMBERS).bytes());
            }
        }
        1 => {
            let line = lines[i].clone();
            lines.insert(rng.below(lines.len() + 1), line);
        }
        2 if lines.len() > 1 => {
            lines.remove(i);
        }
        3 => {
            let longest = if rng.chance(4) { 5000 } else { 40 };
            let n = 3 + rng.below(longest);
            let mut face = String::from("f");
            for k in 0..n {
                face += &format!(" {}", 1 + (k % 8));
            }
            lines.insert(i, face.into_bytes());
        }
        _ => lines.insert(i, rng.pick(OBJ_LINES).as_bytes().to_vec()),
    }
    lines.join(&b'\n')
}

// ------------------------------------------------------------------------- PLY mutations

/// Header lines a PLY mutant may gain: other formats, types, counts and elements.
const PLY_LINES: &[&str] = &[
    "format ascii 1.0",
    "format binary_little_endian 1.0",
    "format binary_big_endian 1.0",
    "format binary_middle_endian 1.0",
    "element vertex 4294967296",
    "element vertex 0",
    "element face 1",
    "element face 99999999",
    "element tristrips 1",
    "property float x",
    "property double nx",
    "property uchar red",
    "property list uchar int vertex_indices",
    "property list uint uint vertex_indices",
    "property list int int vertex_index",
    "property list uchar float vertex_indices",
    "property list uchar char vertex_indices",
    "comment x",
    "obj_info y",
    "end_header",
    "ply",
];

/// A mutation of a PLY file: a header line replaced, inserted, duplicated or removed; in the
/// ASCII body a number changed or a face of many vertices added; else a byte-level mutation
/// (for binary payloads above all).
fn mutate_ply(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let end = input
        .windows(11)
        .position(|w| w == b"end_header\n")
        .map_or(input.len(), |p| p + 11);
    if rng.chance(3) {
        return mutate_bytes(rng, input, corpus);
    }
    let (header, body) = input.split_at(end);
    let mut lines: Vec<Vec<u8>> = header
        .split(|&b| b == b'\n')
        .filter(|l| !l.is_empty())
        .map(|l| l.to_vec())
        .collect();
    let ascii = header.windows(5).any(|w| w == b"ascii");
    let mut body = body.to_vec();
    let i = rng.below(lines.len().max(1));
    match rng.below(6) {
        0 if !lines.is_empty() => lines[i] = rng.pick(PLY_LINES).as_bytes().to_vec(),
        1 => lines.insert(i.min(lines.len()), rng.pick(PLY_LINES).as_bytes().to_vec()),
        2 if lines.len() > 1 => {
            lines.remove(i);
        }
        3 if ascii => {
            let toks = tokens(&body);
            let numbers: Vec<_> = toks
                .into_iter()
                .filter(|t| body[t.start].is_ascii_digit() || body[t.start] == b'-')
                .collect();
            if !numbers.is_empty() {
                let t = numbers[rng.below(numbers.len())].clone();
                body.splice(t, rng.pick(NUMBERS).bytes());
            }
        }
        4 if ascii => {
            let longest = if rng.chance(4) { 3000 } else { 40 };
            let n = 3 + rng.below(longest);
            let mut face = format!("{n}");
            for k in 0..n {
                face += &format!(" {}", k % 4);
            }
            face.push('\n');
            body.extend_from_slice(face.as_bytes());
        }
        _ => {
            // A count changed.
            let counted: Vec<usize> = (0..lines.len())
                .filter(|&k| lines[k].starts_with(b"element "))
                .collect();
            if !counted.is_empty() {
                let k = counted[rng.below(counted.len())];
                let name = lines[k]
                    .split(|&b| b == b' ')
                    .nth(1)
                    .unwrap_or_default()
                    .to_vec();
                lines[k] = [
                    b"element ".as_slice(),
                    &name,
                    b" ",
                    rng.pick(NUMBERS).as_bytes(),
                ]
                .concat();
            }
        }
    }
    let mut out = lines.join(&b'\n');
    out.push(b'\n');
    out.extend_from_slice(&body);
    out
}

// ------------------------------------------------------------------------- EXR mutations

const EXR_ATTRIBUTES: &[&[u8]] = &[
    b"dataWindow\0box2i\0",
    b"displayWindow\0box2i\0",
    b"channels\0chlist\0",
    b"compression\0compression\0",
    b"lineOrder\0lineOrder\0",
    b"pixelAspectRatio\0float\0",
    b"screenWindowWidth\0float\0",
];

const I32S: &[i32] = &[
    0,
    1,
    -1,
    2,
    7,
    8,
    15,
    16,
    255,
    256,
    16383,
    16384,
    65535,
    99_999,
    1 << 20,
    1 << 30,
    i32::MAX,
    i32::MIN,
    i32::MAX - 1,
];

/// A mutation of an EXR file that knows its header: an attribute's size or one of its i32
/// values set to an edge value (the data window above all), a u64 of the offset table or a
/// chunk's size changed, the file truncated; else a byte-level mutation.
fn mutate_exr(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut v = input.to_vec();
    let attribute = rng.pick(EXR_ATTRIBUTES);
    let at = v.windows(attribute.len()).position(|w| w == *attribute);
    match (rng.below(5), at) {
        (0 | 1, Some(at)) => {
            // One of the value's i32s (the size field is the first).
            let k = at + attribute.len() + 4 * rng.below(5);
            if k + 4 <= v.len() {
                v[k..k + 4].copy_from_slice(&rng.pick(I32S).to_le_bytes());
            }
        }
        (2, _) if v.len() >= 8 => {
            // A u64 of the offset table, or any aligned word after the header.
            let k = rng.below(v.len() - 7);
            let value: u64 = match rng.below(4) {
                0 => 0,
                1 => u64::MAX,
                2 => v.len() as u64 + rng.below(64) as u64,
                _ => rng.below(v.len()) as u64,
            };
            v[k..k + 8].copy_from_slice(&value.to_le_bytes());
        }
        (3, _) if !v.is_empty() => v.truncate(rng.below(v.len())),
        _ => return mutate_bytes(rng, input, corpus),
    }
    v
}

// ------------------------------------------------------------------ checkpoint mutations

const CHECKPOINT_WORDS: &[&str] = &[
    "integrator",
    "seed",
    "max_depth",
    "scene",
    "scene_fingerprint",
    "width",
    "height",
    "passes",
    "seconds",
    "nonfinite",
    "nonfinite_splats",
    "first_pass",
    "shard",
    "end_pass",
    "total_passes",
    "made_by",
    "render",
    "settings",
    "pt",
    "bdpt",
    "sppm",
    "extra",
];

/// FNV-1a 64, as checkpoints use it.
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// A mutation of a checkpoint that mostly keeps its checksum right, so that the checks
/// behind it are reached: the header's text mutated as RON (numbers, field names), a pixel's
/// f64 or count set to an edge value, the version switched; then the checksum recomputed
/// for the file's version (four times in five).
fn mutate_checkpoint(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    const MAGIC4: &[u8] = b"stagelight checkpoint 4\n";
    const MAGIC3: &[u8] = b"stagelight checkpoint 3\n";
    const MAGIC2: &[u8] = b"stagelight checkpoint 2\n";
    let Some(&original) = [MAGIC4, MAGIC3, MAGIC2]
        .iter()
        .find(|m| input.starts_with(m))
    else {
        return mutate_bytes(rng, input, corpus);
    };
    if input.len() < MAGIC3.len() + 8 {
        return mutate_bytes(rng, input, corpus);
    }
    let body = &input[MAGIC3.len()..input.len() - 8];
    let Some(newline) = body.iter().position(|&b| b == b'\n') else {
        return mutate_bytes(rng, input, corpus);
    };
    let mut header = body[..newline].to_vec();
    let mut payload = body[newline + 1..].to_vec();
    let mut magic = original;
    match rng.below(6) {
        0 | 1 => header = mutate_ron(rng, &header, corpus),
        2 => {
            let toks = tokens(&header);
            let words: Vec<_> = toks
                .into_iter()
                .filter(|t| header[t.start].is_ascii_alphabetic())
                .collect();
            if !words.is_empty() {
                let t = words[rng.below(words.len())].clone();
                header.splice(t, rng.pick(CHECKPOINT_WORDS).bytes());
            }
        }
        3 if payload.len() >= 8 => {
            let k = 8 * rng.below(payload.len() / 8);
            let value: [u8; 8] = match rng.below(5) {
                0 => f64::NAN.to_le_bytes(),
                1 => f64::INFINITY.to_le_bytes(),
                2 => (-1e300f64).to_le_bytes(),
                3 => u64::MAX.to_le_bytes(),
                _ => (rng.below(10) as u64).to_le_bytes(),
            };
            payload[k..k + 8].copy_from_slice(&value);
        }
        4 => magic = [MAGIC4, MAGIC3, MAGIC2][rng.below(3)],
        _ => payload = mutate_bytes(rng, &payload, corpus),
    }
    let mut out = magic.to_vec();
    out.extend_from_slice(&header);
    out.push(b'\n');
    let payload_start = out.len();
    out.extend_from_slice(&payload);
    let checksum = if rng.chance(5) {
        rng.next()
    } else if magic != MAGIC2 {
        fnv1a(&out)
    } else {
        fnv1a(&out[payload_start..])
    };
    out.extend_from_slice(&checksum.to_le_bytes());
    out
}

// ------------------------------------------------------------------------------ targets

#[test]
fn fuzz_scene() {
    let mut seeds = corpus("scene");
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    for name in ["cornell_box.ron", "furnace.ron", "torus_glass.ron"] {
        seeds.push(std::fs::read(scenes.join(name)).unwrap());
    }
    fuzz("scene", seeds, mutate_ron, targets::scene);
}

#[test]
fn fuzz_mitsuba() {
    let mut seeds = corpus("mitsuba");
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    for name in ["cornell_box.xml", "torus_glass.xml"] {
        seeds.push(std::fs::read(scenes.join(name)).unwrap());
    }
    fuzz("mitsuba", seeds, mutate_ron, targets::mitsuba);
}

#[test]
fn fuzz_obj() {
    fuzz("obj", corpus("obj"), mutate_obj, targets::obj);
}

#[test]
fn fuzz_ply() {
    fuzz("ply", corpus("ply"), mutate_ply, targets::ply);
}

#[test]
fn fuzz_exr() {
    fuzz("exr", corpus("exr"), mutate_exr, targets::exr);
}

#[test]
fn fuzz_checkpoint() {
    fuzz(
        "checkpoint",
        corpus("checkpoint"),
        mutate_checkpoint,
        targets::checkpoint,
    );
}

/// Rewrites the binary seeds (EXR and checkpoint files made by this build):
/// `cargo nextest run write_binary_fuzz_seeds --run-ignored only`.
#[test]
#[ignore]
fn write_binary_fuzz_seeds() {
    use glam::{DVec3, Vec3};
    use stagelight::film::{Film, Image};
    use stagelight::reference::{Checkpoint, CheckpointHeader};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz/corpus");
    let exr = root.join("exr");
    let mut image = Image::new(4, 3);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        *p = Vec3::new(i as f32, 0.5, -1.0);
    }
    image.write_exr(&exr.join("rgb_4x3.exr")).unwrap();
    Image::new(1, 1)
        .write_exr(&exr.join("black_1x1.exr"))
        .unwrap();
    image
        .write_exr_with_attributes(
            &exr.join("reference_4x3.exr"),
            &[(
                "stagelight",
                "spp=4; seed=1; integrator=pt; maxDepth=unlimited; scene=s.ron".into(),
            )],
        )
        .unwrap();
    Image::new(40, 20)
        .write_exr(&exr.join("black_40x20.exr"))
        .unwrap();

    let cp = root.join("checkpoint");
    let header = |width: usize, height: usize, passes: u64| CheckpointHeader {
        integrator: "pt".into(),
        seed: 7,
        sampler: "independent".into(),
        max_depth: u32::MAX,
        scene: "scenes/cornell_box.ron".into(),
        scene_fingerprint: "0123456789abcdef".into(),
        width,
        height,
        passes,
        seconds: 1.5,
        nonfinite: 1,
        nonfinite_splats: 0,
        out_of_range: 0,
        first_pass: 0,
        shard: None,
        made_by: "reference".into(),
        settings: String::new(),
        state: 0,
        unit_exponent: 0,
    };
    let film = |width: usize, height: usize, passes: u64, splat: bool| {
        let n = width * height;
        Film::from_parts(
            width,
            height,
            (0..n).map(|i| DVec3::splat(i as f64)).collect(),
            vec![passes; n],
            if splat {
                vec![DVec3::new(0.25, 0.0, 1.0); n]
            } else {
                Vec::new()
            },
            1,
        )
        .unwrap()
    };
    for (name, w, h, passes, splat) in [("pt_2x2", 2, 2, 3, false), ("bdpt_3x1", 3, 1, 1, true)] {
        let mut c = Checkpoint {
            header: header(w, h, passes),
            film: film(w, h, passes, splat),
        };
        if splat {
            c.header.integrator = "bdpt".into();
        }
        std::fs::write(cp.join(format!("{name}.checkpoint")), c.to_bytes().unwrap()).unwrap();
    }
    // A shard's partial film: passes 2..5 of 8.
    let mut shard = Checkpoint {
        header: header(2, 2, 5),
        film: film(2, 2, 3, false),
    };
    shard.header.first_pass = 2;
    shard.header.made_by = "render".into();
    shard.header.shard = Some(stagelight::reference::ShardRange {
        end_pass: 5,
        total_passes: 8,
    });
    std::fs::write(
        cp.join("pt_shard_2x2.checkpoint"),
        shard.to_bytes().unwrap(),
    )
    .unwrap();
}
