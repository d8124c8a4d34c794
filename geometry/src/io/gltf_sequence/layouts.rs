//! The two layouts built frame by frame: one mesh with a morph target per later frame, and one
//! node per run of frames of one topology (morph targets within a run). Quantised, each mesh
//! sits on a leaf node whose `translation`/`scale` undo its grid, under the node the
//! visibility track animates.

use std::cell::Cell;
use std::ops::Range;
use std::path::Path;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use serde_json::{Map, Value, json};

use super::basis::{BasisFit, BasisLimits};
use super::blocks::{byte_block, float_block, frame_name, short_block, unit_normals, vec3_block};
use super::builder::{Builder, Document, Primitive};
use super::options::{MorphBasis, SEQUENCE_NAME, SegmentSummary};
use super::pca::fit;
use super::quantize::{Grid, delta, normal_bytes, normal_delta_bytes};
use super::source::{FrameSource, surveyed_frame};
use crate::io::error::IoError;
use crate::io::gltf_codes::ARRAY_BUFFER;
use crate::mesh::TriMesh;

/// A run of frames of one topology and, quantised, its grid.
pub(super) struct Segment {
    /// Its frames.
    pub(super) frames: Range<usize>,
    /// Its vertices' bounding box over all its frames.
    pub(super) bounds: (DVec3, DVec3),
    /// The smallest bounding-box diagonal of one of its frames (the basis tolerance's unit).
    pub(super) diagonal: f64,
    /// Its frames' positions at every sketched vertex, as the survey kept them, for the first
    /// basis fit to take (empty: the fit reads the frames).
    pub(super) sketch: Cell<Vec<Vec<DVec3>>>,
}

/// What every segment's mesh is built with: the frames and their keys, the sequence's
/// diagonal (the grid's unit), whether targets carry normals, the morph basis asked for, and
/// where each segment's summary goes.
pub(super) struct Context<'a> {
    pub(super) path: &'a Path,
    pub(super) frames: &'a dyn FrameSource,
    pub(super) keys: &'a [f32],
    pub(super) diagonal: f64,
    pub(super) with_normals: bool,
    pub(super) basis: MorphBasis,
    /// Whether the basis is tried for this file (asked for, and its one-target-per-frame
    /// payload over [`MorphBasis::min_payload`]).
    pub(super) basis_applies: bool,
    pub(super) summaries: Vec<SegmentSummary>,
}

/// The morph targets of frames `run` against the base `primitive` of `base` (their topology
/// already checked): each frame's `POSITION` deltas (relative to the base as stored, so base +
/// delta is the frame: in `f32`, or on `grid`), and `NORMAL` deltas when `base_normals` is
/// given (the base's unit normals).
#[expect(clippy::too_many_arguments, reason = "one call site per layout")]
fn morph_targets(
    builder: &mut Builder<'_>,
    path: &Path,
    frames: &dyn FrameSource,
    base: &TriMesh,
    primitive: &Primitive,
    grid: Option<&Grid>,
    run: Range<usize>,
    base_normals: Option<&[Vec3]>,
) -> Result<Vec<Value>, IoError> {
    let mut targets = Vec::with_capacity(run.len());
    for k in run {
        // The survey saw the base's count: a compressed file is written in one pass, with no
        // second reading to compare.
        let frame = surveyed_frame(path, frames, k, base.vertex_count())?;
        let mut target = Map::new();
        let positions = match (grid, &primitive.steps) {
            (Some(grid), Some(base_steps)) => {
                let steps = grid.quantize(path, k, frame.positions())?;
                builder.push(short_block(&delta(base_steps, &steps)))?
            }
            _ => builder.push(float_block(
                &float_deltas(path, k, frame.positions(), base.positions())?,
                3,
                Some(ARRAY_BUFFER),
                true,
            ))?,
        };
        target.insert("POSITION".into(), json!(positions));
        if let (Some(n0), Some(nk)) = (base_normals, frame.normals()) {
            let unit = unit_normals(nk);
            let normals = match &primitive.normal_bytes {
                Some(b0) => {
                    builder.push(byte_block(&normal_delta_bytes(b0, &normal_bytes(&unit))))?
                }
                None => {
                    let d: Vec<Vec3> = unit.iter().zip(n0).map(|(a, b)| *a - *b).collect();
                    builder.push(vec3_block(&d, Some(ARRAY_BUFFER), false))?
                }
            };
            target.insert("NORMAL".into(), json!(normals));
        }
        targets.push(Value::Object(target));
    }
    Ok(targets)
}

/// Frame `k`'s `f32` offsets from `base` as stored in `f32`.
fn float_deltas(
    path: &Path,
    k: usize,
    positions: &[DVec3],
    base: &[DVec3],
) -> Result<Vec<f32>, IoError> {
    let flat: Vec<f32> = positions
        .par_iter()
        .zip(base)
        .flat_map_iter(|(p, q)| {
            (0..3).map(move |c| {
                #[expect(
                    clippy::cast_possible_truncation,
                    reason = "f32 storage; overflow is checked below"
                )]
                let d = (p[c] - f64::from(q[c] as f32)) as f32;
                d
            })
        })
        .collect();
    if let Some(i) = flat.iter().position(|d| !d.is_finite()) {
        return Err(IoError::malformed(
            path,
            format!("frame {k} vertex {}", i / 3),
            "the offset from its base frame overflows f32",
        ));
    }
    Ok(flat)
}

/// Gives `mesh` (whose primitive is `primitive`) the morph targets of frames `first + 1..`
/// (`targets` of them), named by frame; returns the STEP weights of keys `first..`: all 0 at
/// the first, then target `j - 1` alone at weight 1 at key `first + j`.
fn with_targets(
    mesh: &mut Value,
    primitive: &mut Value,
    targets: Vec<Value>,
    first: usize,
) -> Vec<f32> {
    let n = targets.len();
    primitive["targets"] = json!(targets);
    mesh["weights"] = json!(vec![0.0f32; n]);
    mesh["extras"] =
        json!({"targetNames": (first + 1..=first + n).map(frame_name).collect::<Vec<_>>()});
    let mut weights = vec![0.0f32; (n + 1) * n];
    for j in 1..=n {
        weights[j * n + (j - 1)] = 1.0;
    }
    weights
}

/// A segment's mesh: its index, the STEP weights of its frames' keys when it has morph
/// targets, and the grid it is quantised on.
struct SegmentMesh {
    mesh: usize,
    weights: Option<Vec<f32>>,
    grid: Option<Grid>,
}

/// Gives `mesh` (whose primitive is `primitive`) the basis vectors of `fit` as morph targets
/// (named `basis_000`, ...); returns the STEP weights of its frames' keys (the fit's).
fn with_basis(
    mesh: &mut Value,
    primitive: &mut Value,
    targets: Vec<Value>,
    fit: BasisFit,
) -> Vec<f32> {
    let n = targets.len();
    primitive["targets"] = json!(targets);
    mesh["weights"] = json!(vec![0.0f32; n]);
    mesh["extras"] =
        json!({"targetNames": (0..n).map(|i| format!("basis_{i:03}")).collect::<Vec<_>>()});
    fit.weights
}

/// Fits a morph basis to `segment` when `ctx` asks for one and it can hold the run (quantised,
/// three frames or more, no normal targets): its base (on the finer basis grid) and the fit,
/// or `None` (one target per frame).
fn try_basis(
    ctx: &Context<'_>,
    segment: &Segment,
    base: &TriMesh,
    quantized: bool,
) -> Result<Option<(Grid, BasisFit)>, IoError> {
    let run = segment.frames.clone();
    if !(quantized && ctx.basis_applies && run.len() >= 3 && !ctx.with_normals) {
        return Ok(None);
    }
    let grid = Grid::for_basis(segment.bounds, ctx.diagonal);
    let tolerance = ctx.basis.tolerance * segment.diagonal / grid.step();
    if !(tolerance.is_finite() && tolerance > 0.0) {
        return Ok(None);
    }
    let steps = grid.quantize(ctx.path, run.start, base.positions())?;
    let limits = BasisLimits {
        tolerance,
        max_vectors: ctx.basis.max_components.min(run.len() - 2),
    };
    let sampled = segment.sketch.take();
    Ok(fit(ctx.path, ctx.frames, run, &grid, &steps, sampled, limits)?.map(|f| (grid, f)))
}

/// The mesh of `segment` (its first frame; morph targets for the others when it has more
/// than one: a basis when [`try_basis`] gives one, else one target per frame), appended to
/// `meshes`, its summary to `ctx.summaries`; `None` when its first frame has no triangles (no
/// mesh). `shared` is the index accessor of the last mesh, reused when the triangles repeat
/// (updated here).
fn segment_mesh(
    builder: &mut Builder<'_>,
    ctx: &mut Context<'_>,
    segment: &Segment,
    meshes: &mut Vec<Value>,
    shared: &mut Option<(Vec<[u32; 3]>, usize)>,
) -> Result<Option<SegmentMesh>, IoError> {
    let run = segment.frames.clone();
    let path = ctx.path;
    let frames = ctx.frames;
    let base = frames.frame(run.start)?;
    let quantized = builder.compression().quantizes();
    let mut summary = SegmentSummary {
        frames: run.clone(),
        basis: None,
        max_error: 0.0,
        frame_errors: vec![0.0; run.len()],
        diagonal: segment.diagonal,
    };
    if base.triangle_count() == 0 {
        ctx.summaries.push(summary);
        return Ok(None);
    }
    let basis = try_basis(ctx, segment, &base, quantized)?;
    let grid = match &basis {
        Some((grid, _)) => Some(*grid),
        None => quantized.then(|| Grid::new(segment.bounds, ctx.diagonal)),
    };
    let reuse = shared
        .as_ref()
        .filter(|(triangles, _)| triangles.as_slice() == base.triangles())
        .map(|(_, accessor)| *accessor);
    // A one-frame segment keeps its normals; a longer one only when every frame has them
    // (its targets carry their deltas).
    let normals = run.len() == 1 || ctx.with_normals;
    let mut primitive = builder.primitive(&base, run.start, normals, grid.as_ref(), reuse)?;
    if reuse.is_none() {
        *shared = Some((base.triangles().to_vec(), primitive.indices));
    }
    let mut mesh = json!({"name": frame_name(run.start)});
    let mut weights = None;
    if let Some((grid, fit)) = basis {
        let targets = fit
            .vectors
            .iter()
            .map(|v| Ok(json!({"POSITION": builder.push(short_block(v))?})))
            .collect::<Result<Vec<_>, IoError>>()?;
        summary.basis = Some(targets.len());
        summary.frame_errors = fit.errors.iter().map(|e| e * grid.step()).collect();
        weights = Some(with_basis(&mut mesh, &mut primitive.json, targets, fit));
    } else if run.len() > 1 {
        let base_normals = if ctx.with_normals {
            base.normals().map(unit_normals)
        } else {
            None
        };
        let targets = morph_targets(
            builder,
            path,
            frames,
            &base,
            &primitive,
            grid.as_ref(),
            run.start + 1..run.end,
            base_normals.as_deref(),
        )?;
        weights = Some(with_targets(
            &mut mesh,
            &mut primitive.json,
            targets,
            run.start,
        ));
    }
    if summary.basis.is_none()
        && let Some(grid) = &grid
    {
        // Every position rounded to the grid: at most half a step per axis.
        let bound = 3f64.sqrt() / 2.0 * grid.step();
        summary.frame_errors = vec![bound; run.len()];
    }
    summary.max_error = summary.frame_errors.iter().copied().fold(0.0, f64::max);
    ctx.summaries.push(summary);
    mesh["primitives"] = json!([primitive.json]);
    meshes.push(mesh);
    Ok(Some(SegmentMesh {
        mesh: meshes.len() - 1,
        weights,
        grid,
    }))
}

/// The leaf node that holds mesh `mesh` quantised on `grid`, named after its parent.
fn leaf(name: &str, mesh: usize, grid: &Grid) -> Value {
    let s = grid.scale();
    json!({"name": format!("{name}_mesh"), "mesh": mesh, "translation": grid.translation(),
        "scale": [s, s, s]})
}

/// The morph-target layout (topology already checked), frame by frame.
pub(super) fn build_morph_targets(
    ctx: &mut Context<'_>,
    segment: &Segment,
    builder: Builder<'_>,
) -> Result<Document, IoError> {
    let mut builder = builder;
    let mut meshes = Vec::with_capacity(1);
    let built =
        segment_mesh(&mut builder, ctx, segment, &mut meshes, &mut None)?.ok_or_else(|| {
            IoError::malformed(
                ctx.path,
                "frame 0",
                "has no triangles (morph targets need a base mesh)",
            )
        })?;
    meshes[built.mesh]["name"] = json!(SEQUENCE_NAME);
    // Quantised, the mesh (and its weights track) is on leaf node 1 under node 0.
    let mut nodes = vec![json!({"name": SEQUENCE_NAME})];
    let mesh_node = match &built.grid {
        Some(grid) => {
            nodes[0]["children"] = json!([1]);
            nodes.push(leaf(SEQUENCE_NAME, built.mesh, grid));
            1
        }
        None => {
            nodes[0]["mesh"] = json!(built.mesh);
            0
        }
    };
    let keys = ctx.keys;
    let (sampler, channel) = match built.weights {
        None => (
            builder.sampler(keys, &[1.0; 3], 3)?,
            json!({"sampler": 0, "target": {"node": 0, "path": "scale"}}),
        ),
        Some(weights) => (
            builder.sampler(keys, &weights, 1)?,
            json!({"sampler": 0, "target": {"node": mesh_node, "path": "weights"}}),
        ),
    };
    Ok(builder.document(nodes, meshes, vec![sampler], vec![channel]))
}

/// The node-per-segment layout (one node per frame when every segment is one frame), segment
/// by segment.
pub(super) fn build_segments(
    ctx: &mut Context<'_>,
    segments: &[Segment],
    builder: Builder<'_>,
) -> Result<Document, IoError> {
    let mut builder = builder;
    let keys = ctx.keys;
    let mut nodes =
        vec![json!({"name": SEQUENCE_NAME, "children": (1..=segments.len()).collect::<Vec<_>>()})];
    let mut leaves = Vec::new();
    let mut meshes = Vec::new();
    let mut samplers = Vec::with_capacity(segments.len());
    let mut channels = Vec::with_capacity(segments.len());
    // The index accessor of the last segment with a mesh, shared while the triangles repeat.
    let mut shared: Option<(Vec<[u32; 3]>, usize)> = None;
    for (s, segment) in segments.iter().enumerate() {
        let run = segment.frames.clone();
        let name = frame_name(run.start);
        let mut node = json!({"name": name});
        let mut weights_node = None;
        let mut weights = None;
        if let Some(built) = segment_mesh(&mut builder, ctx, segment, &mut meshes, &mut shared)? {
            weights = built.weights;
            match &built.grid {
                Some(grid) => {
                    let index = segments.len() + 1 + leaves.len();
                    node["children"] = json!([index]);
                    leaves.push(leaf(&name, built.mesh, grid));
                    weights_node = Some(index);
                }
                None => {
                    node["mesh"] = json!(built.mesh);
                    weights_node = Some(s + 1);
                }
            }
        }
        let shown = if s == 0 { 1.0f32 } else { 0.0 };
        node["scale"] = json!([shown, shown, shown]);
        nodes.push(node);
        // Visible (1) from its first key to the next segment's, hidden (0) elsewhere.
        let mut times = Vec::with_capacity(3);
        let mut scales: Vec<f32> = Vec::with_capacity(9);
        if run.start > 0 {
            times.push(keys[0]);
            scales.extend([0.0; 3]);
        }
        times.push(keys[run.start]);
        scales.extend([1.0; 3]);
        if let Some(&next) = keys.get(run.end) {
            times.push(next);
            scales.extend([0.0; 3]);
        }
        samplers.push(builder.sampler(&times, &scales, 3)?);
        channels.push(
            json!({"sampler": samplers.len() - 1, "target": {"node": s + 1, "path": "scale"}}),
        );
        if let (Some(weights), Some(target)) = (weights, weights_node) {
            samplers.push(builder.sampler(&keys[run.clone()], &weights, 1)?);
            channels.push(
                json!({"sampler": samplers.len() - 1, "target": {"node": target, "path": "weights"}}),
            );
        }
    }
    nodes.extend(leaves);
    Ok(builder.document(nodes, meshes, samplers, channels))
}
