//! The native half of the `stagelight` Python package: scenes loaded once and rendered, compared
//! and measured by the same engine the command line runs, without files in between.
//!
//! Keyword options reach the engine as the command line's own arguments (`max_depth=5` is
//! `--max-depth 5`, parsed by the CLI's parser), so every option, its checks and its error
//! messages are the CLI's. The package's Python half (python/stagelight/) turns keywords into
//! those arguments and the raw float buffers returned here into NumPy arrays.

use clap::Parser;
use pyo3::create_exception;
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyDict, PyList};
use stagelight::cli::{Cli, Command, one_line};
use stagelight::film::Image;
use stagelight::integrators::{
    Budget, Control, IntegratorKind, REGISTRY, RenderOutcome, SceneData,
};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

create_exception!(
    _native,
    SceneError,
    PyValueError,
    "A scene file that cannot be read, or asks for what stagelight does not model."
);
create_exception!(
    _native,
    RenderError,
    PyRuntimeError,
    "A render, reference or comparison that could not run (the command line's error)."
);

/// How often a render's waiting thread lets Python run its signal handlers (Ctrl-C).
const SIGNAL_POLL: Duration = Duration::from_millis(25);

/// The CLI's one-line message of an error, as `stagelight` prints it after "error: ".
fn message(e: &anyhow::Error) -> String {
    one_line(&format!("{e:#}"))
}

fn render_error(e: anyhow::Error) -> PyErr {
    RenderError::new_err(message(&e))
}

/// Parses `stagelight ARGS...` as the command line does; clap's refusals become the CLI's first
/// line: an unknown option a TypeError (as an unknown keyword is in Python), a bad value a
/// ValueError.
fn parse(args: Vec<String>) -> PyResult<Cli> {
    let line = std::iter::once("stagelight".to_string()).chain(args);
    Cli::try_parse_from(line).map_err(|e| {
        let text = e.render().to_string();
        let first = text.lines().next().unwrap_or_default();
        let first = one_line(first.trim_start_matches("error: "));
        match e.kind() {
            clap::error::ErrorKind::UnknownArgument => PyTypeError::new_err(first),
            _ => PyValueError::new_err(first),
        }
    })
}

/// `stagelight COMMAND SCENE ARGS... --quiet EXTRA...` parsed as the command line parses it
/// (`parse`): the scene's path stands where the CLI takes a file, though the loaded scene is
/// what renders.
fn command(name: &str, scene: &Scene, args: Vec<String>, extra: &[&str]) -> PyResult<Command> {
    let mut line = vec![name.to_string(), scene.path.display().to_string()];
    line.extend(args);
    line.push("--quiet".to_string());
    line.extend(extra.iter().map(|s| s.to_string()));
    Ok(parse(line)?.command)
}

/// A scene loaded and prepared (its acceleration structure built), ready to render many times.
#[pyclass(frozen, module = "stagelight")]
struct Scene {
    path: PathBuf,
    data: Arc<SceneData>,
    defines: Vec<(String, String)>,
    /// The file's sample count and maximum depth (a Mitsuba scene's sensor and integrator).
    spp: Option<u64>,
    max_depth: Option<u32>,
}

#[pymethods]
impl Scene {
    #[getter]
    fn path(&self) -> String {
        self.path.display().to_string()
    }

    /// (width, height) of the rendered image in pixels.
    #[getter]
    fn size(&self) -> (u32, u32) {
        let c = self.data.scene.camera;
        (c.width, c.height)
    }

    #[getter]
    fn spp(&self) -> Option<u64> {
        self.spp
    }

    #[getter]
    fn max_depth(&self) -> Option<u32> {
        self.max_depth
    }

    #[getter]
    fn defines<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in &self.defines {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    #[getter]
    fn triangles(&self) -> usize {
        self.data.scene.triangles.len()
    }

    #[getter]
    fn emitters(&self) -> usize {
        self.data.scene.emitters.triangle.len()
    }

    /// Each material's kind, in the scene's order.
    #[getter]
    fn materials(&self) -> Vec<String> {
        self.data
            .scene
            .materials
            .iter()
            .map(|m| format!("{:?}", m.kind()))
            .collect()
    }

    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.data.scene.warnings.clone()
    }

    /// The camera: position, forward, up, vertical field of view, projection and filter.
    #[getter]
    fn camera<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.data.scene.camera;
        let d = PyDict::new(py);
        d.set_item("position", c.position.to_array())?;
        d.set_item("forward", c.forward.to_array())?;
        d.set_item("up", c.up.to_array())?;
        d.set_item("fov_y_degrees", c.fov_y_degrees)?;
        d.set_item("width", c.width)?;
        d.set_item("height", c.height)?;
        let projection = match c.projection {
            stagelight::scene::Projection::Perspective => "perspective",
            stagelight::scene::Projection::Orthographic { .. } => "orthographic",
        };
        d.set_item("projection", projection)?;
        d.set_item("filter", format!("{:?}", c.filter).to_lowercase())?;
        Ok(d)
    }

    /// The integrator's graph of systems for this scene, as `stagelight graph` prints it.
    #[pyo3(signature = (integrator = "pt"))]
    fn graph(&self, integrator: &str) -> PyResult<String> {
        let kind = IntegratorKind::from_name(integrator)
            .map_err(|e| PyValueError::new_err(format!("integrator: {e}")))?;
        let settings = stagelight::integrators::RenderSettings::default();
        Ok((kind.info().graph)(&self.data, &settings).description)
    }

    fn __repr__(&self) -> String {
        let c = self.data.scene.camera;
        format!(
            "Scene('{}', {}x{}, {} triangles, {} materials)",
            self.path.display(),
            c.width,
            c.height,
            self.data.scene.triangles.len(),
            self.data.scene.materials.len()
        )
    }
}

/// Loads a RON or Mitsuba XML scene; `defines` are a Mitsuba file's `$name` parameters.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf, defines: Vec<(String, String)>) -> PyResult<Scene> {
    py.detach(|| load_scene(&path, defines))
        .map_err(|e| SceneError::new_err(message(&e)))
}

fn load_scene(path: &Path, defines: Vec<(String, String)>) -> anyhow::Result<Scene> {
    let limits = stagelight::scene::Limits::of_this_machine();
    let prepared = stagelight::scene::load_with_defines(path, &defines, &limits)?;
    let settings = if stagelight::scene::is_mitsuba(path) {
        stagelight::scene::mitsuba::build::file_settings(path, &defines)?
    } else {
        Default::default()
    };
    Ok(Scene {
        path: path.to_path_buf(),
        data: Arc::new(SceneData::new(prepared)),
        defines,
        spp: settings.spp,
        max_depth: settings.max_depth,
    })
}

/// Runs `work` on its own thread with the GIL released, letting Python handle signals every
/// `SIGNAL_POLL` meanwhile. When a signal handler raises (Ctrl-C's KeyboardInterrupt), `stop`
/// is set, the work finishes its passes in flight, and the exception comes back beside the
/// work's result.
fn run_stoppable<T: Send>(
    py: Python<'_>,
    stop: &AtomicBool,
    work: impl FnOnce() -> T + Send,
) -> PyResult<(T, Option<PyErr>)> {
    let (result, raised) = py.detach(|| {
        std::thread::scope(|s| {
            let (done_tx, done_rx) = mpsc::channel::<()>();
            let worker = s.spawn(move || {
                let out = work();
                let _ = done_tx.send(());
                out
            });
            let mut raised = None;
            while let Err(mpsc::RecvTimeoutError::Timeout) = done_rx.recv_timeout(SIGNAL_POLL) {
                if raised.is_none()
                    && let Err(e) = Python::attach(|py| py.check_signals())
                {
                    stop.store(true, Ordering::SeqCst);
                    raised = Some(e);
                }
            }
            (worker.join(), raised)
        })
    });
    let result = result.map_err(|panic| {
        let what = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("a panic");
        RenderError::new_err(format!("the render stopped with {what}"))
    })?;
    Ok((result, raised))
}

/// A float image as a bytearray of width x height x 3 float32 values, row by row (NumPy views
/// it without copying).
fn image_bytes<'py>(py: Python<'py>, image: &Image) -> PyResult<Bound<'py, PyByteArray>> {
    let floats = image.pixels.len() * 3;
    PyByteArray::new_with(py, floats * 4, |bytes| {
        for (chunk, p) in bytes.chunks_exact_mut(12).zip(&image.pixels) {
            chunk[0..4].copy_from_slice(&p.x.to_ne_bytes());
            chunk[4..8].copy_from_slice(&p.y.to_ne_bytes());
            chunk[8..12].copy_from_slice(&p.z.to_ne_bytes());
        }
        Ok(())
    })
}

/// An image from float32 bytes (width x height x 3, native order).
fn image_from_bytes(bytes: &[u8], width: usize, height: usize, what: &str) -> PyResult<Image> {
    if bytes.len() != width * height * 12 {
        return Err(PyValueError::new_err(format!(
            "{what}: {} bytes are not a {width}x{height}x3 float32 image",
            bytes.len()
        )));
    }
    let mut image = Image::new(width, height);
    for (p, c) in image.pixels.iter_mut().zip(bytes.chunks_exact(12)) {
        let f = |i: usize| f32::from_ne_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
        *p = glam::Vec3::new(f(0), f(4), f(8));
    }
    Ok(image)
}

/// What a render made, as a dict the Python half wraps: the image and its size, the
/// per-system timings, the report the CLI prints, and any layers.
fn outcome_dict<'py>(
    py: Python<'py>,
    outcome: &RenderOutcome,
    report: String,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let image = outcome.film.image();
    d.set_item("width", image.width)?;
    d.set_item("height", image.height)?;
    d.set_item("image", image_bytes(py, &image)?)?;
    d.set_item("report", report)?;
    d.set_item("passes", outcome.passes)?;
    d.set_item("samples", outcome.samples)?;
    d.set_item("seconds", outcome.wall.as_secs_f64())?;
    d.set_item("interrupted", outcome.interrupted)?;
    d.set_item("nonfinite", outcome.film.nonfinite)?;
    d.set_item("nonfinite_splats", outcome.film.nonfinite_splats)?;
    d.set_item("closest_rays", outcome.closest_rays())?;
    d.set_item("shadow_rays", outcome.shadow_rays())?;
    let systems = PyList::empty(py);
    for (s, share) in outcome.stats.time_shares() {
        let row = PyDict::new(py);
        row.set_item("name", s.name)?;
        row.set_item("seconds", s.time.as_secs_f64())?;
        row.set_item("share", share / 100.0)?;
        row.set_item("runs", s.runs)?;
        row.set_item("taken", s.taken)?;
        row.set_item("emitted", s.emitted)?;
        systems.append(row)?;
    }
    d.set_item("systems", systems)?;
    let notes = PyDict::new(py);
    for (label, value) in &outcome.notes {
        notes.set_item(*label, value)?;
    }
    d.set_item("notes", notes)?;
    let layers = PyDict::new(py);
    for (name, layer) in &outcome.layers {
        layers.set_item(name, image_bytes(py, layer)?)?;
    }
    d.set_item("layers", layers)?;
    match outcome.film.variance_image() {
        Some(v) => d.set_item("variance", image_bytes(py, &v)?)?,
        None => d.set_item("variance", py.None())?,
    }
    Ok(d)
}

/// Attaches `partial` to a KeyboardInterrupt (or whatever a signal handler raised) as its
/// `.partial` attribute.
fn with_partial(py: Python<'_>, err: PyErr, partial: Option<Bound<'_, PyDict>>) -> PyErr {
    let value = err.value(py);
    let partial = partial.map_or_else(|| py.None(), |p| p.into_any().unbind());
    if value.setattr("partial", partial).is_err() {
        return PyKeyboardInterrupt::new_err("interrupted");
    }
    err
}

/// Renders a loaded scene with the `render` command's arguments (`--spp`, `--integrator`, ...);
/// returns a dict (see `outcome_dict`).
#[pyfunction]
fn render<'py>(
    py: Python<'py>,
    scene: PyRef<'_, Scene>,
    args: Vec<String>,
) -> PyResult<Bound<'py, PyDict>> {
    // Files are never written: the output only satisfies the parser.
    let Command::Render(mut args) = command("render", &scene, args, &["-o", "python.exr"])? else {
        unreachable!("a render command line parses as one")
    };
    // As the CLI: --spp beats the file's sample count, --max-depth the file's.
    if args.time.is_none() {
        args.spp = args.spp.or(scene.spp);
    }
    args.max_depth = args.max_depth.or(scene.max_depth);
    if args.shard.choice().is_some() {
        return Err(PyTypeError::new_err(
            "shard and pass_range make checkpoint files for `stagelight merge`: use the command line",
        ));
    }
    let o = args.options();
    let data = scene.data.clone();
    let prepare = || -> anyhow::Result<rayon::ThreadPool> {
        stagelight::commands::render::check_integrator_options(&o)?;
        if let Budget::SamplesPerPixel(spp) = o.budget {
            stagelight::commands::check_samples("--spp", spp, &data)?;
        }
        let pool = stagelight::commands::thread_pool(o.threads)?;
        stagelight::commands::check_render_memory(
            o.integrator,
            &o.settings,
            &data,
            pool.current_num_threads(),
        )?;
        Ok(pool)
    };
    let pool = prepare().map_err(|e| PyValueError::new_err(message(&e)))?;
    let threads = pool.current_num_threads();
    let stop = AtomicBool::new(false);
    let cpu_start = stagelight::sysinfo::cpu_seconds();
    let (outcome, raised) = run_stoppable(py, &stop, || {
        let control = Control {
            stop: &stop,
            progress: &|_, _| {},
        };
        pool.install(|| {
            stagelight::integrators::render(
                o.integrator,
                data.clone(),
                &o.settings,
                o.budget,
                &control,
            )
        })
    })?;
    let cpu = stagelight::sysinfo::cpu_seconds() - cpu_start;
    let mut report =
        stagelight::report::render_report(&scene.path, o.integrator, threads, &outcome, cpu, &data);
    if outcome.interrupted {
        report += &format!(
            "interrupted: kept the {} finished passes ({} samples)\n",
            outcome.passes, outcome.samples
        );
    }
    if let Some(warning) = stagelight::report::nonfinite_warning(&outcome.film) {
        report += &format!("warning: {warning}\n");
    }
    let finished = outcome.passes > 0;
    let dict = finished
        .then(|| outcome_dict(py, &outcome, report))
        .transpose()?;
    match (raised, dict) {
        (Some(err), partial) => Err(with_partial(py, err, partial)),
        (None, Some(d)) => Ok(d),
        (None, None) => Err(RenderError::new_err("the render finished no pass")),
    }
}

/// Makes, resumes or extends a checkpointed reference with the `reference` command's
/// arguments; returns a dict: its image (as the EXR holds it) and size, passes and render
/// seconds over all its runs, whether Ctrl-C stopped it, the report and the EXR's path.
#[pyfunction]
fn reference<'py>(
    py: Python<'py>,
    scene: PyRef<'_, Scene>,
    args: Vec<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let Command::Reference(mut args) = command("reference", &scene, args, &[])? else {
        unreachable!("a reference command line parses as one")
    };
    args.max_depth = args.max_depth.or(scene.max_depth);
    let o = args.options();
    stagelight::commands::reference::check_reference_options(&o)
        .map_err(|e| PyValueError::new_err(message(&e)))?;
    let data = scene.data.clone();
    let stop = AtomicBool::new(false);
    let (result, raised) = run_stoppable(py, &stop, || {
        stagelight::commands::reference::reference_of(&o, data, &stop)
    })?;
    let (outcome, report) = result.map_err(render_error)?;
    let d = PyDict::new(py);
    if outcome.passes > 0 {
        let image = Image::read_exr(&o.output).map_err(|e| render_error(anyhow::Error::from(e)))?;
        d.set_item("width", image.width)?;
        d.set_item("height", image.height)?;
        d.set_item("image", image_bytes(py, &image)?)?;
    }
    d.set_item("passes", outcome.passes)?;
    d.set_item("seconds", outcome.seconds)?;
    d.set_item("interrupted", outcome.interrupted)?;
    d.set_item("report", report)?;
    d.set_item("path", o.output.display().to_string())?;
    match raised {
        Some(err) => Err(with_partial(py, err, Some(d))),
        None => Ok(d),
    }
}

/// Renders each integrator at each budget and measures it against the reference, with the
/// `compare` command's arguments; returns one dict per run, in run order.
#[pyfunction]
fn compare<'py>(
    py: Python<'py>,
    scene: PyRef<'_, Scene>,
    reference: &[u8],
    args: Vec<String>,
) -> PyResult<Bound<'py, PyList>> {
    let Command::Compare(mut args) = command("compare", &scene, args, &["-o", "python"])? else {
        unreachable!("a compare command line parses as one")
    };
    args.max_depth = args.max_depth.or(scene.max_depth);
    let o = args
        .options()
        .map_err(|e| PyValueError::new_err(message(&e)))?;
    let plan = stagelight::compare::run::ComparePlan::new(&o)
        .map_err(|e| PyValueError::new_err(message(&e)))?;
    let (width, height) = {
        let c = scene.data.scene.camera;
        (c.width as usize, c.height as usize)
    };
    let reference = image_from_bytes(reference, width, height, "reference")?;
    let data = scene.data.clone();
    let pool = stagelight::commands::thread_pool(o.threads)
        .and_then(|pool| {
            for &k in &plan.integrators {
                stagelight::commands::check_render_memory(
                    k,
                    &plan.settings,
                    &data,
                    pool.current_num_threads(),
                )?;
            }
            Ok(pool)
        })
        .map_err(|e| PyValueError::new_err(message(&e)))?;
    let job = stagelight::compare::CompareJob {
        data,
        reference: &reference,
        integrators: &plan.integrators,
        unit: plan.unit,
        budgets: &plan.budgets,
        settings: plan.settings,
    };
    let stop = AtomicBool::new(false);
    let (result, raised) = run_stoppable(py, &stop, || {
        pool.install(|| stagelight::compare::run_comparison(&job, &stop, &|_, _| {}))
    })?;
    let (runs, _) = result.map_err(RenderError::new_err)?;
    let rows = PyList::empty(py);
    for r in &runs {
        let row = PyDict::new(py);
        row.set_item("integrator", r.integrator.as_str())?;
        row.set_item("budget", r.budget)?;
        row.set_item("unit", plan.unit.as_str())?;
        row.set_item("wall", r.wall)?;
        row.set_item("cpu", r.cpu)?;
        row.set_item("samples", r.samples)?;
        row.set_item("passes", r.passes)?;
        row.set_item("closest_rays", r.closest_rays)?;
        row.set_item("shadow_rays", r.shadow_rays)?;
        row.set_item("photons", r.photons)?;
        row.set_item("relmse", r.metrics.relmse)?;
        row.set_item("rmse", r.metrics.rmse)?;
        row.set_item("mae", r.metrics.mae)?;
        row.set_item("efficiency", r.efficiency())?;
        row.set_item("image", image_bytes(py, &r.image)?)?;
        rows.append(row)?;
    }
    match raised {
        Some(err) => {
            let partial = PyDict::new(py);
            partial.set_item("rows", rows)?;
            Err(with_partial(py, err, Some(partial)))
        }
        None => Ok(rows),
    }
}

/// The error measures of an image against a reference (float32 bytes, width x height x 3):
/// relMSE, RMSE, MAE and the channel means, as `stagelight diff` prints them.
#[pyfunction]
fn metrics<'py>(
    py: Python<'py>,
    image: &[u8],
    reference: &[u8],
    width: usize,
    height: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let a = image_from_bytes(image, width, height, "image")?;
    let b = image_from_bytes(reference, width, height, "reference")?;
    let m =
        stagelight::metrics::compare(&a, &b).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let d = PyDict::new(py);
    d.set_item("relmse", m.relmse)?;
    d.set_item("rmse", m.rmse)?;
    d.set_item("mae", m.mae)?;
    d.set_item("mean", m.mean.to_array())?;
    d.set_item("reference_mean", m.reference_mean.to_array())?;
    Ok(d)
}

/// Reads an EXR's RGB (as `stagelight diff` does): (bytes, width, height).
#[pyfunction]
fn read_exr<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(Bound<'py, PyByteArray>, usize, usize)> {
    let image = Image::read_exr(&path).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((image_bytes(py, &image)?, image.width, image.height))
}

/// Writes float32 RGB bytes (width x height x 3) as an EXR, as renders are written.
#[pyfunction]
fn write_exr(path: PathBuf, image: &[u8], width: usize, height: usize) -> PyResult<()> {
    let image = image_from_bytes(image, width, height, "image")?;
    image
        .write_exr(&path)
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The integrators built in, in registry order: name, description, whether unbiased, whether
/// a reference resumes it, and its own options (the CLI's names).
#[pyfunction]
fn integrators<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for info in REGISTRY.iter() {
        let d = PyDict::new(py);
        d.set_item("name", info.name)?;
        d.set_item("description", info.description)?;
        d.set_item("unbiased", info.unbiased)?;
        d.set_item("resumes", info.resumes)?;
        d.set_item("options", info.options.to_vec())?;
        list.append(d)?;
    }
    Ok(list)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("RenderError", m.py().get_type::<RenderError>())?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(reference, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    m.add_function(wrap_pyfunction!(read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(integrators, m)?)?;
    Ok(())
}
