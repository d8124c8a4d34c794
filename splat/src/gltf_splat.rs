//! Gaussians in glTF with the Khronos `KHR_gaussian_splatting` extension (Release Candidate,
//! KhronosGroup/glTF `extensions/2.0/Khronos/KHR_gaussian_splatting`, revision of 2026-04-15,
//! commit 63770cc; docs/conventions.md §3, "glTF").
//!
//! Writing: one scene, one node (no transform), one mesh with one `POINTS` primitive whose
//! `extensions.KHR_gaussian_splatting` is `{"kernel": "ellipse", "colorSpace":
//! "srgb_rec709_display", "projection": "perspective", "sortingMethod": "cameraDistance"}`,
//! float accessors only:
//! - `POSITION` (VEC3, with min/max): the means;
//! - `KHR_gaussian_splatting:ROTATION` (VEC4, x y z w): the unit quaternion (normalised in f64);
//! - `KHR_gaussian_splatting:SCALE` (VEC3): **linear** scales `exp(log-scale)` (f64, rounded
//!   once); a surfel's third axis is 0;
//! - `KHR_gaussian_splatting:OPACITY` (SCALAR): `sigmoid(logit)` in 0..1;
//! - `KHR_gaussian_splatting:SH_DEGREE_0_COEF_0` and `SH_DEGREE_l_COEF_n` (VEC3, r g b) for
//!   l = 1..degree, n = 0..2l (order m = -l..l, the 3DGS basis order): the SH coefficients;
//! - `COLOR_0` (VEC4 float): the fallback colour of viewers without the extension,
//!   `clamp(dc · 0.282095 + 0.5, 0, 1)` decoded from sRGB to linear, alpha the opacity.
//!
//! `.glb` holds the buffer in its binary chunk, `.gltf` as a base64 data URI; written
//! atomically. No axes are changed (as trisplat's mesh glTF files): glTF's frame is +Y up.
//!
//! Reading takes every `POINTS` primitive with the extension in the scene read by geometry's
//! glTF reader (node transforms applied: means by the node's matrix, covariances `M Σ Mᵀ`
//! written as rotation and scales, SH rotated by the matrix's rotation part), accessors in any
//! component type the extension allows (normalised integers decoded per glTF), and refuses
//! other kernels, missing or miscounted attributes, SH degrees given in part, negative scales
//! and opacities outside 0..1. Scales of 0 read as the log-scale [`ZERO_LOG_SCALE`]; opacities
//! 0 and 1 as the logits [`TRANSPARENT_LOGIT`] and [`OPAQUE_LOGIT`]. A set whose third scales
//! are all 0 reads as surfels. `COLOR_0` is ignored (the SH are the colour).
//!
//! What round-trips: means, rotations (as written: unit quaternions) and SH bit for bit; scales
//! and opacities through `exp`/`ln` and sigmoid/logit in f64, each rounded to f32 once.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3, Vec3};
use serde_json::{Value, json};
use trisplat_geometry::io::gltf::{GltfFile, glb_from_parts, gltf_text_from_parts};
use trisplat_geometry::io::{IoError, write_atomically};

use crate::gaussians::{
    GaussianError, GaussianParts, GaussianSet, ParameterSpace, ScaleDims, normalize_wxyz,
    quat_from_rotation, sh_coeffs_per_channel, sigmoid,
};
use crate::sh::{SH_C0, ShChange};
pub use crate::spz::{OPAQUE_LOGIT, TRANSPARENT_LOGIT};
use crate::svd::rotation_and_scales;
use trisplat_geometry::io::gltf_codes::{
    ARRAY_BUFFER, BYTE, FLOAT, POINTS, SHORT, UNSIGNED_BYTE, UNSIGNED_SHORT,
};

/// The extension's name.
pub const EXTENSION: &str = "KHR_gaussian_splatting";

/// The log-scale a scale of 0 reads as (its exponential is 0 in f32).
pub const ZERO_LOG_SCALE: f32 = -110.0;

/// The colour space written: 3DGS trains on sRGB pictures, display-referred.
pub const COLOR_SPACE: &str = "srgb_rec709_display";

/// Errors of reading and writing glTF Gaussians.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GltfSplatError {
    /// The file cannot be read or written, is malformed (naming the accessor, primitive or
    /// attribute) or uses what is not supported.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The values read do not make a valid Gaussian set.
    #[error("{}: {source}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The problem, naming the Gaussian.
        source: GaussianError,
    },
    /// The set cannot be written (bound Gaussians).
    #[error("{}: {message}", path.display())]
    Unrepresentable {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Gaussians read from a glTF file.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfSplats {
    /// Every splat primitive's Gaussians, in scene order, world space.
    pub gaussians: GaussianSet,
    /// The primitives' `colorSpace` (the first one's when they differ).
    pub color_space: String,
    /// How many splat primitives were read.
    pub primitives: usize,
}

// ----------------------------------------------------------------------------------------------
// Writing

fn attribute_name(l: usize, n: usize) -> String {
    format!("{EXTENSION}:SH_DEGREE_{l}_COEF_{n}")
}

/// sRGB-encoded value to linear (IEC 61966-2-1).
fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The JSON document and binary buffer of `set`.
#[expect(
    clippy::cast_possible_truncation,
    reason = "f32 storage of glTF floats"
)]
fn build(set: &GaussianSet) -> (Value, Vec<u8>) {
    let n = set.len();
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut attributes = serde_json::Map::new();
    let mut add = |name: String, kind: &str, values: &mut dyn Iterator<Item = f32>| {
        let offset = bin.len();
        for x in values {
            bin.extend_from_slice(&x.to_le_bytes());
        }
        views.push(json!({"buffer": 0, "byteOffset": offset,
            "byteLength": bin.len() - offset, "target": ARRAY_BUFFER}));
        accessors.push(
            json!({"bufferView": views.len() - 1, "componentType": FLOAT,
            "count": n, "type": kind}),
        );
        attributes.insert(name, json!(accessors.len() - 1));
    };
    add(
        "POSITION".into(),
        "VEC3",
        &mut set.means().iter().flat_map(|m| m.to_array()),
    );
    add(
        format!("{EXTENSION}:ROTATION"),
        "VEC4",
        &mut set.rotations().iter().flat_map(|&q| {
            let u = normalize_wxyz(q).unwrap_or(DQuat::IDENTITY);
            [u.x as f32, u.y as f32, u.z as f32, u.w as f32]
        }),
    );
    let dims = set.scale_dims().count();
    add(
        format!("{EXTENSION}:SCALE"),
        "VEC3",
        &mut set.log_scales().iter().flat_map(|l| {
            let l = l.to_array();
            [0, 1, 2].map(|a| {
                if a < dims {
                    f64::from(l[a]).exp() as f32
                } else {
                    0.0
                }
            })
        }),
    );
    add(
        format!("{EXTENSION}:OPACITY"),
        "SCALAR",
        &mut set.opacity_logits().iter().map(|&a| sigmoid(a)),
    );
    let k = sh_coeffs_per_channel(set.sh_degree());
    let rest = k - 1;
    add(
        format!("{EXTENSION}:SH_DEGREE_0_COEF_0"),
        "VEC3",
        &mut (0..n).flat_map(|i| {
            let c = set.sh_coeffs(i);
            [c[0], c[1], c[2]]
        }),
    );
    for l in 1..=usize::from(set.sh_degree()) {
        for m in 0..=2 * l {
            let j = l * l + m - 1;
            add(
                attribute_name(l, m),
                "VEC3",
                &mut (0..n).flat_map(|i| {
                    let c = set.sh_coeffs(i);
                    [c[3 + j], c[3 + rest + j], c[3 + 2 * rest + j]]
                }),
            );
        }
    }
    add(
        "COLOR_0".into(),
        "VEC4",
        &mut (0..n).flat_map(|i| {
            let c = set.sh_coeffs(i);
            let lin =
                |dc: f32| srgb_to_linear((f64::from(dc) * SH_C0 + 0.5).clamp(0.0, 1.0)) as f32;
            [lin(c[0]), lin(c[1]), lin(c[2]), set.opacity(i)]
        }),
    );
    // POSITION's min and max.
    let (lo, hi) = set.means().iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    accessors[0]["min"] = json!(lo.to_array());
    accessors[0]["max"] = json!(hi.to_array());
    let primitive = json!({
        "attributes": attributes,
        "mode": POINTS,
        "extensions": {EXTENSION: {
            "kernel": "ellipse",
            "colorSpace": COLOR_SPACE,
            "projection": "perspective",
            "sortingMethod": "cameraDistance",
        }},
    });
    let doc = json!({
        "asset": {"version": "2.0", "generator": "trisplat"},
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [primitive]}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    (doc, bin)
}

fn check_writable(set: &GaussianSet, path: &Path) -> Result<(), GltfSplatError> {
    if set.binding().is_some() || set.space() != ParameterSpace::World {
        return Err(GltfSplatError::Unrepresentable {
            path: path.to_path_buf(),
            message: "bound Gaussians (local parameters and a binding) cannot be stored in \
                      glTF; write world-space frames (`trisplat deform`)"
                .into(),
        });
    }
    if set.is_empty() {
        return Err(GltfSplatError::Unrepresentable {
            path: path.to_path_buf(),
            message: "an empty set: glTF accessors need at least one element".into(),
        });
    }
    Ok(())
}

/// The `.glb` bytes of `set`; `path` only names the file in errors.
///
/// # Errors
/// [`GltfSplatError::Unrepresentable`] for a bound or empty set; [`GltfSplatError::Io`] when
/// the file would exceed 4 GiB.
pub fn glb_gaussians(set: &GaussianSet, path: &Path) -> Result<Vec<u8>, GltfSplatError> {
    check_writable(set, path)?;
    let (doc, bin) = build(set);
    Ok(glb_from_parts(path, &doc, bin)?)
}

/// The `.gltf` text of `set` (buffer as a base64 data URI).
///
/// # Errors
/// As [`glb_gaussians`].
pub fn gltf_text_gaussians(set: &GaussianSet, path: &Path) -> Result<String, GltfSplatError> {
    check_writable(set, path)?;
    let (doc, bin) = build(set);
    Ok(gltf_text_from_parts(doc, &bin))
}

/// Writes `set` as `.glb` (binary chunk) or, for any other extension, `.gltf` (data URI),
/// atomically.
///
/// # Errors
/// As [`glb_gaussians`]; [`GltfSplatError::Io`] when the file cannot be written (the target
/// is then untouched).
pub fn write_gltf_gaussians(path: &Path, set: &GaussianSet) -> Result<(), GltfSplatError> {
    let glb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let bytes = if glb {
        glb_gaussians(set, path)?
    } else {
        gltf_text_gaussians(set, path)?.into_bytes()
    };
    write_atomically(path, |w| {
        w.write_all(&bytes).map_err(|e| IoError::os(path, e))
    })?;
    Ok(())
}

// ----------------------------------------------------------------------------------------------
// Reading

/// Whether the glTF/GLB file at `path` has a primitive with `KHR_gaussian_splatting` (its JSON
/// is parsed; `false` when it cannot be read).
#[must_use]
pub fn has_gaussian_splats(path: &Path) -> bool {
    GltfFile::open(path).is_ok_and(|f| has_splat_primitive(f.json()))
}

fn has_splat_primitive(json: &Value) -> bool {
    json["meshes"].as_array().is_some_and(|meshes| {
        meshes.iter().any(|m| {
            m["primitives"]
                .as_array()
                .is_some_and(|ps| ps.iter().any(|p| p["extensions"].get(EXTENSION).is_some()))
        })
    })
}

/// The component types (and whether normalised) the extension allows per attribute.
fn allowed(kind: &str) -> &'static [(u32, bool)] {
    match kind {
        "ROTATION" => &[(FLOAT, false), (BYTE, true), (SHORT, true)],
        "SCALE" => &[
            (FLOAT, false),
            (UNSIGNED_BYTE, false),
            (UNSIGNED_BYTE, true),
            (UNSIGNED_SHORT, false),
            (UNSIGNED_SHORT, true),
        ],
        "OPACITY" => &[
            (FLOAT, false),
            (UNSIGNED_BYTE, true),
            (UNSIGNED_SHORT, true),
        ],
        _ => &[(FLOAT, false)],
    }
}

/// One primitive's values, before the node transform.
struct Raw {
    means: Vec<[f64; 3]>,
    rotations: Vec<[f64; 4]>,
    scales: Vec<[f64; 3]>,
    opacities: Vec<f64>,
    /// Per Gaussian, per basis function (0..k), rgb.
    sh: Vec<f64>,
    degree: u8,
}

struct PrimitiveReader<'a> {
    file: &'a GltfFile,
    element: String,
    attributes: &'a serde_json::Map<String, Value>,
}

impl PrimitiveReader<'_> {
    fn err(&self, message: impl Into<String>) -> GltfSplatError {
        GltfSplatError::Io(IoError::malformed(self.file.path(), &self.element, message))
    }

    /// The accessor of `name`, if the primitive has it.
    fn index(&self, name: &str) -> Result<Option<usize>, GltfSplatError> {
        match self.attributes.get(name) {
            None => Ok(None),
            Some(v) => v
                .as_u64()
                .and_then(|i| usize::try_from(i).ok())
                .map(Some)
                .ok_or_else(|| self.err(format!("attribute {name} is not an accessor index"))),
        }
    }

    /// Reads attribute `name` (`kind` for the allowed types; `components` per element).
    fn read(
        &self,
        name: &str,
        kind: &str,
        components: usize,
        count: Option<usize>,
    ) -> Result<Option<Vec<f64>>, GltfSplatError> {
        let Some(index) = self.index(name)? else {
            return Ok(None);
        };
        let info = self
            .file
            .accessor_info(index)
            .ok_or_else(|| self.err(format!("attribute {name}: no accessor {index}")))?;
        if info.components != components {
            return Err(self.err(format!(
                "attribute {name} (accessor {index}) has {} components per element, {components} expected",
                info.components
            )));
        }
        if !allowed(kind).contains(&(info.component_type, info.normalized)) {
            return Err(self.err(format!(
                "attribute {name} (accessor {index}): component type {}{} is not one the \
                 extension allows",
                info.component_type,
                if info.normalized { " normalized" } else { "" }
            )));
        }
        if let Some(count) = count
            && info.count != count
        {
            return Err(self.err(format!(
                "attribute {name} (accessor {index}) has {} elements, POSITION has {count}",
                info.count
            )));
        }
        Ok(Some(self.file.read_accessor(index)?))
    }

    fn require(
        &self,
        name: &str,
        kind: &str,
        components: usize,
        count: usize,
    ) -> Result<Vec<f64>, GltfSplatError> {
        self.read(name, kind, components, Some(count))?
            .ok_or_else(|| self.err(format!("missing attribute {name}")))
    }

    fn raw(&self) -> Result<Raw, GltfSplatError> {
        let pos = self
            .read("POSITION", "POSITION", 3, None)?
            .ok_or_else(|| self.err("missing attribute POSITION"))?;
        let position_type = self
            .index("POSITION")?
            .and_then(|i| self.file.accessor_info(i))
            .map(|i| i.component_type);
        if position_type != Some(FLOAT) {
            return Err(self.err("POSITION must be float (quantised positions are not read)"));
        }
        let n = pos.len() / 3;
        let rot = self.require(&format!("{EXTENSION}:ROTATION"), "ROTATION", 4, n)?;
        let scale = self.require(&format!("{EXTENSION}:SCALE"), "SCALE", 3, n)?;
        let opacity = self.require(&format!("{EXTENSION}:OPACITY"), "OPACITY", 1, n)?;
        let dc = self.require(&attribute_name(0, 0), "SH", 3, n)?;
        // The degree: every coefficient of each degree up to it, none above.
        let mut bands: Vec<Vec<Vec<f64>>> = Vec::new();
        for l in 1..=3usize {
            let mut band = Vec::new();
            for m in 0..=2 * l {
                band.push(self.read(&attribute_name(l, m), "SH", 3, Some(n))?);
            }
            let have = band.iter().filter(|b| b.is_some()).count();
            if have == 0 {
                for higher in l + 1..=4 {
                    if self.index(&attribute_name(higher, 0))?.is_some() {
                        return Err(
                            self.err(format!("SH degree {higher} is given without degree {l}"))
                        );
                    }
                }
                break;
            }
            if have != band.len() {
                return Err(self.err(format!(
                    "SH degree {l} is given in part: {have} of its {} coefficients",
                    band.len()
                )));
            }
            bands.push(band.into_iter().flatten().collect());
        }
        if self.index(&attribute_name(4, 0))?.is_some() {
            return Err(GltfSplatError::Io(IoError::Unsupported {
                path: self.file.path().to_path_buf(),
                what: format!("{}: SH degree 4 (the extension stops at 3)", self.element),
            }));
        }
        #[expect(clippy::cast_possible_truncation, reason = "at most 3 bands")]
        let degree = bands.len() as u8;
        let k = sh_coeffs_per_channel(degree);
        let mut sh = Vec::with_capacity(n * k * 3);
        for i in 0..n {
            sh.extend_from_slice(&dc[3 * i..3 * i + 3]);
            for band in &bands {
                for coef in band {
                    sh.extend_from_slice(&coef[3 * i..3 * i + 3]);
                }
            }
        }
        let three = |v: &[f64], i: usize| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
        Ok(Raw {
            means: (0..n).map(|i| three(&pos, i)).collect(),
            rotations: rot
                .chunks_exact(4)
                .map(|q| [q[0], q[1], q[2], q[3]])
                .collect(),
            scales: (0..n).map(|i| three(&scale, i)).collect(),
            opacities: opacity,
            sh,
            degree,
        })
    }
}

/// The world transform's linear part and translation, checked to be decomposable.
fn node_transform(
    file: &GltfFile,
    element: &str,
    world: &glam::DMat4,
) -> Result<Option<(DMat3, DVec3)>, GltfSplatError> {
    if *world == glam::DMat4::IDENTITY {
        return Ok(None);
    }
    let m = DMat3::from_mat4(*world);
    let t = world.w_axis.truncate();
    let lengths = [m.x_axis.length(), m.y_axis.length(), m.z_axis.length()];
    let normalised = DMat3::from_cols(
        m.x_axis / lengths[0],
        m.y_axis / lengths[1],
        m.z_axis / lengths[2],
    );
    let ok = lengths.iter().all(|l| l.is_finite() && *l > 0.0)
        && t.is_finite()
        && (normalised.determinant() - 1.0).abs() < 1e-3;
    if !ok {
        return Err(GltfSplatError::Io(IoError::Unsupported {
            path: file.path().to_path_buf(),
            what: format!(
                "{element}: its node transform is not a translation, rotation and positive \
                 scale (splat rendering with it is undefined)"
            ),
        }));
    }
    Ok(Some((m, t)))
}

/// Reads every `KHR_gaussian_splatting` primitive of a glTF/GLB file into one world-space set.
///
/// # Errors
/// [`GltfSplatError::Io`] naming the primitive, attribute or accessor at fault (or the file,
/// when it has no splat primitive), [`GltfSplatError::Invalid`] naming the Gaussian.
pub fn read_gltf_gaussians(path: &Path) -> Result<GltfSplats, GltfSplatError> {
    let file = GltfFile::open(path)?;
    let mut parts = GaussianParts::default();
    let mut degree: Option<u8> = None;
    let mut color_space: Option<String> = None;
    let mut primitives = 0usize;
    let mut all_flat = true;
    for (mesh, world) in file.mesh_instances()? {
        let prims = file.json()["meshes"][mesh]["primitives"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        for (p, prim) in prims.iter().enumerate() {
            let Some(ext) = prim["extensions"].get(EXTENSION) else {
                continue;
            };
            let element = format!("mesh {mesh} primitive {p}");
            let malformed =
                |message: String| GltfSplatError::Io(IoError::malformed(path, &element, message));
            let mode = prim.get("mode").map_or(Some(4), Value::as_u64);
            if mode != Some(u64::from(POINTS)) {
                return Err(malformed(format!(
                    "{EXTENSION} needs mode POINTS (0), found {}",
                    prim.get("mode").unwrap_or(&json!(4))
                )));
            }
            match ext.get("kernel").and_then(Value::as_str) {
                Some("ellipse") => {}
                Some(other) => {
                    return Err(GltfSplatError::Io(IoError::Unsupported {
                        path: path.to_path_buf(),
                        what: format!("{element}: kernel {other:?} (only \"ellipse\" is read)"),
                    }));
                }
                None => return Err(malformed(format!("{EXTENSION} has no `kernel`"))),
            }
            let Some(space) = ext.get("colorSpace").and_then(Value::as_str) else {
                return Err(malformed(format!("{EXTENSION} has no `colorSpace`")));
            };
            color_space.get_or_insert_with(|| space.to_string());
            let Some(attributes) = prim["attributes"].as_object() else {
                return Err(malformed("no attributes".into()));
            };
            let reader = PrimitiveReader {
                file: &file,
                element: element.clone(),
                attributes,
            };
            let raw = reader.raw()?;
            match degree {
                None => degree = Some(raw.degree),
                Some(d) if d != raw.degree => {
                    return Err(malformed(format!(
                        "SH degree {} differs from the first splat primitive's {d}",
                        raw.degree
                    )));
                }
                Some(_) => {}
            }
            let first = parts.means.len();
            append(&mut parts, &raw, &element, path)?;
            if let Some((m, t)) = node_transform(&file, &element, &world)? {
                transform(&mut parts, first, raw.degree, m, t);
            }
            all_flat &= raw.scales.iter().all(|s| s[2] == 0.0);
            primitives += 1;
        }
    }
    if primitives == 0 {
        return Err(GltfSplatError::Io(IoError::malformed(
            path,
            "meshes",
            format!("no primitive of the scene has the {EXTENSION} extension"),
        )));
    }
    parts.sh_degree = degree.unwrap_or(0);
    if all_flat && !parts.means.is_empty() {
        parts.scale_dims = ScaleDims::Two;
        for l in &mut parts.log_scales {
            l.z = 0.0;
        }
    }
    let gaussians = GaussianSet::try_new(parts).map_err(|source| GltfSplatError::Invalid {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(GltfSplats {
        gaussians,
        color_space: color_space.unwrap_or_default(),
        primitives,
    })
}

/// Appends one primitive's Gaussians in our parameters.
#[expect(clippy::cast_possible_truncation, reason = "f32 storage of Gaussians")]
fn append(
    parts: &mut GaussianParts,
    raw: &Raw,
    element: &str,
    path: &Path,
) -> Result<(), GltfSplatError> {
    let bad = |i: usize, message: String| {
        GltfSplatError::Io(IoError::malformed(
            path,
            format!("{element} Gaussian {i}"),
            message,
        ))
    };
    let k3 = 3 * sh_coeffs_per_channel(raw.degree);
    let k = k3 / 3;
    for i in 0..raw.means.len() {
        let [x, y, z] = raw.means[i];
        parts.means.push(Vec3::new(x as f32, y as f32, z as f32));
        let s = raw.scales[i];
        if s.iter().any(|&v| v < 0.0) {
            return Err(bad(i, format!("negative scale {s:?}")));
        }
        let log = s.map(|v| {
            if v == 0.0 {
                ZERO_LOG_SCALE
            } else {
                v.ln() as f32
            }
        });
        parts.log_scales.push(Vec3::from(log));
        let [qx, qy, qz, qw] = raw.rotations[i];
        parts
            .rotations
            .push([qw as f32, qx as f32, qy as f32, qz as f32]);
        let o = raw.opacities[i];
        if !(0.0..=1.0).contains(&o) {
            return Err(bad(i, format!("opacity {o} is outside 0..1")));
        }
        parts.opacity_logits.push(if o == 0.0 {
            TRANSPARENT_LOGIT
        } else if o == 1.0 {
            OPAQUE_LOGIT
        } else {
            (o / (1.0 - o)).ln() as f32
        });
        // Ours: dc rgb, then channel-major rest.
        let g = &raw.sh[i * k3..(i + 1) * k3];
        let base = parts.sh.len();
        parts.sh.resize(base + k3, 0.0);
        let out = &mut parts.sh[base..];
        for c in 0..3 {
            out[c] = g[c] as f32;
            for j in 1..k {
                out[3 + c * (k - 1) + (j - 1)] = g[3 * j + c] as f32;
            }
        }
    }
    Ok(())
}

/// Applies a node transform (`p ↦ m p + t`) to the Gaussians from `first` on.
#[expect(clippy::cast_possible_truncation, reason = "f32 storage of Gaussians")]
fn transform(parts: &mut GaussianParts, first: usize, degree: u8, m: DMat3, t: DVec3) {
    // The rotation part of m: its polar factor U Vᵀ (for m = R S, R itself).
    let svd = nalgebra::Matrix3::from_column_slice(&m.to_cols_array()).svd(true, true);
    let rotation = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => DMat3::from_cols_slice((u * v_t).as_slice()),
        _ => DMat3::IDENTITY,
    };
    let change = (degree > 0).then(|| ShChange::new(degree, rotation));
    let k3 = 3 * sh_coeffs_per_channel(degree);
    for i in first..parts.means.len() {
        let p = m * parts.means[i].as_dvec3() + t;
        parts.means[i] = p.as_vec3();
        let q = normalize_wxyz(parts.rotations[i]).unwrap_or(DQuat::IDENTITY);
        let s = parts.log_scales[i].as_dvec3().exp();
        let axes = m * DMat3::from_quat(q) * DMat3::from_diagonal(s);
        let (r, sigma) = rotation_and_scales(axes);
        let out = quat_from_rotation(r);
        parts.rotations[i] = [out.w as f32, out.x as f32, out.y as f32, out.z as f32];
        parts.log_scales[i] = Vec3::from(sigma.to_array().map(|v| {
            if v > 0.0 {
                v.ln() as f32
            } else {
                ZERO_LOG_SCALE
            }
        }));
        if let Some(change) = &change {
            change.apply(&mut parts.sh[i * k3..(i + 1) * k3]);
        }
    }
}
