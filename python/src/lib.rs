//! `valve_bridge._native`: the Python bindings of the valve-bridge library, built with maturin.
//!
//! Every function calls the library the CLI calls (no analysis is written here) and returns
//! plain Python objects: results are the library's serde structs serialised as JSON (the CLI's
//! `--json` documents, byte for byte) and parsed with Python's `json`, signals are numpy arrays.
//! Long work runs with the GIL released. Errors raise `valve_bridge.Error` with the CLI's
//! one-line message. `valve_bridge/__init__.py` adds the Python-side conveniences (DataFrames,
//! lists, paths).

use std::path::PathBuf;

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use serde::Serialize;
use valve_bridge::diagnose as diagnosis;
use valve_bridge::fit::{self, windows::WindowList};
use valve_bridge::fleet::{self, Job, ValveMap, ValveSummary};
use valve_bridge::metrics::steps::{analyse_recording, StepOptions};
use valve_bridge::model::{ModelKind, ModelSpec, Valve};
use valve_bridge::recording::{self, ColumnMap, ReadOptions};
use valve_bridge::report;

pyo3::create_exception!(
    valve_bridge,
    Error,
    pyo3::exceptions::PyException,
    "A recording, model or analysis that valve-bridge refuses; the message is the CLI's one line."
);

/// The error as the CLI prints it (its causes on one line), raised as `valve_bridge.Error`.
fn err<E: Into<anyhow::Error>>(e: E) -> PyErr {
    Error::new_err(valve_bridge::error_line(&e.into()))
}

/// `value` as the CLI's JSON, parsed by Python's `json` into dicts, lists and numbers.
fn to_py<T: Serialize>(py: Python<'_>, value: &T) -> PyResult<PyObject> {
    let text = serde_json::to_string(value).map_err(err)?;
    from_json(py, &text)
}

fn from_json(py: Python<'_>, text: &str) -> PyResult<PyObject> {
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

/// A Python object as `T`, through `json.dumps`.
fn from_py<T: serde::de::DeserializeOwned>(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<T> {
    let text: String = obj
        .py()
        .import("json")?
        .call_method1("dumps", (obj,))?
        .extract()?;
    serde_json::from_str(&text)
        .map_err(|e| Error::new_err(format!("{what}: {e}; pass it as valve_bridge returned it")))
}

/// A checked recording: t, op, vp (numpy arrays), sample_period, source, warnings.
#[pyclass(frozen, name = "Recording", module = "valve_bridge")]
struct PyRecording(recording::Recording);

#[pymethods]
impl PyRecording {
    #[getter]
    fn t<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.0.t)
    }
    #[getter]
    fn op<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.0.op)
    }
    #[getter]
    fn vp<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.0.vp)
    }
    #[getter]
    fn sample_period(&self) -> f64 {
        self.0.sample_period
    }
    #[getter]
    fn source(&self) -> String {
        self.0.source.clone()
    }
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.0.warnings.clone()
    }
    #[getter]
    fn duration(&self) -> f64 {
        self.0.duration()
    }
    fn __len__(&self) -> usize {
        self.0.len()
    }
    fn __repr__(&self) -> String {
        format!(
            "Recording({}: {} samples every {} s)",
            self.0.source,
            self.0.len(),
            self.0.sample_period
        )
    }
}

/// Reads a recording file, with the CLI's options (`columns="t=TIME,op=CV,vp=POS"`, ...).
#[pyfunction]
#[pyo3(signature = (path, columns=None, skip_missing=false, reverse=false, timestamps=false, scale=1.0))]
fn read(
    py: Python<'_>,
    path: PathBuf,
    columns: Option<&str>,
    skip_missing: bool,
    reverse: bool,
    timestamps: bool,
    scale: f64,
) -> PyResult<PyRecording> {
    let columns = match columns {
        Some(c) => c.parse::<ColumnMap>().map_err(err)?,
        None => ColumnMap::default(),
    };
    let opts = ReadOptions {
        timestamps: timestamps || columns.t_is_date_and_time(),
        columns,
        skip_missing,
        reverse_sorted: reverse,
        scale,
        ..ReadOptions::default()
    };
    let rec = py
        .allow_threads(|| recording::read(&path, &opts))
        .map_err(err)?;
    Ok(PyRecording(rec))
}

/// A recording from float64 arrays (`vp` may be empty), with the file reader's checks.
#[pyfunction]
fn _from_arrays(
    t: PyReadonlyArray1<f64>,
    op: PyReadonlyArray1<f64>,
    vp: PyReadonlyArray1<f64>,
) -> PyResult<PyRecording> {
    let v = |a: &PyReadonlyArray1<f64>| a.as_array().to_vec();
    recording::Recording::from_vectors(v(&t), v(&op), v(&vp))
        .map(PyRecording)
        .map_err(err)
}

/// A valve model: load, save, and the TOML text of a model file.
#[pyclass(frozen, name = "Model", module = "valve_bridge")]
struct PyModel(ModelSpec);

#[pymethods]
impl PyModel {
    /// Loads a model file (as `simulate --model` does).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        ModelSpec::load(&path).map(PyModel).map_err(err)
    }
    /// A model from the text of a model file.
    #[staticmethod]
    fn from_toml(text: &str) -> PyResult<Self> {
        ModelSpec::from_toml(text, std::path::Path::new("<text>"))
            .map(PyModel)
            .map_err(err)
    }
    /// The model file's text.
    fn to_toml(&self) -> String {
        self.0.to_toml()
    }
    /// Writes the model file (loadable by `simulate`, the emulated valve and sim-device).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        std::fs::write(&path, self.0.to_toml())
            .map_err(|e| Error::new_err(format!("{}: cannot write: {e}", path.display())))
    }
    #[getter]
    fn kind(&self) -> String {
        self.0.model.tag().to_string()
    }
    fn __repr__(&self) -> String {
        format!("Model({})", self.0.model.display_name())
    }
}

/// Runs `model` over O_P sampled every `sample_period` s, from V_P = `vp0`; returns V_P.
#[pyfunction]
fn _simulate<'py>(
    py: Python<'py>,
    model: &PyModel,
    op: PyReadonlyArray1<f64>,
    sample_period: f64,
    vp0: f64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let op = op.as_array().to_vec();
    let spec = &model.0;
    let sim =
        py.allow_threads(|| Valve::new(spec, sample_period).map(|mut v| v.simulate(&op, vp0)));
    Ok(PyArray1::from_vec(py, sim.map_err(err)?))
}

/// Fits the paper's models (`identify --json`): `models` as `["fopdt", "pincart2"]`,
/// `windows` as `"12.5-80,130-400"`.
#[pyfunction]
#[pyo3(signature = (rec, models=None, windows=None))]
fn identify(
    py: Python<'_>,
    rec: &PyRecording,
    models: Option<Vec<String>>,
    windows: Option<&str>,
) -> PyResult<PyObject> {
    let kinds = match models {
        Some(m) => m
            .iter()
            .map(|s| s.parse::<ModelKind>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| Error::new_err(format!("models: {e}")))?,
        None => fit::Options::default().models,
    };
    let windows = windows
        .map(|w| w.parse::<WindowList>())
        .transpose()
        .map_err(err)?;
    let opts = fit::Options {
        windows: windows.map(|w| w.0),
        ..fit::Options::for_models(&kinds)
    };
    let id = py
        .allow_threads(|| fit::identify(&rec.0.view(), &opts, &|_, _| {}))
        .map_err(err)?;
    to_py(py, &id)
}

/// The step-delay analysis (`steps --json`).
#[pyfunction]
#[pyo3(signature = (rec, min_size=0.5, fraction=0.1, min_hold=1.0))]
fn steps(
    py: Python<'_>,
    rec: &PyRecording,
    min_size: f64,
    fraction: f64,
    min_hold: f64,
) -> PyResult<PyObject> {
    let opts = StepOptions::new(min_size, fraction, min_hold).map_err(err)?;
    let a = py
        .allow_threads(|| analyse_recording(&rec.0.view(), &opts))
        .map_err(|e| err(anyhow::Error::from(e).context(rec.0.source.clone())))?;
    to_py(py, &a)
}

/// Diagnoses a recording (`diagnose --json`), from `model` or a fitted FOPDT; with `out`, writes
/// `diagnose --out`'s report.html, model.toml and diagnosis.json there.
#[pyfunction]
#[pyo3(signature = (rec, model=None, out=None))]
fn diagnose(
    py: Python<'_>,
    rec: &PyRecording,
    model: Option<&PyModel>,
    out: Option<PathBuf>,
) -> PyResult<PyObject> {
    let base = model.map(|m| &m.0);
    let r = &rec.0;
    let doc = py.allow_threads(|| -> anyhow::Result<String> {
        let d = diagnosis::diagnose(&r.view(), base, &|_, _| {})
            .map_err(|e| anyhow::Error::from(e).context(format!("diagnosing {}", r.source)))?;
        if let Some(dir) = &out {
            report::write_files(dir, &report::diagnose::files(&r.source, &r.view(), &d))?;
        }
        Ok(serde_json::to_string(&report::diagnose::json(&d))?)
    });
    from_json(py, &doc.map_err(err)?)
}

/// The valves of a directory (`fleet DIR [--valves MAP]`), as job dicts for `diagnose_valve`.
#[pyfunction]
#[pyo3(signature = (dir, valves=None))]
fn fleet_jobs(py: Python<'_>, dir: PathBuf, valves: Option<PathBuf>) -> PyResult<PyObject> {
    let map = valves
        .as_deref()
        .map(ValveMap::load)
        .transpose()
        .map_err(err)?;
    to_py(py, &fleet::jobs(&dir, map.as_ref()).map_err(err)?)
}

/// One valve of a fleet diagnosed and summarised (a row of `summary.json`); with `out`, its
/// report goes to `out/valves/<valve>/`. A valve that fails is a row with its `error`.
#[pyfunction]
#[pyo3(signature = (job, out=None))]
fn diagnose_valve(
    py: Python<'_>,
    job: &Bound<'_, PyAny>,
    out: Option<PathBuf>,
) -> PyResult<PyObject> {
    let job: Job = from_py(job, "job")?;
    let s =
        py.allow_threads(|| fleet::diagnose_valve(&job, &ReadOptions::default(), out.as_deref()));
    to_py(py, &s)
}

/// Ranks fleet rows (from `diagnose_valve`) into the fleet summary (`summary.json`); with
/// `out`, writes index.html, summary.csv and summary.json there.
#[pyfunction]
#[pyo3(signature = (rows, out=None))]
fn fleet_report(
    py: Python<'_>,
    rows: &Bound<'_, PyAny>,
    out: Option<PathBuf>,
) -> PyResult<PyObject> {
    let rows: Vec<ValveSummary> = from_py(rows, "rows")?;
    let f = fleet::Fleet::ranked(rows);
    if let Some(dir) = &out {
        py.allow_threads(|| fleet::write(dir, &f)).map_err(err)?;
    }
    to_py(py, &f)
}

/// A whole directory on this machine, in parallel (`valve-bridge fleet`); returns the summary.
#[pyfunction]
#[pyo3(signature = (dir, out=None, valves=None))]
fn fleet_run(
    py: Python<'_>,
    dir: PathBuf,
    out: Option<PathBuf>,
    valves: Option<PathBuf>,
) -> PyResult<PyObject> {
    let map = valves
        .as_deref()
        .map(ValveMap::load)
        .transpose()
        .map_err(err)?;
    let jobs = fleet::jobs(&dir, map.as_ref()).map_err(err)?;
    let f = py.allow_threads(|| -> anyhow::Result<fleet::Fleet> {
        let f = fleet::run(&jobs, &ReadOptions::default(), out.as_deref(), &|_, _| {});
        if let Some(dir) = &out {
            fleet::write(dir, &f)?;
        }
        Ok(f)
    });
    to_py(py, &f.map_err(err)?)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<Error>())?;
    m.add_class::<PyRecording>()?;
    m.add_class::<PyModel>()?;
    for f in [
        wrap_pyfunction!(read, m)?,
        wrap_pyfunction!(_from_arrays, m)?,
        wrap_pyfunction!(_simulate, m)?,
        wrap_pyfunction!(identify, m)?,
        wrap_pyfunction!(steps, m)?,
        wrap_pyfunction!(diagnose, m)?,
        wrap_pyfunction!(fleet_jobs, m)?,
        wrap_pyfunction!(diagnose_valve, m)?,
        wrap_pyfunction!(fleet_report, m)?,
        wrap_pyfunction!(fleet_run, m)?,
    ] {
        m.add_function(f)?;
    }
    Ok(())
}
