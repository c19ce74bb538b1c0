//! Rays as data. `stagelight rays` renders a scene with PT's recording graph and writes what
//! its trace systems traced: the triangles (mesh.ply), the closest-hit and shadow rays
//! (closest.npy, shadow.npy: float32 rows of origin xyz, t_min, direction xyz, t_max) and
//! rays.json, which splits them by bounce. `stagelight bench --rays DIR` builds the
//! accelerator from mesh.ply, traces those rays with the renderer's own trace systems, prints
//! rays/s per bounce group and writes hits.npy, so another tracer can be checked against
//! ours hit by hit (benches/embree_rays.py does so with Embree).
//!
//! mesh.ply holds the scene's triangles in the order of their ids (`TriangleColumns`), three
//! vertices of its own per triangle, so a hit's triangle id is the face index in the file. The
//! accelerator leaves out zero-area triangles and exact copies (never the nearest hit before
//! their original); they stay in the file, so ids keep their meaning.

use super::{check_outputs, load_scene, print_out, thread_pool};
use crate::accel::Accel;
use crate::components::ray_record::{BounceRays, RayRecord, RayRow};
use crate::components::{Hits, MISS, Rays, ShadowRays};
use crate::geometry::TriangleColumns;
use crate::integrators::driver::run_waves_of;
use crate::integrators::pt::{self, PtSettings, PtState, WAVEFRONT};
use crate::integrators::{RenderSettings, SceneData};
use crate::pipeline::Declared;
use crate::systems::trace::{closest::TraceClosest, shadow::TraceShadow};
use anyhow::{Context, Result, bail};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

pub const MESH_FILE: &str = "mesh.ply";
pub const CLOSEST_FILE: &str = "closest.npy";
pub const SHADOW_FILE: &str = "shadow.npy";
pub const INDEX_FILE: &str = "rays.json";
pub const HITS_FILE: &str = "hits.npy";

/// What `stagelight rays` was asked for.
pub struct RaysOptions {
    pub scene: PathBuf,
    pub out: PathBuf,
    pub spp: u64,
    /// Record bounces `0..bounces` (None: all).
    pub bounces: Option<usize>,
    pub threads: Option<usize>,
}

/// rays.json: where each bounce's rays are in closest.npy and shadow.npy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RayIndex {
    /// The scene file the rays were recorded from.
    pub scene: String,
    pub spp: u64,
    /// Triangles in mesh.ply.
    pub triangles: usize,
    /// The columns of a row of closest.npy and shadow.npy.
    pub columns: Vec<String>,
    pub closest: Vec<BounceSpan>,
    pub shadow: Vec<BounceSpan>,
    /// What hits.npy (written by `bench --rays`) holds.
    pub hits: String,
}

/// Rows `first..first + count` of a ray file are the rays of bounce `bounce`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BounceSpan {
    pub bounce: usize,
    pub first: usize,
    pub count: usize,
}

const COLUMNS: [&str; 8] = [
    "origin_x", "origin_y", "origin_z", "t_min", "dir_x", "dir_y", "dir_z", "t_max",
];

const HITS_NOTE: &str = "one row per ray, closest.npy's rows then shadow.npy's: t (float32) and \
    primitive (uint32, the face index in mesh.ply); closest rays: the nearest hit with t in \
    (t_min, t_max), shadow rays: the hit any-hit traversal stopped at (not the nearest); no hit: \
    t = inf and primitive = 4294967295";

/// Renders `spp` passes of the scene with PT's recording graph (the default settings of
/// `render`) and returns the rays traced in bounces `0..bounces` (all by default; the render
/// itself is the same either way).
pub fn record(data: Arc<SceneData>, spp: u64, bounces: Option<usize>) -> RayRecord {
    let settings = PtSettings::from(&RenderSettings::default());
    let graph = pt::recording_graph(&data);
    let mut state = run_waves_of::<PtState>(data, settings, &graph, spp, WAVEFRONT);
    let mut record = std::mem::take(&mut state.record);
    if let Some(bounces) = bounces {
        record.closest.truncate(bounces);
        record.shadow.truncate(bounces);
    }
    record
}

/// `stagelight rays`.
pub fn rays(options: &RaysOptions) -> Result<()> {
    let pool = thread_pool(options.threads)?;
    check_outputs(&[&options.out.join(INDEX_FILE)], &[&options.scene])?;
    let data = load_scene(&options.scene)?;
    let start = Instant::now();
    let record = pool.install(|| record(data.clone(), options.spp, options.bounces));
    let rendered = start.elapsed().as_secs_f64();
    let index = write_rays(&options.out, &data.scene.triangles, &record, options)?;
    let count = |spans: &[BounceSpan]| spans.iter().map(|s| s.count).sum::<usize>();
    print_out(&format!(
        "{}: {} triangles, {} closest-hit and {} shadow rays over {} bounces ({:.2} s to \
         render); wrote {MESH_FILE}, {CLOSEST_FILE}, {SHADOW_FILE} and {INDEX_FILE}\n",
        options.out.display(),
        index.triangles,
        count(&index.closest),
        count(&index.shadow),
        index.closest.len(),
        rendered
    ));
    Ok(())
}

/// Writes mesh.ply, closest.npy, shadow.npy and rays.json into `dir` (created if missing).
pub fn write_rays(
    dir: &Path,
    triangles: &TriangleColumns,
    record: &RayRecord,
    options: &RaysOptions,
) -> Result<RayIndex> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    // A hits.npy of earlier rays would no longer match these.
    let stale = dir.join(HITS_FILE);
    if stale.exists() {
        std::fs::remove_file(&stale)
            .with_context(|| format!("cannot remove the old {}", stale.display()))?;
    }
    write_mesh(&dir.join(MESH_FILE), triangles)?;
    let (closest, closest_spans) = concatenate(&record.closest);
    let (shadow, shadow_spans) = concatenate(&record.shadow);
    crate::npy::write_f32_rows(&dir.join(CLOSEST_FILE), &closest)?;
    crate::npy::write_f32_rows(&dir.join(SHADOW_FILE), &shadow)?;
    let index = RayIndex {
        scene: options.scene.display().to_string(),
        spp: options.spp,
        triangles: triangles.len(),
        columns: COLUMNS.map(String::from).to_vec(),
        closest: closest_spans,
        shadow: shadow_spans,
        hits: HITS_NOTE.to_string(),
    };
    let path = dir.join(INDEX_FILE);
    let text = serde_json::to_string_pretty(&index)? + "\n";
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(index)
}

/// The rows of every bounce, bounce after bounce, and where each bounce's are.
fn concatenate(bounces: &[BounceRays]) -> (Vec<RayRow>, Vec<BounceSpan>) {
    let mut rows = Vec::with_capacity(bounces.iter().map(|b| b.rays.len()).sum());
    let mut spans = Vec::new();
    for (bounce, b) in bounces.iter().enumerate() {
        spans.push(BounceSpan {
            bounce,
            first: rows.len(),
            count: b.rays.len(),
        });
        rows.extend_from_slice(&b.rays);
    }
    (rows, spans)
}

/// The triangles as binary little-endian PLY, in id order, three vertices of their own each
/// (float x, y, z: the scene's f32 coordinates exactly).
fn write_mesh(path: &Path, t: &TriangleColumns) -> Result<()> {
    let fail = || format!("cannot write {}", path.display());
    let file = std::fs::File::create(path).with_context(fail)?;
    let mut out = std::io::BufWriter::with_capacity(1 << 20, file);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment stagelight rays: face i is triangle id \
         i\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        3 * t.len(),
        t.len()
    )
    .with_context(fail)?;
    for i in 0..t.len() {
        for p in [t.p0[i], t.p1[i], t.p2[i]] {
            for c in p.to_array() {
                out.write_all(&c.to_le_bytes()).with_context(fail)?;
            }
        }
    }
    for i in 0..t.len() as u32 {
        out.write_all(&[3]).with_context(fail)?;
        for v in [3 * i, 3 * i + 1, 3 * i + 2] {
            out.write_all(&v.to_le_bytes()).with_context(fail)?;
        }
    }
    out.flush().with_context(fail)
}

/// What `stagelight bench --rays` was asked for.
pub struct RayBenchOptions {
    pub dir: PathBuf,
    pub threads: Option<usize>,
    /// Timed runs of each group (after one warm-up run).
    pub runs: u32,
    /// Write the results as JSON.
    pub save: Option<PathBuf>,
}

/// Rays read back from a folder `stagelight rays` wrote.
pub struct RayFiles {
    pub index: RayIndex,
    pub triangles: TriangleColumns,
    pub closest: Vec<RayRow>,
    pub shadow: Vec<RayRow>,
}

/// Reads mesh.ply, closest.npy, shadow.npy and rays.json from `dir`, checking that they agree
/// (each error names the file and what is wrong).
pub fn read_rays(dir: &Path) -> Result<RayFiles> {
    if !dir.is_dir() {
        bail!(
            "{}: not a folder of rays (make one with `stagelight rays SCENE --out {}`)",
            dir.display(),
            dir.display()
        );
    }
    let index_path = dir.join(INDEX_FILE);
    let text = std::fs::read_to_string(&index_path)
        .with_context(|| format!("cannot read {}", index_path.display()))?;
    let index: RayIndex = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a ray index", index_path.display()))?;
    let mesh_path = dir.join(MESH_FILE);
    let mesh = crate::scene::ply::load_ply(&mesh_path).map_err(anyhow::Error::msg)?;
    let mesh = mesh.mesh;
    let corner = |i: u32| mesh.positions[i as usize].as_vec3();
    let triangles = TriangleColumns {
        p0: mesh.triangles.iter().map(|t| corner(t[0])).collect(),
        p1: mesh.triangles.iter().map(|t| corner(t[1])).collect(),
        p2: mesh.triangles.iter().map(|t| corner(t[2])).collect(),
        ..TriangleColumns::default()
    };
    if triangles.len() != index.triangles {
        bail!(
            "{}: {} triangles, but {} says {}",
            mesh_path.display(),
            triangles.len(),
            index_path.display(),
            index.triangles
        );
    }
    let closest = crate::npy::read_f32_rows::<8>(&dir.join(CLOSEST_FILE))?;
    let shadow = crate::npy::read_f32_rows::<8>(&dir.join(SHADOW_FILE))?;
    for (file, rows, spans) in [
        (CLOSEST_FILE, closest.len(), &index.closest),
        (SHADOW_FILE, shadow.len(), &index.shadow),
    ] {
        let mut at = 0;
        for s in spans {
            if s.first != at {
                bail!(
                    "{}: bounce {} of {file} starts at row {}, not {at} where the bounce before \
                     it ends",
                    index_path.display(),
                    s.bounce,
                    s.first
                );
            }
            at += s.count;
        }
        if at != rows {
            bail!(
                "{}: {rows} rows, but {} lists {at}",
                dir.join(file).display(),
                index_path.display()
            );
        }
    }
    for (file, rows) in [(CLOSEST_FILE, &closest), (SHADOW_FILE, &shadow)] {
        if let Some(r) = rows.iter().position(|r| !(r[3] == 0.0 && r[7] > 0.0)) {
            bail!(
                "{}: row {r} has t_min {} and t_max {}; the tracer takes t_min = 0 and t_max > 0",
                dir.join(file).display(),
                rows[r][3],
                rows[r][7]
            );
        }
    }
    Ok(RayFiles {
        index,
        triangles,
        closest,
        shadow,
    })
}

/// A group of rays timed together: one bounce, or bounces 2 and later.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupResult {
    /// "closest" or "shadow".
    pub kind: String,
    /// "bounce 0", "bounce 1", "bounces 2+" or "all".
    pub group: String,
    /// Rows of the kind's file in the group.
    pub first: usize,
    pub count: usize,
    /// Seconds of each timed run.
    pub seconds: Vec<f64>,
    pub median_seconds: f64,
    pub rays_per_second: f64,
}

/// A saved `bench --rays`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RayBenchFile {
    pub machine: super::bench::Machine,
    pub dir: String,
    pub runs: u32,
    pub build_seconds: f64,
    pub groups: Vec<GroupResult>,
}

/// The row ranges timed: bounce 0, bounce 1, bounces 2 and later (where present).
fn groups(spans: &[BounceSpan]) -> Vec<(String, std::ops::Range<usize>)> {
    let range = |from: usize, to: usize| {
        let s: Vec<_> = spans
            .iter()
            .filter(|s| (from..to).contains(&s.bounce))
            .collect();
        let first = s.first().map_or(0, |s| s.first);
        first..first + s.iter().map(|s| s.count).sum::<usize>()
    };
    [
        ("bounce 0", range(0, 1)),
        ("bounce 1", range(1, 2)),
        ("bounces 2+", range(2, usize::MAX)),
    ]
    .into_iter()
    .filter(|(_, r)| !r.is_empty())
    .map(|(name, r)| (name.to_string(), r))
    .collect()
}

/// The closest-hit rays of `rows` as the trace system's columns.
fn closest_columns(rows: &[RayRow]) -> Rays {
    Rays {
        origin: rows.iter().map(|r| Vec3::new(r[0], r[1], r[2])).collect(),
        dir: rows.iter().map(|r| Vec3::new(r[4], r[5], r[6])).collect(),
    }
}

fn shadow_columns(rows: &[RayRow]) -> ShadowRays {
    let mut s = ShadowRays::new(rows.len());
    for (i, r) in rows.iter().enumerate() {
        s.origin[i] = Vec3::new(r[0], r[1], r[2]);
        s.dir[i] = Vec3::new(r[4], r[5], r[6]);
        s.t_max[i] = r[7];
    }
    s
}

/// Median of a non-empty list.
fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Runs `trace` once to warm up, then `runs` times, timed.
fn time_runs(runs: u32, mut trace: impl FnMut()) -> Vec<f64> {
    trace();
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            trace();
            start.elapsed().as_secs_f64()
        })
        .collect()
}

/// `stagelight bench --rays DIR`: traces the folder's rays with the renderer's trace systems
/// (closest-hit rays with `trace_closest`, shadow rays with `trace_shadow`), bounce group by
/// group, prints rays/s, and writes hits.npy.
pub fn bench_rays(options: &RayBenchOptions) -> Result<()> {
    let pool = thread_pool(options.threads)?;
    let files = read_rays(&options.dir)?;
    check_outputs(&[&options.dir.join(HITS_FILE)], &[])?;
    let threads = pool.current_num_threads();
    let (accel, build_seconds) = pool.install(|| {
        let start = Instant::now();
        let accel = Accel::build(&files.triangles);
        (accel, start.elapsed().as_secs_f64())
    });
    let mut results = Vec::new();
    let mut hit_t = vec![f32::INFINITY; files.closest.len() + files.shadow.len()];
    let mut hit_primitive = vec![MISS; hit_t.len()];
    pool.install(|| -> Result<()> {
        for (name, range) in groups(&files.index.closest) {
            let rays = closest_columns(&files.closest[range.clone()]);
            let mut hits = Hits::new(range.len());
            let seconds = time_runs(options.runs, || {
                TraceClosest.run_columns((&accel, &rays, &range.len(), &mut hits));
            });
            for (k, i) in range.clone().enumerate() {
                if hits.triangle[k] != MISS {
                    hit_t[i] = hits.t[k];
                    hit_primitive[i] = hits.triangle[k];
                }
            }
            results.push(group_result("closest", name, range, seconds));
        }
        let offset = files.closest.len();
        for (name, range) in groups(&files.index.shadow) {
            let mut shadow = shadow_columns(&files.shadow[range.clone()]);
            let seconds = time_runs(options.runs, || {
                TraceShadow.run_columns((&accel, &range.len(), &mut shadow));
            });
            for (k, i) in range.clone().enumerate() {
                let (o, d) = (shadow.origin[k], shadow.dir[k]);
                let found = accel.any_hit_found(o, d, shadow.t_max[k]);
                if found.is_some() == shadow.unoccluded[k] {
                    bail!(
                        "shadow ray {i}: trace_shadow and any_hit_found disagree (a bug in \
                         stagelight)"
                    );
                }
                if let Some(hit) = found {
                    hit_t[offset + i] = hit.t;
                    hit_primitive[offset + i] = hit.triangle;
                }
            }
            results.push(group_result("shadow", name, range, seconds));
        }
        Ok(())
    })?;
    for kind in ["closest", "shadow"] {
        let of_kind: Vec<&GroupResult> = results.iter().filter(|g| g.kind == kind).collect();
        if of_kind.len() > 1 {
            // All of a kind: its rays over the sum of its groups' medians.
            let count: usize = of_kind.iter().map(|g| g.count).sum();
            let seconds: f64 = of_kind.iter().map(|g| g.median_seconds).sum();
            results.push(GroupResult {
                kind: kind.to_string(),
                group: "all".to_string(),
                first: 0,
                count,
                seconds: Vec::new(),
                median_seconds: seconds,
                rays_per_second: count as f64 / seconds.max(1e-12),
            });
        }
    }
    crate::npy::write_hits(&options.dir.join(HITS_FILE), &hit_t, &hit_primitive)?;
    let machine = super::bench::Machine::this(threads, None);
    let (node_bytes, packet_bytes) = accel.memory_bytes();
    let mut text = format!(
        "{}: {} triangles ({} in the tree of {:.2} MB, built in {:.3} s); {} threads, median \
         of {} runs\n{}\n{:<8} {:<11} {:>10} {:>12} {:>12}\n",
        options.dir.display(),
        files.triangles.len(),
        accel.len(),
        (node_bytes + packet_bytes) as f64 / 1e6,
        build_seconds,
        threads,
        options.runs,
        machine.describe(),
        "rays",
        "group",
        "count",
        "median ms",
        "Mrays/s"
    );
    for g in &results {
        text += &format!(
            "{:<8} {:<11} {:>10} {:>12.3} {:>12.3}\n",
            g.kind,
            g.group,
            g.count,
            1e3 * g.median_seconds,
            g.rays_per_second / 1e6
        );
    }
    text += &format!("wrote {}\n", options.dir.join(HITS_FILE).display());
    print_out(&text);
    if let Some(path) = &options.save {
        let file = RayBenchFile {
            machine,
            dir: options.dir.display().to_string(),
            runs: options.runs,
            build_seconds,
            groups: results,
        };
        let json = serde_json::to_string_pretty(&file)? + "\n";
        std::fs::write(path, json).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn group_result(
    kind: &str,
    group: String,
    range: std::ops::Range<usize>,
    seconds: Vec<f64>,
) -> GroupResult {
    let median_seconds = median(&seconds);
    GroupResult {
        kind: kind.to_string(),
        group,
        first: range.start,
        count: range.len(),
        rays_per_second: range.len() as f64 / median_seconds.max(1e-12),
        seconds,
        median_seconds,
    }
}
