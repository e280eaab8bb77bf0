//! `mipray._mipray`: the render delegate for Python (pyo3). A thin layer: argument conversion,
//! errors as Python exceptions with the prim path in the message, and the GIL released for the
//! whole render (`render.rs`: the render and its progress and per-pass callbacks).

// No unwrap across the FFI boundary: a panic here would abort a render host (STYLE.md).
#![cfg_attr(not(test), warn(clippy::unwrap_used))]

mod render;

use std::collections::HashMap;
use std::path::Path;

use glam::Mat4;
use hd_mipray::instancer::InstancerData;
use hd_mipray::light::{AreaKind, DistantLightData, IesData, LightPrim, LinkData, MeshLightData, ShapingData};

use hd_mipray::material::{input_from_usd, FaceMaterials, NetworkInput, NetworkTextureInput, SurfaceInputs, TextureInput};
use hd_mipray::mesh::{Gprim, MeshData};
use hd_mipray::{RenderDelegate as Delegate, RenderPass, RenderSettings};
use mipray::aov::Aov;
use mipray::camera::{Camera, Projection};
use mipray::displacement::Displacement;
use mipray::image_io::{ChannelFormat, ImageIo, MetaValue};
use mipray::image_output::{self, write_layers, ColorCorrection, Layer, WriteOptions};
use mipray::material::Input;
use mipray::settings::{SettingType, SettingValue, SETTINGS};
use mipray::texture::{Interpolation, Primvar2, SourceColorSpace, Wrap};
use mipray::topology::{BoundaryInterpolation, FaceVaryingInterpolation, MeshTopology, Scheme, TriangleSubdivision};
use mipray_bridge::OiioImageIo;
use numpy::ndarray::Array3;
use numpy::{
    IntoPyArray, PyArray3, PyArrayDyn, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4,
    PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyList, PyType};

/// Collects the Rust side's `log` records while native code runs (render threads included, no
/// GIL needed), so they can be replayed into Python's `logging` ("mipray" logger) once the call
/// returns. Warnings and errors only: they are what a user must see.
struct Collector(std::sync::Mutex<Vec<(log::Level, String)>>);

impl log::Log for Collector {
    fn enabled(&self, m: &log::Metadata<'_>) -> bool {
        m.level() <= log::Level::Warn
    }

    fn log(&self, r: &log::Record<'_>) {
        if self.enabled(r.metadata()) {
            if let Ok(mut v) = self.0.lock() {
                // A runaway producer must not grow this without bound.
                if v.len() < 10_000 {
                    v.push((r.level(), r.args().to_string()));
                }
            }
        }
    }

    fn flush(&self) {}
}

static COLLECTOR: Collector = Collector(std::sync::Mutex::new(Vec::new()));

/// Replays collected records into `logging.getLogger("mipray")`.
pub(crate) fn forward_logs(py: Python<'_>) {
    let records: Vec<(log::Level, String)> = match COLLECTOR.0.lock() {
        Ok(mut v) => std::mem::take(&mut *v),
        Err(_) => return,
    };
    if records.is_empty() {
        return;
    }
    let Ok(logger) = py.import("logging").and_then(|m| m.call_method1("getLogger", ("mipray",))) else { return };
    for (level, msg) in records {
        let method = if level == log::Level::Error { "error" } else { "warning" };
        let _ = logger.call_method1(method, (msg,));
    }
}

/// `mipray.errors.PrimDataError(path, msg)`: prim data the delegate refuses is a MiprayError
/// naming the prim (`prim_path`, `reason`), and a ValueError as it always was. Should the
/// package's errors module fail to import, a ValueError with the same one line.
fn value_error(path: &str, msg: impl std::fmt::Display) -> PyErr {
    static PRIM_DATA_ERROR: PyOnceLock<Py<PyType>> = PyOnceLock::new();
    let reason = msg.to_string();
    Python::attach(|py| match PRIM_DATA_ERROR.import(py, "mipray.errors", "PrimDataError").and_then(|t| t.call1((path, &reason))) {
        Ok(exc) => PyErr::from_value(exc),
        Err(_) => PyValueError::new_err(format!("{path}: {reason}")),
    })
}

/// A delegate's refusal as Python sees it: a prim's bad data as [`value_error`], the rest as
/// ValueError with the delegate's line.
fn delegate_error(e: hd_mipray::DelegateError) -> PyErr {
    match e {
        hd_mipray::DelegateError::Prim { path, message } => value_error(&path, message),
        e => PyValueError::new_err(e.to_string()),
    }
}

fn matrix(path: &str, m: &PyReadonlyArray2<'_, f64>) -> PyResult<Mat4> {
    let a = m.as_array();
    if a.shape() != [4, 4] {
        return Err(value_error(path, format!("transform must be 4x4, got {:?}", a.shape())));
    }
    // USD matrices are row-major for row vectors (p' = p·M); read as columns, the same numbers
    // are the column-vector matrix glam uses (p' = M·p).
    let mut cols = [0f32; 16];
    for (i, v) in a.iter().enumerate() {
        cols[i] = *v as f32;
    }
    Ok(Mat4::from_cols_array(&cols))
}

/// (N, 4, 4) USD-layout matrices as glam matrices (see [`matrix`]).
fn matrices(path: &str, m: &PyReadonlyArray3<'_, f64>) -> PyResult<Vec<Mat4>> {
    let a = m.as_array();
    if a.shape()[1..] != [4, 4] {
        return Err(value_error(path, format!("transforms must be N×4×4, got {:?}", a.shape())));
    }
    let mut out = Vec::with_capacity(a.shape()[0]);
    for m in a.outer_iter() {
        let mut cols = [0f32; 16];
        for (c, v) in cols.iter_mut().zip(m.iter()) {
            *c = *v as f32;
        }
        out.push(Mat4::from_cols_array(&cols));
    }
    Ok(out)
}

/// The normals, primvar-fed inputs and network primvars of `set_mesh`'s `primvars`:
/// `{"normals", a UsdPreviewSurface input name or "geomprop:<primvar>": {"values": (N, C)
/// float32, C ≤ 3 (≤ 4 for a geomprop), "indices": int32 or None, "interpolation": USD
/// token}}` (checked against the topology by the delegate's `set_mesh`). An input's primvar
/// shades the faces of the mesh's own material; a geomprop is read by the networks that name
/// it (`"primvars"` of a network).
#[allow(clippy::type_complexity)]
fn read_primvars(
    path: &str,
    d: &Bound<'_, PyDict>,
) -> PyResult<(Vec<Primvar2>, Vec<(Input, Vec<Primvar2>)>, Vec<(String, Vec<Primvar2>)>)> {
    let mut normals = Vec::new();
    let mut inputs = Vec::new();
    let mut named = Vec::new();
    for (key, value) in d.iter() {
        let role: String = key.extract()?;
        let entry = value.cast::<PyDict>().map_err(|_| value_error(path, format!("primvars['{role}'] must be a dict")))?;
        let item = |k: &str| entry.get_item(k);
        let values: PyReadonlyArray2<'_, f32> = item("values")?
            .ok_or_else(|| value_error(path, format!("primvars['{role}'] has no values")))?
            .extract()
            .map_err(|_| value_error(path, format!("primvars['{role}'] values must be an (N, C) float32 array")))?;
        let indices: Option<PyReadonlyArray1<'_, i32>> = match item("indices")? {
            Some(v) if !v.is_none() => {
                Some(v.extract().map_err(|_| value_error(path, format!("primvars['{role}'] indices must be int32")))?)
            }
            _ => None,
        };
        let token: String = match item("interpolation")? {
            Some(v) => v.extract()?,
            None => "vertex".into(),
        };
        let interpolation = Interpolation::from_usd(&token)
            .ok_or_else(|| value_error(path, format!("primvars:{role} interpolation '{token}' is not a USD interpolation")))?;
        let a = values.as_array();
        let components = a.ncols();
        let geomprop = role.strip_prefix("geomprop:");
        let wanted = match role.as_str() {
            "normals" => 3,
            _ if geomprop.is_some() => a.ncols().clamp(1, 4),
            name => match input_from_usd(name) {
                Some(Input::DiffuseColor | Input::SpecularColor | Input::EmissiveColor) => 3,
                Some(Input::Normal) | None => {
                    return Err(value_error(path, format!("primvars: '{role}' is not an input a primvar can feed")))
                }
                Some(_) => 1,
            },
        };
        if components != wanted {
            return Err(value_error(path, format!("primvars:{role} has {components} components, expected {wanted}")));
        }
        let lane = |r: &numpy::ndarray::ArrayView1<'_, f32>, k: usize| r.get(k).copied().unwrap_or(0.0);
        let rows: Vec<[f32; 3]> = a.rows().into_iter().map(|r| [lane(&r, 0), lane(&r, 1), lane(&r, 2)]).collect();
        let indices = vec_i32(indices);
        let mut channels = Primvar2::split(&role, interpolation, &rows, components.min(3), &indices);
        if components == 4 {
            // The second channel holds components 2 and 3.
            let rows: Vec<[f32; 3]> = a.rows().into_iter().map(|r| [lane(&r, 2), lane(&r, 3), 0.0]).collect();
            channels.truncate(1);
            channels.extend(Primvar2::split(&role, interpolation, &rows, 2, &indices));
        }
        match (role.as_str(), geomprop) {
            ("normals", _) => normals = channels,
            (_, Some(name)) => named.push((name.to_string(), channels)),
            (name, None) => inputs.push((input_from_usd(name).expect("checked above"), channels)),
        }
    }
    Ok((normals, inputs, named))
}

fn vec_i32(a: Option<PyReadonlyArray1<'_, i32>>) -> Vec<i32> {
    a.map(|a| a.as_array().to_vec()).unwrap_or_default()
}

fn vec_f32(a: Option<PyReadonlyArray1<'_, f32>>) -> Vec<f32> {
    a.map(|a| a.as_array().to_vec()).unwrap_or_default()
}

/// The render delegate. Prims are inserted or updated with `set_*`, removed with `remove`, and
/// synced by `render`, which syncs only what changed.
#[pyclass(module = "mipray._mipray")]
struct RenderDelegate {
    inner: Delegate,
}

#[pymethods]
impl RenderDelegate {
    #[new]
    fn new() -> Self {
        RenderDelegate { inner: Delegate::new() }
    }

    /// Inserts or updates a mesh. See the stubs for argument meanings.
    #[pyo3(signature = (path, *, points, face_vertex_counts, face_vertex_indices, transform, scheme="catmullClark", interpolate_boundary="edgeAndCorner", face_varying_linear_interpolation="cornersPlus1", triangle_subdivision_rule="catmullClark", crease_indices=None, crease_lengths=None, crease_sharpnesses=None, corner_indices=None, corner_sharpnesses=None, hole_indices=None, left_handed=false, double_sided=false, displacement_bound=None, displacement=None, prototype=false, st_values=None, st_indices=None, st_interpolation="faceVarying", displacement_texture=None, material=None, gprim=None, primvars=None, face_materials=None, face_material_indices=None, light=None))]
    #[allow(clippy::too_many_arguments)]
    fn set_mesh(
        &mut self,
        path: &str,
        points: PyReadonlyArrayDyn<'_, f32>,
        face_vertex_counts: PyReadonlyArray1<'_, i32>,
        face_vertex_indices: PyReadonlyArray1<'_, i32>,
        transform: PyReadonlyArray2<'_, f64>,
        scheme: &str,
        interpolate_boundary: &str,
        face_varying_linear_interpolation: &str,
        triangle_subdivision_rule: &str,
        crease_indices: Option<PyReadonlyArray1<'_, i32>>,
        crease_lengths: Option<PyReadonlyArray1<'_, i32>>,
        crease_sharpnesses: Option<PyReadonlyArray1<'_, f32>>,
        corner_indices: Option<PyReadonlyArray1<'_, i32>>,
        corner_sharpnesses: Option<PyReadonlyArray1<'_, f32>>,
        hole_indices: Option<PyReadonlyArray1<'_, i32>>,
        left_handed: bool,
        double_sided: bool,
        displacement_bound: Option<f32>,
        displacement: Option<(f32, f32, u32, f32)>,
        prototype: bool,
        st_values: Option<PyReadonlyArray2<'_, f32>>,
        st_indices: Option<PyReadonlyArray1<'_, i32>>,
        st_interpolation: &str,
        displacement_texture: Option<&Bound<'_, PyDict>>,
        material: Option<&Bound<'_, PyDict>>,
        gprim: Option<&Bound<'_, PyDict>>,
        primvars: Option<&Bound<'_, PyDict>>,
        face_materials: Option<Vec<Bound<'_, PyDict>>>,
        face_material_indices: Option<PyReadonlyArray1<'_, i32>>,
        light: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<()> {
        let gprim = gprim.map(|g| read_gprim(path, g)).transpose()?;
        let light = light.map(|d| read_mesh_light(path, d)).transpose()?;
        let pts = points.as_array();
        let shape = pts.shape();
        if shape.len() != 2 || shape[1] != 3 {
            // The shape as numpy writes it: (36,) or (4, 2).
            let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
            let shape = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
            return Err(value_error(path, format!("points has shape {shape}, expected (N, 3)")));
        }
        let points: Vec<[f32; 3]> = pts.outer_iter().map(|r| [r[0], r[1], r[2]]).collect();
        let topology = MeshTopology {
            scheme: Scheme::from_usd(scheme).map_err(|e| value_error(path, e))?,
            face_vertex_counts: face_vertex_counts.as_array().to_vec(),
            face_vertex_indices: face_vertex_indices.as_array().to_vec(),
            crease_indices: vec_i32(crease_indices),
            crease_lengths: vec_i32(crease_lengths),
            crease_sharpnesses: vec_f32(crease_sharpnesses),
            corner_indices: vec_i32(corner_indices),
            corner_sharpnesses: vec_f32(corner_sharpnesses),
            hole_indices: vec_i32(hole_indices),
            boundary: BoundaryInterpolation::from_usd(interpolate_boundary).map_err(|e| value_error(path, e))?,
            face_varying: FaceVaryingInterpolation::from_usd(face_varying_linear_interpolation).map_err(|e| value_error(path, e))?,
            triangle_subdivision: TriangleSubdivision::from_usd(triangle_subdivision_rule).map_err(|e| value_error(path, e))?,
            left_handed,
        };
        let face_materials = match (face_materials, face_material_indices) {
            (None, None) => None,
            (Some(m), Some(i)) => Some(FaceMaterials {
                materials: m.iter().map(|d| surface_inputs(path, d)).collect::<PyResult<_>>()?,
                indices: i.as_array().to_vec(),
            }),
            _ => return Err(value_error(path, "face_materials and face_material_indices go together")),
        };
        let st = match st_values {
            None => None,
            Some(v) => {
                let a = v.as_array();
                if a.ncols() != 2 {
                    return Err(value_error(path, format!("primvars:st must be N×2, got {:?}", a.shape())));
                }
                let interpolation = Interpolation::from_usd(st_interpolation).ok_or_else(|| {
                    value_error(path, format!("primvars:st interpolation '{st_interpolation}' is not a USD interpolation"))
                })?;
                Some(Primvar2 {
                    name: "st".into(),
                    interpolation,
                    values: a.rows().into_iter().map(|r| [r[0], r[1]]).collect(),
                    indices: vec_i32(st_indices),
                })
            }
        };
        let (normals, primvar_inputs, network_primvars) = match primvars {
            None => (Vec::new(), Vec::new(), Vec::new()),
            Some(d) => read_primvars(path, d)?,
        };
        let displacement_texture = displacement_texture.map(|d| texture_input(path, "displacement", d)).transpose()?;
        let material = material.map(|d| surface_inputs(path, d)).transpose()?;
        let transform = matrix(path, &transform)?;
        let displacement = displacement.map(|(amplitude, frequency, octaves, gain)| Displacement { amplitude, frequency, octaves, gain });
        self.inner.set_mesh(
            path,
            MeshData {
                topology,
                points,
                transform,
                double_sided,
                material,
                displacement_bound,
                displacement,
                prototype,
                face_materials,
                st,
                normals,
                primvar_inputs,
                network_primvars,
                displacement_texture,
                gprim,
                light,
            },
        );
        // The delegate checks the data, once; what it refuses is not kept, and is an error
        // naming the prim now rather than a line in the next render's stats.
        if let Some(problem) = self.inner.mesh_problem(path) {
            self.inner.remove(path);
            return Err(delegate_error(problem));
        }
        Ok(())
    }

    /// Moves a mesh without resending its points (a transform-only edit). See the stubs.
    fn set_transform(&mut self, path: &str, transform: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        let transform = matrix(path, &transform)?;
        self.inner.set_transform(path, transform).map_err(delegate_error)
    }

    /// Sets a mesh's world transform over the camera's shutter (transform motion blur). See the
    /// stubs.
    fn set_motion(&mut self, path: &str, times: PyReadonlyArray1<'_, f32>, transforms: PyReadonlyArray3<'_, f64>) -> PyResult<()> {
        let times = times.as_array().to_vec();
        let transforms = matrices(path, &transforms)?;
        if times.len() != transforms.len() {
            return Err(value_error(path, format!("{} motion times for {} transforms", times.len(), transforms.len())));
        }
        let keys = times
            .into_iter()
            .zip(transforms)
            .map(|(time, render_from_object)| mipray::motion::MotionKey { time, render_from_object })
            .collect();
        self.inner.set_motion(path, keys).map_err(delegate_error)
    }

    /// Sets a mesh's (or a Points or curves prim's) points, and maybe widths, at times across
    /// the camera's shutter (deformation motion blur); no times clear them. See the stubs.
    #[pyo3(signature = (path, times, points, widths=None, gprims=None))]
    fn set_deformation(
        &mut self,
        path: &str,
        times: PyReadonlyArray1<'_, f32>,
        points: PyReadonlyArray3<'_, f32>,
        widths: Option<PyReadonlyArray2<'_, f32>>,
        gprims: Option<Vec<Bound<'_, PyDict>>>,
    ) -> PyResult<()> {
        let times = times.as_array().to_vec();
        let points = points.as_array();
        let (n, count, three) = points.dim();
        if n != times.len() || (n > 0 && three != 3) {
            return Err(value_error(path, format!("{} deformation times for points of shape {:?}", times.len(), points.dim())));
        }
        let widths: Vec<Vec<f32>> = match &widths {
            None => Vec::new(),
            Some(w) => {
                let w = w.as_array();
                if w.nrows() != n {
                    return Err(value_error(path, format!("{n} deformation times for widths of shape {:?}", w.dim())));
                }
                w.rows().into_iter().map(|r| r.to_vec()).collect()
            }
        };
        let mut shapes = Vec::new();
        for (k, g) in gprims.iter().flatten().enumerate() {
            match read_gprim(path, g)? {
                Gprim::Implicit(shape) => shapes.push(shape),
                _ => return Err(value_error(path, format!("gprims[{k}] is not an implicit prim"))),
            }
        }
        let samples = times
            .into_iter()
            .enumerate()
            .map(|(k, time)| (time, (0..count).map(|i| [points[[k, i, 0]], points[[k, i, 1]], points[[k, i, 2]]]).collect()))
            .collect();
        self.inner.set_deformation(path, samples, widths, shapes).map_err(delegate_error)
    }

    /// Inserts or replaces an instancer: `prototypes[proto_indices[i]]` placed at
    /// `transforms[i]`. See the stubs.
    #[pyo3(signature = (path, *, prototypes, proto_indices, transforms, prototype=false))]
    fn set_instancer(
        &mut self,
        path: &str,
        prototypes: Vec<String>,
        proto_indices: PyReadonlyArray1<'_, i32>,
        transforms: PyReadonlyArray3<'_, f64>,
        prototype: bool,
    ) -> PyResult<()> {
        let transforms = matrices(path, &transforms)?;
        let indices = proto_indices.as_array();
        let data = match indices.as_slice() {
            Some(s) => InstancerData::new(path, prototypes, s, transforms, prototype),
            None => InstancerData::new(path, prototypes, &indices.to_vec(), transforms, prototype),
        };
        self.inner.set_instancer(path, data.map_err(delegate_error)?);
        Ok(())
    }

    /// Sets an instancer's per-instance transforms over the camera's shutter: `transforms[k, i]`
    /// is instance `i`'s at `times[k]`; no times clear them. See the stubs.
    fn set_instancer_motion(
        &mut self,
        path: &str,
        times: PyReadonlyArray1<'_, f32>,
        transforms: PyReadonlyArray4<'_, f64>,
    ) -> PyResult<()> {
        let times = times.as_array().to_vec();
        let a = transforms.as_array();
        let (k, n) = (a.shape()[0], a.shape()[1]);
        if a.shape()[2..] != [4, 4] || k != times.len() {
            return Err(value_error(path, format!("{} motion times for transforms of shape {:?} (want K×N×4×4)", times.len(), a.shape())));
        }
        let mut mats = Vec::with_capacity(k * n);
        for per_time in a.outer_iter() {
            for m in per_time.outer_iter() {
                // USD's row-vector layout read as columns (see `matrix`).
                let mut cols = [0f32; 16];
                for (c, v) in cols.iter_mut().zip(m.iter()) {
                    *c = *v as f32;
                }
                mats.push(Mat4::from_cols_array(&cols));
            }
        }
        self.inner.set_instancer_motion(path, &times, &mats).map_err(delegate_error)
    }

    /// Inserts or replaces a camera (USD units; apertures and focal length as authored).
    #[pyo3(signature = (path, *, transform, projection="perspective", focal_length=50.0, horizontal_aperture=20.955, vertical_aperture=15.2908, horizontal_aperture_offset=0.0, vertical_aperture_offset=0.0, clipping_range=(1.0, 1.0e6), f_stop=0.0, focus_distance=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn set_camera(
        &mut self,
        path: &str,
        transform: PyReadonlyArray2<'_, f64>,
        projection: &str,
        focal_length: f32,
        horizontal_aperture: f32,
        vertical_aperture: f32,
        horizontal_aperture_offset: f32,
        vertical_aperture_offset: f32,
        clipping_range: (f32, f32),
        f_stop: f32,
        focus_distance: f32,
    ) -> PyResult<()> {
        let projection = match projection {
            "perspective" => Projection::Perspective,
            "orthographic" => Projection::Orthographic,
            _ => return Err(value_error(path, format!("projection '{projection}' is not perspective or orthographic"))),
        };
        let camera = Camera {
            name: path.to_string(),
            render_from_camera: matrix(path, &transform)?,
            projection,
            focal_length,
            horizontal_aperture,
            vertical_aperture,
            horizontal_aperture_offset,
            vertical_aperture_offset,
            clipping_range,
            f_stop,
            focus_distance,
        };
        camera.validate().map_err(|e| value_error(path, e))?;
        self.inner.set_camera(path, camera);
        Ok(())
    }

    /// Inserts or replaces a UsdLux.DistantLight.
    #[pyo3(signature = (path, *, transform, intensity=1.0, exposure=0.0, color=(1.0, 1.0, 1.0), angle=0.53, normalize=false, shadow_enable=true, unlit=Vec::new(), no_shadow=Vec::new()))]
    #[allow(clippy::too_many_arguments)]
    fn set_distant_light(
        &mut self,
        path: &str,
        transform: PyReadonlyArray2<'_, f64>,
        intensity: f32,
        exposure: f32,
        color: (f32, f32, f32),
        angle: f32,
        normalize: bool,
        shadow_enable: bool,
        unlit: Vec<String>,
        no_shadow: Vec<String>,
    ) -> PyResult<()> {
        let vals = [intensity, exposure, color.0, color.1, color.2, angle];
        if vals.iter().any(|v| !v.is_finite()) {
            return Err(value_error(path, "light inputs must be finite"));
        }
        let transform = matrix(path, &transform)?;
        let data = DistantLightData {
            transform,
            intensity,
            exposure,
            color: [color.0, color.1, color.2],
            angle_deg: angle,
            normalize,
            shadow_enable,
        };
        self.inner.set_light(LightPrim { path: path.to_string(), data, area: None, shaping: None, links: LinkData { unlit, no_shadow } });
        Ok(())
    }

    /// Inserts or replaces a UsdLux light of any kind: ``distant`` (as `set_distant_light`),
    /// ``sphere`` (radius), ``rect`` (width, height), ``disk`` (radius), ``cylinder`` (radius,
    /// length, along local X), ``dome`` (``portals``: the PortalLight paths its ``portals``
    /// relationship names; ``None``, every portal guides it) or ``portal`` (width, height: a
    /// PortalLight, which guides the domes' sampling and emits nothing itself).
    /// ``cone_angle`` (degrees), ``cone_softness``, ``focus`` and ``focus_tint`` are UsdLux's
    /// ShapingAPI on sphere, rect and disk lights (the defaults shape nothing); ``unlit`` and
    /// ``no_shadow`` the mesh prims its light- and shadow-linking collections leave out.
    /// ``ies_file``, ``ies_angle_scale``, ``ies_normalize``: its IES profile; ``ies_down``: the
    /// stage's down in render space, from which a tilt table's tilt is taken (by its
    /// lamp-to-luminaire geometry); ``ies_profile_sampling``: directions drawn by the profile.
    #[pyo3(signature = (path, *, kind, transform, intensity=1.0, exposure=0.0, color=(1.0, 1.0, 1.0), normalize=false, shadow_enable=true, angle=0.53, radius=0.5, width=1.0, height=1.0, texture=None, length=1.0, cone_angle=180.0, cone_softness=0.0, focus=0.0, focus_tint=(0.0, 0.0, 0.0), unlit=Vec::new(), no_shadow=Vec::new(), ies_file=None, ies_angle_scale=0.0, ies_normalize=false, ies_down=(0.0, -1.0, 0.0), ies_profile_sampling=false, portals=None))]
    #[allow(clippy::too_many_arguments)]
    fn set_light(
        &mut self,
        path: &str,
        kind: &str,
        transform: PyReadonlyArray2<'_, f64>,
        intensity: f32,
        exposure: f32,
        color: (f32, f32, f32),
        normalize: bool,
        shadow_enable: bool,
        angle: f32,
        radius: f32,
        width: f32,
        height: f32,
        texture: Option<String>,
        length: f32,
        cone_angle: f32,
        cone_softness: f32,
        focus: f32,
        focus_tint: (f32, f32, f32),
        unlit: Vec<String>,
        no_shadow: Vec<String>,
        ies_file: Option<String>,
        ies_angle_scale: f32,
        ies_normalize: bool,
        ies_down: (f32, f32, f32),
        ies_profile_sampling: bool,
        portals: Option<Vec<String>>,
    ) -> PyResult<()> {
        let vals = [
            ies_angle_scale,
            intensity,
            exposure,
            color.0,
            color.1,
            color.2,
            angle,
            radius,
            width,
            height,
            length,
            cone_angle,
            cone_softness,
            focus,
            focus_tint.0,
            focus_tint.1,
            focus_tint.2,
        ];
        if vals.iter().any(|v| !v.is_finite()) {
            return Err(value_error(path, "light inputs must be finite"));
        }
        let data = DistantLightData {
            transform: matrix(path, &transform)?,
            intensity,
            exposure,
            color: [color.0, color.1, color.2],
            angle_deg: angle,
            normalize,
            shadow_enable,
        };
        let size =
            |name: &str, v: f32| if v > 0.0 { Ok(v) } else { Err(value_error(path, format!("inputs:{name} = {v} must be positive"))) };
        let links = LinkData { unlit, no_shadow };
        let area = match kind {
            "distant" => {
                self.inner.set_light(LightPrim { path: path.to_string(), data, area: None, shaping: None, links });
                return Ok(());
            }
            "sphere" => AreaKind::Sphere { radius: size("radius", radius)? },
            "rect" => AreaKind::Rect { width: size("width", width)?, height: size("height", height)?, texture },
            "disk" => AreaKind::Disk { radius: size("radius", radius)? },
            "cylinder" => AreaKind::Cylinder { radius: size("radius", radius)?, length: size("length", length)? },
            "dome" => AreaKind::Dome { texture, portals },
            "portal" => AreaKind::Portal { width: size("width", width)?, height: size("height", height)? },
            _ => {
                return Err(value_error(path, format!("light kind '{kind}' is not distant, sphere, rect, disk, cylinder, dome or portal")))
            }
        };
        let shaping = Some(ShapingData {
            cone_angle_deg: cone_angle,
            cone_softness,
            focus,
            focus_tint: [focus_tint.0, focus_tint.1, focus_tint.2],
            ies: ies_file.map(|file| IesData {
                profile_sampling: ies_profile_sampling,
                ..IesData::read(&file, ies_angle_scale, ies_normalize, [ies_down.0, ies_down.1, ies_down.2])
            }),
        });
        self.inner.set_light(LightPrim { path: path.to_string(), data, area: Some(area), shaping, links });
        Ok(())
    }

    /// Removes a prim; returns whether it existed.
    fn remove(&mut self, path: &str) -> bool {
        self.inner.remove(path)
    }

    /// Every prim path held, sorted.
    fn prim_paths(&self) -> Vec<String> {
        self.inner.prim_paths()
    }

    /// How many times the mesh's surface has been (re)built or updated; `None` if unknown.
    fn mesh_sync_count(&self, path: &str) -> Option<u64> {
        self.inner.mesh(path).map(|m| m.surface_syncs)
    }

    /// How many times the instancer has been set; `None` if there is none.
    fn instancer_update_count(&self, path: &str) -> Option<u64> {
        self.inner.instancer(path).map(|i| i.updates)
    }

    /// Syncs and renders. Returns (`RenderBuffers`: {aov: read-only H×W×C float32 view}, stats
    /// JSON). Releases the GIL; calls `on_update(samples, converged, {aov: view})` after each pass and writes every pass but
    /// the last to `pass_output` (see `render.rs`); Ctrl-C cancels it.
    #[pyo3(signature = (camera, width, height, aovs, settings=None, progress=None, *, on_update=None, pass_output=None))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &mut self,
        py: Python<'py>,
        camera: &str,
        width: usize,
        height: usize,
        aovs: Vec<String>,
        settings: Option<&Bound<'py, PyDict>>,
        progress: Option<Py<PyAny>>,
        on_update: Option<Py<PyAny>>,
        pass_output: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<(Bound<'py, render::RenderBuffers>, String)> {
        // Names become AOVs here, at the boundary: the render never sees an unknown one.
        let aovs = aovs.iter().map(|a| Aov::parse(a)).collect::<Result<Vec<_>, _>>().map_err(|e| PyValueError::new_err(e.to_string()))?;
        let pass_output = pass_output.map(render::PassOutput::from_py).transpose()?;
        let mut pairs = Vec::new();
        if let Some(s) = settings {
            for (k, v) in s.iter() {
                pairs.push((k.extract::<String>()?, render::py_to_json(&v)?));
            }
        }
        let settings =
            RenderSettings::from_pairs(pairs.iter().map(|(k, v)| (k.as_str(), v))).map_err(|e| PyValueError::new_err(e.to_string()))?;
        let pass = RenderPass { camera: camera.to_string(), width, height, aovs, settings };
        render::render(py, &mut self.inner, &pass, progress, on_update, pass_output)
    }
}

/// A UsdPreviewSurface from Python: `{"name": material path, <input>: value for any of
/// diffuseColor, emissiveColor, specularColor (3 floats), useSpecularWorkflow (bool or int),
/// metallic, roughness, clearcoat, clearcoatRoughness, opacity, opacityThreshold, ior (float),
/// "textures": {<input>: UsdUVTexture description}, "networks": {<input>: node network}}`
/// (an input in one of the two at most; [`network_input`]). Inputs left out keep UsdPreviewSurface's
/// fallbacks; values out of range (NaN included) are kept, and clamped with one warning when the
/// delegate builds the material. Unknown keys are errors naming the prim (a misspelt input
/// would otherwise silently render its fallback).
fn surface_inputs(path: &str, d: &Bound<'_, PyDict>) -> PyResult<SurfaceInputs> {
    let mut out = SurfaceInputs::new(path);
    let color = |key: &str, v: &Bound<'_, PyAny>| -> PyResult<glam::Vec3A> {
        let c: Vec<f32> = v.extract().map_err(|_| value_error(path, format!("material {key} must be 3 floats")))?;
        match c[..] {
            [r, g, b] => Ok(glam::Vec3A::new(r, g, b)),
            _ => Err(value_error(path, format!("material {key} must be 3 floats, got {}", c.len()))),
        }
    };
    let float = |key: &str, v: &Bound<'_, PyAny>| -> PyResult<f32> {
        v.extract::<f32>().map_err(|_| value_error(path, format!("material {key} must be a float")))
    };
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        let s = &mut out.surface;
        match key.as_str() {
            "name" => out.name = v.extract().map_err(|_| value_error(path, "material name must be a string"))?,
            "diffuseColor" => s.diffuse_color = color(&key, &v)?,
            "emissiveColor" => s.emissive_color = color(&key, &v)?,
            "specularColor" => s.specular_color = color(&key, &v)?,
            "useSpecularWorkflow" => {
                s.use_specular_workflow = v
                    .extract::<bool>()
                    .or_else(|_| v.extract::<i64>().map(|i| i != 0))
                    .map_err(|_| value_error(path, "material useSpecularWorkflow must be a bool or an int"))?
            }
            "metallic" => s.metallic = float(&key, &v)?,
            "roughness" => s.roughness = float(&key, &v)?,
            "clearcoat" => s.clearcoat = float(&key, &v)?,
            "clearcoatRoughness" => s.clearcoat_roughness = float(&key, &v)?,
            "opacity" => s.opacity = float(&key, &v)?,
            "opacityThreshold" => s.opacity_threshold = float(&key, &v)?,
            "ior" => s.ior = float(&key, &v)?,
            "textures" => {
                let textures = v.cast::<PyDict>().map_err(|_| value_error(path, "material textures must be a dict"))?;
                for (name, tex) in textures.iter() {
                    let name: String = name.extract()?;
                    let input = input_from_usd(&name)
                        .ok_or_else(|| value_error(path, format!("material texture for '{name}', which is not a textured input")))?;
                    let tex = tex.cast::<PyDict>().map_err(|_| value_error(path, format!("material {name} texture must be a dict")))?;
                    out.textures.retain(|(i, _)| *i != input);
                    out.textures.push((input, texture_input(path, &name, tex)?));
                }
            }
            "networks" => {
                let networks = v.cast::<PyDict>().map_err(|_| value_error(path, "material networks must be a dict"))?;
                for (name, net) in networks.iter() {
                    let name: String = name.extract()?;
                    let input = input_from_usd(&name)
                        .ok_or_else(|| value_error(path, format!("material network for '{name}', which is not a textured input")))?;
                    let net = net.cast::<PyDict>().map_err(|_| value_error(path, format!("material {name} network must be a dict")))?;
                    out.networks.retain(|(i, _)| *i != input);
                    out.networks.push((input, network_input(path, &name, net)?));
                }
            }
            _ => return Err(value_error(path, format!("material input '{key}' is not a UsdPreviewSurface input mipray reads"))),
        }
    }
    // Dict order is the caller's; the delegate's comparisons (dirty bits) want one order.
    out.textures.sort_by_key(|(i, _)| *i as u8);
    out.networks.sort_by_key(|(i, _)| *i as u8);
    if let Some((input, _)) = out.networks.iter().find(|(i, _)| out.textures.iter().any(|(t, _)| t == i)) {
        return Err(value_error(path, format!("material {} has both a texture and a network", input.usd_name())));
    }
    Ok(out)
}

/// A node network feeding material input `input`: `{"ops": [(name, *float arguments), …],
/// "lookups": [texture description as in `textures`, plus "channels" (1–4) and
/// "st_transform" (6 floats: s' = a·s + b·t + c, t' = d·s + e·t + f)]}`; the ops are
/// [`mipray::material::network::Op::parse`]'s, checked as a whole
/// ([`mipray::material::InputNetwork::check`]).
fn network_input(path: &str, input: &str, d: &Bound<'_, PyDict>) -> PyResult<NetworkInput> {
    use mipray::material::network::{Op, StTransform};
    let bad = |e: String| value_error(path, format!("{input} network: {e}"));
    let mut ops = Vec::new();
    if let Some(list) = d.get_item("ops")? {
        for item in list.try_iter()? {
            let parts: Vec<Bound<'_, PyAny>> = item?.extract().map_err(|_| bad("an op must be a tuple (name, *arguments)".into()))?;
            let Some((name, args)) = parts.split_first() else { return Err(bad("an op is empty".into())) };
            let name: String = name.extract().map_err(|_| bad("an op's name must be a string".into()))?;
            let args = args.iter().map(|a| a.extract::<f32>()).collect::<Result<Vec<_>, _>>();
            let args = args.map_err(|_| bad(format!("op '{name}' arguments must be numbers")))?;
            ops.push(Op::parse(&name, &args).map_err(bad)?);
        }
    }
    let mut lookups = Vec::new();
    if let Some(list) = d.get_item("lookups")? {
        for item in list.try_iter()? {
            let item = item?;
            let tex = item.cast::<PyDict>().map_err(|_| bad("a lookup must be a dict".into()))?;
            let channels: u8 = match tex.get_item("channels")? {
                None => 3,
                Some(v) => v.extract().map_err(|_| bad("lookup channels must be 1–4".into()))?,
            };
            if !(1..=4).contains(&channels) {
                return Err(bad(format!("lookup channels {channels} is not 1–4")));
            }
            let st_transform = match tex.get_item("st_transform")? {
                None => StTransform::IDENTITY,
                Some(v) => {
                    let m: [f32; 6] = v.extract().map_err(|_| bad("lookup st_transform must be 6 floats".into()))?;
                    if !m.iter().all(|x| x.is_finite()) {
                        return Err(bad(format!("lookup st_transform {m:?} is not finite")));
                    }
                    StTransform(m)
                }
            };
            lookups.push(NetworkTextureInput { texture: texture_input(path, input, tex)?, channels, st_transform });
        }
    }
    let mut primvars = Vec::new();
    if let Some(list) = d.get_item("primvars")? {
        for item in list.try_iter()? {
            let item = item?;
            let p = item.cast::<PyDict>().map_err(|_| bad("a primvar must be a dict".into()))?;
            let name: String = p
                .get_item("name")?
                .ok_or_else(|| bad("a primvar has no name".into()))?
                .extract()
                .map_err(|_| bad("a primvar's name must be a string".into()))?;
            let components: u8 = match p.get_item("components")? {
                None => 1,
                Some(v) => v.extract().map_err(|_| bad("primvar components must be 1–4".into()))?,
            };
            if !(1..=4).contains(&components) {
                return Err(bad(format!("primvar {name} components {components} is not 1–4")));
            }
            let fallback: [f32; 4] = match p.get_item("fallback")? {
                None => [0.0; 4],
                Some(v) => v.extract().map_err(|_| bad(format!("primvar {name} fallback must be 4 floats")))?,
            };
            if !fallback.iter().all(|x| x.is_finite()) {
                return Err(bad(format!("primvar {name} fallback {fallback:?} is not finite")));
            }
            primvars.push(mipray::material::network::NetworkPrimvar {
                name,
                components,
                channels: None,
                fallback: glam::Vec4::from(fallback),
            });
        }
    }
    mipray::material::InputNetwork::check(&ops, lookups.len()).map_err(bad)?;
    mipray::material::InputNetwork::check_primvars(&ops, primvars.len()).map_err(bad)?;
    Ok(NetworkInput { ops, lookups, primvars })
}

/// A UsdUVTexture description from Python: `{"file", "scale", "bias", "fallback" (4 floats
/// each, optional), "wrapS", "wrapT", "sourceColorSpace" (USD tokens), "channel" (0–3),
/// "udim_tiles" ((tile, file) pairs of a `<UDIM>` file)}`.
/// `set_mesh`'s `gprim` dict: `type` (Sphere, Cube, Cylinder, Capsule, Plane, Points) and the
/// shape's sizes (`radius`, `size`, `radius_bottom`, `radius_top`, `height`, `width`,
/// `length`, `axis`; `widths` for Points). Sizes are checked here, so a bad one names the prim.
/// `set_mesh`'s ``light``: ``{"intensity", "exposure", "color", "normalize", "shadow_enable",
/// "unlit", "no_shadow", "tint", "tint_materials"}``, every key optional (UsdLux's fallbacks;
/// no links; `tint`: the bound material's emission tints the light, default false;
/// `tint_materials`: the GeomSubsets' materials, by name, whose emission tints their faces).
fn read_mesh_light(path: &str, d: &Bound<'_, PyDict>) -> PyResult<MeshLightData> {
    fn get<'py, T: for<'a> FromPyObject<'a, 'py>>(path: &str, d: &Bound<'py, PyDict>, key: &str, default: T) -> PyResult<T> {
        match d.get_item(key)? {
            Some(v) => v.extract().map_err(|_| value_error(path, format!("light {key} has the wrong type"))),
            None => Ok(default),
        }
    }
    let color: (f32, f32, f32) = get(path, d, "color", (1.0, 1.0, 1.0))?;
    let l = MeshLightData {
        intensity: get(path, d, "intensity", 1.0)?,
        exposure: get(path, d, "exposure", 0.0)?,
        color: [color.0, color.1, color.2],
        normalize: get(path, d, "normalize", false)?,
        shadow_enable: get(path, d, "shadow_enable", true)?,
        links: LinkData { unlit: get(path, d, "unlit", Vec::new())?, no_shadow: get(path, d, "no_shadow", Vec::new())? },
        tint: get(path, d, "tint", false)?,
        tint_materials: get(path, d, "tint_materials", Vec::new())?,
    };
    if ![l.intensity, l.exposure, l.color[0], l.color[1], l.color[2]].iter().all(|v| v.is_finite()) {
        return Err(value_error(path, "light inputs must be finite"));
    }
    if l.intensity < 0.0 || l.color.iter().any(|c| *c < 0.0) {
        return Err(value_error(path, "light intensity and color must be >= 0"));
    }
    Ok(l)
}

fn read_gprim(path: &str, d: &Bound<'_, PyDict>) -> PyResult<Gprim> {
    use mipray::implicit::{Axis, ImplicitSurface, Shape};
    let kind: String = d.get_item("type")?.ok_or_else(|| value_error(path, "gprim has no type"))?.extract()?;
    let float = |key: &str| -> PyResult<f32> {
        d.get_item(key)?
            .ok_or_else(|| value_error(path, format!("{kind} needs {key}")))?
            .extract::<f32>()
            .map_err(|_| value_error(path, format!("{key} must be a number")))
    };
    let axis = || -> PyResult<Axis> {
        let token: String = match d.get_item("axis")? {
            Some(v) => v.extract()?,
            None => "Z".into(),
        };
        Axis::from_usd(&token).ok_or_else(|| value_error(path, format!("axis '{token}' is not X, Y or Z")))
    };
    let shape = match kind.as_str() {
        "Points" => {
            let widths: Vec<f32> = match d.get_item("widths")? {
                Some(v) => v.extract().map_err(|_| value_error(path, "widths must be numbers"))?,
                None => Vec::new(),
            };
            return Ok(Gprim::Points { widths });
        }
        "Curves" => return read_curves(path, d).map(Gprim::Curves),
        "Nurbs" => return read_nurbs(path, d).map(Gprim::Nurbs),
        "Sphere" => Shape::Sphere { radius: float("radius")? },
        "Cube" => Shape::Cube { size: float("size")? },
        "Cylinder" => Shape::Cylinder {
            radius_bottom: float("radius_bottom")?,
            radius_top: float("radius_top")?,
            height: float("height")?,
            axis: axis()?,
        },
        "Capsule" => Shape::Capsule {
            radius_bottom: float("radius_bottom")?,
            radius_top: float("radius_top")?,
            height: float("height")?,
            axis: axis()?,
        },
        "Plane" => Shape::Plane { width: float("width")?, length: float("length")?, axis: axis()? },
        other => return Err(value_error(path, format!("gprim type '{other}' is not an implicit prim, Points, Curves or Nurbs"))),
    };
    ImplicitSurface::new(shape).map_err(|e| value_error(path, e))?;
    Ok(Gprim::Implicit(shape))
}

/// A `Curves` gprim dict: `curve_vertex_counts` (ints), `curve_type` (`linear`, `cubic`),
/// `basis` (`bezier`, `bspline`, `catmullRom`), `wrap` (`nonperiodic`, `periodic`, `pinned`),
/// `style` (`tube`, `ribbon`), `widths` (floats) and `widths_interpolation`, `normals` (N×3
/// floats) and `normals_interpolation` (USD's interpolation tokens). Counts and primvar
/// lengths are checked with the points by the delegate's `set_mesh`.
fn read_curves(path: &str, d: &Bound<'_, PyDict>) -> PyResult<hd_mipray::mesh::CurvesSpec> {
    use mipray::curves::{Basis, CurveType, Interpolation, Style, Wrap};
    let token = |key: &str, default: &str| -> PyResult<String> {
        match d.get_item(key)? {
            Some(v) => v.extract().map_err(|_| value_error(path, format!("{key} must be a token"))),
            None => Ok(default.to_string()),
        }
    };
    let bad = |attr: &str, t: &str| value_error(path, format!("{attr} '{t}' is not a USD token for it"));
    let ty = token("curve_type", "cubic")?;
    let basis = token("basis", "bezier")?;
    let wrap = token("wrap", "nonperiodic")?;
    let style = token("style", "tube")?;
    let wi = token("widths_interpolation", "vertex")?;
    let ni = token("normals_interpolation", "vertex")?;
    let counts: Vec<i32> = match d.get_item("curve_vertex_counts")? {
        Some(v) => v.extract().map_err(|_| value_error(path, "curveVertexCounts must be integers"))?,
        None => return Err(value_error(path, "Curves needs curve_vertex_counts")),
    };
    let widths: Vec<f32> = match d.get_item("widths")? {
        Some(v) => v.extract().map_err(|_| value_error(path, "widths must be numbers"))?,
        None => Vec::new(),
    };
    let normals: Vec<[f32; 3]> = match d.get_item("normals")? {
        Some(v) => v.extract().map_err(|_| value_error(path, "normals must be N×3 numbers"))?,
        None => Vec::new(),
    };
    Ok(hd_mipray::mesh::CurvesSpec {
        counts,
        curve_type: CurveType::from_usd(&ty).ok_or_else(|| bad("type", &ty))?,
        basis: Basis::from_usd(&basis).ok_or_else(|| bad("basis", &basis))?,
        wrap: Wrap::from_usd(&wrap).ok_or_else(|| bad("wrap", &wrap))?,
        widths,
        widths_interpolation: Interpolation::from_usd(&wi).ok_or_else(|| bad("widths interpolation", &wi))?,
        normals,
        normals_interpolation: Interpolation::from_usd(&ni).ok_or_else(|| bad("normals interpolation", &ni))?,
        style: Style::from_usd(&style).ok_or_else(|| bad("style", &style))?,
    })
}

/// A `Nurbs` gprim dict (a UsdGeom.NurbsPatch): `u_vertex_count`, `v_vertex_count`, `u_order`,
/// `v_order` (ints), `u_knots`, `v_knots` (floats), optional `u_range`, `v_range` (two floats)
/// and `weights` (floats, one per point). Counts, knots and weights are checked with the points
/// by the delegate's `set_mesh`, naming the USD attribute.
fn read_nurbs(path: &str, d: &Bound<'_, PyDict>) -> PyResult<hd_mipray::mesh::NurbsSpec> {
    let count = |key: &str, attr: &str| -> PyResult<usize> {
        let v: i64 = d
            .get_item(key)?
            .ok_or_else(|| value_error(path, format!("Nurbs needs {key}")))?
            .extract()
            .map_err(|_| value_error(path, format!("{attr} must be an integer")))?;
        usize::try_from(v).map_err(|_| value_error(path, format!("{attr} = {v} must not be negative")))
    };
    let floats = |key: &str, attr: &str| -> PyResult<Vec<f64>> {
        match d.get_item(key)? {
            Some(v) => v.extract().map_err(|_| value_error(path, format!("{attr} must be numbers"))),
            None => Ok(Vec::new()),
        }
    };
    let range = |key: &str, attr: &str| -> PyResult<Option<[f64; 2]>> {
        match d.get_item(key)? {
            None => Ok(None),
            Some(v) if v.is_none() => Ok(None),
            Some(v) => {
                v.extract::<(f64, f64)>().map(|(a, b)| Some([a, b])).map_err(|_| value_error(path, format!("{attr} must be two numbers")))
            }
        }
    };
    Ok(hd_mipray::mesh::NurbsSpec {
        u_count: count("u_vertex_count", "uVertexCount")?,
        v_count: count("v_vertex_count", "vVertexCount")?,
        u_order: count("u_order", "uOrder")?,
        v_order: count("v_order", "vOrder")?,
        u_knots: floats("u_knots", "uKnots")?,
        v_knots: floats("v_knots", "vKnots")?,
        u_range: range("u_range", "uRange")?,
        v_range: range("v_range", "vRange")?,
        weights: floats("weights", "pointWeights")?,
        trim: match d.get_item("trim")? {
            None => None,
            Some(t) if t.is_none() => None,
            Some(t) => Some(Box::new(
                read_trim(t.cast::<PyDict>().map_err(|_| value_error(path, "trim must be a dict"))?).map_err(|e| value_error(path, e))?,
            )),
        },
    })
}

/// A NurbsPatch's `trimCurve:*` from the dict `mipray.usd.gprim` sends: `counts`, `orders`,
/// `vertex_counts` (integers), `knots` (numbers), `ranges` (pairs, or empty) and `points`
/// (homogeneous triples). The error names the attribute of a value of the wrong kind.
fn read_trim(d: &Bound<'_, PyDict>) -> Result<hd_mipray::mesh::TrimSpec, String> {
    fn get<'py, T: for<'a> FromPyObject<'a, 'py> + Default>(
        d: &Bound<'py, PyDict>,
        key: &str,
        attr: &str,
        what: &str,
    ) -> Result<T, String> {
        let fail = || format!("trimCurve:{attr} must be {what}");
        match d.get_item(key).map_err(|_| fail())? {
            Some(v) => v.extract().map_err(|_| fail()),
            None => Ok(T::default()),
        }
    }
    let ranges: Vec<(f64, f64)> = get(d, "ranges", "ranges", "pairs of numbers")?;
    let points: Vec<(f64, f64, f64)> = get(d, "points", "points", "triples of numbers")?;
    Ok(hd_mipray::mesh::TrimSpec {
        counts: get(d, "counts", "counts", "integers")?,
        orders: get(d, "orders", "orders", "integers")?,
        vertex_counts: get(d, "vertex_counts", "vertexCounts", "integers")?,
        knots: get(d, "knots", "knots", "numbers")?,
        ranges: ranges.into_iter().map(|(a, b)| [a, b]).collect(),
        points: points.into_iter().map(|(u, v, w)| [u, v, w]).collect(),
    })
}

/// What is wrong with a NurbsPatch's trim curves (the dict `mipray.usd.gprim` sends as
/// `gprim["trim"]`), in one line naming the `trimCurve:*` attribute; `None` when they trim.
#[pyfunction]
fn check_trim_curves(trim: &Bound<'_, PyDict>) -> Option<String> {
    let spec = match read_trim(trim) {
        Ok(spec) => spec,
        Err(e) => return Some(e),
    };
    mipray::trim::TrimRegion::new(&spec.desc()).err()
}

fn texture_input(path: &str, input: &str, d: &Bound<'_, PyDict>) -> PyResult<TextureInput> {
    let file: String = d.get_item("file")?.ok_or_else(|| value_error(path, format!("{input} texture has no file")))?.extract()?;
    let four = |key: &str, default: [f32; 4]| -> PyResult<[f32; 4]> {
        match d.get_item(key)? {
            None => Ok(default),
            Some(v) => {
                let v: Vec<f32> = v.extract()?;
                let mut out = default;
                for (o, x) in out.iter_mut().zip(v) {
                    if !x.is_finite() {
                        return Err(value_error(path, format!("{input} texture {key} is not finite")));
                    }
                    *o = x;
                }
                Ok(out)
            }
        }
    };
    let wrap = |key: &str| -> PyResult<Wrap> {
        match d.get_item(key)? {
            None => Ok(Wrap::FromFile),
            Some(v) => {
                let t: String = v.extract()?;
                Wrap::from_usd(&t).ok_or_else(|| {
                    value_error(path, format!("{input} texture {key} '{t}' is not black, clamp, repeat, mirror or useMetadata"))
                })
            }
        }
    };
    let channel: u32 = match d.get_item("channel")? {
        None => 0,
        Some(v) => v.extract()?,
    };
    if channel > 3 {
        return Err(value_error(path, format!("{input} texture channel {channel} is not 0–3")));
    }
    let color_space = match d.get_item("sourceColorSpace")? {
        None => SourceColorSpace::Auto,
        Some(v) => {
            let t: String = v.extract()?;
            SourceColorSpace::from_usd(&t)
                .ok_or_else(|| value_error(path, format!("{input} texture sourceColorSpace '{t}' is not auto, raw or sRGB")))?
        }
    };
    Ok(TextureInput {
        file,
        scale: four("scale", [1.0; 4])?,
        bias: four("bias", [0.0; 4])?,
        fallback: four("fallback", [0.0, 0.0, 0.0, 1.0])?,
        wrap_s: wrap("wrapS")?,
        wrap_t: wrap("wrapT")?,
        channel,
        color_space,
        udim_tiles: match d.get_item("udim_tiles")? {
            None => Vec::new(),
            Some(v) => v.extract().map_err(|_| value_error(path, format!("{input} texture udim_tiles must be (tile, file) pairs")))?,
        },
    })
}

fn parse_format(s: &str) -> PyResult<ChannelFormat> {
    ChannelFormat::from_name(s)
        .ok_or_else(|| PyValueError::new_err(format!("format '{s}' is not one of {}", ChannelFormat::NAMES.join(", "))))
}

fn meta_value(v: &Bound<'_, PyAny>) -> PyResult<MetaValue> {
    if let Ok(s) = v.extract::<String>() {
        return Ok(MetaValue::Str(s));
    }
    if let Ok(b) = v.extract::<bool>() {
        return Ok(MetaValue::Int(b as i64));
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(MetaValue::Int(i));
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(MetaValue::Float(f as f32));
    }
    if let Ok(m) = v.extract::<Vec<f64>>() {
        if m.len() == 16 {
            let mut a = [0f32; 16];
            for (d, s) in a.iter_mut().zip(m) {
                *d = s as f32;
            }
            return Ok(MetaValue::Matrix44(a));
        }
    }
    Err(PyValueError::new_err(format!("metadata value {v} must be a string, number or 16 numbers")))
}

/// `color_correction` as the writer takes it; ValueError naming the valid modes.
pub(crate) fn color_correction(name: &str) -> PyResult<ColorCorrection> {
    ColorCorrection::from_name(name).map_err(PyValueError::new_err)
}

/// Image attributes from a dict of strings, numbers and 16-number matrices.
pub(crate) fn metadata(m: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, MetaValue)>> {
    let mut meta = Vec::new();
    if let Some(m) = m {
        for (k, v) in m.iter() {
            meta.push((k.extract::<String>()?, meta_value(&v)?));
        }
    }
    Ok(meta)
}

/// Writes AOV arrays (H×W×C float32, all one size) into one image file through the core's
/// writer (`mipray::image_output`): `order` (default: every array, as given), the file type's
/// pixel types unless `formats` names others, the colour sRGB-encoded in 8-bit files with
/// `color_correction="sRGB"` (raw values by default, as this function always wrote them;
/// `mipray.image.write_aovs` defaults to sRGB, as usdrecord), `metadata` as image attributes, and with `atomic` a
/// temporary file renamed over `path`. The arrays are read where they are (no copy) unless one
/// is not C-contiguous. The GIL is released while writing.
#[pyfunction]
#[pyo3(signature = (path, aovs, order=None, formats=None, metadata=None, *, color_correction="disabled", atomic=false))]
#[allow(clippy::too_many_arguments)]
fn write_image(
    py: Python<'_>,
    path: &str,
    aovs: &Bound<'_, PyDict>,
    order: Option<Vec<String>>,
    formats: Option<HashMap<String, String>>,
    metadata: Option<&Bound<'_, PyDict>>,
    color_correction: &str,
    atomic: bool,
) -> PyResult<()> {
    let mut arrays = Vec::new();
    for (k, v) in aovs.iter() {
        let name: String = k.extract()?;
        let arr = v
            .cast_into::<PyArray3<f32>>()
            .map_err(|_| PyValueError::new_err(format!("{path}: AOV '{name}' must be an H×W×C float32 array")))?;
        arrays.push((name, arr.readonly()));
    }
    let (height, width) = arrays.first().map_or((0, 0), |(_, a)| (a.shape()[0], a.shape()[1]));
    if let Some((name, a)) = arrays.iter().find(|(_, a)| (a.shape()[0], a.shape()[1]) != (height, width)) {
        return Err(PyValueError::new_err(format!("{path}: AOV '{name}' is {:?}, the image is {height}×{width}", a.shape())));
    }
    // Non-contiguous arrays (a slice, a transpose) are copied once into standard layout.
    let owned: Vec<Option<Vec<f32>>> =
        arrays.iter().map(|(_, a)| if a.as_slice().is_ok() { None } else { Some(a.as_array().iter().copied().collect()) }).collect();
    let layers: Vec<Layer<'_>> = arrays
        .iter()
        .zip(&owned)
        .map(|((name, a), copy)| Layer { name, channels: a.shape()[2], data: copy.as_deref().or(a.as_slice().ok()).unwrap_or_default() })
        .collect();
    let mut chosen = Vec::new();
    for (name, f) in formats.unwrap_or_default() {
        chosen.push((name, parse_format(&f)?));
    }
    let options = WriteOptions {
        order: order.unwrap_or_default(),
        formats: chosen,
        color_correction: self::color_correction(color_correction)?,
        metadata: self::metadata(metadata)?,
        atomic,
    };
    let written = py.detach(|| write_layers(&OiioImageIo, Path::new(path), width, height, &layers, &options));
    // Values clamped to the file's range are warned about: the warning reaches Python now.
    forward_logs(py);
    written.map_err(|e| PyOSError::new_err(e.to_string()))
}

/// How `write_image` writes `aovs` to `path`: `(order, {aov: pixel type}, encode_srgb)`.
/// ValueError naming the path when it cannot (no extension, an 8-bit file without colour).
#[pyfunction]
#[pyo3(signature = (path, aovs, color_correction="sRGB"))]
fn output_plan(
    py: Python<'_>,
    path: &str,
    aovs: Vec<String>,
    color_correction: &str,
) -> PyResult<(Vec<String>, HashMap<String, &'static str>, bool)> {
    let names: Vec<&str> = aovs.iter().map(String::as_str).collect();
    let plan = image_output::plan(Path::new(path), &names, self::color_correction(color_correction)?);
    // The AOVs an 8-bit file leaves out are warned about: the warning reaches Python now.
    forward_logs(py);
    let plan = plan.map_err(|e| PyValueError::new_err(e.to_string()))?;
    let formats = plan.aovs.iter().cloned().zip(plan.formats.iter().map(|f| f.name())).collect();
    Ok((plan.aovs, formats, plan.encode_srgb))
}

/// The AOVs an 8-bit file at `path` holds (`mipray::image_output::eight_bit_aovs`): color, and
/// alpha where the type has an alpha channel; empty for other types.
#[pyfunction]
fn eight_bit_aovs(path: &str) -> Vec<&'static str> {
    image_output::eight_bit_aovs(Path::new(path))
}

/// The sRGB transfer curve (`mipray::image_output::srgb_encode`) of linear values, clamped to
/// [0, 1], NaN as 0: a new float32 array of the same shape.
#[pyfunction]
fn srgb_encode<'py>(py: Python<'py>, linear: PyReadonlyArrayDyn<'py, f32>) -> Bound<'py, PyArrayDyn<f32>> {
    linear.as_array().mapv(image_output::srgb_encode).into_pyarray(py)
}

/// Reads an image: (H×W×C float32 array, channel names).
#[pyfunction]
fn read_image<'py>(py: Python<'py>, path: &str) -> PyResult<(Bound<'py, PyArray3<f32>>, Vec<String>)> {
    let img = py.detach(|| OiioImageIo.read(Path::new(path))).map_err(|e| PyOSError::new_err(e.to_string()))?;
    let nc = img.channels.len();
    let arr = Array3::from_shape_vec((img.height, img.width, nc), img.pixels).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok((arr.into_pyarray(py), img.channels))
}

/// An image's string attributes, as OpenImageIO reads them (`Software`, `mipray:camera`, ...).
#[pyfunction]
fn read_metadata(py: Python<'_>, path: &str) -> PyResult<HashMap<String, String>> {
    let img = py.detach(|| OiioImageIo.read(Path::new(path))).map_err(|e| PyOSError::new_err(e.to_string()))?;
    Ok(img.metadata.into_iter().collect())
}

/// The render settings the delegate accepts: [(key, default, description)], the default `""`
/// for a setting unset unless given.
#[pyfunction]
fn render_settings() -> Vec<(&'static str, String, &'static str)> {
    SETTINGS.iter().map(|s| (s.key, s.default_text(), s.help)).collect()
}

/// A checked setting value as Python holds it: int, float or str; on/off settings as 0 or 1
/// (the form `--setting` and the sweep's knobs take), unset as None.
fn setting_to_py<'py>(py: Python<'py>, value: &SettingValue) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        SettingValue::Int(x) => x.into_pyobject(py)?.into_any(),
        SettingValue::Float(x) => x.into_pyobject(py)?.into_any(),
        SettingValue::Bool(b) => u8::from(*b).into_pyobject(py)?.into_any(),
        SettingValue::Choice(c) => c.into_pyobject(py)?.into_any(),
        SettingValue::Window(_) => value.to_text().into_pyobject(py)?.into_any(),
        SettingValue::Unset => py.None().into_bound(py),
    })
}

/// The settings table (`mipray::settings::SETTINGS`), one dict a row: key, type (`int`,
/// `float`, `bool`, `choice`), min, max, min_open, max_open (numbers; None otherwise), choices,
/// default (None when unset), range (the values it takes, in words), help, scope.
#[pyfunction]
fn settings(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let defaults = RenderSettings::default();
    let rows = PyList::empty(py);
    for s in SETTINGS {
        let d = PyDict::new(py);
        d.set_item("key", s.key)?;
        let (kind, min, max, min_open, max_open, choices): (_, Option<f64>, Option<f64>, bool, bool, &[&str]) = match s.ty {
            SettingType::Int { min, max } => ("int", Some(min as f64), Some(max as f64), false, false, &[]),
            SettingType::Float { min, min_open, max, max_open } => ("float", Some(min), Some(max), min_open, max_open, &[]),
            SettingType::Bool => ("bool", Some(0.0), Some(1.0), false, false, &[]),
            SettingType::Choice(names) => ("choice", None, None, false, false, names),
            SettingType::Window => ("window", Some(0.0), Some(1.0), false, false, &[]),
        };
        d.set_item("type", kind)?;
        d.set_item("min", min)?;
        d.set_item("max", max)?;
        d.set_item("min_open", min_open)?;
        d.set_item("max_open", max_open)?;
        d.set_item("choices", choices.to_vec())?;
        let default = defaults.value(s.key).unwrap_or(SettingValue::Unset);
        d.set_item("default", setting_to_py(py, &default)?)?;
        d.set_item("range", s.ty.describe())?;
        d.set_item("help", s.help)?;
        d.set_item("scope", s.scope.name())?;
        rows.append(d)?;
    }
    Ok(rows)
}

/// `value` (a number, or text as on a command line) checked as setting `key`'s and returned as
/// Python holds it; ValueError naming the setting, the value and the range otherwise. The
/// delegate applies the same check to every setting a render is given.
#[pyfunction]
fn parse_setting<'py>(py: Python<'py>, key: &str, value: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let json = render::py_to_json(value)?;
    let parsed = mipray::settings::parse(key, &json).map_err(|e| PyValueError::new_err(e.to_string()))?;
    setting_to_py(py, &parsed)
}

/// The AOVs the delegate can render.
#[pyfunction]
fn aov_names(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    PyList::new(py, mipray::aov::AOV_NAMES)
}

/// The AOV table (`mipray::aov::AOV_TABLE`), one dict an AOV: name, channels, meaning,
/// averaged (over a pixel's samples, else the pixel centre's), clear, file_channels, format
/// (`half` or `float`, the EXR pixel type).
#[pyfunction]
fn aovs(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let rows = PyList::empty(py);
    for aov in mipray::aov::Aov::ALL {
        let info = aov.info();
        let d = PyDict::new(py);
        d.set_item("name", info.name)?;
        d.set_item("channels", info.channels)?;
        d.set_item("meaning", info.meaning)?;
        d.set_item("averaged", aov.averaged())?;
        d.set_item("clear", info.clear)?;
        d.set_item("file_channels", aov.file_channel_names())?;
        d.set_item("format", info.format.name())?;
        rows.append(d)?;
    }
    Ok(rows)
}

/// The package version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// Compares a mesh's subdivision surface with OpenSubdiv's (limit evaluation against its own
/// patch table's, tessellations per tier, rate and split, seams, uniform refinement): the
/// report as one JSON object, or as a readable table with `table=True`. The mesh is an OBJ in
/// OpenSubdiv's regression-shape format (`obj_text`) or USD's mesh attributes (as `set_mesh`
/// takes them). `heatmap` writes a picture of the tessellation error at `heatmap_rate` quads a
/// side. The GIL is released while comparing.
#[cfg(feature = "tools")]
#[pyfunction]
#[pyo3(signature = (name, *, obj_text=None, points=None, face_vertex_counts=None, face_vertex_indices=None, scheme="catmullClark", interpolate_boundary="edgeAndCorner", face_varying_linear_interpolation="cornersPlus1", triangle_subdivision_rule="catmullClark", crease_indices=None, crease_lengths=None, crease_sharpnesses=None, corner_indices=None, corner_sharpnesses=None, hole_indices=None, left_handed=false, uniform_level=2, samples_per_side=5, tessellation_patches=512, split_depth=2, split_patches=64, quick=false, table=false, heatmap=None, heatmap_rate=4))]
#[allow(clippy::too_many_arguments)]
fn subdiv_compare(
    py: Python<'_>,
    name: &str,
    obj_text: Option<String>,
    points: Option<PyReadonlyArray2<'_, f32>>,
    face_vertex_counts: Option<PyReadonlyArray1<'_, i32>>,
    face_vertex_indices: Option<PyReadonlyArray1<'_, i32>>,
    scheme: &str,
    interpolate_boundary: &str,
    face_varying_linear_interpolation: &str,
    triangle_subdivision_rule: &str,
    crease_indices: Option<PyReadonlyArray1<'_, i32>>,
    crease_lengths: Option<PyReadonlyArray1<'_, i32>>,
    crease_sharpnesses: Option<PyReadonlyArray1<'_, f32>>,
    corner_indices: Option<PyReadonlyArray1<'_, i32>>,
    corner_sharpnesses: Option<PyReadonlyArray1<'_, f32>>,
    hole_indices: Option<PyReadonlyArray1<'_, i32>>,
    left_handed: bool,
    uniform_level: u32,
    samples_per_side: usize,
    tessellation_patches: usize,
    split_depth: u32,
    split_patches: usize,
    quick: bool,
    table: bool,
    heatmap: Option<String>,
    heatmap_rate: usize,
) -> PyResult<String> {
    use hd_mipray::subdiv_compare::{compare, compare_obj, heatmap as hm, CompareOptions};
    let mut options = if quick { CompareOptions::quick() } else { CompareOptions::default() };
    if !quick {
        options.uniform_level = uniform_level.min(10);
        options.samples_per_side = samples_per_side.clamp(2, 65);
        options.tessellation_patches = tessellation_patches;
        options.split_depth = split_depth.min(6);
        options.split_patches = split_patches;
    }
    let rate = mipray::tessellate::Rate::ALL
        .into_iter()
        .find(|r| r.quads() == heatmap_rate)
        .ok_or_else(|| value_error(name, format!("heatmap_rate {heatmap_rate} is not one of 1, 2, 4, 8, 16")))?;
    let (topology, pts) = match (&obj_text, &points) {
        (Some(text), None) => {
            let shape = mipray::obj_shape::parse_obj_shape(name, text).map_err(|e| value_error(name, e))?;
            (shape.topology, shape.points)
        }
        (None, Some(p)) => {
            let a = p.as_array();
            if a.ncols() != 3 {
                return Err(value_error(name, format!("points must be N×3, got {:?}", a.shape())));
            }
            let pts: Vec<[f32; 3]> = a.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
            let topology = MeshTopology {
                scheme: Scheme::from_usd(scheme).map_err(|e| value_error(name, e))?,
                face_vertex_counts: vec_i32(face_vertex_counts),
                face_vertex_indices: vec_i32(face_vertex_indices),
                crease_indices: vec_i32(crease_indices),
                crease_lengths: vec_i32(crease_lengths),
                crease_sharpnesses: vec_f32(crease_sharpnesses),
                corner_indices: vec_i32(corner_indices),
                corner_sharpnesses: vec_f32(corner_sharpnesses),
                hole_indices: vec_i32(hole_indices),
                boundary: BoundaryInterpolation::from_usd(interpolate_boundary).map_err(|e| value_error(name, e))?,
                face_varying: FaceVaryingInterpolation::from_usd(face_varying_linear_interpolation).map_err(|e| value_error(name, e))?,
                triangle_subdivision: TriangleSubdivision::from_usd(triangle_subdivision_rule).map_err(|e| value_error(name, e))?,
                left_handed,
            };
            (topology, pts)
        }
        _ => return Err(value_error(name, "give either obj_text or points (with the topology), not both")),
    };
    py.detach(|| -> Result<String, String> {
        let report = match &obj_text {
            Some(text) => compare_obj(name, text, &options),
            None => compare(name, &topology, &pts, &options),
        }
        .map_err(|e| e.to_string())?;
        if let Some(out) = &heatmap {
            let surface = mipray_bridge::OsdSurface::with_options(name, &topology, &pts, &options.osd).map_err(|e| e.to_string())?;
            let img = hm::render(&surface, report.bbox_diagonal, &hm::HeatmapOptions { rate, ..Default::default() });
            OiioImageIo.write(Path::new(out), &img, &[ChannelFormat::U8], &[]).map_err(|e| e.to_string())?;
        }
        if table {
            Ok(report.table())
        } else {
            serde_json::to_string(&report).map_err(|e| format!("{name}: {e}"))
        }
    })
    .map_err(PyValueError::new_err)
}

/// Panics are caught where a prim's work is isolated and reported there in one line naming the
/// prim; the default hook would also print several lines of its own to the host's stderr for
/// each. Kept when `RUST_BACKTRACE` asks for the backtrace.
fn quiet_panics() {
    if std::env::var_os("RUST_BACKTRACE").is_none() {
        std::panic::set_hook(Box::new(|info| log::debug!("panic: {info}")));
    }
}

#[pymodule]
fn _mipray(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // Another extension may have installed a logger already; then ours is not needed.
    if log::set_logger(&COLLECTOR).is_ok() {
        log::set_max_level(log::LevelFilter::Warn);
    }
    quiet_panics();
    m.add_class::<RenderDelegate>()?;
    m.add_function(wrap_pyfunction!(write_image, m)?)?;
    m.add_function(wrap_pyfunction!(output_plan, m)?)?;
    m.add_function(wrap_pyfunction!(eight_bit_aovs, m)?)?;
    m.add_function(wrap_pyfunction!(srgb_encode, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_metadata, m)?)?;
    m.add_function(wrap_pyfunction!(render_settings, m)?)?;
    m.add_function(wrap_pyfunction!(settings, m)?)?;
    m.add_function(wrap_pyfunction!(parse_setting, m)?)?;
    m.add_function(wrap_pyfunction!(aov_names, m)?)?;
    m.add_function(wrap_pyfunction!(aovs, m)?)?;
    m.add_function(wrap_pyfunction!(check_trim_curves, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    #[cfg(feature = "tools")]
    m.add_function(wrap_pyfunction!(subdiv_compare, m)?)?;
    Ok(())
}
