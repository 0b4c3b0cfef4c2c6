//! `hemishadow._native.panorama_hits` and `hemishadow._native.Relighter`: primary visibility
//! and native relighting of panoramas. Shapes and dtypes are checked by `hemishadow.panorama`
//! too; the engine checks sizes again.

use hemishadow_engine as engine;
use engine::panorama::relight::{Lighting, Maps, PointLight, Relighter};
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4, PyReadwriteArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::run;
use crate::scene::PyScene;

fn rotation(m: &PyReadonlyArray2<f64>) -> PyResult<[[f64; 3]; 3]> {
    let v = m.as_array();
    if v.shape() != [3, 3] {
        return Err(PyValueError::new_err(format!("rotation must have shape (3, 3), got {:?}", v.shape())));
    }
    Ok(std::array::from_fn(|r| std::array::from_fn(|c| v[[r, c]])))
}

fn triples(a: &PyReadonlyArray2<f32>, what: &str) -> PyResult<Vec<[f32; 3]>> {
    let v = a.as_array();
    if v.ncols() != 3 {
        return Err(PyValueError::new_err(format!("{what} must have shape (K, 3), got {:?}", v.shape())));
    }
    Ok(v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect())
}

type HitArrays<'py> = (
    Bound<'py, PyArray2<f32>>,
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray2<i32>>,
    Bound<'py, PyArray2<i32>>,
    Bound<'py, PyArray2<bool>>,
);

/// Primary visibility: (t, position, normal, instance, mesh, back), rows top to bottom.
#[pyfunction]
pub fn panorama_hits<'py>(py: Python<'py>, scene: &PyScene, origin: PyReadonlyArray1<f64>, rotation_rows: PyReadonlyArray2<f64>,
                          width: usize, height: usize) -> PyResult<HitArrays<'py>> {
    let o = match origin.as_slice()? {
        [x, y, z] => [*x, *y, *z],
        _ => return Err(PyValueError::new_err("origin must have 3 components")),
    };
    let rot = rotation(&rotation_rows)?;
    let inner = &scene.inner;
    let hits = run(py, || engine::panorama::hits::primary_hits(inner, o, &rot, width, height))?;
    let (w, h) = (width, height);
    let flat3 = |v: Vec<[f32; 3]>| Array3::from_shape_vec((h, w, 3), v.into_iter().flatten().collect()).expect("shape");
    Ok((
        Array2::from_shape_vec((h, w), hits.t).expect("shape").into_pyarray(py),
        flat3(hits.position).into_pyarray(py),
        flat3(hits.normal).into_pyarray(py),
        Array2::from_shape_vec((h, w), hits.instance).expect("shape").into_pyarray(py),
        Array2::from_shape_vec((h, w), hits.mesh).expect("shape").into_pyarray(py),
        Array2::from_shape_vec((h, w), hits.back).expect("shape").into_pyarray(py),
    ))
}

#[pyclass(name = "Relighter", module = "hemishadow._native")]
pub struct PyRelighter {
    inner: Relighter,
}

#[pymethods]
impl PyRelighter {
    /// maps: (k, H, W, 3) uint8 (with scale, offset (k, 3)) or uint16 half bits (scale and
    /// offset None); position (H, W, 3); hit (H, W) bool; rotation (3, 3) rows.
    #[new]
    #[allow(clippy::too_many_arguments)] // the Python constructor's arguments
    #[pyo3(signature = (maps_u8, maps_f16, scale, offset, position, hit, rotation_rows))]
    fn new(py: Python<'_>, maps_u8: Option<PyReadonlyArray4<u8>>, maps_f16: Option<PyReadonlyArray4<u16>>,
           scale: Option<PyReadonlyArray2<f32>>, offset: Option<PyReadonlyArray2<f32>>, position: PyReadonlyArray3<f32>,
           hit: PyReadonlyArray2<bool>, rotation_rows: PyReadonlyArray2<f64>) -> PyResult<Self> {
        let (shape, maps) = match (maps_u8, maps_f16) {
            (Some(m), None) => (m.as_array().shape().to_vec(), Maps::U8(m.as_array().iter().copied().collect())),
            (None, Some(m)) => (m.as_array().shape().to_vec(), Maps::F16(m.as_array().iter().copied().collect())),
            _ => return Err(PyValueError::new_err("give either 8-bit or float16 maps")),
        };
        if shape.len() != 4 || shape[3] != 3 {
            return Err(PyValueError::new_err(format!("maps must have shape (K, H, W, 3), got {shape:?}")));
        }
        let (k, h, w) = (shape[0], shape[1], shape[2]);
        let scale = scale.map(|s| triples(&s, "scale")).transpose()?.unwrap_or_default();
        let offset = offset.map(|s| triples(&s, "offset")).transpose()?.unwrap_or_default();
        let pos = position.as_array();
        if pos.shape() != [h, w, 3] || hit.as_array().shape() != [h, w] {
            return Err(PyValueError::new_err("position (H, W, 3) and hit (H, W) must match the maps"));
        }
        let positions: Vec<[f32; 3]> = pos.iter().copied().collect::<Vec<f32>>().chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        let hits: Vec<bool> = hit.as_array().iter().copied().collect();
        let rot = rotation(&rotation_rows)?;
        let inner = run(py, || Relighter::new(w, h, k, maps, scale, offset, &positions, hits, rot))?;
        Ok(PyRelighter { inner })
    }

    /// Radiance (H, W, 3) float32 into `out` (or a new array): uniform (k, 3) SH weights,
    /// points (n, 7) rows x, y, z, intensity r, g, b, inverse-square flag; background (k, 3)
    /// radiance SH or None; simd False forces the portable code.
    #[pyo3(signature = (uniform, points, background=None, out=None, simd=true))]
    fn relight<'py>(&self, py: Python<'py>, uniform: PyReadonlyArray2<f32>, points: PyReadonlyArray2<f32>,
                    background: Option<PyReadonlyArray2<f32>>, out: Option<Bound<'py, PyArray3<f32>>>, simd: bool)
                    -> PyResult<Bound<'py, PyArray3<f32>>> {
        let uniform = triples(&uniform, "uniform")?;
        let background = background.map(|b| triples(&b, "background")).transpose()?;
        let pv = points.as_array();
        if pv.ncols() != 7 {
            return Err(PyValueError::new_err(format!("points must have shape (N, 7), got {:?}", pv.shape())));
        }
        let lamps: Vec<PointLight> = pv
            .rows()
            .into_iter()
            .map(|r| PointLight { position: [r[0], r[1], r[2]], intensity: [r[3], r[4], r[5]], inverse_square: r[6] != 0.0 })
            .collect();
        let (h, w) = (self.inner.height, self.inner.width);
        let out = match out {
            Some(o) => o,
            None => Array3::<f32>::zeros((h, w, 3)).into_pyarray(py),
        };
        {
            let mut rw: PyReadwriteArray3<f32> = out.try_readwrite()?;
            let slice = rw.as_slice_mut().map_err(|_| PyValueError::new_err("out must be a C-contiguous (H, W, 3) float32 array"))?;
            let inner = &self.inner;
            let lighting = Lighting { uniform: &uniform, points: &lamps, background: background.as_deref() };
            run(py, || inner.relight(&lighting, slice, simd))?;
        }
        Ok(out)
    }

    /// Bytes one relight reads (maps, plus positions with point lights).
    fn bytes_read(&self, points: bool) -> usize {
        self.inner.bytes_read(points)
    }

    #[staticmethod]
    fn simd_available() -> bool {
        Relighter::simd_available()
    }
}
