//! The Python module `hemishadow._native`: converts arrays, releases the GIL while the engine
//! works, and maps engine errors to ValueError and any panic to RuntimeError, so nothing the
//! caller passes can take the interpreter (or Blender) down. Argument checks that need Python
//! (dtypes, shapes) happen in the pure-Python layer; everything is checked again here.

use std::panic::{catch_unwind, AssertUnwindSafe};

use hemishadow_engine as engine;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBool;

mod panorama;
mod scene;

create_exception!(_native, Cancelled, PyException, "The computation was stopped by its progress callback.");

fn to_py_err(error: engine::Error) -> PyErr {
    match error {
        engine::Error::Cancelled => Cancelled::new_err("cancelled"),
        engine::Error::InvalidInput(_) => PyValueError::new_err(error.to_string()),
    }
}

/// The engine's progress callback over an optional Python callable. Between chunks of work it
/// takes the GIL, lets Python handle pending signals (Ctrl-C) and calls the callable with the
/// fraction done; `False` from the callable, or any exception, stops the work. The exception
/// is kept and raised in place of `Cancelled`.
struct PyProgress {
    callback: Option<Py<PyAny>>,
    error: Option<PyErr>,
}

impl PyProgress {
    fn new(callback: Option<Py<PyAny>>) -> Self {
        PyProgress { callback, error: None }
    }

    fn report(&mut self, fraction: f32) -> bool {
        Python::attach(|py| {
            let outcome = py.check_signals().and_then(|_| match &self.callback {
                Some(callback) => callback.call1(py, (fraction,)).map(|v| !is_false(v.bind(py))),
                None => Ok(true),
            });
            outcome.unwrap_or_else(|error| {
                self.error = Some(error);
                false
            })
        })
    }

    /// The callback's exception, if it raised one, else `result`'s error as usual.
    fn finish<T>(self, result: PyResult<T>) -> PyResult<T> {
        match self.error {
            Some(error) => Err(error),
            None => result,
        }
    }
}

fn is_false(value: &Bound<'_, PyAny>) -> bool {
    value.is_instance_of::<PyBool>() && !value.is_truthy().unwrap_or(true)
}

/// Runs engine work without the GIL and with panics caught.
fn run<T: Send>(py: Python<'_>, work: impl FnOnce() -> engine::Result<T> + Send) -> PyResult<T> {
    py.detach(|| catch_unwind(AssertUnwindSafe(work)))
        .map_err(|panic| {
            let message = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            PyRuntimeError::new_err(format!("internal error in the hemishadow engine: {message}"))
        })?
        .map_err(to_py_err)
}

fn rows3(array: &PyReadonlyArray2<f32>, what: &str) -> PyResult<Vec<[f32; 3]>> {
    let view = array.as_array();
    if view.ncols() != 3 {
        return Err(PyValueError::new_err(format!("{what} must have shape (N, 3), got {:?}", view.shape())));
    }
    Ok(view.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

/// (F, N, 3) -> F lists of points.
fn frames3(array: &PyReadonlyArray3<f32>, what: &str) -> PyResult<Vec<Vec<[f32; 3]>>> {
    let view = array.as_array();
    if view.shape()[2] != 3 {
        return Err(PyValueError::new_err(format!("{what} must have shape (F, N, 3), got {:?}", view.shape())));
    }
    Ok(view.outer_iter().map(|frame| frame.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect()).collect())
}

fn triangles3(array: &PyReadonlyArray2<u32>) -> PyResult<Vec<[u32; 3]>> {
    let view = array.as_array();
    if view.ncols() != 3 {
        return Err(PyValueError::new_err(format!("triangles must have shape (M, 3), got {:?}", view.shape())));
    }
    Ok(view.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

fn vec3(array: &PyReadonlyArray1<f32>, what: &str) -> PyResult<[f32; 3]> {
    match array.as_slice()? {
        [x, y, z] => Ok([*x, *y, *z]),
        other => Err(PyValueError::new_err(format!("{what} must have 3 components, got {}", other.len()))),
    }
}

fn matrix(rows: Vec<f32>, n: usize, k: usize, py: Python<'_>) -> Bound<'_, PyArray2<f32>> {
    Array2::from_shape_vec((n, k), rows).expect("engine output has the promised shape").into_pyarray(py)
}

/// (1024, 4) float64: each mask cell's first moment and solid angle (`engine::scene::lobes::cell_moments`).
#[pyfunction]
fn cell_moments(py: Python<'_>) -> PyResult<Bound<'_, PyArray2<f64>>> {
    let rows = run(py, || Ok(engine::scene::lobes::cell_moments()))?;
    Ok(Array2::from_shape_vec((rows.len(), 4), rows.into_iter().flatten().collect()).expect("1024 x 4").into_pyarray(py))
}

/// Real SH basis Y_i(d) of unit directions (N, 3): float32 (N, bands^2).
#[pyfunction]
fn sh_basis<'py>(py: Python<'py>, directions: PyReadonlyArray2<f32>, bands: usize) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let dirs = rows3(&directions, "directions")?;
    let n = dirs.len();
    let values = run(py, || {
        let basis = engine::sh::ShBasis::new(bands)?;
        let k = basis.coeffs();
        let mut out = vec![0.0f32; n * k];
        for (d, row) in dirs.iter().zip(out.chunks_mut(k)) {
            basis.eval(*d, row);
        }
        Ok(out)
    })?;
    Ok(matrix(values, n, bands * bands, py))
}

/// SH coefficients (K, C) of C functions given in world space, expressed in each of the frames
/// (P, 3, 3) (rows: the frame's x, y, z axes in world space): float32 (P, K, C).
#[pyfunction]
fn sh_to_frames<'py>(py: Python<'py>, coefficients: PyReadonlyArray2<f32>, frames: PyReadonlyArray3<f32>) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let (k, channels) = coefficients.as_array().dim();
    let bands = (k as f64).sqrt().round() as usize;
    if bands * bands != k {
        return Err(PyValueError::new_err(format!("coefficients must have a square number of rows (9, 16, 25), got {k}")));
    }
    let world: Vec<f32> = coefficients.as_array().iter().copied().collect();
    let frames = frames.as_array();
    if frames.shape()[1..] != [3, 3] {
        return Err(PyValueError::new_err(format!("frames must have shape (P, 3, 3), got {:?}", frames.shape())));
    }
    let axes: Vec<[[f32; 3]; 3]> = frames.outer_iter().map(|f| std::array::from_fn(|r| std::array::from_fn(|c| f[[r, c]]))).collect();
    if axes.iter().flatten().flatten().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err("frames must be finite"));
    }
    let out = run(py, || Ok(engine::sh_rotation::ShRotator::new(engine::sh::ShBasis::new(bands)?).to_frames(&world, channels, &axes)))?;
    Ok(Array3::from_shape_vec((axes.len(), k, channels), out).expect("P x K x C").into_pyarray(py))
}

/// Per-vertex transfer vectors; returns (transfer (N, bands^2), vertices without a normal).
#[pyfunction]
#[pyo3(signature = (vertices, triangles, normals, bands, exponent, view, views, offset, table_resolution, downsample, receivers=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn transfer<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<f32>,
    triangles: PyReadonlyArray2<u32>,
    normals: Option<PyReadonlyArray2<f32>>,
    bands: usize,
    exponent: Option<f32>,
    view: Option<PyReadonlyArray1<f32>>,
    views: Option<PyReadonlyArray2<f32>>,
    offset: Option<f32>,
    table_resolution: usize,
    downsample: Option<usize>,
    receivers: Option<PyReadonlyArray1<u32>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Bound<'py, PyArray2<f32>>, usize)> {
    let vertices = rows3(&vertices, "vertices")?;
    let triangles = triangles3(&triangles)?;
    let normals = normals.map(|n| rows3(&n, "normals")).transpose()?;
    let view = view_argument(view, views)?;
    let brdf = exponent.map_or(engine::Brdf::Diffuse, |exponent| engine::Brdf::Phong { exponent });
    let settings = engine::Settings { bands, brdf, view, offset, table_resolution, downsample };
    let receivers = receivers.map(|r| r.as_slice().map(<[u32]>::to_vec)).transpose()?;
    let n = receivers.as_ref().map_or(vertices.len(), Vec::len);
    let mut reporter = PyProgress::new(progress);
    let report = &mut reporter;
    let result = run(py, || {
        engine::transfer_with_progress(&vertices, &triangles, normals.as_deref(), &settings, receivers.as_deref(), &mut |f| {
            report.report(f)
        })
    });
    let output = reporter.finish(result)?;
    Ok((matrix(output.transfer, n, output.coeffs, py), output.missing_normals))
}

/// A per-mesh solver for deforming meshes (see `hemishadow.TransferSolver`).
#[pyclass(name = "Solver", module = "hemishadow._native")]
struct PySolver {
    /// Boxed: Python allocates its objects 16-byte aligned, and the solver holds 64-byte
    /// aligned masks (read with aligned vector loads).
    inner: Box<engine::Solver>,
}

fn view_argument(view: Option<PyReadonlyArray1<f32>>, views: Option<PyReadonlyArray2<f32>>) -> PyResult<Option<engine::View>> {
    Ok(match (view, views) {
        (Some(v), _) => Some(engine::View::Direction(vec3(&v, "view")?)),
        (None, Some(v)) => Some(engine::View::PerVertex(rows3(&v, "view")?)),
        (None, None) => None,
    })
}

#[pymethods]
impl PySolver {
    #[new]
    #[pyo3(signature = (rest, triangles, bands, exponent, offset, table_resolution, downsample, hierarchy, coarse_triangles, ring, cull, reuse, near_scale, far_lod))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        rest: PyReadonlyArray2<f32>,
        triangles: PyReadonlyArray2<u32>,
        bands: usize,
        exponent: Option<f32>,
        offset: Option<f32>,
        table_resolution: usize,
        downsample: Option<usize>,
        hierarchy: bool,
        coarse_triangles: Option<usize>,
        ring: usize,
        cull: bool,
        reuse: bool,
        near_scale: f32,
        far_lod: f32,
    ) -> PyResult<Self> {
        let rest = rows3(&rest, "rest_vertices")?;
        let triangles = triangles3(&triangles)?;
        let brdf = exponent.map_or(engine::Brdf::Diffuse, |exponent| engine::Brdf::Phong { exponent });
        let settings = engine::Settings { bands, brdf, view: None, offset, table_resolution, downsample };
        let blockers = engine::Blockers { hierarchy, coarse_triangles, ring, cull, reuse, near_scale, far_lod };
        let inner = run(py, || engine::Solver::new(&rest, &triangles, &settings, blockers))?;
        Ok(PySolver { inner: Box::new(inner) })
    }

    /// Transfer (N, bands^2) for this frame's positions.
    /// `casters`: a Scene whose blockers shadow the mesh too, `to_world` (4x4, rigid) placing
    /// the vertices in its world, `exclude` its instances left out.
    #[pyo3(signature = (vertices, normals, view, views, progress=None, casters=None, to_world=None, exclude=None))]
    #[allow(clippy::too_many_arguments)]
    fn solve<'py>(
        &mut self,
        py: Python<'py>,
        vertices: PyReadonlyArray2<f32>,
        normals: Option<PyReadonlyArray2<f32>>,
        view: Option<PyReadonlyArray1<f32>>,
        views: Option<PyReadonlyArray2<f32>>,
        progress: Option<Py<PyAny>>,
        casters: Option<Bound<'py, scene::PyScene>>,
        to_world: Option<PyReadonlyArray2<f64>>,
        exclude: Option<PyReadonlyArray1<u32>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let vertices = rows3(&vertices, "vertices")?;
        let normals = normals.map(|n| rows3(&n, "normals")).transpose()?;
        let view = view_argument(view, views)?;
        let to_world = to_world.map(|m| scene::matrix16(&m)).transpose()?;
        let exclude: Vec<u32> = exclude.map(|e| e.as_array().to_vec()).unwrap_or_default();
        let n = vertices.len();
        let k = self.inner.coeffs();
        if let Some(c) = casters.as_ref().filter(|c| !c.borrow().inner.prepared()) {
            let mut c = c.try_borrow_mut()?;
            let scene = &mut c.inner;
            run(py, || {
                scene.prepare();
                Ok(())
            })?;
        }
        // Shared from here on: other objects' solves may read the same scene meanwhile.
        let casters = casters.as_ref().map(|c| c.try_borrow()).transpose()?;
        let scene = casters.as_ref().map(|c| &*c.inner);
        let inner = &mut self.inner;
        let mut reporter = PyProgress::new(progress);
        let report = &mut reporter;
        let result = run(py, || {
            let place = to_world.as_ref().map_or(Ok(engine::scene::casters::Rigid::IDENTITY), engine::scene::casters::Rigid::from_rows)?;
            let casters = scene.map(|s| s.casters(&exclude, place)).transpose()?;
            inner.solve_with_casters(&vertices, normals.as_deref(), view.as_ref(), casters.as_ref(), &mut |f| report.report(f))
        });
        let values = reporter.finish(result)?;
        Ok(matrix(values, n, k, py))
    }

    /// (blockers per computed receiver, receivers computed, receivers reused, PVS used) of the
    /// last solve.
    fn stats(&self) -> (f64, usize, usize, bool) {
        let s = self.inner.stats();
        (s.blockers_per_receiver, s.computed, s.reused, s.used_pvs)
    }

    /// Samples poses (F, N, 3) for potentially visible sets.
    #[pyo3(signature = (poses, normals, tolerance, progress))]
    fn build_pvs(
        &mut self,
        py: Python<'_>,
        poses: PyReadonlyArray3<f32>,
        normals: Option<PyReadonlyArray3<f32>>,
        tolerance: f32,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<()> {
        let poses = frames3(&poses, "poses")?;
        let normals = normals.map(|n| frames3(&n, "normals")).transpose()?;
        let slices: Vec<&[[f32; 3]]> = poses.iter().map(Vec::as_slice).collect();
        let normal_slices: Option<Vec<&[[f32; 3]]>> = normals.as_ref().map(|n| n.iter().map(Vec::as_slice).collect());
        let inner = &mut self.inner;
        let mut reporter = PyProgress::new(progress);
        let report = &mut reporter;
        let result = run(py, || inner.build_pvs(&slices, normal_slices.as_deref(), tolerance, &mut |f| report.report(f)));
        reporter.finish(result)
    }

    fn clear_pvs(&mut self) {
        self.inner.clear_pvs();
    }

    /// (sampled poses, clusters kept per vertex, tolerance), or None without a PVS.
    fn pvs_info(&self) -> Option<(usize, f64, f32)> {
        self.inner.pvs().map(|p| (p.poses(), p.clusters_per_vertex(), p.tolerance))
    }

    #[getter]
    fn memory_bytes(&self) -> usize {
        self.inner.memory_bytes()
    }

    #[getter]
    fn coarse_triangles(&self) -> usize {
        self.inner.coarse_triangles()
    }

    #[getter]
    fn vertex_count(&self) -> usize {
        self.inner.vertex_count()
    }
}

/// SH lighting (bands^2, 3) of an equirectangular float image (H, W, 3 or 4), top row first.
#[pyfunction]
fn project_equirectangular<'py>(
    py: Python<'py>,
    image: PyReadonlyArray3<f32>,
    bands: usize,
    rotation: PyReadonlyArray2<f32>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let shape = image.as_array().shape().to_vec();
    let pixels = image.as_slice()?.to_vec();
    let r = rotation.as_array();
    if r.shape() != [3, 3] {
        return Err(PyValueError::new_err("rotation must be a 3x3 matrix"));
    }
    let rotation = [[r[[0, 0]], r[[0, 1]], r[[0, 2]]], [r[[1, 0]], r[[1, 1]], r[[1, 2]]], [r[[2, 0]], r[[2, 1]], r[[2, 2]]]];
    let values = run(py, || {
        let image = engine::environment::Image { pixels: &pixels, height: shape[0], width: shape[1], channels: shape[2] };
        engine::environment::project(&image, bands, rotation)
    })?;
    Ok(matrix(values, bands * bands, 3, py))
}

fn mask_rows(mask: &engine::disk_mask::Mask) -> Vec<bool> {
    let side = engine::disk_mask::MASK_SIDE;
    (0..side * side).map(|i| mask.get(i / side, i % side)).collect()
}

fn mask_array<'py>(py: Python<'py>, mask: &engine::disk_mask::Mask) -> Bound<'py, PyArray2<bool>> {
    let side = engine::disk_mask::MASK_SIDE;
    Array2::from_shape_vec((side, side), mask_rows(mask)).expect("32x32").into_pyarray(py)
}

/// The rasterized mask (32, 32) of triangles (M, 9) given in a receiver's tangent frame.
#[pyfunction]
fn rasterize_local<'py>(py: Python<'py>, triangles: PyReadonlyArray2<f32>, table_resolution: usize) -> PyResult<Bound<'py, PyArray2<bool>>> {
    let view = triangles.as_array();
    if view.ncols() != 9 {
        return Err(PyValueError::new_err("triangles must have shape (M, 3, 3)"));
    }
    if view.iter().any(|v| !v.is_finite()) {
        return Err(PyValueError::new_err("triangles must be finite"));
    }
    let tris: Vec<[[f32; 3]; 3]> = view.rows().into_iter().map(|r| [[r[0], r[1], r[2]], [r[3], r[4], r[5]], [r[6], r[7], r[8]]]).collect();
    let mask = run(py, || {
        let table = engine::plane_table::PlaneTable::shared(table_resolution)?;
        let mut mask = engine::disk_mask::Mask::EMPTY;
        engine::rasterizer::rasterize(&table, &tris, &mut mask);
        Ok(mask)
    })?;
    Ok(mask_array(py, &mask))
}

/// The visibility mask (32, 32) seen from `point` with `normal` over a world-space mesh.
#[pyfunction]
fn visibility_mask<'py>(
    py: Python<'py>,
    point: PyReadonlyArray1<f32>,
    normal: PyReadonlyArray1<f32>,
    vertices: PyReadonlyArray2<f32>,
    triangles: PyReadonlyArray2<u32>,
    table_resolution: usize,
) -> PyResult<Bound<'py, PyArray2<bool>>> {
    let (point, normal) = (vec3(&point, "point")?, vec3(&normal, "normal")?);
    let (vertices, triangles) = (rows3(&vertices, "vertices")?, triangles3(&triangles)?);
    let mask = run(py, || engine::transfer::visibility_mask(point, normal, &vertices, &triangles, table_resolution))?;
    Ok(mask_array(py, &mask))
}

/// The cells (32, 32) that belong to the unit disk.
#[pyfunction]
fn disk_cells(py: Python<'_>) -> Bound<'_, PyArray2<bool>> {
    mask_array(py, &engine::disk_mask::disk())
}

/// a (N, K) @ b (K, M) by ndarray (matrixmultiply) in the calling thread, without the GIL.
/// numpy's OpenBLAS runs large products on its own threads, which then spin for about 0.1 s of
/// CPU each and take the cores the engine's next solve needs (see `hemishadow.products`).
fn product<'py, T>(py: Python<'py>, a: PyReadonlyArray2<'py, T>, b: PyReadonlyArray2<'py, T>) -> PyResult<Bound<'py, PyArray2<T>>>
where
    T: numpy::Element + numpy::ndarray::LinalgScalar + Send + Sync,
{
    let (a, b) = (a.as_array(), b.as_array());
    if a.ncols() != b.nrows() {
        return Err(PyValueError::new_err(format!("cannot multiply shapes {:?} and {:?}", a.shape(), b.shape())));
    }
    Ok(py.detach(|| a.dot(&b)).into_pyarray(py))
}

#[pyfunction]
fn product_f32<'py>(py: Python<'py>, a: PyReadonlyArray2<'py, f32>, b: PyReadonlyArray2<'py, f32>) -> PyResult<Bound<'py, PyArray2<f32>>> {
    product(py, a, b)
}

#[pyfunction]
fn product_f64<'py>(py: Python<'py>, a: PyReadonlyArray2<'py, f64>, b: PyReadonlyArray2<'py, f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    product(py, a, b)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sh_basis, m)?)?;
    m.add_function(wrap_pyfunction!(sh_to_frames, m)?)?;
    m.add_function(wrap_pyfunction!(cell_moments, m)?)?;
    m.add_function(wrap_pyfunction!(transfer, m)?)?;
    m.add_function(wrap_pyfunction!(project_equirectangular, m)?)?;
    m.add_function(wrap_pyfunction!(rasterize_local, m)?)?;
    m.add_function(wrap_pyfunction!(visibility_mask, m)?)?;
    m.add_function(wrap_pyfunction!(disk_cells, m)?)?;
    m.add_function(wrap_pyfunction!(product_f32, m)?)?;
    m.add_function(wrap_pyfunction!(product_f64, m)?)?;
    m.add_class::<PySolver>()?;
    m.add_class::<scene::PyScene>()?;
    m.add_class::<scene::PyBounceWeights>()?;
    m.add_function(wrap_pyfunction!(panorama::panorama_hits, m)?)?;
    m.add_class::<panorama::PyRelighter>()?;
    m.add("Cancelled", m.py().get_type::<Cancelled>())?;
    m.add("DEFAULT_TABLE_RESOLUTION", engine::plane_table::DEFAULT_RESOLUTION)?;
    m.add("DEFAULT_FAR_LOD", engine::group_tree::FAR_LOD)?;
    m.add("BACK_FACE_LIMIT", engine::scene::receivers::BACK_FACE_LIMIT)?;
    m.add("MASK_SIDE", engine::disk_mask::MASK_SIDE)?;
    Ok(())
}
