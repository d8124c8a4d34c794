//! The model's weights as a safetensors file beside the Gaussians' PLY
//! (`<name>.safetensors`; docs/conventions.md §5 "Neural appearance"): the 8-byte
//! little-endian header length, a JSON header (each tensor's dtype, shape and data offsets, and
//! string metadata), then the data. Written with the `safetensors` crate, atomically.
//!
//! Tensors: `aabb` (F64 [2, 3], the box's smallest and largest corners), `geometry_mlp.{0,1,2}`
//! and `color_mlp.{0,1,2}` `.weight` (F32 [outputs, inputs], PyTorch `nn.Linear`'s layout) and
//! `.bias` (F32 [outputs]), `hash_grid.level{l}` (F32 [rows, features]). Metadata: `format`
//! (`trisplat-neural-appearance`), `version` (`1`), `gaussians` (the PLY's count the weights
//! were fitted for) and the configuration's fields.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use trisplat_geometry::io::write_atomically;

use super::config::NeuralConfig;
use super::error::NeuralError;
use super::model::{Aabb, NeuralAppearance};

/// The `format` metadata value.
pub const FORMAT: &str = "trisplat-neural-appearance";
/// The `version` metadata value.
pub const VERSION: &str = "1";

/// `<name>.safetensors` beside `ply`.
#[must_use]
pub fn weights_path(ply: &Path) -> PathBuf {
    ply.with_extension("safetensors")
}

fn layer_name(k: usize) -> String {
    let mlp = if k < 3 { "geometry_mlp" } else { "color_mlp" };
    format!("{mlp}.{}", k % 3)
}

fn le_f32(v: impl Iterator<Item = f32>) -> Vec<u8> {
    v.flat_map(f32::to_le_bytes).collect()
}

/// Writes `model`, fitted for a set of `gaussians` Gaussians, to `path` (temporary file, then
/// rename: nothing half-written).
///
/// # Errors
/// [`NeuralError::File`] when serialising or writing fails.
pub fn write_weights(
    path: &Path,
    model: &NeuralAppearance<f32>,
    gaussians: usize,
) -> Result<(), NeuralError> {
    let c = model.config();
    let mut owned: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    let a = model.aabb();
    let aabb: Vec<u8> =
        a.lo.iter()
            .chain(&a.hi)
            .flat_map(|v| v.to_le_bytes())
            .collect();
    owned.push(("aabb".into(), Dtype::F64, vec![2, 3], aabb));
    let p = model.mlp();
    for (k, s) in model.slots().iter().enumerate() {
        // Stored input-major; the file has PyTorch's [outputs, inputs].
        let w = le_f32(
            (0..s.outputs)
                .flat_map(|o| (0..s.inputs).map(move |i| p[s.weights + i * s.outputs + o])),
        );
        owned.push((
            format!("{}.weight", layer_name(k)),
            Dtype::F32,
            vec![s.outputs, s.inputs],
            w,
        ));
        let b = le_f32(p[s.biases..s.biases + s.outputs].iter().copied());
        owned.push((
            format!("{}.bias", layer_name(k)),
            Dtype::F32,
            vec![s.outputs],
            b,
        ));
    }
    let f = c.features_per_level;
    for (l, lv) in model.grid().levels().iter().enumerate() {
        let r = lv.offset as usize * f..(lv.offset + lv.rows) as usize * f;
        let t = le_f32(model.tables()[r].iter().copied());
        owned.push((
            format!("hash_grid.level{l}"),
            Dtype::F32,
            vec![lv.rows as usize, f],
            t,
        ));
    }
    let views = owned
        .iter()
        .map(|(name, dtype, shape, data)| {
            TensorView::new(*dtype, shape.clone(), data).map(|v| (name.clone(), v))
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| NeuralError::file(path, format!("cannot serialise: {e}")))?;
    let meta: HashMap<String, String> = [
        ("format", FORMAT.to_string()),
        ("version", VERSION.to_string()),
        ("gaussians", gaussians.to_string()),
        ("levels", c.levels.to_string()),
        ("features_per_level", c.features_per_level.to_string()),
        ("log2_table_size", c.log2_table_size.to_string()),
        ("base_resolution", c.base_resolution.to_string()),
        ("growth", c.growth.to_string()),
        ("hidden", c.hidden.to_string()),
        ("feature_width", c.feature_width.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    let bytes = safetensors::serialize(views, Some(meta))
        .map_err(|e| NeuralError::file(path, format!("cannot serialise: {e}")))?;
    write_atomically(path, |w| {
        w.write_all(&bytes)
            .map_err(|e| trisplat_geometry::io::IoError::os(path, e))
    })
    .map_err(|e| NeuralError::file(path, e.to_string()))
}

/// Reads the weights at `path` for a PLY of `gaussians` Gaussians.
///
/// # Errors
/// [`NeuralError::File`] naming `path`: unreadable, not safetensors, another format or version,
/// fitted for another Gaussian count, a configuration out of range, a tensor missing, extra, of
/// another dtype or shape, or a non-finite value.
pub fn read_weights(path: &Path, gaussians: usize) -> Result<NeuralAppearance<f32>, NeuralError> {
    let err = |m: String| NeuralError::file(path, m);
    let bytes = std::fs::read(path).map_err(|e| err(format!("cannot read: {e}")))?;
    let (_, header) = SafeTensors::read_metadata(&bytes)
        .map_err(|e| err(format!("not a safetensors file: {e:?}")))?;
    let st = SafeTensors::deserialize(&bytes)
        .map_err(|e| err(format!("not a safetensors file: {e:?}")))?;
    let meta = header
        .metadata()
        .clone()
        .ok_or_else(|| err("no metadata: not a trisplat neural appearance file".into()))?;
    let get = |k: &str| {
        meta.get(k)
            .ok_or_else(|| err(format!("metadata '{k}' missing")))
    };
    if get("format")? != FORMAT {
        return Err(err(format!(
            "format '{}', expected '{FORMAT}'",
            get("format")?
        )));
    }
    if get("version")? != VERSION {
        return Err(err(format!(
            "version '{}', expected '{VERSION}'",
            get("version")?
        )));
    }
    fn parse<V: std::str::FromStr>(
        meta: &HashMap<String, String>,
        k: &str,
        path: &Path,
    ) -> Result<V, NeuralError> {
        let v = meta
            .get(k)
            .ok_or_else(|| NeuralError::file(path, format!("metadata '{k}' missing")))?;
        v.parse()
            .map_err(|_| NeuralError::file(path, format!("metadata '{k}' = '{v}' is not a number")))
    }
    let fitted: usize = parse(&meta, "gaussians", path)?;
    if fitted != gaussians {
        return Err(err(format!(
            "the weights were fitted for {fitted} Gaussians, the PLY has {gaussians}"
        )));
    }
    let config = NeuralConfig {
        levels: parse(&meta, "levels", path)?,
        features_per_level: parse(&meta, "features_per_level", path)?,
        log2_table_size: parse(&meta, "log2_table_size", path)?,
        base_resolution: parse(&meta, "base_resolution", path)?,
        growth: parse(&meta, "growth", path)?,
        hidden: parse(&meta, "hidden", path)?,
        feature_width: parse(&meta, "feature_width", path)?,
    };
    config.check().map_err(|e| err(e.to_string()))?;
    let shell = NeuralAppearance::<f32>::from_parts(
        config,
        Aabb {
            lo: [0.0; 3],
            hi: [1.0; 3],
        },
        vec![0.0; super::config::mlp_layout(&config).1],
        vec![0.0; super::grid::HashGrid::new(&config).total_rows() * config.features_per_level],
    )?;
    let mut expected = vec![("aabb".to_string(), Dtype::F64, vec![2usize, 3])];
    for (k, s) in shell.slots().iter().enumerate() {
        expected.push((
            format!("{}.weight", layer_name(k)),
            Dtype::F32,
            vec![s.outputs, s.inputs],
        ));
        expected.push((
            format!("{}.bias", layer_name(k)),
            Dtype::F32,
            vec![s.outputs],
        ));
    }
    let f = config.features_per_level;
    for (l, lv) in shell.grid().levels().iter().enumerate() {
        expected.push((
            format!("hash_grid.level{l}"),
            Dtype::F32,
            vec![lv.rows as usize, f],
        ));
    }
    for name in st.names() {
        if !expected.iter().any(|(n, ..)| n == name) {
            return Err(err(format!("unexpected tensor '{name}'")));
        }
    }
    let mut data: HashMap<String, Vec<u8>> = HashMap::new();
    for (name, dtype, shape) in &expected {
        let t = st
            .tensor(name)
            .map_err(|_| err(format!("tensor '{name}' missing")))?;
        if t.dtype() != *dtype || t.shape() != shape.as_slice() {
            return Err(err(format!(
                "tensor '{name}' is {:?} {:?}, the configuration wants {dtype:?} {shape:?}",
                t.dtype(),
                t.shape()
            )));
        }
        data.insert(name.clone(), t.data().to_vec());
    }
    let f32s = |name: &str| -> Vec<f32> {
        data[name]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    };
    let aabb_v: Vec<f64> = data["aabb"]
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(std::array::from_fn(|k| b[k])))
        .collect();
    let aabb = Aabb {
        lo: [aabb_v[0], aabb_v[1], aabb_v[2]],
        hi: [aabb_v[3], aabb_v[4], aabb_v[5]],
    };
    if !(0..3).all(|a| aabb.lo[a] <= aabb.hi[a]) {
        return Err(err("'aabb': a smallest corner above the largest".into()));
    }
    let mut mlp = vec![0.0f32; shell.mlp().len()];
    for (k, s) in shell.slots().iter().enumerate() {
        let w = f32s(&format!("{}.weight", layer_name(k)));
        for o in 0..s.outputs {
            for i in 0..s.inputs {
                mlp[s.weights + i * s.outputs + o] = w[o * s.inputs + i];
            }
        }
        let b = f32s(&format!("{}.bias", layer_name(k)));
        mlp[s.biases..s.biases + s.outputs].copy_from_slice(&b);
    }
    let mut tables = Vec::with_capacity(shell.tables().len());
    for l in 0..config.levels {
        tables.extend(f32s(&format!("hash_grid.level{l}")));
    }
    NeuralAppearance::from_parts(config, aabb, mlp, tables).map_err(|e| err(e.to_string()))
}
