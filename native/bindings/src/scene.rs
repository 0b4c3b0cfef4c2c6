//! `hemishadow._native.Scene`: the engine's scene visibility (many meshes and instances,
//! arbitrary receivers) behind a thin class. Shapes and dtypes are checked by the Python
//! `hemishadow.Scene`; everything is checked again here or in the engine.

use hemishadow_engine as engine;
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::{rows3, run, triangles3, vec3, PyProgress};

/// `Scene.visibility_valid`'s result: masks (P, 16) uint64 and validity (P,).
type MasksAndValid<'py> = (Bound<'py, PyArray2<u64>>, Bound<'py, PyArray1<bool>>);

#[pyclass(name = "Scene", module = "hemishadow._native")]
pub struct PyScene {
    /// Boxed for the same reason as the solver: Python objects are only 16-byte aligned.
    pub(crate) inner: Box<engine::scene::Scene>,
}

/// Recorded gather weights of receivers (`Scene.bounce_weights`), applied with
/// `Scene.apply_bounce_weights` to the radiance the scene shows at the time.
#[pyclass(name = "BounceWeights", module = "hemishadow._native", frozen)]
pub struct PyBounceWeights {
    inner: engine::scene::bounce_weights::BounceWeights,
}

#[pymethods]
impl PyBounceWeights {
    fn __len__(&self) -> usize {
        self.inner.receivers()
    }

    /// (vertex, weight) pairs stored over all receivers.
    #[getter]
    fn entries(&self) -> usize {
        self.inner.entries()
    }

    /// The receivers' visibility masks (P, 16) uint64, as `Scene.visibility` gives them.
    #[getter]
    fn masks<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u64>> {
        packed_masks(py, &self.inner.masks)
    }

    /// Whether each receiver is outside solid geometry (P,) bool, as `Scene.valid` decides it.
    #[getter]
    fn valid<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        self.inner.valid.clone().into_pyarray(py)
    }
}

/// Masks as (P, 16) uint64 rows, bit r * 32 + c set when cell (r, c) is blocked.
fn packed_masks<'py>(py: Python<'py>, masks: &[engine::disk_mask::Mask]) -> Bound<'py, PyArray2<u64>> {
    let flat: Vec<u64> = masks.iter().flat_map(|m| m.0).collect();
    Array2::from_shape_vec((masks.len(), engine::disk_mask::MASK_WORDS), flat).expect("P x words").into_pyarray(py)
}

pub(crate) fn matrix16(m: &PyReadonlyArray2<f64>) -> PyResult<[f64; 16]> {
    let view = m.as_array();
    if view.shape() != [4, 4] {
        return Err(PyValueError::new_err(format!("matrix must have shape (4, 4), got {:?}", view.shape())));
    }
    Ok(std::array::from_fn(|i| view[[i / 4, i % 4]]))
}

#[pymethods]
impl PyScene {
    #[new]
    fn new() -> Self {
        PyScene { inner: Box::new(engine::scene::Scene::new()) }
    }

    fn add_mesh(&mut self, py: Python<'_>, vertices: PyReadonlyArray2<f32>, triangles: PyReadonlyArray2<u32>) -> PyResult<u32> {
        let (v, t) = (rows3(&vertices, "vertices")?, triangles3(&triangles)?);
        let inner = &mut self.inner;
        run(py, || inner.add_mesh(&v, &t))
    }

    fn add_instance(&mut self, py: Python<'_>, mesh: u32, matrix: PyReadonlyArray2<f64>) -> PyResult<u32> {
        let m = matrix16(&matrix)?;
        let inner = &mut self.inner;
        run(py, || inner.add_instance(mesh, &m))
    }

    fn set_vertices(&mut self, py: Python<'_>, mesh: u32, vertices: PyReadonlyArray2<f32>) -> PyResult<()> {
        let v = rows3(&vertices, "vertices")?;
        let inner = &mut self.inner;
        run(py, || inner.set_vertices(mesh, &v))
    }

    fn set_matrix(&mut self, py: Python<'_>, instance: u32, matrix: PyReadonlyArray2<f64>) -> PyResult<()> {
        let m = matrix16(&matrix)?;
        let inner = &mut self.inner;
        run(py, || inner.set_matrix(instance, &m))
    }

    fn set_radiance(&mut self, py: Python<'_>, mesh: u32, rgb: PyReadonlyArray2<f32>) -> PyResult<()> {
        let c = rows3(&rgb, "rgb")?;
        let inner = &mut self.inner;
        run(py, || inner.set_radiance(mesh, &c))
    }

    fn set_instance_radiance(&mut self, py: Python<'_>, instance: u32, rgb: PyReadonlyArray2<f32>) -> PyResult<()> {
        let c = rows3(&rgb, "rgb")?;
        let inner = &mut self.inner;
        run(py, || inner.set_instance_radiance(instance, &c))
    }

    fn set_lod(&mut self, py: Python<'_>, lod: f32) -> PyResult<()> {
        let inner = &mut self.inner;
        run(py, || inner.set_lod(lod))
    }

    #[getter]
    fn lod(&self) -> f32 {
        self.inner.lod()
    }

    /// The plane table resolution of `transfer`'s default, `visibility`, `valid` and `gather`.
    #[getter]
    fn table_resolution(&self) -> usize {
        self.inner.table_resolution()
    }

    /// Builds what is missing (cluster hierarchies, the top tree) now rather than on the first query.
    fn prepare(&mut self, py: Python<'_>) -> PyResult<()> {
        let inner = &mut self.inner;
        run(py, || {
            inner.prepare();
            Ok(())
        })
    }

    #[getter]
    fn size(&mut self, py: Python<'_>) -> PyResult<f32> {
        let inner = &mut self.inner;
        run(py, || Ok(inner.size()))
    }

    #[getter]
    fn mesh_count(&self) -> usize {
        self.inner.mesh_count()
    }

    #[getter]
    fn instance_count(&self) -> usize {
        self.inner.instance_count()
    }

    #[getter]
    fn triangle_count(&self) -> usize {
        self.inner.triangle_count()
    }

    /// Triangles handed to the rasterizer per receiver in the last `transfer`.
    #[getter]
    fn blockers_per_receiver(&self) -> f64 {
        self.inner.stats().blockers_per_receiver
    }

    #[pyo3(signature = (points, normals, bands, exponent, view, views, offset, table_resolution, downsample, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn transfer<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: PyReadonlyArray2<f32>,
        bands: usize,
        exponent: Option<f32>,
        view: Option<PyReadonlyArray1<f32>>,
        views: Option<PyReadonlyArray2<f32>>,
        offset: Option<f32>,
        table_resolution: usize,
        downsample: Option<usize>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let (p, n) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let view = match (view, views) {
            (Some(v), _) => Some(engine::View::Direction(vec3(&v, "view")?)),
            (None, Some(v)) => Some(engine::View::PerVertex(rows3(&v, "view")?)),
            (None, None) => None,
        };
        let brdf = exponent.map_or(engine::Brdf::Diffuse, |exponent| engine::Brdf::Phong { exponent });
        let settings = engine::Settings { bands, brdf, view, offset, table_resolution, downsample };
        let inner = &mut self.inner;
        let mut reporter = PyProgress::new(progress);
        let report = &mut reporter;
        let result = run(py, || inner.transfer(&p, &n, &settings, &mut |f| report.report(f)));
        let values = reporter.finish(result)?;
        let k = bands * bands;
        Ok(Array2::from_shape_vec((p.len(), k), values).expect("P x k").into_pyarray(py))
    }

    /// Raw masks (P, 16) uint64.
    fn visibility<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: PyReadonlyArray2<f32>,
        offset: Option<f32>,
    ) -> PyResult<Bound<'py, PyArray2<u64>>> {
        let (p, n) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let inner = &mut self.inner;
        let masks = run(py, || inner.visibility(&p, &n, offset))?;
        Ok(packed_masks(py, &masks))
    }

    /// Masks (P, 16) uint64 and validity (P,) from one rasterization each.
    fn visibility_valid<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: PyReadonlyArray2<f32>,
        offset: Option<f32>,
    ) -> PyResult<MasksAndValid<'py>> {
        let (p, n) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let inner = &mut self.inner;
        let (masks, valid) = run(py, || inner.visibility_valid(&p, &n, offset))?;
        Ok((packed_masks(py, &masks), Array1::from_vec(valid).into_pyarray(py)))
    }

    fn valid<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: PyReadonlyArray2<f32>,
        offset: Option<f32>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (p, n) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let inner = &mut self.inner;
        let valid = run(py, || inner.valid(&p, &n, offset))?;
        Ok(Array1::from_vec(valid).into_pyarray(py))
    }

    /// Lobe integrals over packed masks (`engine::scene::lobes`): masks (P, 16) uint64, lobes
    /// (P, L, 3) in each receiver's frame, moments (1024, 3), values (1024, K) -> (P, L, K).
    #[staticmethod]
    fn lobe_integrals<'py>(
        py: Python<'py>,
        masks: PyReadonlyArray2<u64>,
        lobes: PyReadonlyArray3<f32>,
        moments: PyReadonlyArray2<f32>,
        values: PyReadonlyArray2<f32>,
    ) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let words = engine::disk_mask::MASK_WORDS;
        let m = masks.as_array();
        if m.shape()[1] != words {
            return Err(PyValueError::new_err(format!("masks must have shape (P, {words}), got {:?}", m.shape())));
        }
        let masks: Vec<engine::disk_mask::Mask> =
            m.outer_iter().map(|r| engine::disk_mask::Mask(std::array::from_fn(|i| r[i]))).collect();
        let l = lobes.as_array();
        if l.shape()[0] != masks.len() || l.shape()[2] != 3 {
            return Err(PyValueError::new_err(format!("lobes must have shape ({}, L, 3), got {:?}", masks.len(), l.shape())));
        }
        let count = l.shape()[1];
        let dirs: Vec<[f32; 3]> = l.as_standard_layout().as_slice().expect("standard layout").chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let mom = rows3(&moments, "moments")?;
        let vals = values.as_array();
        let k = vals.shape()[1];
        let flat: Vec<f32> = vals.iter().copied().collect();
        let out = run(py, || engine::scene::lobes::lobe_integrals(&masks, &dirs, count, &mom, &flat))?;
        Ok(Array3::from_shape_vec((masks.len(), count, k), out).expect("P x L x K").into_pyarray(py))
    }

    /// bool (P,): whether anything crosses the segment from each point to its target.
    fn occluded<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        targets: PyReadonlyArray2<f32>,
        offset: Option<f32>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (p, t) = (rows3(&points, "points")?, rows3(&targets, "targets")?);
        let inner = &mut self.inner;
        let hit = run(py, || inner.occluded(&p, &t, offset))?;
        Ok(Array1::from_vec(hit).into_pyarray(py))
    }

    /// bool (P,): whether nothing lies between each point and the whole of a convex polygon
    /// (`engine::scene::beams`): polygons (corners, 3) shared or (P * corners, 3).
    fn beams_clear<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: PyReadonlyArray2<f32>,
        polygons: PyReadonlyArray2<f32>,
        corners: usize,
        offset: Option<f32>,
    ) -> PyResult<Bound<'py, PyArray1<bool>>> {
        let (p, n, q) = (rows3(&points, "points")?, rows3(&normals, "normals")?, rows3(&polygons, "polygons")?);
        let inner = &mut self.inner;
        let clear = run(py, || inner.beams_clear(&p, &n, &q, corners, offset))?;
        Ok(Array1::from_vec(clear).into_pyarray(py))
    }

    /// `gather`, with each walked hemisphere's mask (P, H, 16), back-face fraction (P, H) and
    /// harmonic mean distance (P, H).
    #[pyo3(signature = (points, normals, bands, offset, progress=None))]
    #[allow(clippy::type_complexity)]
    fn gather_views<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: Option<PyReadonlyArray2<f32>>,
        bands: usize,
        offset: Option<f32>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<(Bound<'py, PyArray3<f32>>, Bound<'py, PyArray3<u64>>, Bound<'py, PyArray2<f32>>, Bound<'py, PyArray2<f32>>)> {
        let p = rows3(&points, "points")?;
        let n = normals.map(|n| rows3(&n, "normals")).transpose()?;
        let hemispheres = if n.is_some() { 1 } else { 2 };
        let inner = &mut self.inner;
        let mut reporter = PyProgress::new(progress);
        let report = &mut reporter;
        let result = run(py, || inner.gather_views(&p, n.as_deref(), bands, offset, &mut |f| report.report(f)));
        let (values, views) = reporter.finish(result)?;
        let words = engine::disk_mask::MASK_WORDS;
        let masks: Vec<u64> = views.iter().flat_map(|v| v.mask.0).collect();
        let per_view = |f: fn(&engine::scene::HemisphereView) -> f32| {
            let values: Vec<f32> = views.iter().map(f).collect();
            Array2::from_shape_vec((p.len(), hemispheres), values).expect("P x H").into_pyarray(py)
        };
        Ok((
            Array3::from_shape_vec((p.len(), bands * bands, 3), values).expect("P x k x 3").into_pyarray(py),
            Array3::from_shape_vec((p.len(), hemispheres, words), masks).expect("P x H x words").into_pyarray(py),
            per_view(|v| v.back),
            per_view(|v| v.distance),
        ))
    }

    #[pyo3(signature = (points, normals, offset, progress=None))]
    fn bounce_weights(
        &mut self,
        py: Python<'_>,
        points: PyReadonlyArray2<f32>,
        normals: PyReadonlyArray2<f32>,
        offset: Option<f32>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<PyBounceWeights> {
        let (p, n) = (rows3(&points, "points")?, rows3(&normals, "normals")?);
        let inner = &mut self.inner;
        let mut reporter = PyProgress::new(progress);
        let report = &mut reporter;
        let result = run(py, || inner.bounce_weights(&p, &n, offset, &mut |f| report.report(f)));
        Ok(PyBounceWeights { inner: reporter.finish(result)? })
    }

    fn apply_bounce_weights<'py>(&self, py: Python<'py>, weights: &PyBounceWeights) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let inner = &self.inner;
        let values = run(py, || inner.apply_bounce_weights(&weights.inner))?;
        Ok(Array2::from_shape_vec((weights.inner.receivers(), 3), values).expect("P x 3").into_pyarray(py))
    }

    #[pyo3(signature = (points, normals, bands, offset, progress=None))]
    fn gather<'py>(
        &mut self,
        py: Python<'py>,
        points: PyReadonlyArray2<f32>,
        normals: Option<PyReadonlyArray2<f32>>,
        bands: usize,
        offset: Option<f32>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let p = rows3(&points, "points")?;
        let n = normals.map(|n| rows3(&n, "normals")).transpose()?;
        let inner = &mut self.inner;
        let mut reporter = PyProgress::new(progress);
        let report = &mut reporter;
        let result = run(py, || inner.gather(&p, n.as_deref(), bands, offset, &mut |f| report.report(f)));
        let values = reporter.finish(result)?;
        Ok(Array3::from_shape_vec((p.len(), bands * bands, 3), values).expect("P x k x 3").into_pyarray(py))
    }
}
