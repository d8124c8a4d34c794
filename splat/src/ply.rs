//! INRIA 3DGS PLY files: reading and writing [`GaussianSet`]s (docs/conventions.md §3).
//!
//! Reading finds properties by name in any order: `x y z`, `scale_0..2` (or only `scale_0..1`:
//! a 2DGS file), `rot_0..3` (w first), `opacity`, `f_dc_0..2` and `f_rest_*` (0, 9, 24 or 45 of
//! them: SH degree 0..3). A GaussianAvatars `binding_0` float property, or an integer `binding`,
//! becomes the [`Binding`] and marks the parameters as local. HRAvatar's material attributes
//! `albedo_0..2`, `roughness` and `reflectance` (all five or none) become the set's
//! [`Material`] (values in 0..=1, checked). Every other vertex property is kept
//! by name, in its stored type, and written back. The standard properties are stored as `f32`;
//! when a file stores them in another type they are converted (exactly for `float`).
//!
//! The file itself is read and written by geometry's PLY core ([`trisplat_geometry::io::ply`]):
//! binary little-endian, big-endian or ascii; header counts are never trusted (a file shorter
//! than its header says is an error naming the element, and nothing is allocated beyond what
//! the bytes present can hold). This module maps the `vertex` element's columns to a
//! [`GaussianSet`] and back. Non-finite values in standard properties and zero quaternions are
//! errors naming the file and the Gaussian.
//!
//! Writing keeps the property order of the file a set was read from (recorded in
//! [`GaussianParts::property_order`]); properties it does not list follow in the INRIA order
//! (`x y z f_dc f_rest opacity scale rot`, then extras, then the binding). Floats are written
//! bit for bit (ascii uses the shortest representation that reads back to the same `f32`), so
//! writing what was read reproduces every value exactly. Files are written atomically.

use std::io::Write;
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use trisplat_geometry::io::ply::{
    ColumnView, PlyDocument, PlyProperty, PropertyData, parse_ply, write_ply_columns,
};
use trisplat_geometry::io::{IoError, write_atomically};
use trisplat_geometry::{Aabb, TriId};

pub use trisplat_geometry::io::PlyEncoding;

use crate::gaussians::{
    Binding, BindingEncoding, ExtraProperty, GaussianError, GaussianParts, GaussianSet,
    ParameterSpace, PropertyValues, ScalarType, ScaleDims, sh_coeffs_per_channel,
};
use crate::material::attributes::{Material, PLY_ALBEDO, PLY_REFLECTANCE, PLY_ROUGHNESS};

/// Largest triangle index a `float` `binding_0` can hold exactly (2²⁴).
pub const MAX_FLOAT_BINDING: u32 = 1 << 24;

/// Errors of reading and writing Gaussian PLY files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlyError {
    /// The operating system refused (missing file, permissions).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file is not a well-formed PLY file (header, truncated body, a value that does not
    /// parse); the message names the header line or the element row at fault.
    #[error(transparent)]
    Malformed(IoError),
    /// No `vertex` element.
    #[error("{}: no `vertex` element", path.display())]
    NoVertexElement {
        /// The file.
        path: PathBuf,
    },
    /// A property a Gaussian needs is missing.
    #[error("{}: missing vertex property `{name}`", path.display())]
    MissingProperty {
        /// The file.
        path: PathBuf,
        /// The property.
        name: String,
    },
    /// A vertex property we cannot use (a list, a duplicate, an impossible `f_rest` count).
    #[error("{}: vertex property `{name}`: {message}", path.display())]
    BadProperty {
        /// The file.
        path: PathBuf,
        /// The property.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// A binding value that is not a triangle index (negative, fractional, not finite).
    #[error("{}: Gaussian {index}: binding {value} is not a triangle index", path.display())]
    BadBinding {
        /// The file.
        path: PathBuf,
        /// Gaussian index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// The values read do not make a valid Gaussian set (NaN, zero quaternion, ...).
    #[error("{}: {source}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The problem, naming the Gaussian.
        source: GaussianError,
    },
    /// A binding that the chosen encoding cannot store.
    #[error("{}: Gaussian {index}: triangle {triangle} cannot be stored as {ty:?}", path.display())]
    BindingNotRepresentable {
        /// The file.
        path: PathBuf,
        /// Gaussian index.
        index: usize,
        /// The triangle.
        triangle: TriId,
        /// The property type.
        ty: ScalarType,
    },
    /// Writing failed; the target is untouched.
    #[error(transparent)]
    Write(IoError),
}

/// Options for [`write_gaussians`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PlyWriteOptions {
    /// Body encoding.
    pub encoding: PlyEncoding,
}

// ----------------------------------------------------------------------------------------------
// Property roles

/// Where each standard parameter lives among the vertex properties (indices into the property
/// list).
struct Layout {
    mean: [usize; 3],
    scale: Vec<usize>,
    rot: [usize; 4],
    opacity: usize,
    /// SH columns in storage order (dc 0..2, then rest 0..).
    sh: Vec<usize>,
    sh_degree: u8,
    binding: Option<(usize, BindingEncoding)>,
    /// `albedo_0..2`, `roughness`, `reflectance`, when the file has them.
    material: Option<[usize; 5]>,
    extras: Vec<usize>,
}

fn find_layout(props: &[PlyProperty], path: &Path) -> Result<Layout, PlyError> {
    let bad = |name: &str, message: &str| PlyError::BadProperty {
        path: path.to_path_buf(),
        name: name.to_string(),
        message: message.to_string(),
    };
    for (i, p) in props.iter().enumerate() {
        if props[..i].iter().any(|q| q.name == p.name) {
            return Err(bad(&p.name, "appears twice"));
        }
        if matches!(p.data, PropertyData::List { .. }) {
            return Err(bad(
                &p.name,
                "list properties are not supported on vertices",
            ));
        }
    }
    let find = |name: &str| props.iter().position(|p| p.name == name);
    let need = |name: &str| {
        find(name).ok_or_else(|| PlyError::MissingProperty {
            path: path.to_path_buf(),
            name: name.to_string(),
        })
    };
    let mean = [need("x")?, need("y")?, need("z")?];
    let mut scale = vec![need("scale_0")?, need("scale_1")?];
    if let Some(i) = find("scale_2") {
        scale.push(i);
    }
    let rot = [
        need("rot_0")?,
        need("rot_1")?,
        need("rot_2")?,
        need("rot_3")?,
    ];
    let opacity = need("opacity")?;
    let mut sh = vec![need("f_dc_0")?, need("f_dc_1")?, need("f_dc_2")?];
    let rest_count = props
        .iter()
        .filter(|p| p.name.starts_with("f_rest_"))
        .count();
    let sh_degree = match rest_count {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => {
            return Err(bad(
                "f_rest_*",
                &format!("{n} coefficients; expected 0, 9, 24 or 45 (SH degree 0..3)"),
            ));
        }
    };
    for k in 0..rest_count {
        sh.push(need(&format!("f_rest_{k}"))?);
    }
    let binding = match (find("binding_0"), find("binding")) {
        (Some(_), Some(_)) => return Err(bad("binding", "both `binding_0` and `binding` present")),
        (Some(i), None) => Some((i, BindingEncoding::Float)),
        (None, Some(i)) => match &props[i].data {
            PropertyData::Scalar(c) if c.scalar_type().is_integer() => {
                Some((i, BindingEncoding::Integer(c.scalar_type())))
            }
            _ => Some((i, BindingEncoding::Float)),
        },
        (None, None) => None,
    };
    let material_names = [
        PLY_ALBEDO[0],
        PLY_ALBEDO[1],
        PLY_ALBEDO[2],
        PLY_ROUGHNESS,
        PLY_REFLECTANCE,
    ];
    let material_found = material_names.map(find);
    let material = if material_found.iter().all(Option::is_some) {
        Some(material_found.map(|i| i.unwrap_or(0)))
    } else if let Some(k) = material_found.iter().position(Option::is_some) {
        let missing = material_names[material_found.iter().position(Option::is_none).unwrap_or(0)];
        return Err(bad(
            material_names[k],
            &format!(
                "material attributes come together (albedo_0..2, roughness, reflectance); \
                 `{missing}` is missing"
            ),
        ));
    } else {
        None
    };
    let mut used = vec![false; props.len()];
    for &i in mean
        .iter()
        .chain(&scale)
        .chain(&rot)
        .chain(std::iter::once(&opacity))
        .chain(&sh)
    {
        used[i] = true;
    }
    if let Some((i, _)) = binding {
        used[i] = true;
    }
    for &i in material.iter().flatten() {
        used[i] = true;
    }
    let extras = (0..props.len()).filter(|&i| !used[i]).collect();
    Ok(Layout {
        mean,
        scale,
        rot,
        opacity,
        sh,
        sh_degree,
        binding,
        material,
        extras,
    })
}

// ----------------------------------------------------------------------------------------------
// Reading

/// Reads a Gaussian PLY file.
///
/// # Errors
/// [`PlyError`] naming the file and, for bad values, the Gaussian index.
pub fn read_gaussians(path: &Path) -> Result<GaussianSet, PlyError> {
    let bytes = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let document = parse_ply(path, &bytes).map_err(PlyError::Malformed)?;
    drop(bytes);
    gaussians_from_document(document, path)
}

/// Reads a Gaussian PLY file with its means relative to a local origin, returned beside the
/// set: the origin of the means' bounding box ([`trisplat_geometry::Aabb::local_origin`], zero
/// unless the Gaussians are far from the world origin), subtracted from the file's values in
/// `f64` before they are stored in `f32`, so `double` coordinates at any offset keep the
/// precision they have near the origin. A renderer then moves its cameras by `-origin`.
///
/// # Errors
/// As [`read_gaussians`].
pub fn read_gaussians_local(path: &Path) -> Result<(GaussianSet, DVec3), PlyError> {
    let bytes = std::fs::read(path).map_err(|source| PlyError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut document = parse_ply(path, &bytes).map_err(PlyError::Malformed)?;
    drop(bytes);
    let origin = move_means_to_local_origin(&mut document);
    Ok((gaussians_from_document(document, path)?, origin))
}

/// Moves the `x`, `y`, `z` columns of the `vertex` element to their local origin (in `f64`),
/// returning it; a document without them is left alone (the reader reports it).
fn move_means_to_local_origin(document: &mut PlyDocument) -> DVec3 {
    let Some(vertex) = document.elements.iter_mut().find(|e| e.name == "vertex") else {
        return DVec3::ZERO;
    };
    let find = |name: &str| vertex.properties.iter().position(|p| p.name == name);
    let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
        return DVec3::ZERO;
    };
    let column = |i: usize| match &vertex.properties[i].data {
        PropertyData::Scalar(c) => Some(c.to_f64()),
        PropertyData::List { .. } => None,
    };
    let (Some(x), Some(y), Some(z)) = (column(ix), column(iy), column(iz)) else {
        return DVec3::ZERO;
    };
    let points: Vec<DVec3> = (0..x.len().min(y.len()).min(z.len()))
        .map(|i| DVec3::new(x[i], y[i], z[i]))
        .collect();
    let origin = Aabb::from_dpoints(&points).map_or(DVec3::ZERO, |b| b.local_origin());
    if origin == DVec3::ZERO {
        return origin;
    }
    for ((column, values), o) in [(ix, x), (iy, y), (iz, z)]
        .into_iter()
        .zip(origin.to_array())
    {
        #[expect(
            clippy::cast_possible_truncation,
            reason = "f32 storage, as every mean"
        )]
        let local = values.iter().map(|&v| (v - o) as f32).collect();
        vertex.properties[column].data = PropertyData::Scalar(PropertyValues::F32(local));
    }
    origin
}

/// Reads a Gaussian PLY file held in memory; `path` only names it in errors.
///
/// # Errors
/// As [`read_gaussians`].
pub fn read_gaussians_from_bytes(bytes: &[u8], path: &Path) -> Result<GaussianSet, PlyError> {
    let document = parse_ply(path, bytes).map_err(PlyError::Malformed)?;
    gaussians_from_document(document, path)
}

/// The Gaussians of a parsed PLY document's `vertex` element (other elements are ignored).
///
/// # Errors
/// [`PlyError::NoVertexElement`], [`PlyError::MissingProperty`], [`PlyError::BadProperty`],
/// [`PlyError::BadBinding`] or [`PlyError::Invalid`], naming `path`.
pub fn gaussians_from_document(
    mut document: PlyDocument,
    path: &Path,
) -> Result<GaussianSet, PlyError> {
    let Some(at) = document.elements.iter().position(|e| e.name == "vertex") else {
        return Err(PlyError::NoVertexElement {
            path: path.to_path_buf(),
        });
    };
    let vertex = document.elements.swap_remove(at);
    let layout = find_layout(&vertex.properties, path)?;
    let n = vertex.count;
    let property_order: Vec<String> = vertex.properties.iter().map(|p| p.name.clone()).collect();
    let mut columns: Vec<PropertyValues> = vertex
        .properties
        .into_iter()
        .map(|p| match p.data {
            PropertyData::Scalar(c) => c,
            // Refused by `find_layout`.
            PropertyData::List { values, .. } => values,
        })
        .collect();
    let mut standard = standard_from_columns(&mut columns, &layout, n);
    standard.material = layout.material.map(|[r, g, b, rough, f0]| {
        let (r, g, b) = (
            take_f32(&mut columns, r),
            take_f32(&mut columns, g),
            take_f32(&mut columns, b),
        );
        Material {
            albedo: (0..n).map(|i| [r[i], g[i], b[i]]).collect(),
            roughness: take_f32(&mut columns, rough),
            f0: take_f32(&mut columns, f0),
        }
    });
    assemble(columns, standard, property_order, n, &layout, path)
}

/// Moves column `i` out as `f32` values (no copy for `float`; rounded for `double`, converted
/// for integers), leaving an empty column behind.
fn take_f32(columns: &mut [PropertyValues], i: usize) -> Vec<f32> {
    match std::mem::replace(&mut columns[i], PropertyValues::F32(Vec::new())) {
        PropertyValues::F32(v) => v,
        other => other.to_f32(),
    }
}

/// The standard parameters of every Gaussian.
struct Standard {
    means: Vec<Vec3>,
    log_scales: Vec<Vec3>,
    rotations: Vec<[f32; 4]>,
    opacity_logits: Vec<f32>,
    sh: Vec<f32>,
    material: Option<Material>,
}

/// Gathers the standard parameters from their columns (each `n` long), which are consumed.
fn standard_from_columns(columns: &mut [PropertyValues], layout: &Layout, n: usize) -> Standard {
    let mut take = |i: usize| take_f32(columns, i);
    let [x, y, z] = layout.mean.map(&mut take);
    let means = (0..n).map(|i| Vec3::new(x[i], y[i], z[i])).collect();
    let s: Vec<Vec<f32>> = layout.scale.iter().map(|&i| take(i)).collect();
    let log_scales = (0..n)
        .map(|i| Vec3::new(s[0][i], s[1][i], s.get(2).map_or(0.0, |c| c[i])))
        .collect();
    let [r0, r1, r2, r3] = layout.rot.map(&mut take);
    let rotations = (0..n).map(|i| [r0[i], r1[i], r2[i], r3[i]]).collect();
    let opacity_logits = take(layout.opacity);
    let sh_columns: Vec<Vec<f32>> = layout.sh.iter().map(|&i| take(i)).collect();
    let k = sh_columns.len();
    let mut sh = vec![0.0f32; n * k];
    // Interleaved block by block (a block of rows stays in cache while every column fills it).
    const BLOCK: usize = 1024;
    for (b, rows) in sh.chunks_mut(BLOCK * k.max(1)).enumerate() {
        let first = b * BLOCK;
        for (j, column) in sh_columns.iter().enumerate() {
            for (row, value) in rows.chunks_exact_mut(k).zip(&column[first..]) {
                row[j] = *value;
            }
        }
    }
    Standard {
        means,
        log_scales,
        rotations,
        opacity_logits,
        sh,
        material: None,
    }
}

fn assemble(
    mut columns: Vec<PropertyValues>,
    standard: Standard,
    property_order: Vec<String>,
    n: usize,
    layout: &Layout,
    path: &Path,
) -> Result<GaussianSet, PlyError> {
    let scale_dims = if layout.scale.len() == 3 {
        ScaleDims::Three
    } else {
        ScaleDims::Two
    };
    let Standard {
        means,
        log_scales,
        rotations,
        opacity_logits,
        sh,
        material,
    } = standard;
    let binding = match layout.binding {
        None => None,
        Some((b, encoding)) => {
            let values = &columns[b];
            let mut triangles = Vec::with_capacity(n);
            for index in 0..n {
                let value = values.get_f64(index).unwrap_or(f64::NAN);
                let ok = value >= 0.0 && value.fract() == 0.0 && value <= f64::from(u32::MAX);
                if !ok {
                    return Err(PlyError::BadBinding {
                        path: path.to_path_buf(),
                        index,
                        value,
                    });
                }
                triangles.push(TriId(value as u32));
            }
            Some(Binding {
                triangles,
                encoding,
            })
        }
    };
    let extras = layout
        .extras
        .iter()
        .map(|&i| ExtraProperty {
            name: property_order[i].clone(),
            values: std::mem::replace(&mut columns[i], PropertyValues::F32(Vec::new())),
        })
        .collect();
    let space = if binding.is_some() {
        ParameterSpace::Local
    } else {
        ParameterSpace::World
    };
    let parts = GaussianParts {
        means,
        log_scales,
        scale_dims,
        rotations,
        opacity_logits,
        sh_degree: layout.sh_degree,
        sh,
        binding,
        material,
        space,
        extras,
        property_order: Some(property_order),
    };
    GaussianSet::try_new(parts).map_err(|source| PlyError::Invalid {
        path: path.to_path_buf(),
        source,
    })
}

// ----------------------------------------------------------------------------------------------
// Writing

/// A column to write.
enum Column<'a> {
    Mean(usize),
    LogScale(usize),
    Rot(usize),
    Opacity,
    Sh(usize),
    Albedo(usize),
    Roughness,
    Reflectance,
    BindingFloat,
    BindingInt(ScalarType),
    Extra(&'a PropertyValues),
}

fn columns_to_write(set: &GaussianSet) -> Vec<(String, Column<'_>)> {
    let mut canonical: Vec<(String, Column<'_>)> = Vec::new();
    for (i, n) in ["x", "y", "z"].iter().enumerate() {
        canonical.push(((*n).to_string(), Column::Mean(i)));
    }
    let k = sh_coeffs_per_channel(set.sh_degree());
    for c in 0..3 {
        canonical.push((format!("f_dc_{c}"), Column::Sh(c)));
    }
    for j in 0..3 * (k - 1) {
        canonical.push((format!("f_rest_{j}"), Column::Sh(3 + j)));
    }
    canonical.push(("opacity".into(), Column::Opacity));
    for i in 0..set.scale_dims().count() {
        canonical.push((format!("scale_{i}"), Column::LogScale(i)));
    }
    for i in 0..4 {
        canonical.push((format!("rot_{i}"), Column::Rot(i)));
    }
    if set.material().is_some() {
        for (c, name) in PLY_ALBEDO.iter().enumerate() {
            canonical.push(((*name).to_string(), Column::Albedo(c)));
        }
        canonical.push((PLY_ROUGHNESS.into(), Column::Roughness));
        canonical.push((PLY_REFLECTANCE.into(), Column::Reflectance));
    }
    for e in set.extras() {
        canonical.push((e.name.clone(), Column::Extra(&e.values)));
    }
    if let Some(b) = set.binding() {
        match b.encoding {
            BindingEncoding::Float => canonical.push(("binding_0".into(), Column::BindingFloat)),
            BindingEncoding::Integer(t) => {
                canonical.push(("binding".into(), Column::BindingInt(t)));
            }
        }
    }
    let Some(order) = set.property_order() else {
        return canonical;
    };
    // The recorded order first (names we still write), then the rest in canonical order.
    let mut out = Vec::with_capacity(canonical.len());
    let mut slots: Vec<Option<(String, Column<'_>)>> = canonical.into_iter().map(Some).collect();
    for name in order {
        if let Some(slot) = slots
            .iter_mut()
            .find(|s| s.as_ref().is_some_and(|(n, _)| n == name))
        {
            out.extend(slot.take());
        }
    }
    out.extend(slots.into_iter().flatten());
    out
}

/// Checks that every binding fits its encoding.
fn check_binding(set: &GaussianSet, path: &Path) -> Result<(), PlyError> {
    let Some(b) = set.binding() else {
        return Ok(());
    };
    let (limit, ty) = match b.encoding {
        BindingEncoding::Float => (u64::from(MAX_FLOAT_BINDING), ScalarType::F32),
        BindingEncoding::Integer(t) => {
            let limit = match t {
                ScalarType::I8 => i8::MAX as u64,
                ScalarType::U8 => u64::from(u8::MAX),
                ScalarType::I16 => i16::MAX as u64,
                ScalarType::U16 => u64::from(u16::MAX),
                ScalarType::I32 => i32::MAX as u64,
                ScalarType::U32 => u64::from(u32::MAX),
                ScalarType::F32 => u64::from(MAX_FLOAT_BINDING),
                ScalarType::F64 => u64::from(u32::MAX),
            };
            (limit, t)
        }
    };
    match b.triangles.iter().position(|t| u64::from(t.0) > limit) {
        Some(index) => Err(PlyError::BindingNotRepresentable {
            path: path.to_path_buf(),
            index,
            triangle: b.triangles[index],
            ty,
        }),
        None => Ok(()),
    }
}

/// Writes `set` to `path` atomically (temporary file + rename).
///
/// # Errors
/// [`PlyError::BindingNotRepresentable`] when a binding does not fit its encoding,
/// [`PlyError::Write`] when the file cannot be written (the target is then untouched).
pub fn write_gaussians(
    path: &Path,
    set: &GaussianSet,
    options: &PlyWriteOptions,
) -> Result<(), PlyError> {
    check_binding(set, path)?;
    write_atomically(path, |w| {
        write_vertex_element(path, w, set, options.encoding)
    })
    .map_err(PlyError::Write)
}

/// Writes `set` as PLY to any writer (no atomicity; see [`write_gaussians`]).
///
/// # Errors
/// [`PlyError::BindingNotRepresentable`], or [`PlyError::Write`] (with an empty path) when the
/// writer fails.
pub fn write_gaussians_to(
    w: &mut dyn Write,
    set: &GaussianSet,
    options: &PlyWriteOptions,
) -> Result<(), PlyError> {
    let path = Path::new("");
    check_binding(set, path)?;
    write_vertex_element(path, w, set, options.encoding).map_err(PlyError::Write)
}

/// Writes `set` as one `vertex` element in the order described in the module docs, straight
/// from the set's own arrays (only the binding is converted into a column).
fn write_vertex_element(
    path: &Path,
    w: &mut dyn Write,
    set: &GaussianSet,
    encoding: PlyEncoding,
) -> Result<(), IoError> {
    let sh_stride = 3 * sh_coeffs_per_channel(set.sh_degree());
    let binding = set.binding().map(|b| b.triangles.as_slice()).unwrap_or(&[]);
    let columns = columns_to_write(set);
    let binding_column = columns.iter().find_map(|(_, c)| match c {
        Column::BindingFloat => Some(binding_column(ScalarType::F32, binding)),
        Column::BindingInt(ty) => Some(binding_column(*ty, binding)),
        _ => None,
    });
    let rotations = set.rotations().as_flattened();
    let (albedo, roughness, f0) = set.material().map_or((&[][..], &[][..], &[][..]), |m| {
        (m.albedo.as_flattened(), &m.roughness[..], &m.f0[..])
    });
    let properties: Vec<(&str, ColumnView<'_>)> = columns
        .iter()
        .map(|(name, column)| {
            let view = match *column {
                Column::Mean(axis) => ColumnView::Vec3Axis {
                    values: set.means(),
                    axis,
                },
                Column::LogScale(axis) => ColumnView::Vec3Axis {
                    values: set.log_scales(),
                    axis,
                },
                Column::Rot(a) => ColumnView::StridedF32 {
                    values: rotations,
                    offset: a,
                    stride: 4,
                },
                Column::Opacity => ColumnView::StridedF32 {
                    values: set.opacity_logits(),
                    offset: 0,
                    stride: 1,
                },
                Column::Sh(a) => ColumnView::StridedF32 {
                    values: set.sh(),
                    offset: a,
                    stride: sh_stride,
                },
                Column::Albedo(c) => ColumnView::StridedF32 {
                    values: albedo,
                    offset: c,
                    stride: 3,
                },
                Column::Roughness => ColumnView::StridedF32 {
                    values: roughness,
                    offset: 0,
                    stride: 1,
                },
                Column::Reflectance => ColumnView::StridedF32 {
                    values: f0,
                    offset: 0,
                    stride: 1,
                },
                Column::BindingFloat | Column::BindingInt(_) => match &binding_column {
                    Some(c) => ColumnView::Column(c),
                    // Not reached: binding columns are listed only for a bound set.
                    None => ColumnView::StridedF32 {
                        values: &[],
                        offset: 0,
                        stride: 1,
                    },
                },
                Column::Extra(values) => ColumnView::Column(values),
            };
            (name.as_str(), view)
        })
        .collect();
    write_ply_columns(path, w, encoding, "vertex", set.len(), &properties)?;
    w.flush().map_err(|e| IoError::os(path, e))
}

/// The bindings as a column of type `ty` (the caller checked they fit, see `check_binding`).
#[expect(
    clippy::cast_possible_truncation,
    clippy::cast_possible_wrap,
    reason = "check_binding refused bindings that do not fit the type"
)]
fn binding_column(ty: ScalarType, binding: &[TriId]) -> PropertyValues {
    let ids = binding.iter().map(|t| t.0);
    match ty {
        ScalarType::I8 => PropertyValues::I8(ids.map(|x| x as i8).collect()),
        ScalarType::U8 => PropertyValues::U8(ids.map(|x| x as u8).collect()),
        ScalarType::I16 => PropertyValues::I16(ids.map(|x| x as i16).collect()),
        ScalarType::U16 => PropertyValues::U16(ids.map(|x| x as u16).collect()),
        ScalarType::I32 => PropertyValues::I32(ids.map(|x| x as i32).collect()),
        ScalarType::U32 => PropertyValues::U32(ids.collect()),
        ScalarType::F32 => PropertyValues::F32(ids.map(|x| x as f32).collect()),
        ScalarType::F64 => PropertyValues::F64(ids.map(f64::from).collect()),
    }
}

/// Whether the PLY file at `path` holds 3DGS Gaussians: its header (the first 64 KiB are
/// looked at) declares the vertex properties `x`, `opacity`, `f_dc_0`, `scale_0` and `rot_0`.
/// `false` when the file cannot be read or is not such a PLY.
#[must_use]
pub fn is_gaussian_ply(path: &Path) -> bool {
    use std::io::Read as _;
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let mut head = Vec::new();
    if file.take(64 * 1024).read_to_end(&mut head).is_err() {
        return false;
    }
    let text = String::from_utf8_lossy(&head);
    let Some(end) = text.find("end_header") else {
        return false;
    };
    let mut in_vertex = false;
    let mut found = [false; 5];
    const NEEDED: [&str; 5] = ["x", "opacity", "f_dc_0", "scale_0", "rot_0"];
    for line in text[..end].lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", name, ..] => in_vertex = *name == "vertex",
            ["property", .., name] if in_vertex => {
                if let Some(i) = NEEDED.iter().position(|n| n == name) {
                    found[i] = true;
                }
            }
            _ => {}
        }
    }
    found.iter().all(|&f| f)
}
