//! Per-vertex transfer vectors of a whole mesh, every triangle a potential blocker
//! (Kautz et al. 2004, section 3: "for each vertex, we clear the visibility mask and
//! rasterize all blocking triangles into it").

use crate::disk_mask::{disk, Mask};
use crate::error::{Error, Result};
use crate::integrate::{Brdf, Frame, Quadrature};
use crate::mesh::{mean_edge_length, normalize, tangent_frame, weld, welded_normals, Vec3, WeldedMesh};
use crate::plane_table::{PlaneTable, DEFAULT_RESOLUTION};
use crate::progress::{par_rows, Progress};
use crate::packets::PacketLists;
use crate::rasterizer::{dot, triangle_mask, Pipeline, Viewer};
use crate::sh::ShBasis;

/// Where glossy receivers are seen from.
#[derive(Clone, Debug, PartialEq)]
pub enum View {
    /// One direction (towards the viewer) for every vertex.
    Direction(Vec3),
    /// One direction per input vertex.
    PerVertex(Vec<Vec3>),
}

#[derive(Clone, Debug)]
pub struct Settings {
    pub bands: usize,
    pub brdf: Brdf,
    pub view: Option<View>,
    /// Receivers sit this far along their normal; None: 1e-3 x the mean edge length.
    pub offset: Option<f32>,
    /// Plane-table cube-map resolution (6 x R x R texels).
    pub table_resolution: usize,
    /// Mask cells per side of an integration block: 4 is the paper's 8x8 grey occlusion term;
    /// 2 and 1 integrate finer (about half and a third of the error, see docs/algorithm.md).
    /// None: 1 for diffuse and for glossy beyond exponent 16, 2 for glossy up to it (see
    /// default_downsample).
    pub downsample: Option<usize>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            bands: 5,
            brdf: Brdf::Diffuse,
            view: None,
            offset: None,
            table_resolution: DEFAULT_RESOLUTION,
            downsample: None,
        }
    }
}

/// Default downsampling of the mask before integration. Diffuse: every cell (not the paper's
/// 4 x 4 blocks): a third of the error for about 1.3x the time, which Embree would need about
/// 4x the rays to match (docs/benchmarks.md). Glossy: 2 x 2 blocks up to exponent 16 (4 x 4
/// give 7 % median error at exponent 8; each block costs a basis evaluation), every cell for
/// sharper lobes.
pub fn default_downsample(brdf: Brdf) -> usize {
    match brdf {
        Brdf::Diffuse => 1,
        Brdf::Phong { exponent } if exponent <= 16.0 => 2,
        Brdf::Phong { .. } => 1,
    }
}

/// Transfer vectors, `bands^2` per input vertex, row-major. Vertices that no triangle touches
/// and that have no usable normal get zeros; `Output::missing_normals` counts them.
pub struct Output {
    pub coeffs: usize,
    pub transfer: Vec<f32>,
    pub missing_normals: usize,
}

/// Everything a receiver needs, shared by all threads.
struct Scene<'a> {
    mesh: &'a WeldedMesh,
    /// Every triangle, in packets.
    packets: PacketLists,
    normals: &'a [Vec3],
    views: Option<Vec<Vec3>>,
    offset: f32,
    brdf: Brdf,
    table: &'a PlaneTable,
    quadrature: Quadrature,
    disk: Mask,
}

pub fn transfer(vertices: &[Vec3], triangles: &[[u32; 3]], normals: Option<&[Vec3]>, settings: &Settings) -> Result<Output> {
    transfer_with_progress(vertices, triangles, normals, settings, None, &mut |_| true)
}

/// `transfer` of the input vertices listed in `receivers` only (rows in that order), or of all
/// of them; reports the fraction done to `progress` (on this thread) and stops with
/// `Error::Cancelled` when it returns false.
pub fn transfer_with_progress(
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    normals: Option<&[Vec3]>,
    settings: &Settings,
    receivers: Option<&[u32]>,
    progress: Progress,
) -> Result<Output> {
    let basis = ShBasis::new(settings.bands)?;
    check_brdf(settings.brdf)?;
    let downsample = checked_downsample(settings)?;
    let (mesh, normalization) = weld(vertices, triangles)?.normalized();
    let normals = welded_normals(&mesh.positions, &mesh.triangles, &mesh.remap, normals)?;
    let views = welded_views(&mesh.first_copies(), mesh.remap.len(), settings.brdf, settings.view.as_ref())?;
    let offset = checked_offset(settings.offset, &mesh, normalization.scale())?;
    let table = PlaneTable::shared(settings.table_resolution)?;
    let mut packets = PacketLists::new(std::iter::once(&mesh.triangles[..]));
    packets.update(&mesh.positions);
    let scene = Scene {
        mesh: &mesh,
        packets,
        normals: &normals,
        views,
        offset,
        brdf: settings.brdf,
        table: &table,
        quadrature: Quadrature::new(downsample, basis),
        disk: disk(),
    };
    let k = scene.quadrature.basis().coeffs();
    let Some(receivers) = receivers else {
        let mut welded = vec![0.0f32; mesh.positions.len() * k];
        par_rows(&mut welded, k, progress, || (), |r, _, out| scene.receiver(r, out))?;
        let transfer = mesh.remap.iter().flat_map(|&w| welded[w as usize * k..(w as usize + 1) * k].iter().copied()).collect();
        let missing_normals = mesh.remap.iter().filter(|&&w| normals[w as usize] == [0.0; 3]).count();
        return Ok(Output { coeffs: k, transfer, missing_normals });
    };
    if let Some(&i) = receivers.iter().find(|&&i| i as usize >= vertices.len()) {
        return Err(Error::invalid(format!("receiver {i} is not a vertex: the mesh has {} vertices", vertices.len())));
    }
    let rows: Vec<usize> = receivers.iter().map(|&i| mesh.remap[i as usize] as usize).collect();
    let mut transfer = vec![0.0f32; rows.len() * k];
    par_rows(&mut transfer, k, progress, || (), |i, _, out| scene.receiver(rows[i], out))?;
    let missing_normals = rows.iter().filter(|&&w| normals[w] == [0.0; 3]).count();
    Ok(Output { coeffs: k, transfer, missing_normals })
}

pub(crate) fn check_brdf(brdf: Brdf) -> Result<()> {
    match brdf {
        Brdf::Phong { exponent } if !(exponent.is_finite() && exponent >= 0.0) => {
            Err(Error::invalid(format!("the Phong exponent must be finite and non-negative, got {exponent}")))
        }
        _ => Ok(()),
    }
}

/// The integration block size the settings ask for, or its default.
pub(crate) fn checked_downsample(settings: &Settings) -> Result<usize> {
    let downsample = settings.downsample.unwrap_or(default_downsample(settings.brdf));
    if !matches!(downsample, 1 | 2 | 4 | 8) {
        return Err(Error::invalid(format!("downsample must be 1, 2, 4 or 8 cells, got {downsample}")));
    }
    Ok(downsample)
}

/// The receivers' offset along the normal in the normalised mesh's units: as given (in the
/// input's units, times `scale`), or 1e-3 x the mean edge length.
pub(crate) fn checked_offset(offset: Option<f32>, mesh: &WeldedMesh, scale: f32) -> Result<f32> {
    match offset {
        Some(o) if o.is_finite() && o >= 0.0 => Ok(o * scale),
        Some(o) => Err(Error::invalid(format!("offset must be a finite, non-negative distance, got {o}"))),
        None => Ok(1e-3 * mean_edge_length(mesh)),
    }
}

/// Unit view direction per welded vertex (its first copy's), for glossy BRDFs; None for
/// diffuse ones. `first_copy` maps welded vertices to input vertices.
pub(crate) fn welded_views(first_copy: &[u32], input_count: usize, brdf: Brdf, view: Option<&View>) -> Result<Option<Vec<Vec3>>> {
    let unit = |v: Vec3, what: String| normalize(v).ok_or_else(|| Error::invalid(format!("{what} must be a finite, non-zero direction, got {v:?}")));
    match (brdf, view) {
        (Brdf::Diffuse, _) => Ok(None),
        (Brdf::Phong { .. }, None) => Err(Error::invalid("a glossy BRDF needs a view direction")),
        (_, Some(View::Direction(v))) => Ok(Some(vec![unit(*v, "view".into())?; first_copy.len()])),
        (_, Some(View::PerVertex(views))) => {
            if views.len() != input_count {
                return Err(Error::invalid(format!("view has {} rows but vertices has {input_count}", views.len())));
            }
            first_copy.iter().map(|&i| unit(views[i as usize], format!("view {i}"))).collect::<Result<Vec<_>>>().map(Some)
        }
    }
}

/// How far below a receiver's horizon (in the normalised positions' units) a bound must lie
/// for the walks to skip what it holds without changing a result: far above the rounding of
/// the heights the rasterizer computes (`Receiver::clearly_below_horizon`, the solver's
/// cluster spheres).
pub const HORIZON_MARGIN: f32 = 1e-5;

/// A receiver's tangent frame and the point it sees from, `offset` along its normal.
#[derive(Clone, Copy)]
pub struct Receiver {
    pub frame: Frame,
    pub origin: Vec3,
}

impl Receiver {
    /// None for a vertex without a normal.
    #[inline]
    pub fn new(position: Vec3, n: Vec3, offset: f32) -> Option<Self> {
        if n == [0.0; 3] {
            return None;
        }
        let (t, b) = tangent_frame(n);
        let origin = [position[0] + offset * n[0], position[1] + offset * n[1], position[2] + offset * n[2]];
        Some(Receiver { frame: Frame { t, b, n }, origin })
    }

    /// A world-space point in the receiver's tangent frame, relative to its origin.
    #[inline(always)]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        let d = [v[0] - self.origin[0], v[1] - self.origin[1], v[2] - self.origin[2]];
        [dot(d, self.frame.t), dot(d, self.frame.b), dot(d, self.frame.n)]
    }

    /// Whether a box lies entirely on or below the receiver's tangent plane.
    #[inline(always)]
    pub fn below_horizon(&self, bounds: &[Vec3; 2]) -> bool {
        dot(self.frame.n, self.highest_corner(bounds)) <= dot(self.frame.n, self.origin)
    }

    /// `below_horizon` with a margin far above rounding (`HORIZON_MARGIN`): every point of
    /// the box is then below the horizon in the receiver's local coordinates too, so skipping
    /// it changes no result.
    #[inline(always)]
    pub fn clearly_below_horizon(&self, bounds: &[Vec3; 2]) -> bool {
        dot(self.frame.n, self.highest_corner(bounds)) < dot(self.frame.n, self.origin) - HORIZON_MARGIN
    }

    /// The box corner farthest along the normal.
    #[inline(always)]
    fn highest_corner(&self, bounds: &[Vec3; 2]) -> Vec3 {
        [0, 1, 2].map(|a| if self.frame.n[a] >= 0.0 { bounds[1][a] } else { bounds[0][a] })
    }
}

impl Scene<'_> {
    /// Transfer of welded vertex `r`.
    fn receiver(&self, r: usize, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { self.receiver_avx2(r, out) };
        }
        self.receiver_portable(r, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn receiver_avx2(&self, r: usize, out: &mut [f32]) {
        self.receiver_portable(r, out)
    }

    #[inline(always)]
    fn receiver_portable(&self, r: usize, out: &mut [f32]) {
        let Some(receiver) = Receiver::new(self.mesh.positions[r], self.normals[r], self.offset) else {
            out.fill(0.0);
            return;
        };
        let mask = self.visibility(r as u32, &receiver);
        let view = self.views.as_ref().map_or(receiver.frame.n, |v| v[r]);
        self.quadrature.integrate(&mask, &receiver.frame, self.brdf, view, out);
    }

    /// The receiver's visibility mask: every triangle but its own incident ones.
    #[inline(always)]
    fn visibility(&self, r: u32, receiver: &Receiver) -> Mask {
        let mut mask = Mask::EMPTY;
        let mut pipeline = Pipeline::default();
        let viewer = Viewer { origin: receiver.origin, frame: &receiver.frame, exclude: r };
        let mut batch = Vec::with_capacity(8);
        for chunk in self.packets.packets.chunks(8) {
            batch.clear();
            batch.extend(chunk.iter().filter(|p| !receiver.clearly_below_horizon(&p.bounds)).map(|p| (p, u32::MAX)));
            pipeline.rasterize_batch(self.table, &viewer, &batch, &mut mask);
            if mask == self.disk {
                return mask; // fully occluded: nothing more can change
            }
        }
        pipeline.drain(self.table, &mut mask);
        mask
    }
}

/// The visibility mask of one receiver point with normal n, over the given triangles
/// (world space, no exclusions): for inspection, pictures and tests.
pub fn visibility_mask(point: Vec3, normal: Vec3, vertices: &[Vec3], triangles: &[[u32; 3]], table_resolution: usize) -> Result<Mask> {
    let n = normalize(normal).ok_or_else(|| Error::invalid("normal must be a finite, non-zero direction"))?;
    if !point.iter().all(|c| c.is_finite()) {
        return Err(Error::invalid("point must be finite"));
    }
    let mesh = weld(vertices, triangles)?;
    let table = PlaneTable::shared(table_resolution)?;
    let receiver = Receiver::new(point, n, 0.0).expect("a unit normal is non-zero");
    let local: Vec<Vec3> = mesh.positions.iter().map(|v| receiver.to_local(*v)).collect();
    let mut mask = Mask::EMPTY;
    for tri in &mesh.triangles {
        let [a, b, c] = tri.map(|i| local[i as usize]);
        if let Some(covered) = triangle_mask(&table, a, b, c) {
            mask.or_assign(&covered);
        }
    }
    Ok(mask)
}
