//! `vesselhex._native`: the library's meshing, centerlines and writers for Python, on arrays.
//!
//! The Python API (argument checks, conversion of PyVista, meshio and VTK objects, docstrings)
//! is `python/vesselhex/__init__.py`; this module takes clean arguments (paths or float64 and
//! int64 arrays), runs the library with the GIL released and hands back numpy arrays. Every
//! library error becomes a `vesselhex.VesselhexError` subclass carrying the command line's
//! one-line message.

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use std::path::{Path, PathBuf};
use vesselhex::centerline_extract::{extract_centerlines, ExtractOptions, Extraction, InletChoice};
use vesselhex::config::{MeshConfig, Preset};
use vesselhex::inlets::InletMark;
use vesselhex::input::{PolylineArrays, TriangleSurface};
use vesselhex::pipeline::{CenterlineSource, MeshSettings, MeshedVessel};
use vesselhex::progress::Progress;
use vesselhex::units::LengthUnit;

pyo3::create_exception!(
    _native,
    VesselhexError,
    PyException,
    "A vesselhex error: the message names the file, the place and the fix."
);
pyo3::create_exception!(
    _native,
    InputError,
    VesselhexError,
    "An input (surface, centerlines, case file) vesselhex cannot use."
);
pyo3::create_exception!(_native, ConfigError, VesselhexError, "A setting out of range or inconsistent.");
pyo3::create_exception!(_native, GeometryError, VesselhexError, "The geometry defeats the method at a named place.");
pyo3::create_exception!(_native, FileError, VesselhexError, "A file or folder that cannot be read or written.");

/// A polyline handed to Python: points (n, 3) and, when known, radii (n,).
type PyPolyline<'py> = (Bound<'py, PyArray2<f64>>, Option<Bound<'py, PyArray1<f64>>>);
/// A polyline handed over by Python.
type PolylineIn<'py> = (PyReadonlyArray2<'py, f64>, Option<PyReadonlyArray1<'py, f64>>);

/// The library's error as the Python exception of its kind, with the command line's message.
fn to_py(error: vesselhex::Error) -> PyErr {
    let message = vesselhex::error::one_line(&error.to_string());
    match error {
        vesselhex::Error::Input { .. } => InputError::new_err(message),
        vesselhex::Error::Config(_) => ConfigError::new_err(message),
        vesselhex::Error::Geometry(_) | vesselhex::Error::ShortBranch { .. } => GeometryError::new_err(message),
        vesselhex::Error::Io { .. } => FileError::new_err(message),
    }
}

fn config_error(message: String) -> PyErr {
    ConfigError::new_err(message)
}

fn unit(name: Option<&str>, what: &str) -> PyResult<Option<LengthUnit>> {
    name.map(|u| u.parse::<LengthUnit>().map_err(|e| config_error(format!("{what}={u:?}: {e}")))).transpose()
}

/// A surface given as a file (or a folder of wall and caps, or a wall with `caps`) or as arrays,
/// with the caps given in files of their own.
fn read_surface_and_caps(
    path: Option<PathBuf>,
    arrays: Option<(PyReadonlyArray2<f64>, PyReadonlyArray2<i64>)>,
    caps: Vec<(String, PathBuf)>,
    units: LengthUnit,
    max_memory: u64,
) -> PyResult<(TriangleSurface, Vec<vesselhex::input::NamedCap>)> {
    let limits = vesselhex::input::ReadLimits::within(max_memory);
    let in_parts = path.as_ref().is_some_and(|p| !caps.is_empty() || p.is_dir());
    let (Some(path), true) = (&path, in_parts) else {
        if !caps.is_empty() {
            return Err(config_error("caps come with a wall file as the surface, not with arrays".into()));
        }
        return read_surface(path, arrays, units, max_memory).map(|s| (s, vec![]));
    };
    let files = vesselhex::input::surface_files(path, &caps).map_err(to_py)?;
    let (surface, _, named) = vesselhex::input::read_surface_parts(&files, units, &limits).map_err(to_py)?;
    Ok((surface, named))
}

/// A surface given as a file or as arrays.
fn read_surface(
    path: Option<PathBuf>,
    arrays: Option<(PyReadonlyArray2<f64>, PyReadonlyArray2<i64>)>,
    units: LengthUnit,
    max_memory: u64,
) -> PyResult<TriangleSurface> {
    let limits = vesselhex::input::ReadLimits::within(max_memory);
    let result = match (path, arrays) {
        (Some(path), None) => vesselhex::input::read_surface_within(&path, units, &limits),
        (None, Some((points, triangles))) => {
            let points = rows::<3, f64>(&points, "points")?;
            let triangles = rows::<3, i64>(&triangles, "triangles")?;
            vesselhex::input::surface_from_arrays(&points, &triangles, units, Path::new("surface (points, triangles)"))
        }
        _ => return Err(config_error("give the surface as a file or as (points, triangles)".into())),
    };
    result.map(|(surface, _)| surface).map_err(to_py)
}

/// The rows of an (n, N) array.
fn rows<const N: usize, T: numpy::Element + Copy>(array: &PyReadonlyArray2<T>, what: &str) -> PyResult<Vec<[T; N]>> {
    let view = array.as_array();
    if view.ncols() != N {
        return Err(config_error(format!("{what} must have {N} columns, not {}", view.ncols())));
    }
    Ok(view.rows().into_iter().map(|r| std::array::from_fn(|k| r[k])).collect())
}

/// A case-file table from a Python dict (str keys; bool, int, float, str, lists and dicts).
fn toml_table(dict: &Bound<PyDict>, at: &str) -> PyResult<toml::Table> {
    let mut table = toml::Table::new();
    for (key, value) in dict.iter() {
        let key: String = key.extract().map_err(|_| config_error(format!("config{at}: keys must be strings")))?;
        let here = format!("{at}[{key:?}]");
        table.insert(key, toml_value(&value, &here)?);
    }
    Ok(table)
}

fn toml_value(value: &Bound<PyAny>, at: &str) -> PyResult<toml::Value> {
    if value.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(value.extract()?));
    }
    if let Ok(dict) = value.cast::<PyDict>() {
        return Ok(toml::Value::Table(toml_table(dict, at)?));
    }
    if value.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(value.extract()?));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items: Vec<Bound<PyAny>> = value.try_iter()?.collect::<PyResult<_>>()?;
        let values = items.iter().enumerate().map(|(i, v)| toml_value(v, &format!("{at}[{i}]")));
        return Ok(toml::Value::Array(values.collect::<PyResult<_>>()?));
    }
    if value.is_instance_of::<PyInt>() || (!value.is_instance_of::<PyFloat>() && value.hasattr("__index__")?) {
        return Ok(toml::Value::Integer(value.extract()?));
    }
    match value.extract::<f64>() {
        Ok(x) => Ok(toml::Value::Float(x)),
        Err(_) => Err(config_error(format!(
            "config{at}: a {} is not a setting (use numbers, strings, booleans, lists and dicts)",
            value.get_type().name()?
        ))),
    }
}

/// The configuration as the command line builds it: preset, then the case file (a path or a
/// dict), then the keyword arguments.
fn build_config(
    preset: Option<&str>,
    config_path: Option<PathBuf>,
    config_dict: Option<&Bound<PyDict>>,
    units: Option<LengthUnit>,
    output_units: Option<LengthUnit>,
    formats: Option<Vec<String>>,
) -> PyResult<MeshConfig> {
    let preset = preset.map(|p| p.parse::<Preset>().map_err(|e| config_error(format!("preset: {e}")))).transpose()?;
    let mut config = match (config_path, config_dict) {
        (Some(path), None) => MeshConfig::from_case_file(&path, preset).map_err(to_py)?,
        (None, Some(dict)) => {
            MeshConfig::from_case_table(toml_table(dict, "")?, Path::new("config"), preset).map_err(to_py)?
        }
        (None, None) => MeshConfig::preset(preset.unwrap_or_default()),
        (Some(_), Some(_)) => return Err(config_error("give config as a path or as a dict, not both".into())),
    };
    if let Some(u) = units {
        config.units = u;
    }
    if let Some(u) = output_units {
        config.output_units = u;
    }
    if let Some(f) = formats {
        config.formats = f;
    }
    config.validate().map_err(to_py)?;
    Ok(config)
}

/// Extraction options with the points given in `units`.
fn extract_options(inlet: Option<[f64; 3]>, ends: Vec<[f64; 3]>, units: LengthUnit) -> ExtractOptions {
    let mm = |p: [f64; 3]| nalgebra::Point3::from(p) * units.to_mm();
    ExtractOptions {
        inlet: inlet.map_or(InletChoice::Largest, |p| InletChoice::Nearest(mm(p))),
        ends: ends.into_iter().map(mm).collect(),
        ..Default::default()
    }
}

/// A progress that calls a Python function with each stage's name (its exceptions are kept and
/// raised when meshing ends).
fn progress_calling(callback: Option<Py<PyAny>>, raised: std::sync::Arc<std::sync::Mutex<Option<PyErr>>>) -> Progress {
    match callback {
        None => Progress::new(true, 0),
        Some(callback) => Progress::with_listener(Box::new(move |stage: &str| {
            Python::attach(|py| {
                if let Err(e) = callback.call1(py, (stage,)) {
                    raised.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                }
            })
        })),
    }
}

/// Meshes a vessel; see `vesselhex.mesh` for the arguments.
#[pyfunction]
#[pyo3(signature = (*, surface_path=None, surface_arrays=None, centerlines_path=None, centerline_arrays=None,
    centerlines_computed=None, preset=None, config_path=None, config_dict=None, units=None, centerline_units=None,
    output_units=None, formats=None, inlet=None, ends=vec![], max_memory=None, progress=None, caps=vec![], inlets=vec![]))]
#[allow(clippy::too_many_arguments)]
fn mesh(
    py: Python<'_>,
    surface_path: Option<PathBuf>,
    surface_arrays: Option<(PyReadonlyArray2<f64>, PyReadonlyArray2<i64>)>,
    centerlines_path: Option<PathBuf>,
    centerline_arrays: Option<Vec<PolylineIn>>,
    centerlines_computed: Option<PyRef<Centerlines>>,
    preset: Option<&str>,
    config_path: Option<PathBuf>,
    config_dict: Option<Bound<PyDict>>,
    units: Option<&str>,
    centerline_units: Option<&str>,
    output_units: Option<&str>,
    formats: Option<Vec<String>>,
    inlet: Option<[f64; 3]>,
    ends: Vec<[f64; 3]>,
    max_memory: Option<u64>,
    progress: Option<Py<PyAny>>,
    caps: Vec<(String, PathBuf)>,
    inlets: Vec<[f64; 3]>,
) -> PyResult<Mesh> {
    for (name, _) in &caps {
        vesselhex::input::check_end_name(name).map_err(|e| config_error(format!("caps: {e}")))?;
    }
    let config = build_config(
        preset,
        config_path.clone(),
        config_dict.as_ref(),
        unit(units, "units")?,
        unit(output_units, "output_units")?,
        formats,
    )?;
    let centerline_units = unit(centerline_units, "centerline_units")?;
    let max_memory = max_memory.unwrap_or_else(vesselhex::io::memory::default_max_memory);
    let raised = std::sync::Arc::new(std::sync::Mutex::new(None));
    let mut progress = progress_calling(progress, raised.clone());
    progress.stage("reading");
    let cap_files: Vec<PathBuf> = caps.iter().map(|(_, file)| file.clone()).collect();
    let (surface, caps) = read_surface_and_caps(surface_path.clone(), surface_arrays, caps, config.units, max_memory)?;
    let cl_units = centerline_units.unwrap_or(config.units);
    let centerlines = match (centerlines_path.clone(), centerline_arrays, centerlines_computed) {
        (Some(path), None, None) => {
            let limits = vesselhex::input::ReadLimits::within(max_memory);
            CenterlineSource::Given(vesselhex::input::read_centerlines_within(&path, cl_units, &limits).map_err(to_py)?)
        }
        (None, Some(lines), None) => {
            let lines: Vec<PolylineArrays> = lines
                .iter()
                .map(|(points, radii)| {
                    Ok((rows::<3, f64>(points, "centerline points")?, radii.as_ref().map(|r| r.as_array().to_vec())))
                })
                .collect::<PyResult<_>>()?;
            let source = Path::new("centerlines (arrays)");
            CenterlineSource::Given(vesselhex::input::centerlines_from_arrays(lines, cl_units, source).map_err(to_py)?)
        }
        (None, None, Some(computed)) => CenterlineSource::Given(computed.extraction.centerlines.clone()),
        (None, None, None) => CenterlineSource::Extract(extract_options(inlet, ends, config.units)),
        _ => return Err(config_error("give the centerlines one way only".into())),
    };
    let to_mm = config.units.to_mm();
    let inlets = inlets.into_iter().map(|p| InletMark::Point(nalgebra::Point3::from(p) * to_mm)).collect();
    let settings =
        MeshSettings { config: config.clone(), centerline_units, max_memory, warnings: vec![], caps, inlets };
    let vessel = py.detach(move || {
        let vessel = vesselhex::pipeline::mesh_surface(surface, centerlines, settings, &mut progress);
        progress.finish();
        vessel.map(|v| (v, std::mem::take(&mut progress.timings)))
    });
    if let Some(e) = raised.lock().unwrap_or_else(|p| p.into_inner()).take() {
        return Err(e);
    }
    let (vessel, timings) = vessel.map_err(to_py)?;
    let inputs: Vec<PathBuf> =
        [surface_path, centerlines_path, config_path].into_iter().flatten().chain(cap_files).collect();
    Ok(Mesh { vessel, config, timings, inputs })
}

/// A meshed vessel: its arrays, its report and its writers.
#[pyclass(module = "vesselhex._native", frozen)]
struct Mesh {
    vessel: MeshedVessel,
    config: MeshConfig,
    timings: Vec<(String, f64)>,
    /// The files it was read from (never inside a folder `write` replaces).
    inputs: Vec<PathBuf>,
}

impl Mesh {
    fn mesh(&self) -> &vesselhex::mesh::VesselMesh {
        &self.vessel.meshed.mesh
    }
    fn per_element<'py, T: numpy::Element>(
        &self,
        py: Python<'py>,
        value: impl Fn(usize) -> T,
    ) -> Bound<'py, PyArray1<T>> {
        (0..self.mesh().hexes.len()).map(value).collect::<Array1<T>>().into_pyarray(py)
    }
    fn vectors<'py>(
        &self,
        py: Python<'py>,
        k: usize,
        value: impl Fn(usize) -> Vec<nalgebra::Vector3<f64>>,
    ) -> Bound<'py, PyArray3<f64>> {
        let n = self.mesh().hexes.len();
        let flat: Vec<f64> = (0..n).flat_map(|e| value(e).into_iter().flat_map(|v| [v.x, v.y, v.z])).collect();
        Array3::from_shape_vec((n, k, 3), flat).expect("k vectors per element").into_pyarray(py)
    }
}

#[pymethods]
impl Mesh {
    /// Node coordinates (n, 3), in `length_unit` (as mesh.vtu writes them).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let scale = self.config.output_units.from_mm();
        let nodes = &self.mesh().nodes;
        let flat: Vec<f64> =
            nodes.iter().flat_map(|p| (p.coords * scale).into_iter().copied().collect::<Vec<_>>()).collect();
        Array2::from_shape_vec((nodes.len(), 3), flat).expect("three per node").into_pyarray(py)
    }
    /// Hexahedra (m, 8) as 0-based node indices, VTK's corner order.
    #[getter]
    fn hexes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        let hexes = &self.mesh().hexes;
        let flat: Vec<i64> = hexes.iter().flatten().map(|&n| n as i64).collect();
        Array2::from_shape_vec((hexes.len(), 8), flat).expect("eight per hex").into_pyarray(py)
    }
    #[getter]
    fn region<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        self.per_element(py, |e| self.mesh().regions[e].code())
    }
    #[getter]
    fn branch<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        self.per_element(py, |e| self.mesh().branch_of[e] as i32)
    }
    /// 1 where the element lies in a saccular aneurysm's sac (mesh.vtu's `sac`), else 0.
    #[getter]
    fn sac<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        self.per_element(py, |e| self.mesh().in_sac(e) as i32)
    }
    #[getter]
    fn scaled_jacobian<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.per_element(py, |e| self.mesh().quality[e].scaled_jacobian)
    }
    #[getter]
    fn equiangle_skew<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.per_element(py, |e| self.mesh().quality[e].equiangle_skew)
    }
    /// (m, 3, 3): e_long, e_circ, e_rad of each element.
    #[getter]
    fn triads<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        self.vectors(py, 3, |e| {
            let t = &self.mesh().triads[e];
            vec![t.e_long, t.e_circ, t.e_rad]
        })
    }
    /// (m, 2, 3): the two fibre directions of each element.
    #[getter]
    fn fibres<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        self.vectors(py, 2, |e| self.mesh().fibres[e].to_vec())
    }
    #[getter]
    fn length_unit(&self) -> &'static str {
        self.config.output_units.name()
    }
    #[getter]
    fn branch_names(&self) -> Vec<String> {
        self.mesh().branch_names.clone()
    }
    /// Node sets: name -> sorted 0-based node indices.
    #[getter]
    fn node_sets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let sets = PyDict::new(py);
        for (name, nodes) in &self.mesh().node_sets {
            sets.set_item(name, nodes.iter().map(|&n| n as i64).collect::<Array1<i64>>().into_pyarray(py))?;
        }
        Ok(sets)
    }
    /// Face sets: name -> (k, 2) rows of (element, canonical face 0-5).
    #[getter]
    fn face_sets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let sets = PyDict::new(py);
        for (name, faces) in &self.mesh().face_sets {
            let flat: Vec<i64> = faces.iter().flat_map(|f| [f.element as i64, f.face as i64]).collect();
            sets.set_item(name, Array2::from_shape_vec((faces.len(), 2), flat).expect("pairs").into_pyarray(py))?;
        }
        Ok(sets)
    }
    /// The centerlines the mesh was built on: (points (n, 3), radii (n,)) per polyline, in the
    /// input unit.
    #[getter]
    fn centerlines<'py>(&self, py: Python<'py>) -> Vec<PyPolyline<'py>> {
        polylines(py, &self.vessel.centerlines, self.config.units)
    }
    /// report.json as the command line would write it (outputs empty), as JSON text.
    fn report_json(&self, reproducible: bool) -> PyResult<String> {
        let mut report = vesselhex::pipeline::vessel_report(&self.vessel, &self.config, &self.timings);
        if reproducible {
            report.timings_s.values_mut().for_each(|t| *t = 0.0);
        }
        serde_json::to_string_pretty(&report).map_err(|e| config_error(format!("internal: the report: {e}")))
    }
    /// Writes the formats (default: the configuration's) into `folder` as `vesselhex mesh`
    /// does; returns the files written, relative to it.
    #[pyo3(signature = (folder, formats=None, force=false, reproducible=false))]
    fn write(
        &self,
        py: Python<'_>,
        folder: PathBuf,
        formats: Option<Vec<String>>,
        force: bool,
        reproducible: bool,
    ) -> PyResult<Vec<String>> {
        let mut config = self.config.clone();
        if let Some(f) = formats {
            config.formats = f;
        }
        let inputs: Vec<&Path> = self.inputs.iter().map(PathBuf::as_path).collect();
        let timings = self.timings.clone();
        let report = py
            .detach(|| {
                let output = vesselhex::pipeline::claim_output(&folder, &inputs, &config, force)?;
                let mut progress = Progress::new(true, 1);
                progress.timings = timings;
                vesselhex::pipeline::write_vessel(&self.vessel, &config, output, reproducible, &mut progress)
            })
            .map_err(to_py)?;
        Ok(report.outputs)
    }
}

/// Polylines in mm as (points, radii) arrays in `units`.
fn polylines<'py>(
    py: Python<'py>,
    centerlines: &vesselhex::input::Centerlines,
    units: LengthUnit,
) -> Vec<PyPolyline<'py>> {
    let scale = units.from_mm();
    centerlines
        .polylines
        .iter()
        .map(|l| {
            let flat: Vec<f64> = l.points.iter().flat_map(|p| [p.x * scale, p.y * scale, p.z * scale]).collect();
            let points = Array2::from_shape_vec((l.points.len(), 3), flat).expect("three per point").into_pyarray(py);
            let radii = l.radii.as_ref().map(|r| r.iter().map(|x| x * scale).collect::<Array1<f64>>().into_pyarray(py));
            (points, radii)
        })
        .collect()
}

/// Centerlines computed from a surface; see `vesselhex.centerlines`.
#[pyclass(module = "vesselhex._native", frozen)]
struct Centerlines {
    extraction: Extraction,
    units: LengthUnit,
}

#[pymethods]
impl Centerlines {
    /// (points (n, 3), radii (n,)) per polyline, inlet first, in `units`.
    #[getter]
    fn polylines<'py>(&self, py: Python<'py>) -> Vec<PyPolyline<'py>> {
        polylines(py, &self.extraction.centerlines, self.units)
    }
    #[getter]
    fn units(&self) -> &'static str {
        self.units.name()
    }
    /// The ends found: (kind, centre, radius) in `units`.
    #[getter]
    fn ends(&self) -> Vec<(String, [f64; 3], f64)> {
        let scale = self.units.from_mm();
        self.extraction
            .ends
            .iter()
            .map(|e| (format!("{:?}", e.kind), (e.centre.coords * scale).into(), e.radius * scale))
            .collect()
    }
    #[getter]
    fn inlet(&self) -> usize {
        self.extraction.inlet
    }
    #[getter]
    fn notes(&self) -> Vec<String> {
        self.extraction.notes.clone()
    }
    /// Writes the VMTK-compatible .vtp (and the branch-split variant) as `vesselhex
    /// centerlines` does.
    #[pyo3(signature = (path, branch_split=None))]
    fn write(&self, py: Python<'_>, path: PathBuf, branch_split: Option<PathBuf>) -> PyResult<()> {
        let scale = self.units.from_mm();
        py.detach(|| {
            vesselhex::writers::centerlines::write_vtp(&self.extraction.centerlines, scale, &path)?;
            if let Some(split) = &branch_split {
                vesselhex::writers::centerlines::write_branch_split(&self.extraction, scale, split)?;
            }
            Ok(())
        })
        .map_err(to_py)
    }
}

/// Computes centerlines from a surface; see `vesselhex.centerlines`.
#[pyfunction]
#[pyo3(signature = (*, surface_path=None, surface_arrays=None, units=None, inlet=None, ends=vec![], max_memory=None))]
fn centerlines(
    py: Python<'_>,
    surface_path: Option<PathBuf>,
    surface_arrays: Option<(PyReadonlyArray2<f64>, PyReadonlyArray2<i64>)>,
    units: Option<&str>,
    inlet: Option<[f64; 3]>,
    ends: Vec<[f64; 3]>,
    max_memory: Option<u64>,
) -> PyResult<Centerlines> {
    let units = unit(units, "units")?.unwrap_or(LengthUnit::Mm);
    let max_memory = max_memory.unwrap_or_else(vesselhex::io::memory::default_max_memory);
    let surface = read_surface(surface_path, surface_arrays, units, max_memory)?;
    let options = extract_options(inlet, ends, units);
    // As `vesselhex centerlines` does: the surface cleaned first, its repairs noted first.
    let extraction = py
        .detach(move || -> vesselhex::Result<Extraction> {
            let (surface, hygiene) = vesselhex::input::clean_surface(surface)?;
            let mut extraction = extract_centerlines(&surface, &options)?;
            extraction.notes.splice(0..0, hygiene.notes());
            Ok(extraction)
        })
        .map_err(to_py)?;
    Ok(Centerlines { extraction, units })
}

/// The cases of a batch as JSON: from a manifest file, or from rows (a JSON list of objects with
/// the manifest's keys) whose relative paths are taken from `base`.
#[pyfunction]
#[pyo3(signature = (*, manifest=None, rows=None, base=None))]
fn batch_cases(manifest: Option<PathBuf>, rows: Option<String>, base: Option<PathBuf>) -> PyResult<String> {
    use vesselhex::batch::manifest;
    let cases = match (manifest, rows) {
        (Some(path), None) => manifest::read_manifest(&path).map_err(to_py)?,
        (None, Some(rows)) => {
            let rows: Vec<serde_json::Map<String, serde_json::Value>> = serde_json::from_str(&rows)
                .map_err(|e| config_error(format!("cases: each case must be a dict of the manifest's keys ({e})")))?;
            let base = base.unwrap_or_else(|| PathBuf::from("."));
            manifest::cases_from_rows(&rows, &base, Path::new("cases")).map_err(to_py)?
        }
        _ => return Err(config_error("give the cases as a manifest file or as rows".into())),
    };
    json_text(&cases)
}

fn json_text(value: &impl serde::Serialize) -> PyResult<String> {
    serde_json::to_string(value).map_err(|e| config_error(format!("internal: {e}")))
}

fn from_json<T: serde::de::DeserializeOwned>(text: &str, what: &str) -> PyResult<T> {
    serde_json::from_str(text).map_err(|e| config_error(format!("{what}: {e}")))
}

/// A batch over an output folder (`vesselhex.mesh_many`): its cases planned, the folder locked
/// while it lives.
#[pyclass(module = "vesselhex._native", frozen)]
struct Batch {
    batch: vesselhex::batch::Batch,
}

#[pymethods]
impl Batch {
    #[new]
    fn new(py: Python<'_>, cases: &str, settings: &str, output: PathBuf) -> PyResult<Batch> {
        let cases: Vec<vesselhex::batch::Case> = from_json(cases, "cases")?;
        let settings: vesselhex::batch::Settings = from_json(settings, "settings")?;
        let batch = py.detach(|| vesselhex::batch::Batch::open(cases, settings, &output)).map_err(to_py)?;
        Ok(Batch { batch })
    }
    /// The cases still to mesh: (name, job as JSON, fingerprint).
    fn pending(&self) -> PyResult<Vec<(String, String, Option<String>)>> {
        let settings = &self.batch.settings;
        self.batch
            .pending()
            .map(|p| Ok((p.case.name.clone(), json_text(&self.batch.job(p, settings))?, p.fingerprint.clone())))
            .collect()
    }
    /// Every case's row as JSON, in the cases' order, from those done before and `ran` (a JSON
    /// list of the rows of the cases meshed now); writes the summary.
    fn finish(&self, py: Python<'_>, ran: &str) -> PyResult<String> {
        let ran: Vec<vesselhex::batch::Row> = from_json(ran, "rows")?;
        json_text(&py.detach(|| self.batch.finish(ran)).map_err(to_py)?)
    }
    /// Meshes the pending cases here, each in a process `program args` runs, as `vesselhex
    /// batch --jobs jobs` does; `event(kind, what)` is called with ("plan", what the memory plan
    /// decided) first, then ("started" or "finished", the case's name). Returns every case's row
    /// as JSON and what the memory plan decided.
    fn run_local(
        &self,
        py: Python<'_>,
        jobs: usize,
        program: PathBuf,
        args: Vec<String>,
        event: Option<Py<PyAny>>,
    ) -> PyResult<(String, String)> {
        let child = vesselhex::batch::ChildCommand { program, args };
        let raised = std::sync::Mutex::new(None::<PyErr>);
        let tell = |kind: &str, what: &str| {
            if let Some(event) = &event {
                Python::attach(|py| {
                    if let Err(e) = event.call1(py, (kind, what)) {
                        raised.lock().unwrap_or_else(|p| p.into_inner()).get_or_insert(e);
                    }
                });
            }
        };
        let rows = py.detach(|| {
            let plan = self.batch.plan_memory(jobs);
            tell("plan", &plan.message);
            let rows = self.batch.run_local(&plan, &child, &mut |e| match e {
                vesselhex::batch::Event::Started(case) => tell("started", &case.name),
                vesselhex::batch::Event::Finished(row) => tell("finished", &row.case),
            });
            rows.map(|rows| (rows, plan.message))
        });
        if let Some(e) = raised.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(e);
        }
        let (rows, message) = rows.map_err(to_py)?;
        Ok((json_text(&rows)?, message))
    }
}

/// Meshes one case (a job from `Batch.pending`) in a process `program args` runs and returns
/// its row as JSON: a Dask task's work.
#[pyfunction]
fn batch_run_case(
    py: Python<'_>,
    job: &str,
    fingerprint: Option<String>,
    program: PathBuf,
    args: Vec<String>,
) -> PyResult<String> {
    let job: vesselhex::batch::Job = from_json(job, "job")?;
    let child = vesselhex::batch::ChildCommand { program, args };
    json_text(&py.detach(|| vesselhex::batch::run_case_in_child(&child, &job, fingerprint)))
}

/// The row of a case whose task failed before giving one, as JSON.
#[pyfunction]
fn batch_failed_row(case: &str, cause: &str) -> PyResult<String> {
    json_text(&vesselhex::batch::Row::failed(case, vesselhex::batch::EXIT_ERROR, cause))
}

/// The body of `python -m vesselhex._case`: one case read on standard input, its row written on
/// standard output; returns the exit code.
#[pyfunction]
fn batch_child(py: Python<'_>) -> PyResult<i32> {
    vesselhex::output::install_signal_handlers().map_err(to_py)?;
    Ok(py.detach(vesselhex::batch::child::child_main))
}

/// The formats `Mesh.write` knows: (name, what it writes).
#[pyfunction]
fn formats() -> Vec<(&'static str, &'static str)> {
    vesselhex::writers::WRITERS.iter().map(|w| (w.0, w.1)).collect()
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_function(wrap_pyfunction!(mesh, m)?)?;
    m.add_function(wrap_pyfunction!(centerlines, m)?)?;
    m.add_function(wrap_pyfunction!(formats, m)?)?;
    m.add_function(wrap_pyfunction!(batch_cases, m)?)?;
    m.add_function(wrap_pyfunction!(batch_run_case, m)?)?;
    m.add_function(wrap_pyfunction!(batch_failed_row, m)?)?;
    m.add_function(wrap_pyfunction!(batch_child, m)?)?;
    m.add_class::<Batch>()?;
    m.add_class::<Mesh>()?;
    m.add_class::<Centerlines>()?;
    m.add("VesselhexError", py.get_type::<VesselhexError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("GeometryError", py.get_type::<GeometryError>())?;
    m.add("FileError", py.get_type::<FileError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
