//! `photon._photon`: the photon library as a Python extension module. Scenes load through the
//! same loader as the command line, runs go through the same driver (`photon::run`) and results
//! through the same estimates (`photon::output`), so every number equals the CLI's bit for bit.
//! The Python package `photon` (python/photon/) re-exports these names.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::IntoPyArray;
use pyo3::create_exception;
use pyo3::exceptions::{PyKeyError, PyKeyboardInterrupt, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PySlice, PyString, PyTuple};

use photon::error::Error;
use photon::integrators::particle::{Estimator, TransportOptions};
use photon::output;
use photon::run::{RunOptions, RunResult, StopReason};

create_exception!(
    photon,
    SceneError,
    PyValueError,
    "A bad scene (or mesh, spectrum or luminaire file it names). Attributes: `file` (str), `key` \
     (the dotted key path, '' when none applies), `line` (1-based, or None) and `message`."
);
create_exception!(
    photon,
    RunInterrupted,
    PyKeyboardInterrupt,
    "Ctrl-C (SIGINT) during Scene.run or validate: the run stopped at the next batch boundary, as \
     `photon run` does. A KeyboardInterrupt, so loops stop; its `result` attribute holds the \
     Result of the batches merged before the stop (None for validate)."
);

/// A library error as a Python exception: bad input is a SceneError (a ValueError) with its
/// file, key and line; bad arguments a ValueError; anything else a RuntimeError.
fn py_err(py: Python<'_>, e: Error) -> PyErr {
    match e {
        Error::Input(ie) => {
            let err = SceneError::new_err(ie.to_string());
            let v = err.value(py);
            let _ = v.setattr("file", ie.file.display().to_string());
            let _ = v.setattr("key", ie.key.clone());
            let _ = v.setattr("line", ie.line);
            let _ = v.setattr("message", ie.message.clone());
            err
        }
        Error::Usage(m) => PyValueError::new_err(m),
        Error::Other(m) => PyRuntimeError::new_err(m),
    }
}

/// serde_json values (flux.json, run.json, `info`) as Python objects: numbers stay the exact
/// f64 (or integer) the files write.
fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => match (n.as_u64(), n.as_i64()) {
            (Some(u), _) => u.into_pyobject(py)?.into_any(),
            (None, Some(i)) => i.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => PyString::new(py, s).into_any(),
        Value::Array(a) => {
            let list = PyList::empty(py);
            for x in a {
                list.append(json_to_py(py, x)?)?;
            }
            list.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

fn serialize_to_py<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let json = serde_json::to_value(v).map_err(|e| PyRuntimeError::new_err(format!("cannot encode: {e}")))?;
    json_to_py(py, &json)
}

fn toml_to_py<'py>(py: Python<'py>, v: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    use toml::Value;
    Ok(match v {
        Value::String(s) => PyString::new(py, s).into_any(),
        Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        Value::Float(f) => f.into_pyobject(py)?.into_any(),
        Value::Boolean(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Datetime(d) => PyString::new(py, &d.to_string()).into_any(),
        Value::Array(a) => {
            let list = PyList::empty(py);
            for x in a {
                list.append(toml_to_py(py, x)?)?;
            }
            list.into_any()
        }
        Value::Table(t) => table_to_py(py, t)?.into_any(),
    })
}

fn table_to_py<'py>(py: Python<'py>, t: &toml::Table) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for (k, x) in t {
        d.set_item(k, toml_to_py(py, x)?)?;
    }
    Ok(d)
}

/// A Python value as TOML: bool, int, float (numpy scalars too), str, list or tuple, dict with
/// str keys. `at` names the key in messages.
fn py_to_toml(v: &Bound<'_, PyAny>, at: &str) -> PyResult<toml::Value> {
    use toml::Value;
    if v.is_instance_of::<PyBool>() {
        return Ok(Value::Boolean(v.extract()?));
    }
    if v.is_instance_of::<PyInt>() {
        return v
            .extract::<i64>()
            .map(Value::Integer)
            .map_err(|_| PyValueError::new_err(format!("{at}: the integer {v} does not fit TOML's 64-bit integers")));
    }
    if v.is_instance_of::<PyFloat>() {
        return Ok(Value::Float(v.extract()?));
    }
    if let Ok(s) = v.cast::<PyString>() {
        return Ok(Value::String(s.to_str()?.to_string()));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        return Ok(Value::Table(dict_to_table(d, at)?));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut a = Vec::new();
        for (i, x) in v.try_iter()?.enumerate() {
            a.push(py_to_toml(&x?, &format!("{at}[{i}]"))?);
        }
        return Ok(Value::Array(a));
    }
    // numpy arrays and scalars: integers first (numpy's ints convert through __index__).
    if v.hasattr("tolist")? {
        return py_to_toml(&v.call_method0("tolist")?, at);
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(Value::Integer(i));
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(Value::Float(f));
    }
    Err(PyTypeError::new_err(format!(
        "{at}: a {} cannot be written to a scene (use bool, int, float, str, list or dict)",
        v.get_type().name()?
    )))
}

fn dict_to_table(d: &Bound<'_, PyDict>, at: &str) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    for (k, x) in d.iter() {
        let key: String = k.extract().map_err(|_| PyTypeError::new_err(format!("{at}: keys must be str")))?;
        let path = if at.is_empty() { key.clone() } else { format!("{at}.{key}") };
        if x.is_none() {
            continue;
        }
        t.insert(key, py_to_toml(&x, &path)?);
    }
    Ok(t)
}

/// Sets (or, for None, removes) the value at a dotted key path. A step into an array of tables
/// (`surfaces`, `lights`, `detectors`) picks the entry by its `name`, or by its index.
fn set_path(root: &mut toml::Table, key: &str, value: Option<toml::Value>) -> PyResult<()> {
    let steps: Vec<&str> = key.split('.').collect();
    if steps.iter().any(|s| s.is_empty()) {
        return Err(PyKeyError::new_err(format!("{key}: an empty step in the key path")));
    }
    let mut table = root;
    for (i, step) in steps.iter().enumerate() {
        let last = i + 1 == steps.len();
        if last {
            match value {
                Some(v) => {
                    table.insert(step.to_string(), v);
                }
                None => {
                    table.remove(*step);
                }
            }
            return Ok(());
        }
        let here = steps[..=i].join(".");
        let entry = table.entry(step.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = match entry {
            toml::Value::Table(t) => t,
            toml::Value::Array(items) => {
                let pick = steps[i + 1];
                let names: Vec<String> =
                    items.iter().filter_map(|x| x.get("name").and_then(|n| n.as_str()).map(String::from)).collect();
                let k = items
                    .iter()
                    .position(|x| x.get("name").and_then(|n| n.as_str()) == Some(pick))
                    .or_else(|| pick.parse::<usize>().ok().filter(|&k| k < items.len()))
                    .ok_or_else(|| {
                        PyKeyError::new_err(format!(
                            "{key}: `{here}` has no entry named (or numbered) `{pick}`; its names: {}",
                            names.join(", ")
                        ))
                    })?;
                if i + 2 == steps.len() {
                    // The whole entry: replace (a dict) or remove it.
                    match value {
                        Some(v) => items[k] = v,
                        None => {
                            items.remove(k);
                        }
                    }
                    return Ok(());
                }
                return set_path_in(items[k].as_table_mut(), key, &steps[i + 2..], value, &format!("{here}.{pick}"));
            }
            _ => return Err(PyKeyError::new_err(format!("{key}: `{here}` is a value, not a table"))),
        };
    }
    Ok(())
}

fn set_path_in(
    table: Option<&mut toml::Table>,
    key: &str,
    rest: &[&str],
    value: Option<toml::Value>,
    here: &str,
) -> PyResult<()> {
    let table = table.ok_or_else(|| PyKeyError::new_err(format!("{key}: `{here}` is not a table")))?;
    set_path(table, &rest.join("."), value)
        .map_err(|e| Python::attach(|py| PyKeyError::new_err(format!("{key}: {}", e.value(py)))))
}

/// Runs `work` on its own thread with the GIL released, waking every 20 ms to let Python handle
/// signals and to call `tick` (the progress bar). A signal's exception (KeyboardInterrupt) sets
/// `interrupt`, which the work polls, and is handed back once the work has ended.
fn interruptible<'py, T: Send>(
    py: Python<'py>,
    interrupt: &AtomicBool,
    work: impl FnOnce() -> T + Send,
    mut tick: impl FnMut(Python<'py>),
) -> PyResult<(T, Option<PyErr>)> {
    std::thread::scope(|s| {
        let handle = s.spawn(work);
        let mut raised = None;
        while !handle.is_finished() {
            py.detach(|| {
                let start = Instant::now();
                while !handle.is_finished() && start.elapsed() < Duration::from_millis(20) {
                    std::thread::sleep(Duration::from_millis(1));
                }
            });
            if raised.is_none() {
                if let Err(e) = py.check_signals() {
                    interrupt.store(true, Ordering::Relaxed);
                    raised = Some(e);
                }
            }
            tick(py);
        }
        match handle.join() {
            Ok(t) => Ok((t, raised)),
            Err(_) => Err(PyRuntimeError::new_err("photon: the run failed (a panic); please report it")),
        }
    })
}

/// The progress bar of `run(progress=True)`: tqdm's when it is installed, else one line on
/// sys.stderr redrawn in place.
struct Bar<'py> {
    tqdm: Option<Bound<'py, PyAny>>,
    total: Option<u64>,
    shown: u64,
    start: Instant,
}

impl<'py> Bar<'py> {
    fn new(py: Python<'py>, total: Option<u64>) -> Self {
        let tqdm = py.import("tqdm.auto").and_then(|m| {
            let kw = PyDict::new(py);
            kw.set_item("total", total)?;
            kw.set_item("unit", "photon")?;
            kw.set_item("unit_scale", true)?;
            kw.set_item("desc", "photon")?;
            m.getattr("tqdm")?.call((), Some(&kw))
        });
        Bar { tqdm: tqdm.ok(), total, shown: 0, start: Instant::now() }
    }

    fn update(&mut self, py: Python<'py>, photons: u64) {
        if photons == self.shown {
            return;
        }
        let step = photons - self.shown;
        self.shown = photons;
        if let Some(t) = &self.tqdm {
            let _ = t.call_method1("update", (step,));
            return;
        }
        let secs = self.start.elapsed().as_secs_f64();
        let line = match self.total {
            Some(n) => {
                format!("\rphoton: {:5.1}%  {} photons  {secs:.1} s", 100.0 * photons as f64 / n as f64, photons)
            }
            None => format!("\rphoton: {photons} photons  {secs:.1} s"),
        };
        if let Ok(err) = py.import("sys").and_then(|s| s.getattr("stderr")) {
            let _ = err.call_method1("write", (line,));
            let _ = err.call_method0("flush");
        }
    }

    fn close(self, py: Python<'py>) {
        match &self.tqdm {
            Some(t) => {
                let _ = t.call_method0("close");
            }
            None => {
                if let Ok(err) = py.import("sys").and_then(|s| s.getattr("stderr")) {
                    let _ = err.call_method1("write", ("\n",));
                }
            }
        }
    }
}

fn warn(py: Python<'_>, message: &str) {
    if let Ok(w) = py.import("warnings") {
        let _ = w.call_method1("warn", (message, py.get_type::<pyo3::exceptions::PyUserWarning>(), 3));
    }
}

/// A loaded, checked scene. Make one with `photon.load(path)`, `photon.loads(text)` or
/// `photon.from_dict(d)`; it does not change: `with_overrides` makes a new one.
#[pyclass(module = "photon", name = "Scene", frozen)]
struct PyScene {
    scene: Arc<photon::scene::Scene>,
    /// The TOML text it was loaded from.
    text: String,
}

fn load_text(py: Python<'_>, path: &Path, text: String) -> PyResult<PyScene> {
    let loaded = py.detach(|| photon::scene::load_str(path, &text));
    let scene = loaded.map_err(|e| py_err(py, e))?;
    for w in &scene.warnings {
        warn(py, w);
    }
    Ok(PyScene { scene: Arc::new(scene), text })
}

fn parse_table(py: Python<'_>, scene: &PyScene) -> PyResult<toml::Table> {
    // The text was loaded, so it is TOML; the error is there for completeness.
    scene.text.parse::<toml::Table>().map_err(|e| {
        py_err(py, Error::Other(format!("{}: cannot re-read the scene's TOML: {e}", scene.scene.path.display())))
    })
}

fn from_table(py: Python<'_>, path: &Path, table: &toml::Table) -> PyResult<PyScene> {
    let text =
        toml::to_string(table).map_err(|e| PyValueError::new_err(format!("cannot write the scene as TOML: {e}")))?;
    load_text(py, path, text)
}

#[pymethods]
impl PyScene {
    /// Simulate the scene and return a Result (tallies, ledger, image, maps, ...).
    ///
    /// Every argument left None takes the scene's `[simulation]` value, as on the command line
    /// (`photon run`): photons (default 1 000 000; with rel_error or time, the most to trace),
    /// seed, threads (all cores; results never depend on it), rel_error (stop when every tallied
    /// surface, or those in `tally`, reaches this relative standard error), time (stop at this
    /// budget in seconds), integrator ("light", "path" or "bdpt": what makes the image),
    /// max_bounces. image=False skips the camera image. estimator "auto" | "expected" | "analog",
    /// stratified and hero are the transport options of `photon run` (`--no-hero` is hero=False).
    ///
    /// Same scene, seed and photons give the same numbers as `photon run`, bit for bit. The GIL is
    /// released while photons are traced. Ctrl-C stops the run at the next batch (within a
    /// fraction of a second) and raises photon.RunInterrupted, a KeyboardInterrupt whose
    /// `result` holds what was traced. progress=True shows a progress bar (tqdm's if installed).
    #[pyo3(signature = (photons=None, seed=None, threads=None, rel_error=None, time=None, integrator=None,
                        image=true, progress=false, tally=None, max_bounces=None, estimator="auto",
                        stratified=false, hero=true))]
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        py: Python<'_>,
        photons: Option<u64>,
        seed: Option<u64>,
        threads: Option<usize>,
        rel_error: Option<f64>,
        time: Option<f64>,
        integrator: Option<&str>,
        image: bool,
        progress: bool,
        tally: Option<Vec<String>>,
        max_bounces: Option<u32>,
        estimator: &str,
        stratified: bool,
        hero: bool,
    ) -> PyResult<PyRunResult> {
        let integrator = match integrator {
            None => None,
            Some(s) => Some(photon::integrators::camera::Integrator::parse(s).ok_or_else(|| {
                PyValueError::new_err(format!("integrator must be \"light\", \"path\" or \"bdpt\", found {s:?}"))
            })?),
        };
        let estimator = match estimator {
            "auto" => Estimator::Auto,
            "expected" => Estimator::Expected,
            "analog" => Estimator::Analog,
            s => {
                return Err(PyValueError::new_err(format!(
                    "estimator must be \"auto\", \"expected\" or \"analog\", found {s:?}"
                )))
            }
        };
        let opts = RunOptions {
            photons,
            seed,
            threads,
            max_bounces,
            rel_error,
            tallies: tally.unwrap_or_default(),
            time_s: time,
            // The command line's bar draws on a terminal only; this one draws wherever Python does.
            progress: false,
            no_image: !image,
            integrator,
            transport: TransportOptions { estimator, stratified, hero },
        };
        let mut scene = (*self.scene).clone();
        let chosen = photon::run::apply_options(&mut scene, &opts).map_err(|e| py_err(py, e))?;
        let open_ended = opts.rel_error.is_some() || opts.time_s.is_some();
        let total = match opts.photons {
            Some(p) => Some(p),
            None if open_ended => None,
            None => Some(scene.simulation.photons),
        };
        let interrupt = AtomicBool::new(false);
        let merged = AtomicU64::new(0);
        let mut bar = progress.then(|| Bar::new(py, total));
        let (simulated, raised) = interruptible(
            py,
            &interrupt,
            || {
                photon::run::simulate_observed(&scene, &opts, &chosen, &interrupt, &mut |p| {
                    merged.store(p.tallies.photons, Ordering::Relaxed)
                })
            },
            |py| {
                if let Some(b) = bar.as_mut() {
                    b.update(py, merged.load(Ordering::Relaxed));
                }
            },
        )?;
        if let Some(b) = bar {
            b.close(py);
        }
        let run = match simulated {
            Ok(r) => r,
            Err(e) => return Err(raised.unwrap_or_else(|| py_err(py, e))),
        };
        let result = PyRunResult::new(py, Arc::new(scene), run)?;
        match raised {
            None => Ok(result),
            Some(e) if e.is_instance_of::<PyKeyboardInterrupt>(py) => {
                let err = RunInterrupted::new_err("stopped by Ctrl-C: `.result` holds the batches traced before it");
                err.value(py).setattr("result", Py::new(py, result)?)?;
                Err(err)
            }
            Some(e) => Err(e),
        }
    }

    /// What `photon info` prints, as a dict: surfaces (name, material, kind, triangles, area_m2,
    /// light), lights (power_w, power_lm, distribution, shape), media, triangles, total_power_w,
    /// wavelength_range_nm, transport, effects, camera, maps, spectra, detectors, volumes.
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &output::info::scene_info(&self.scene))
    }

    /// The text of `photon info`.
    fn describe(&self) -> String {
        output::info::describe(&self.scene)
    }

    /// The scene file's contents as nested dicts and lists (TOML's data model): edit it and
    /// give it to `photon.from_dict`.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        table_to_py(py, &parse_table(py, self)?)
    }

    /// A new Scene with some values replaced, given as {dotted key: value}. Keys follow the
    /// scene file: "simulation.photons", "materials.white.reflectance", "lights.lamp.power_w".
    /// A step into an array of tables (surfaces, lights, detectors) picks the entry by its name
    /// or its index ("surfaces.0.material"). A value None removes the key; a missing table is
    /// created. Relative file paths keep resolving against the original scene's folder.
    ///
    ///     for r in [0.2, 0.5, 0.8]:
    ///         res = scene.with_overrides({"materials.white.reflectance": r}).run(photons=100_000)
    fn with_overrides(&self, py: Python<'_>, overrides: &Bound<'_, PyDict>) -> PyResult<PyScene> {
        let mut table = parse_table(py, self)?;
        for (k, v) in overrides.iter() {
            let key: String = k.extract().map_err(|_| PyTypeError::new_err("override keys must be str"))?;
            let value = if v.is_none() { None } else { Some(py_to_toml(&v, &key)?) };
            set_path(&mut table, &key, value)?;
        }
        from_table(py, &self.scene.path, &table)
    }

    /// The scene's TOML text (for a Scene made by with_overrides or from_dict, the text written
    /// for it: line numbers in its SceneErrors refer to this).
    #[getter]
    fn toml(&self) -> &str {
        &self.text
    }

    /// The scene file's path (for loads/from_dict: base_dir/name.toml, which anchors relative
    /// file paths and names the default output folder).
    #[getter]
    fn path(&self) -> String {
        self.scene.path.display().to_string()
    }

    /// The scene's name: its file's stem.
    #[getter]
    fn name(&self) -> String {
        self.scene.stem()
    }

    fn __repr__(&self) -> String {
        format!(
            "<photon.Scene {} · {} surfaces, {} lights, {} triangles, {} W>",
            self.scene.path.display(),
            self.scene.surfaces.len(),
            self.scene.lights.len(),
            self.scene.geometry.len(),
            self.scene.total_power_w()
        )
    }
}

/// The outcome of Scene.run: the numbers of flux.json and run.json, and the image, maps, far
/// fields and volume grids as numpy arrays. `save(dir)` writes exactly what `photon run` writes.
#[pyclass(module = "photon", name = "Result")]
struct PyRunResult {
    scene: Arc<photon::scene::Scene>,
    run: RunResult,
    flux_json: Py<PyAny>,
    run_info: Py<PyAny>,
    image: Option<Py<PyAny>>,
    xyz: Option<Py<PyAny>>,
    y: Option<Py<PyAny>>,
    y_var: Option<Py<PyAny>>,
    maps: Py<PyDict>,
    farfield: Py<PyDict>,
    volumes: Py<PyDict>,
    warnings: Vec<String>,
}

/// (value, s.e.) pairs as two numpy arrays of `shape`, texel k at row-major position `order(k)`.
fn split_pairs<'py>(
    py: Python<'py>,
    pairs: &[(f64, f64)],
    shape: &[usize],
    order: impl Fn(usize) -> usize,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let n = pairs.len();
    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
    for (k, &(x, s)) in pairs.iter().enumerate() {
        a[order(k)] = x;
        b[order(k)] = s;
    }
    let arr = |v: Vec<f64>| -> PyResult<Bound<'py, PyAny>> {
        let a = ndarray::ArrayD::from_shape_vec(shape.to_vec(), v)
            .map_err(|e| PyRuntimeError::new_err(format!("array shape: {e}")))?;
        Ok(a.into_pyarray(py).into_any())
    };
    Ok((arr(a)?, arr(b)?))
}

impl PyRunResult {
    fn new(py: Python<'_>, scene: Arc<photon::scene::Scene>, run: RunResult) -> PyResult<Self> {
        let est = output::estimates(&scene, &run).map_err(|e| py_err(py, e))?;
        for w in &est.warnings {
            warn(py, w);
        }
        let flux_json = serialize_to_py(py, &est.flux)?.unbind();
        let run_info = serialize_to_py(py, &est.info)?.unbind();
        let (mut image, mut xyz, mut y, mut y_var) = (None, None, None, None);
        if let Some(im) = est.image {
            let (w, h) = (im.width, im.height);
            let shape_err = |e: ndarray::ShapeError| PyRuntimeError::new_err(format!("image shape: {e}"));
            // Moved into numpy, not copied: rgb is [H, W, 3] already; xyz (pixel, channel) and
            // y_var (pixel) are row-major over the pixels, so only their shapes change.
            image = Some(im.rgb.into_pyarray(py).into_any().unbind());
            let xyz_arr = im.xyz.into_shape_with_order((h, w, 3)).map_err(shape_err)?.into_pyarray(py);
            let full = PySlice::full(py);
            y = Some(xyz_arr.as_any().get_item((full.clone(), full, 1))?.unbind());
            xyz = Some(xyz_arr.into_any().unbind());
            let var = ndarray::Array2::from_shape_vec((h, w), im.y_var).map_err(shape_err)?;
            y_var = Some(var.into_pyarray(py).into_any().unbind());
        }
        let maps = PyDict::new(py);
        for m in &est.maps {
            let [nu, nv] = m.resolution;
            // Row 0 is the largest v, as in maps/<surface>.exr: imshow shows what the PNG shows.
            let flip = |k: usize| (nv - 1 - k / nu) * nu + k % nu;
            let d = PyDict::new(py);
            for (name, values) in [
                ("irradiance_w_m2", m.irradiance_w_m2()),
                ("illuminance_lx", m.illuminance_lx()),
                ("flux_w", m.flux_w.clone()),
                ("flux_lm", m.flux_lm.clone()),
            ] {
                let (v, se) = split_pairs(py, &values, &[nv, nu], flip)?;
                d.set_item(name, v)?;
                d.set_item(format!("{name}_stderr"), se)?;
            }
            let area: Vec<(f64, f64)> = m.texel_area_m2.iter().map(|&a| (a, 0.0)).collect();
            d.set_item("texel_area_m2", split_pairs(py, &area, &[nv, nu], flip)?.0)?;
            d.set_item("size_m", m.size_m)?;
            maps.set_item(&m.surface, d)?;
        }
        let farfield = PyDict::new(py);
        for e in &est.farfields {
            let [ng, nc] = e.detector.resolution;
            let mut parts: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
            for j in 0..nc {
                for i in 0..ng {
                    let (w, cd) = e.intensity(i, j);
                    parts[0].push(w);
                    parts[1].push(cd);
                }
            }
            let d = PyDict::new(py);
            // [C, γ] like the CSV's rows: C slowest.
            for (name, values) in [("intensity_w_sr", &parts[0]), ("intensity_cd", &parts[1])] {
                let (v, se) = split_pairs(py, values, &[nc, ng], |k| k)?;
                d.set_item(name, v)?;
                d.set_item(format!("{name}_stderr"), se)?;
            }
            let gamma: Vec<(f64, f64)> = (0..ng)
                .map(|i| {
                    let (g0, g1, _) = e.detector.bin_angles(i, 0);
                    (g0, g1)
                })
                .collect();
            let (g0, g1) = split_pairs(py, &gamma, &[ng], |k| k)?;
            d.set_item("gamma_lo_deg", g0)?;
            d.set_item("gamma_hi_deg", g1)?;
            let c: Vec<(f64, f64)> = (0..nc).map(|j| (e.detector.bin_angles(0, j).2, 0.0)).collect();
            d.set_item("c_deg", split_pairs(py, &c, &[nc], |k| k)?.0)?;
            let sr: Vec<(f64, f64)> = (0..ng).map(|i| (e.detector.solid_angle_sr(i), 0.0)).collect();
            d.set_item("solid_angle_sr", split_pairs(py, &sr, &[ng], |k| k)?.0)?;
            farfield.set_item(&e.detector.name, d)?;
        }
        let volumes = PyDict::new(py);
        for v in &est.volumes {
            let [nx, ny, nz] = v.grid.resolution;
            let d = PyDict::new(py);
            // [z, y, x], as volume_<name>.npy's planes.
            for (name, values) in [("absorbed_w_m3", &v.absorbed_w_m3), ("fluence_w_m2", &v.fluence_w_m2)] {
                let (a, se) = split_pairs(py, values, &[nz, ny, nx], |k| k)?;
                d.set_item(name, a)?;
                d.set_item(format!("{name}_stderr"), se)?;
            }
            // The grid's corners in the scene file's coordinates and units.
            let (lo, hi) = (scene.file_coordinates(v.grid.min), scene.file_coordinates(v.grid.max));
            d.set_item("min", [lo.x, lo.y, lo.z])?;
            d.set_item("max", [hi.x, hi.y, hi.z])?;
            volumes.set_item(&v.grid.name, d)?;
        }
        let warnings = est.warnings;
        Ok(PyRunResult {
            scene,
            run,
            flux_json,
            run_info,
            image,
            xyz,
            y,
            y_var,
            maps: maps.unbind(),
            farfield: farfield.unbind(),
            volumes: volumes.unbind(),
            warnings,
        })
    }
}

fn item<'py>(py: Python<'py>, d: &Py<PyAny>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.bind(py).get_item(key)
}

#[pymethods]
impl PyRunResult {
    /// flux.json's surface rows: one dict per surface (name, area_m2, incident_w and its stderr,
    /// absorbed_w, rel_error, the same in lumens, irradiance_w_m2, illuminance_lx, ...).
    #[getter]
    fn flux<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        item(py, &self.flux_json, "surfaces")
    }

    /// flux.json's medium rows (absorbed_w, and reemitted_w with fluorescence); [] without media.
    #[getter]
    fn media<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match item(py, &self.flux_json, "media") {
            Ok(m) => Ok(m),
            Err(_) => Ok(PyList::empty(py).into_any()),
        }
    }

    /// The energy ledger: emitted_w = absorbed_w + escaped_w + truncated_w.
    #[getter]
    fn ledger<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        item(py, &self.flux_json, "ledger")
    }

    /// The whole of flux.json as a dict (photons, emitted_w, emitted_lm, surfaces, media, ledger).
    #[getter]
    fn flux_json<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.flux_json.bind(py).clone()
    }

    /// run.json as a dict (seed, photons, threads, wall_seconds, stop_reason, counters, ...);
    /// `files` is filled in by save().
    #[getter]
    fn run_info<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        self.run_info.bind(py).clone()
    }

    /// The image: numpy float32 [H, W, 3], linear sRGB (D65) radiance, row 0 at the top; None
    /// without a camera or with image=False.
    #[getter]
    fn image<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.image.as_ref().map(|a| a.bind(py).clone())
    }

    /// CIE 1931 XYZ per pixel: numpy float32 [H, W, 3] (Y in W m^-2 sr^-1 nm^-1 weighted by ȳ).
    #[getter]
    fn xyz<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.xyz.as_ref().map(|a| a.bind(py).clone())
    }

    /// Luminance-weighted radiance Y per pixel: numpy float32 [H, W] (a view into `xyz`).
    #[getter]
    fn y<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.y.as_ref().map(|a| a.bind(py).clone())
    }

    /// The variance of each pixel's Y (from the spread between batches): numpy float32 [H, W].
    #[getter]
    fn y_var<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.y_var.as_ref().map(|a| a.bind(py).clone())
    }

    /// Irradiance maps, surface name → dict of float64 arrays [nv, nu] (row 0 the largest v, as
    /// in maps/<surface>.exr): irradiance_w_m2, illuminance_lx, flux_w, flux_lm, each with
    /// *_stderr, texel_area_m2; and size_m ([u, v] extent of a planar map, else None).
    #[getter]
    fn maps<'py>(&self, py: Python<'py>) -> Bound<'py, PyDict> {
        self.maps.bind(py).clone()
    }

    /// Far-field detectors, name → dict: intensity_w_sr, intensity_cd and their *_stderr as
    /// float64 [n_C, n_γ]; gamma_lo_deg, gamma_hi_deg, solid_angle_sr [n_γ]; c_deg [n_C].
    #[getter]
    fn farfield<'py>(&self, py: Python<'py>) -> Bound<'py, PyDict> {
        self.farfield.bind(py).clone()
    }

    /// Volume detectors, name → dict: absorbed_w_m3, fluence_w_m2 and their *_stderr as float64
    /// [nz, ny, nx] (as volume_<name>.npy), and the grid's min and max corners (file units).
    #[getter]
    fn volumes<'py>(&self, py: Python<'py>) -> Bound<'py, PyDict> {
        self.volumes.bind(py).clone()
    }

    /// What the run warned of (also issued as Python warnings).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// Writes into `dir` exactly the files `photon run --out dir` writes (flux.json, flux.csv,
    /// run.json, image.exr/png, maps/, far-field and volume files), staged and moved into place
    /// whole. Returns the list of files written.
    fn save(&mut self, py: Python<'_>, dir: PathBuf) -> PyResult<Vec<String>> {
        let image = self.run.film.is_some();
        let (scene, run) = (&self.scene, &self.run);
        let written = py.detach(|| -> Result<Vec<String>, Error> {
            let staged = output::OutputDir::prepare(&dir, &output::run_file_names(scene, image))?;
            let report = output::write_run(staged.path(), scene, run)?;
            staged.commit(&output::previous_run_files(&dir))?;
            Ok(report.files)
        });
        let files = written.map_err(|e| py_err(py, e))?;
        self.run_info.bind(py).set_item("files", files.clone())?;
        Ok(files)
    }

    /// The table `photon run` prints at the end.
    fn summary(&self, py: Python<'_>) -> PyResult<String> {
        let flux = output::flux(&self.scene, &self.run);
        let _ = py;
        let mut info = output::run_info(&self.scene, &self.run, &flux);
        if let Some(film) = &self.run.film {
            info.image_mean_y = Some(film.mean_y(self.run.emitted_w));
            info.image_pixel_rel_error =
                Some(film.image(self.run.emitted_w).pixel_rel_error()).filter(|v| v.is_finite());
        }
        Ok(output::summary_table(&flux, &info))
    }

    /// Whether the run was stopped early by Ctrl-C.
    #[getter]
    fn interrupted(&self) -> bool {
        self.run.stop_reason == StopReason::Interrupted
    }

    fn __repr__(&self) -> String {
        format!(
            "<photon.Result {} · {} photons, stopped by {}>",
            self.scene.stem(),
            self.run.tallies.photons,
            self.run.stop_reason.describe()
        )
    }
}

/// Loads and checks a scene file (TOML). Bad input raises photon.SceneError naming the file,
/// key and line.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<PyScene> {
    let text = photon::error::read_utf8(&path, "the scene file").map_err(|e| py_err(py, e.into()))?;
    load_text(py, &path, text)
}

/// Loads a scene from TOML text. Relative file paths in it resolve against `base_dir`; the
/// scene is named `name` (its output folder, plot titles and messages: base_dir/name.toml).
#[pyfunction]
#[pyo3(signature = (toml_text, base_dir=PathBuf::from("."), name="scene"))]
fn loads(py: Python<'_>, toml_text: String, base_dir: PathBuf, name: &str) -> PyResult<PyScene> {
    load_text(py, &base_dir.join(format!("{name}.toml")), toml_text)
}

/// Makes a scene from nested dicts and lists in the scene file's layout (see Scene.to_dict);
/// `base_dir` and `name` as for loads.
#[pyfunction]
#[pyo3(signature = (scene, base_dir=PathBuf::from("."), name="scene"))]
fn from_dict(py: Python<'_>, scene: &Bound<'_, PyDict>, base_dir: PathBuf, name: &str) -> PyResult<PyScene> {
    let table = dict_to_table(scene, "")?;
    from_table(py, &base_dir.join(format!("{name}.toml")), &table)
}

/// Runs the built-in closed-form validation cases (what `photon validate` runs) and returns
/// {"passed": bool, "complete": bool, "cases": [dict per case]}. quick=True takes about 10 s
/// on 2 cores. verbose=True prints each case's line as it finishes. Ctrl-C raises
/// photon.RunInterrupted.
#[pyfunction]
#[pyo3(signature = (quick=true, threads=None, verbose=false))]
fn validate<'py>(py: Python<'py>, quick: bool, threads: Option<usize>, verbose: bool) -> PyResult<Bound<'py, PyDict>> {
    if threads.is_some_and(|t| t == 0 || t > photon::run::MAX_THREADS) {
        return Err(PyValueError::new_err(format!("threads must be between 1 and {}", photon::run::MAX_THREADS)));
    }
    let interrupt = AtomicBool::new(false);
    let lines = std::sync::Mutex::new(Vec::<String>::new());
    let print = |py: Python<'py>, lines: &std::sync::Mutex<Vec<String>>| {
        let new: Vec<String> = lines.lock().map(|mut l| l.drain(..).collect()).unwrap_or_default();
        if verbose && !new.is_empty() {
            if let Ok(out) = py.import("sys").and_then(|s| s.getattr("stdout")) {
                for l in new {
                    let _ = out.call_method1("write", (l,));
                }
                let _ = out.call_method0("flush");
            }
        }
    };
    if verbose {
        lines.lock().map(|mut l| l.push(photon::validate::header())).ok();
    }
    let (ran, raised) = interruptible(
        py,
        &interrupt,
        || {
            photon::validate::run_all(quick, threads, &interrupt, &mut |c| {
                if let Ok(mut l) = lines.lock() {
                    l.push(photon::validate::line(c));
                }
            })
        },
        |py| print(py, &lines),
    )?;
    print(py, &lines);
    let (cases, complete) = ran.map_err(|e| py_err(py, e))?;
    if let Some(e) = raised {
        return Err(if e.is_instance_of::<PyKeyboardInterrupt>(py) {
            let err = RunInterrupted::new_err("validation stopped by Ctrl-C");
            err.value(py).setattr("result", py.None())?;
            err
        } else {
            e
        });
    }
    let list = PyList::empty(py);
    for c in &cases {
        let d = PyDict::new(py);
        d.set_item("name", &c.name)?;
        d.set_item("measured", c.measured)?;
        d.set_item("expected", c.expected)?;
        d.set_item("stderr", c.stderr)?;
        d.set_item("z", c.z())?;
        d.set_item("rel_error", c.rel_error())?;
        d.set_item("rel_target", c.rel_target)?;
        d.set_item("exact", c.exact)?;
        d.set_item("note", &c.note)?;
        d.set_item("passed", c.passed())?;
        list.append(d)?;
    }
    let out = PyDict::new(py);
    out.set_item("passed", complete && cases.iter().all(|c| c.passed()))?;
    out.set_item("complete", complete)?;
    out.set_item("cases", list)?;
    Ok(out)
}

#[pymodule]
fn _photon(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<PyScene>()?;
    m.add_class::<PyRunResult>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(loads, m)?)?;
    m.add_function(wrap_pyfunction!(from_dict, m)?)?;
    m.add_function(wrap_pyfunction!(validate, m)?)?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("RunInterrupted", py.get_type::<RunInterrupted>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
