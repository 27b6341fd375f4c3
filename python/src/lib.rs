//! `photon._photon`: the photon library as a Python extension module. Scenes load through the
//! same loader as the command line, runs go through the same driver (`photon::run`) and results
//! through the same estimates (`photon::output`), so every number equals the CLI's bit for bit.
//! The Python package `photon` (python/photon/) re-exports these names.

use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::IntoPyArray;
use pyo3::create_exception;
use pyo3::exceptions::{
    PyException, PyKeyError, PyKeyboardInterrupt, PyRuntimeError, PyTypeError, PyUserWarning, PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyMapping, PySlice, PyString, PyTuple};

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

/// Deepest nesting of lists and mappings accepted: deeper (or a dict that contains itself) would
/// overflow the stack.
const MAX_DEPTH: usize = 64;

/// A Python value as TOML: bool, int, float (numpy scalars too), str, list or tuple, a mapping
/// with str keys. `at` names the key in messages; `depth` counts the containers around it.
fn py_to_toml(v: &Bound<'_, PyAny>, at: &str, depth: usize) -> PyResult<toml::Value> {
    use toml::Value;
    if depth > MAX_DEPTH {
        return Err(PyValueError::new_err(format!(
            "{at}: nested more than {MAX_DEPTH} levels deep (does a dict or list contain itself?)"
        )));
    }
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
    if let Ok(d) = v.cast::<PyMapping>() {
        return Ok(Value::Table(mapping_to_table(d, at, depth + 1)?));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut a = Vec::new();
        for (i, x) in v.try_iter()?.enumerate() {
            a.push(py_to_toml(&x?, &format!("{at}[{i}]"), depth + 1)?);
        }
        return Ok(Value::Array(a));
    }
    // numpy arrays and scalars become Python lists and numbers (counted as a level, so a
    // `tolist` that returns itself ends too).
    if v.hasattr("tolist")? {
        return py_to_toml(&v.call_method0("tolist")?, at, depth + 1);
    }
    // Other integers (through __index__) before floats, so they stay integers.
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

/// A mapping as a TOML table. None values are dropped: TOML has no null, so a key set to None
/// is a key left out.
fn mapping_to_table(d: &Bound<'_, PyMapping>, at: &str, depth: usize) -> PyResult<toml::Table> {
    let mut t = toml::Table::new();
    for kv in d.items()?.iter() {
        let (k, x): (Bound<'_, PyAny>, Bound<'_, PyAny>) = kv.extract()?;
        let key: String = k.extract().map_err(|_| {
            PyTypeError::new_err(format!("{}: keys must be str", if at.is_empty() { "the scene" } else { at }))
        })?;
        let path = if at.is_empty() { key.clone() } else { format!("{at}.{key}") };
        if x.is_none() {
            continue;
        }
        t.insert(key, py_to_toml(&x, &path, depth)?);
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
    set_steps(root, &steps, value).map_err(|m| PyKeyError::new_err(format!("{key}: {m}")))
}

fn set_steps(root: &mut toml::Table, steps: &[&str], value: Option<toml::Value>) -> Result<(), String> {
    let mut table = root;
    let mut i = 0;
    loop {
        let step = steps[i];
        if i + 1 == steps.len() {
            match value {
                Some(v) => {
                    table.insert(step.to_string(), v);
                }
                None => {
                    table.remove(step);
                }
            }
            return Ok(());
        }
        let here = steps[..=i].join(".");
        let entry = table.entry(step.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        let (next, taken) = match entry {
            toml::Value::Table(t) => (t, 1),
            toml::Value::Array(items) => {
                let pick = steps[i + 1];
                let names: Vec<String> =
                    items.iter().filter_map(|x| x.get("name").and_then(|n| n.as_str()).map(String::from)).collect();
                let k = items
                    .iter()
                    .position(|x| x.get("name").and_then(|n| n.as_str()) == Some(pick))
                    .or_else(|| pick.parse::<usize>().ok().filter(|&k| k < items.len()))
                    .ok_or_else(|| {
                        format!("`{here}` has no entry named (or numbered) `{pick}`; its names: {}", names.join(", "))
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
                match items[k].as_table_mut() {
                    Some(t) => (t, 2),
                    None => return Err(format!("`{here}.{pick}` is not a table")),
                }
            }
            _ => return Err(format!("`{here}` is a value, not a table")),
        };
        table = next;
        i += taken;
    }
}

/// Runs `work` on its own thread with the GIL released, waking every 20 ms to let Python handle
/// signals and to call `tick` (the progress bar, printing). A signal's exception
/// (KeyboardInterrupt), or one `tick` raises (a Ctrl-C can land inside it), sets `interrupt`,
/// which the work polls, and is handed back once the work has ended; `tick` is not called again
/// after it raised.
fn interruptible<'py, T: Send>(
    py: Python<'py>,
    interrupt: &AtomicBool,
    work: impl FnOnce() -> T + Send,
    mut tick: impl FnMut(Python<'py>) -> PyResult<()>,
) -> PyResult<(T, Option<PyErr>)> {
    std::thread::scope(|s| {
        // The stack the command line's main thread has (8 MiB), not a spawned thread's 2 MiB.
        let handle = std::thread::Builder::new()
            .name("photon-run".into())
            .stack_size(8 << 20)
            .spawn_scoped(s, work)
            .map_err(|e| PyRuntimeError::new_err(format!("photon: cannot start the run's thread: {e}")))?;
        let mut raised = None;
        let mut ticking = true;
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
            if ticking {
                if let Err(e) = tick(py) {
                    ticking = false;
                    interrupt.store(true, Ordering::Relaxed);
                    raised.get_or_insert(e);
                }
            }
        }
        match handle.join() {
            Ok(t) => Ok((t, raised)),
            Err(_) => Err(PyRuntimeError::new_err("photon: the run failed (a panic); please report it")),
        }
    })
}

/// The exception `raised` during a run or validation once the work has ended: a
/// KeyboardInterrupt becomes RunInterrupted with `result` (None when there is none), chained to
/// `cause` (what went wrong after it); any other exception is raised as it is.
fn stopped(
    py: Python<'_>,
    raised: PyErr,
    message: &str,
    result: Option<Bound<'_, PyAny>>,
    cause: Option<PyErr>,
) -> PyErr {
    if !raised.is_instance_of::<PyKeyboardInterrupt>(py) {
        return raised;
    }
    let err = RunInterrupted::new_err(message.to_string());
    if let Err(e) = err.value(py).setattr("result", result.unwrap_or_else(|| py.None().into_bound(py))) {
        return e;
    }
    err.set_cause(py, cause);
    err
}

/// The progress bar of `run(progress=True)`: tqdm's when it is installed, else one line on
/// sys.stderr redrawn in place. Exceptions from drawing are the caller's (an interrupt).
struct Bar<'py> {
    tqdm: Option<Bound<'py, PyAny>>,
    total: Option<u64>,
    shown: u64,
    /// Whether the fallback line was drawn (and so needs its newline).
    drew: bool,
    start: Instant,
}

impl<'py> Bar<'py> {
    /// tqdm's bar, or the fallback when tqdm is missing or fails with an Exception; a
    /// KeyboardInterrupt (any BaseException but Exception) is raised.
    fn new(py: Python<'py>, total: Option<u64>) -> PyResult<Self> {
        let made = py.import("tqdm.auto").and_then(|m| {
            let kw = PyDict::new(py);
            kw.set_item("total", total)?;
            kw.set_item("unit", "photon")?;
            kw.set_item("unit_scale", true)?;
            kw.set_item("desc", "photon")?;
            m.getattr("tqdm")?.call((), Some(&kw))
        });
        let tqdm = match made {
            Ok(t) => Some(t),
            Err(e) if e.is_instance_of::<PyException>(py) => None,
            Err(e) => return Err(e),
        };
        Ok(Bar { tqdm, total, shown: 0, drew: false, start: Instant::now() })
    }

    fn update(&mut self, py: Python<'py>, photons: u64) -> PyResult<()> {
        if photons == self.shown {
            return Ok(());
        }
        let step = photons.saturating_sub(self.shown);
        self.shown = photons;
        if let Some(t) = &self.tqdm {
            t.call_method1("update", (step,))?;
            return Ok(());
        }
        let secs = self.start.elapsed().as_secs_f64();
        let line = match self.total {
            Some(n) => {
                format!("\rphoton: {:5.1}%  {} photons  {secs:.1} s", 100.0 * photons as f64 / n as f64, photons)
            }
            None => format!("\rphoton: {photons} photons  {secs:.1} s"),
        };
        let err = py.import("sys")?.getattr("stderr")?;
        // pythonw and some embedders have no stderr: nothing to draw on.
        if err.is_none() {
            return Ok(());
        }
        self.drew = true;
        err.call_method1("write", (line,))?;
        err.call_method0("flush")?;
        Ok(())
    }

    fn close(self, py: Python<'py>) -> PyResult<()> {
        if let Some(t) = &self.tqdm {
            t.call_method0("close")?;
        } else if self.drew {
            py.import("sys")?.getattr("stderr")?.call_method1("write", ("\n",))?;
        }
        Ok(())
    }
}

/// Issues a UserWarning. Stack level 1 is the Python line that called into this module (native
/// code has no frame); under `-W error` the warning's exception is returned.
fn warn(py: Python<'_>, message: &str) -> PyResult<()> {
    let text = CString::new(message.replace('\0', " ")).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    PyErr::warn(py, &py.get_type::<PyUserWarning>(), &text, 1)
}

/// A loaded, checked scene. Make one with `photon.load(path)`, `photon.loads(text)` or
/// `photon.from_dict(d)`; it does not change: `with_overrides` makes a new one.
#[pyclass(module = "photon", name = "Scene", frozen)]
struct PyScene {
    scene: Arc<photon::scene::Scene>,
    /// The TOML text it was loaded from.
    text: String,
    /// `scene.path` made absolute when first loaded: reloads (with_overrides) resolve relative
    /// file paths from its folder whatever the current directory is by then.
    file: PathBuf,
}

/// Loads `text` as the scene file `path` (the path shown: run.json's `scene`, messages),
/// resolving its relative file paths from the folder of `file`.
fn load_text(py: Python<'_>, path: &Path, file: &Path, text: String) -> PyResult<PyScene> {
    let loaded = py.detach(|| photon::scene::load_str(file, &text));
    let mut scene = loaded.map_err(|e| {
        py_err(
            py,
            match e {
                Error::Input(mut ie) if ie.file == file => {
                    ie.file = path.to_path_buf();
                    Error::Input(ie)
                }
                e => e,
            },
        )
    })?;
    scene.path = path.to_path_buf();
    for w in &scene.warnings {
        warn(py, w)?;
    }
    let file = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
    Ok(PyScene { scene: Arc::new(scene), text, file })
}

fn parse_table(py: Python<'_>, scene: &PyScene) -> PyResult<toml::Table> {
    // The text was loaded, so it is TOML; the error is there for completeness.
    scene.text.parse::<toml::Table>().map_err(|e| {
        py_err(py, Error::Other(format!("{}: cannot re-read the scene's TOML: {e}", scene.scene.path.display())))
    })
}

fn table_text(table: &toml::Table) -> PyResult<String> {
    toml::to_string(table).map_err(|e| PyValueError::new_err(format!("cannot write the scene as TOML: {e}")))
}

/// `loads`' and `from_dict`'s scene path, base_dir/name.toml; `name` is a file name's stem.
fn named_path(base_dir: &Path, name: &str) -> PyResult<PathBuf> {
    if name.is_empty() || name.contains(['/', '\\', '\0']) || name.contains("..") {
        return Err(PyValueError::new_err(format!(
            "name must be a file name without a folder (no '/', '\\' or '..'), got {name:?}"
        )));
    }
    Ok(base_dir.join(format!("{name}.toml")))
}

/// An integer argument in lo..=hi: an int (numpy's too) or a float with an integral value
/// (1e6). Out of range is a ValueError, not an int at all a TypeError; both name the argument.
fn int_arg(v: &Bound<'_, PyAny>, name: &str, what: &str, lo: u64, hi: u64) -> PyResult<u64> {
    let got = || v.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into());
    let bad = || PyValueError::new_err(format!("{name} must be {what}, got {}", got()));
    let not_int = || {
        let kind = v.get_type().name().map(|n| n.to_string()).unwrap_or_default();
        PyTypeError::new_err(format!("{name} must be {what}, got a {kind}: {}", got()))
    };
    if v.is_instance_of::<PyBool>() {
        return Err(not_int());
    }
    let n: i128 = if let Ok(n) = v.extract::<i128>() {
        n
    } else if v.is_instance_of::<PyInt>() {
        return Err(bad());
    } else if let Ok(f) = v.extract::<f64>() {
        if f.fract() != 0.0 {
            return Err(bad());
        }
        f as i128
    } else {
        return Err(not_int());
    };
    if n < lo as i128 || n > hi as i128 {
        return Err(bad());
    }
    Ok(n as u64)
}

/// `apply_options`' messages name the command line's flags: any it still gives (a check added
/// there later) names run's arguments instead.
fn python_names(e: Error) -> Error {
    match e {
        Error::Usage(mut m) => {
            for (flag, arg) in [
                ("--photons", "photons"),
                ("--seed", "seed"),
                ("--threads", "threads"),
                ("--max-bounces", "max_bounces"),
                ("--rel-error", "rel_error"),
                ("--time", "time"),
                ("--tally", "tally"),
                ("--integrator", "integrator"),
                ("--no-image", "image=False"),
            ] {
                m = m.replace(flag, arg);
            }
            Error::Usage(m)
        }
        e => e,
    }
}

fn threads_arg(v: Option<&Bound<'_, PyAny>>) -> PyResult<Option<usize>> {
    let max = photon::run::MAX_THREADS;
    v.map(|v| int_arg(v, "threads", &format!("an integer between 1 and {max}"), 1, max as u64).map(|t| t as usize))
        .transpose()
}

#[pymethods]
impl PyScene {
    /// Simulate the scene and return a Result (tallies, ledger, image, maps, ...).
    ///
    /// Every argument left None takes the scene's `[simulation]` value, as on the command line
    /// (`photon run`): photons (default 1 000 000; with rel_error or time, the most to trace; an
    /// int, or an integral float such as 1e6), seed, threads (all cores; results never depend
    /// on it), rel_error (stop when every tallied surface, or those in `tally`, reaches this
    /// relative standard error), time (stop at this budget in seconds), integrator ("light",
    /// "path" or "bdpt": what makes the image), max_bounces. image=False skips the camera image.
    /// estimator "auto" | "expected" | "analog", stratified and hero are the transport options
    /// of `photon run` (`--no-hero` is hero=False). A value out of range raises ValueError.
    ///
    /// Same scene, seed and photons give the same numbers as `photon run`, bit for bit. The GIL is
    /// released while photons are traced. Ctrl-C stops the run at the next batch (within a
    /// fraction of a second) and raises photon.RunInterrupted, a KeyboardInterrupt whose
    /// `result` holds what was traced (None if no Result could be made of it; the reason is its
    /// __cause__). progress=True shows a progress bar (tqdm's if installed); an exception from
    /// drawing it stops the run the same way.
    #[pyo3(signature = (photons=None, seed=None, threads=None, rel_error=None, time=None, integrator=None,
                        image=true, progress=false, tally=None, max_bounces=None, estimator="auto",
                        stratified=false, hero=true))]
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        py: Python<'_>,
        photons: Option<&Bound<'_, PyAny>>,
        seed: Option<&Bound<'_, PyAny>>,
        threads: Option<&Bound<'_, PyAny>>,
        rel_error: Option<f64>,
        time: Option<f64>,
        integrator: Option<&str>,
        image: bool,
        progress: bool,
        tally: Option<Vec<String>>,
        max_bounces: Option<&Bound<'_, PyAny>>,
        estimator: &str,
        stratified: bool,
        hero: bool,
    ) -> PyResult<PyRunResult> {
        // The checks of `apply_options`, made here first so messages name these arguments, not
        // the command line's flags.
        let photons = photons.map(|v| int_arg(v, "photons", "a positive integer", 1, u64::MAX)).transpose()?;
        let seed = seed
            .map(|v| int_arg(v, "seed", &format!("an integer between 0 and {}", u64::MAX), 0, u64::MAX))
            .transpose()?;
        let threads = threads_arg(threads)?;
        let max_bounces = max_bounces
            .map(|v| {
                let what = format!("an integer between 0 and {}", u32::MAX);
                int_arg(v, "max_bounces", &what, 0, u32::MAX as u64).map(|b| b as u32)
            })
            .transpose()?;
        for (name, value) in [("rel_error", rel_error), ("time", time)] {
            if let Some(x) = value.filter(|x| !(*x > 0.0 && x.is_finite())) {
                return Err(PyValueError::new_err(format!("{name} must be a positive number, got {x}")));
            }
        }
        let tally = tally.unwrap_or_default();
        for name in &tally {
            let s = &self.scene;
            if !s.surfaces.iter().any(|x| &x.name == name) && !s.media.iter().any(|m| &m.name == name) {
                let surfaces: Vec<&str> = s.surfaces.iter().map(|x| x.name.as_str()).collect();
                let media: Vec<&str> = s.media.iter().map(|m| m.name.as_str()).collect();
                let media = if media.is_empty() { String::new() } else { format!("; media: {}", media.join(", ")) };
                return Err(PyValueError::new_err(format!(
                    "tally: no surface or medium is named {name:?}; surfaces: {}{media}",
                    surfaces.join(", ")
                )));
            }
        }
        if !tally.is_empty() && rel_error.is_none() {
            return Err(PyValueError::new_err("tally only makes sense with rel_error"));
        }
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
            tallies: tally,
            time_s: time,
            // The command line's bar draws on a terminal only; this one draws wherever Python does.
            progress: false,
            no_image: !image,
            integrator,
            transport: TransportOptions { estimator, stratified, hero },
            ..RunOptions::default()
        };
        let mut scene = (*self.scene).clone();
        let chosen = photon::run::apply_options(&mut scene, &opts).map_err(|e| py_err(py, python_names(e)))?;
        let open_ended = opts.rel_error.is_some() || opts.time_s.is_some();
        let total = match opts.photons {
            Some(p) => Some(p),
            None if open_ended => None,
            None => Some(scene.simulation.photons),
        };
        let interrupt = AtomicBool::new(false);
        let merged = AtomicU64::new(0);
        let mut bar = if progress { Some(Bar::new(py, total)?) } else { None };
        let outcome = interruptible(
            py,
            &interrupt,
            || {
                photon::run::simulate_observed(&scene, &opts, &chosen, &interrupt, &mut |p| {
                    merged.store(p.tallies.photons, Ordering::Relaxed)
                })
            },
            |py| match bar.as_mut() {
                Some(b) => b.update(py, merged.load(Ordering::Relaxed)),
                None => Ok(()),
            },
        );
        // The bar ends at the final count and is closed on every path; what it raises then
        // counts as an interrupt too.
        let drawn = bar.map(|mut b| {
            let count = match &outcome {
                Ok((Ok(r), _)) => r.tallies.photons,
                _ => merged.load(Ordering::Relaxed),
            };
            let updated = b.update(py, count);
            updated.and(b.close(py))
        });
        let (simulated, mut raised) = outcome?;
        if let Some(Err(e)) = drawn {
            raised.get_or_insert(e);
        }
        let message = "stopped by Ctrl-C: `.result` holds the batches traced before it";
        let run = match simulated {
            Ok(r) => r,
            Err(e) => {
                return Err(match raised {
                    Some(r) => stopped(py, r, message, None, Some(py_err(py, e))),
                    None => py_err(py, e),
                })
            }
        };
        let made = PyRunResult::new(py, Arc::new(scene), run);
        match (made, raised) {
            (made, None) => made,
            (Ok(result), Some(r)) => {
                let result = Bound::new(py, result)?.into_any();
                Err(stopped(py, r, message, Some(result), None))
            }
            (Err(e), Some(r)) => Err(stopped(py, r, message, None, Some(e))),
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

    /// A new Scene with some values replaced, given as a mapping {dotted key: value}. Keys
    /// follow the scene file: "simulation.photons", "materials.white.reflectance",
    /// "lights.lamp.power_w". A step into an array of tables (surfaces, lights, detectors) picks
    /// the entry by its name or its index ("surfaces.0.material"). A value None removes the key
    /// (or the entry); a missing table is created; values may be nested mappings and lists.
    /// Relative file paths keep resolving against the original scene's folder (also after a
    /// change of the current directory). A key naming no entry raises KeyError.
    ///
    ///     for r in [0.2, 0.5, 0.8]:
    ///         res = scene.with_overrides({"materials.white.reflectance": r}).run(photons=100_000)
    fn with_overrides(&self, py: Python<'_>, overrides: &Bound<'_, PyMapping>) -> PyResult<PyScene> {
        let mut table = parse_table(py, self)?;
        for kv in overrides.items()?.iter() {
            let (k, v): (Bound<'_, PyAny>, Bound<'_, PyAny>) = kv.extract()?;
            let key: String = k.extract().map_err(|_| PyTypeError::new_err("override keys must be str"))?;
            let value = if v.is_none() { None } else { Some(py_to_toml(&v, &key, 0)?) };
            set_path(&mut table, &key, value)?;
        }
        load_text(py, &self.scene.path, &self.file, table_text(&table)?)
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
#[pyclass(module = "photon", name = "Result", frozen)]
struct PyRunResult {
    scene: Arc<photon::scene::Scene>,
    run: RunResult,
    /// flux.json and run.json's contents (the image's mean Y and pixel error included), for
    /// summary().
    flux: output::Flux,
    info: output::RunInfo,
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

/// One detector's entries in the order they are handed out: float64 arrays, then plain values.
struct Entries {
    name: String,
    arrays: Vec<(String, ndarray::ArrayD<f64>)>,
    values: Vec<(&'static str, Option<Vec<f64>>)>,
}

/// Everything of a Result that takes work, made with the GIL released.
struct Made {
    flux: output::Flux,
    info: output::RunInfo,
    warnings: Vec<String>,
    /// rgb [H, W, 3], xyz [H, W, 3], y_var [H, W].
    image: Option<(ndarray::Array3<f32>, ndarray::Array3<f32>, ndarray::Array2<f32>)>,
    maps: Vec<Entries>,
    farfields: Vec<Entries>,
    volumes: Vec<Entries>,
}

/// (value, s.e.) pairs as two arrays of `shape`, texel k at row-major position `order(k)`.
fn split_pairs(
    pairs: &[(f64, f64)],
    shape: &[usize],
    order: impl Fn(usize) -> usize,
) -> Result<(ndarray::ArrayD<f64>, ndarray::ArrayD<f64>), Error> {
    let n = pairs.len();
    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
    for (k, &(x, s)) in pairs.iter().enumerate() {
        a[order(k)] = x;
        b[order(k)] = s;
    }
    let arr = |v: Vec<f64>| {
        ndarray::ArrayD::from_shape_vec(shape.to_vec(), v).map_err(|e| Error::Other(format!("array shape: {e}")))
    };
    Ok((arr(a)?, arr(b)?))
}

/// The coordinate as the user wrote it, as `photon info` shows it: 12 significant digits drop
/// the rounding of the recentring (1.2999999999999998 -> 1.3).
fn round_shown(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

fn make(scene: &photon::scene::Scene, run: &RunResult) -> Result<Made, Error> {
    let est = output::estimates(scene, run)?;
    let image = match est.image {
        Some(im) => {
            let (w, h) = (im.width, im.height);
            let shape_err = |e: ndarray::ShapeError| Error::Other(format!("image shape: {e}"));
            // Moved, not copied: rgb is [H, W, 3] already; xyz (pixel, channel) and y_var
            // (pixel) are row-major over the pixels, so only their shapes change.
            let xyz = im.xyz.into_shape_with_order((h, w, 3)).map_err(shape_err)?;
            let y_var = ndarray::Array2::from_shape_vec((h, w), im.y_var).map_err(shape_err)?;
            Some((im.rgb, xyz, y_var))
        }
        None => None,
    };
    let with_stderr = |arrays: &mut Vec<(String, ndarray::ArrayD<f64>)>, name: &str, (v, se)| {
        arrays.push((name.to_string(), v));
        arrays.push((format!("{name}_stderr"), se));
    };
    let mut maps = Vec::new();
    for m in &est.maps {
        let [nu, nv] = m.resolution;
        // Row 0 is the largest v, as in maps/<surface>.exr: imshow shows what the PNG shows.
        let flip = |k: usize| (nv - 1 - k / nu) * nu + k % nu;
        let mut arrays = Vec::new();
        for (name, values) in [
            ("irradiance_w_m2", m.irradiance_w_m2()),
            ("illuminance_lx", m.illuminance_lx()),
            ("flux_w", m.flux_w.clone()),
            ("flux_lm", m.flux_lm.clone()),
        ] {
            with_stderr(&mut arrays, name, split_pairs(&values, &[nv, nu], flip)?);
        }
        let area: Vec<(f64, f64)> = m.texel_area_m2.iter().map(|&a| (a, 0.0)).collect();
        arrays.push(("texel_area_m2".into(), split_pairs(&area, &[nv, nu], flip)?.0));
        let values = vec![("size_m", m.size_m.map(|s| s.to_vec()))];
        maps.push(Entries { name: m.surface.clone(), arrays, values });
    }
    let mut farfields = Vec::new();
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
        let mut arrays = Vec::new();
        // [C, γ] like the CSV's rows: C slowest.
        for (name, values) in [("intensity_w_sr", &parts[0]), ("intensity_cd", &parts[1])] {
            with_stderr(&mut arrays, name, split_pairs(values, &[nc, ng], |k| k)?);
        }
        let gamma: Vec<(f64, f64)> = (0..ng)
            .map(|i| {
                let (g0, g1, _) = e.detector.bin_angles(i, 0);
                (g0, g1)
            })
            .collect();
        let (g0, g1) = split_pairs(&gamma, &[ng], |k| k)?;
        arrays.push(("gamma_lo_deg".into(), g0));
        arrays.push(("gamma_hi_deg".into(), g1));
        let c: Vec<(f64, f64)> = (0..nc).map(|j| (e.detector.bin_angles(0, j).2, 0.0)).collect();
        arrays.push(("c_deg".into(), split_pairs(&c, &[nc], |k| k)?.0));
        let sr: Vec<(f64, f64)> = (0..ng).map(|i| (e.detector.solid_angle_sr(i), 0.0)).collect();
        arrays.push(("solid_angle_sr".into(), split_pairs(&sr, &[ng], |k| k)?.0));
        farfields.push(Entries { name: e.detector.name.clone(), arrays, values: Vec::new() });
    }
    let mut volumes = Vec::new();
    for v in &est.volumes {
        let [nx, ny, nz] = v.grid.resolution;
        let mut arrays = Vec::new();
        // [z, y, x], as volume_<name>.npy's planes.
        for (name, values) in [("absorbed_w_m3", &v.absorbed_w_m3), ("fluence_w_m2", &v.fluence_w_m2)] {
            with_stderr(&mut arrays, name, split_pairs(values, &[nz, ny, nx], |k| k)?);
        }
        // The grid's corners in the scene file's coordinates and units.
        let corner = |p| {
            let p = scene.file_coordinates(p);
            Some(vec![round_shown(p.x), round_shown(p.y), round_shown(p.z)])
        };
        let values = vec![("min", corner(v.grid.min)), ("max", corner(v.grid.max))];
        volumes.push(Entries { name: v.grid.name.clone(), arrays, values });
    }
    Ok(Made { flux: est.flux, info: est.info, warnings: est.warnings, image, maps, farfields, volumes })
}

fn entries_to_py<'py>(py: Python<'py>, all: Vec<Entries>) -> PyResult<Py<PyDict>> {
    let out = PyDict::new(py);
    for e in all {
        let d = PyDict::new(py);
        for (name, a) in e.arrays {
            d.set_item(name, a.into_pyarray(py))?;
        }
        for (name, v) in e.values {
            d.set_item(name, v)?;
        }
        out.set_item(e.name, d)?;
    }
    Ok(out.unbind())
}

impl PyRunResult {
    fn new(py: Python<'_>, scene: Arc<photon::scene::Scene>, run: RunResult) -> PyResult<Self> {
        let made = py.detach(|| make(&scene, &run)).map_err(|e| py_err(py, e))?;
        for w in &made.warnings {
            warn(py, w)?;
        }
        let flux_json = serialize_to_py(py, &made.flux)?.unbind();
        let run_info = serialize_to_py(py, &made.info)?.unbind();
        let (mut image, mut xyz, mut y, mut y_var) = (None, None, None, None);
        if let Some((rgb, xyz_a, var)) = made.image {
            // Into numpy without a copy; y is a view into xyz.
            image = Some(rgb.into_pyarray(py).into_any().unbind());
            let xyz_arr = xyz_a.into_pyarray(py);
            let full = PySlice::full(py);
            y = Some(xyz_arr.as_any().get_item((full.clone(), full, 1))?.unbind());
            xyz = Some(xyz_arr.into_any().unbind());
            y_var = Some(var.into_pyarray(py).into_any().unbind());
        }
        Ok(PyRunResult {
            scene,
            run,
            flux: made.flux,
            info: made.info,
            flux_json,
            run_info,
            image,
            xyz,
            y,
            y_var,
            maps: entries_to_py(py, made.maps)?,
            farfield: entries_to_py(py, made.farfields)?,
            volumes: entries_to_py(py, made.volumes)?,
            warnings: made.warnings,
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

    /// flux.json's work-plane rows (E_min, E_mean, E_max and U0 in illuminance_lx and
    /// irradiance_w_m2, each with its stderr); [] without work planes.
    #[getter]
    fn planes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match item(py, &self.flux_json, "planes") {
            Ok(m) => Ok(m),
            Err(_) => Ok(PyList::empty(py).into_any()),
        }
    }

    /// The energy ledger: emitted_w = absorbed_w + escaped_w + truncated_w.
    #[getter]
    fn ledger<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        item(py, &self.flux_json, "ledger")
    }

    /// The whole of flux.json as a dict (photons, emitted_w, emitted_lm, surfaces, media, maps,
    /// planes, ledger).
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
    /// run.json, image.exr/png, maps/, far-field and volume files), staged in a hidden folder and
    /// moved into place whole; files an earlier run there listed and this one does not write are
    /// removed, nothing else is touched. Returns the list of files written (also run_info's
    /// `files`). The GIL is released while writing; saves from several threads may run at once.
    fn save(&self, py: Python<'_>, dir: PathBuf) -> PyResult<Vec<String>> {
        let image = self.run.film.is_some();
        let (scene, run) = (&self.scene, &self.run);
        let written = py.detach(|| -> Result<Vec<String>, Error> {
            let staged = output::OutputDir::prepare(&dir, &output::run_file_names(scene, image, false))?;
            let report = output::write_run(staged.path(), scene, run)?;
            staged.commit(&output::previous_run_files(&dir))?;
            Ok(report.files)
        });
        let files = written.map_err(|e| match e {
            // The library names the command line's flag; here the folder is save's argument.
            Error::Usage(m) if m.starts_with("--out ") => PyValueError::new_err(format!("save: dir {}", &m[6..])),
            e => py_err(py, e),
        })?;
        self.run_info.bind(py).set_item("files", files.clone())?;
        Ok(files)
    }

    /// The table `photon run` prints at the end.
    fn summary(&self) -> String {
        output::summary_table(&self.flux, &self.info)
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
/// key and line. Relative file paths in it (meshes, spectra, IES files) resolve against the
/// scene file's folder, also in later with_overrides after a change of directory.
#[pyfunction]
fn load(py: Python<'_>, path: PathBuf) -> PyResult<PyScene> {
    let text = photon::error::read_utf8(&path, "the scene file").map_err(|e| py_err(py, e.into()))?;
    load_text(py, &path, &path, text)
}

/// Loads a scene from TOML text. Relative file paths in it resolve against `base_dir`; the
/// scene is named `name` (its output folder, plot titles and messages: base_dir/name.toml);
/// `name` must be a file name's stem (no '/', '\' or '..': ValueError).
#[pyfunction]
#[pyo3(signature = (toml_text, base_dir=PathBuf::from("."), name="scene"))]
fn loads(py: Python<'_>, toml_text: String, base_dir: PathBuf, name: &str) -> PyResult<PyScene> {
    let path = named_path(&base_dir, name)?;
    load_text(py, &path, &path, toml_text)
}

/// Makes a scene from nested mappings (dicts) and lists in the scene file's layout (see
/// Scene.to_dict); `base_dir` and `name` as for loads. TOML has no null: a key whose value is
/// None is left out (as if absent); None inside a list is a TypeError. Nesting deeper than 64
/// levels (a dict that contains itself) is a ValueError.
#[pyfunction]
#[pyo3(signature = (scene, base_dir=PathBuf::from("."), name="scene"))]
fn from_dict(py: Python<'_>, scene: &Bound<'_, PyMapping>, base_dir: PathBuf, name: &str) -> PyResult<PyScene> {
    let path = named_path(&base_dir, name)?;
    let table = mapping_to_table(scene, "", 0)?;
    load_text(py, &path, &path, table_text(&table)?)
}

/// Runs the built-in closed-form validation cases (what `photon validate` runs) and returns
/// {"passed": bool, "complete": bool, "cases": [dict per case]}. quick=True takes about 10 s
/// on 2 cores. verbose=True prints each case's line as it finishes. Ctrl-C raises
/// photon.RunInterrupted.
#[pyfunction]
#[pyo3(signature = (quick=true, threads=None, verbose=false))]
fn validate<'py>(
    py: Python<'py>,
    quick: bool,
    threads: Option<&Bound<'py, PyAny>>,
    verbose: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let threads = threads_arg(threads)?;
    let interrupt = AtomicBool::new(false);
    let lines = std::sync::Mutex::new(Vec::<String>::new());
    let print = |py: Python<'py>, lines: &std::sync::Mutex<Vec<String>>| -> PyResult<()> {
        let new: Vec<String> = lines.lock().map(|mut l| l.drain(..).collect()).unwrap_or_default();
        if verbose && !new.is_empty() {
            let out = py.import("sys")?.getattr("stdout")?;
            if out.is_none() {
                return Ok(());
            }
            for l in new {
                out.call_method1("write", (l,))?;
            }
            out.call_method0("flush")?;
        }
        Ok(())
    };
    if verbose {
        lines.lock().map(|mut l| l.push(photon::validate::header())).ok();
    }
    let (ran, mut raised) = interruptible(
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
    if let Err(e) = print(py, &lines) {
        raised.get_or_insert(e);
    }
    let message = "validation stopped by Ctrl-C";
    let (cases, complete) = match (ran, raised) {
        (Ok(done), None) => done,
        (Err(e), None) => return Err(py_err(py, e)),
        (Ok(_), Some(r)) => return Err(stopped(py, r, message, None, None)),
        (Err(e), Some(r)) => return Err(stopped(py, r, message, None, Some(py_err(py, e)))),
    };
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
