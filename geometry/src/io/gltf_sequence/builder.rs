//! The buffer views and accessors of a sequence under construction, appended block by block to
//! a [`Sink`] (plain, or compressed with `EXT_meshopt_compression` over a fallback buffer), and
//! the document around them.

use std::path::Path;

use serde_json::{Map, Value, json};

use super::blocks::{
    Block, Bound, byte_block, float_block, index_block, short_block, unit_normals, vec3_block,
};
use super::codec::{encode, mode_name};
use super::options::{GltfCompression, SEQUENCE_NAME};
use super::quantize::{Grid, normal_bytes};
use super::sink::Sink;
use crate::io::error::IoError;
use crate::io::gltf_codes::{ARRAY_BUFFER, TRIANGLES};
use crate::mesh::TriMesh;

/// The name of the compression extension.
const MESHOPT: &str = "EXT_meshopt_compression";
/// The name of the quantisation extension.
const QUANTIZATION: &str = "KHR_mesh_quantization";

/// A buffer view of the document, kept compact until the JSON is written: a long sequence has
/// several per frame, and a `serde_json::Value` map each would grow the run's memory with its
/// length.
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
pub(super) struct ViewJson {
    buffer: u32,
    byte_offset: usize,
    byte_length: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    byte_stride: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    target: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    extensions: Option<MeshoptExtension>,
}

/// A view's `extensions` object with its `EXT_meshopt_compression` entry.
#[derive(serde::Serialize)]
struct MeshoptExtension {
    #[serde(rename = "EXT_meshopt_compression")]
    view: MeshoptView,
}

/// Where a view's compressed bytes are and how to decode them.
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
struct MeshoptView {
    buffer: u32,
    byte_offset: usize,
    byte_length: usize,
    byte_stride: usize,
    count: usize,
    mode: &'static str,
}

/// An accessor of the document (one per buffer view), compact as [`ViewJson`].
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
pub(super) struct AccessorJson {
    buffer_view: usize,
    component_type: u32,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    normalized: bool,
    count: usize,
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    min: Option<Bound>,
    #[serde(skip_serializing_if = "Option::is_none")]
    max: Option<Bound>,
}

/// A primitive as written, and what its morph targets are taken against.
pub(super) struct Primitive {
    /// The primitive's JSON.
    pub(super) json: Value,
    /// Its index accessor.
    pub(super) indices: usize,
    /// Quantised: its positions on the grid.
    pub(super) steps: Option<Vec<[i16; 3]>>,
    /// Quantised with normals: its normals as bytes.
    pub(super) normal_bytes: Option<Vec<[i8; 3]>>,
}

/// The buffer views and accessors under construction; the bytes go to a [`Sink`]. Views start
/// on 4-byte boundaries (of the fallback layout and of the compressed buffer alike).
pub(super) struct Builder<'s> {
    sink: &'s mut dyn Sink,
    path: &'s Path,
    compression: GltfCompression,
    /// Bytes of buffer 0 (the GLB chunk or the data URI).
    len: usize,
    /// `Meshopt`: bytes of the uncompressed layout (the fallback buffer, 1).
    fallback: usize,
    views: Vec<ViewJson>,
    accessors: Vec<AccessorJson>,
}

impl<'s> Builder<'s> {
    pub(super) fn new(
        sink: &'s mut dyn Sink,
        path: &'s Path,
        compression: GltfCompression,
    ) -> Self {
        Self {
            sink,
            path,
            compression,
            len: 0,
            fallback: 0,
            views: Vec::new(),
            accessors: Vec::new(),
        }
    }

    /// The storage the builder writes.
    pub(super) fn compression(&self) -> GltfCompression {
        self.compression
    }

    /// Pads buffer 0 to a multiple of 4 bytes.
    fn align(&mut self) -> Result<(), IoError> {
        let padding = (4 - self.len % 4) % 4;
        self.sink.put(&[0u8; 3][..padding])?;
        self.len += padding;
        Ok(())
    }

    /// Appends `block` as a buffer view and an accessor; returns the accessor index.
    pub(super) fn push(&mut self, block: Block) -> Result<usize, IoError> {
        self.align()?;
        let offset = self.len;
        let stride = block.declares_stride.then_some(block.stride);
        let view = if self.compression == GltfCompression::Meshopt {
            let element = format!("buffer view {}", self.views.len());
            let encoded = encode(self.path, &element, &block)?;
            self.sink.put(&encoded)?;
            self.len += encoded.len();
            let fallback_offset = self.fallback.next_multiple_of(4);
            self.fallback = fallback_offset + block.bytes.len();
            ViewJson {
                buffer: 1,
                byte_offset: fallback_offset,
                byte_length: block.bytes.len(),
                byte_stride: stride,
                target: block.target,
                extensions: Some(MeshoptExtension {
                    view: MeshoptView {
                        buffer: 0,
                        byte_offset: offset,
                        byte_length: encoded.len(),
                        byte_stride: block.stride,
                        count: block.bytes.len() / block.stride,
                        mode: mode_name(block.codec),
                    },
                }),
            }
        } else {
            self.sink.put(&block.bytes)?;
            self.len += block.bytes.len();
            ViewJson {
                buffer: 0,
                byte_offset: offset,
                byte_length: block.bytes.len(),
                byte_stride: stride,
                target: block.target,
                extensions: None,
            }
        };
        self.views.push(view);
        let (min, max) = block.bounds.unzip();
        self.accessors.push(AccessorJson {
            buffer_view: self.views.len() - 1,
            component_type: block.component_type,
            normalized: block.normalized,
            count: block.count,
            kind: block.kind,
            min,
            max,
        });
        Ok(self.accessors.len() - 1)
    }

    /// Appends the attributes of `mesh` (frame `k`; positions on `grid` when quantising) and
    /// its indices (unless `shared_indices` names an accessor holding the same triangles).
    pub(super) fn primitive(
        &mut self,
        mesh: &TriMesh,
        k: usize,
        with_normals: bool,
        grid: Option<&Grid>,
        shared_indices: Option<usize>,
    ) -> Result<Primitive, IoError> {
        let mut attributes = Map::new();
        let mut steps = None;
        let mut bytes = None;
        let position = match grid {
            Some(grid) => {
                let q = grid.quantize(self.path, k, mesh.positions())?;
                let accessor = self.push(short_block(&q))?;
                steps = Some(q);
                accessor
            }
            None => self.push(vec3_block(&mesh.positions_f32(), Some(ARRAY_BUFFER), true))?,
        };
        attributes.insert("POSITION".into(), json!(position));
        if with_normals && let Some(normals) = mesh.normals() {
            let unit = unit_normals(normals);
            let normal = if grid.is_some() {
                let b = normal_bytes(&unit);
                let accessor = self.push(byte_block(&b))?;
                bytes = Some(b);
                accessor
            } else {
                self.push(vec3_block(&unit, Some(ARRAY_BUFFER), false))?
            };
            attributes.insert("NORMAL".into(), json!(normal));
        }
        if let Some(uvs) = mesh.uvs() {
            let flat: Vec<f32> = uvs.iter().flat_map(|v| v.to_array()).collect();
            let uv = self.push(float_block(&flat, 2, Some(ARRAY_BUFFER), false))?;
            attributes.insert("TEXCOORD_0".into(), json!(uv));
        }
        if let Some(colors) = mesh.colors() {
            let flat: Vec<f32> = colors
                .iter()
                .flat_map(|c| c.map(|x| x.clamp(0.0, 1.0)))
                .collect();
            let color = self.push(float_block(&flat, 4, Some(ARRAY_BUFFER), false))?;
            attributes.insert("COLOR_0".into(), json!(color));
        }
        let indices = match shared_indices {
            Some(i) => i,
            None => self.push(index_block(
                mesh.triangles(),
                mesh.vertex_count(),
                self.compression.quantizes(),
            ))?,
        };
        Ok(Primitive {
            json: json!({"attributes": attributes, "indices": indices, "mode": TRIANGLES}),
            indices,
            steps,
            normal_bytes: bytes,
        })
    }

    /// Appends an animation sampler's key times and values; returns the sampler's JSON.
    pub(super) fn sampler(
        &mut self,
        keys: &[f32],
        values: &[f32],
        width: usize,
    ) -> Result<Value, IoError> {
        let input = self.push(float_block(keys, 1, None, true))?;
        let output = self.push(float_block(values, width, None, false))?;
        Ok(json!({"input": input, "output": output, "interpolation": "STEP"}))
    }

    /// The document around `nodes`, `meshes` and one animation.
    pub(super) fn document(
        self,
        nodes: Vec<Value>,
        meshes: Vec<Value>,
        samplers: Vec<Value>,
        channels: Vec<Value>,
    ) -> Document {
        let (extensions, buffers) = match self.compression {
            GltfCompression::None => (vec![], json!([{"byteLength": self.len}])),
            GltfCompression::Quantize => (vec![QUANTIZATION], json!([{"byteLength": self.len}])),
            // The fallback buffer has no data: the extension is required (its spec, "Fallback
            // buffers"); in a GLB it comes after the binary chunk's buffer 0.
            GltfCompression::Meshopt => (
                vec![MESHOPT, QUANTIZATION],
                json!([
                    {"byteLength": self.len},
                    {"byteLength": self.fallback, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}
                ]),
            ),
        };
        Document {
            asset: json!({"version": "2.0", "generator": "trisplat"}),
            extensions_used: extensions.clone(),
            extensions_required: extensions,
            scene: 0,
            scenes: json!([{"nodes": [0]}]),
            nodes,
            meshes,
            animations: json!([{"name": SEQUENCE_NAME, "samplers": samplers, "channels": channels}]),
            accessors: self.accessors,
            buffer_views: self.views,
            buffers,
        }
    }
}

/// The glTF JSON of a sequence, serialised straight from its parts: the accessors and buffer
/// views (several per frame) stay compact structs instead of becoming one `Value` tree.
#[derive(serde::Serialize)]
#[serde(rename_all = "camelCase")]
pub(super) struct Document {
    pub(super) asset: Value,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(super) extensions_used: Vec<&'static str>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(super) extensions_required: Vec<&'static str>,
    pub(super) scene: u32,
    pub(super) scenes: Value,
    pub(super) nodes: Vec<Value>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(super) meshes: Vec<Value>,
    pub(super) animations: Value,
    pub(super) accessors: Vec<AccessorJson>,
    pub(super) buffer_views: Vec<ViewJson>,
    pub(super) buffers: Value,
}
