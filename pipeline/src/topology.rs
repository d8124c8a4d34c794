//! One method's meshes through a track (`--topology`): meshed every frame, or a key mesh
//! carried by the template ([`crate::carry`]) and, `adaptive`, meshed again where it drifts.
//!
//! Whatever a carrier decides is a function of the whole track: the first key is the track's
//! first frame, and `adaptive` decides its keys frame by frame from there. A run that starts
//! elsewhere (a shard, `--frames`, `--resume`) first replays the frames before its own
//! ([`Carrier::history`]), meshing only at keys, so any split gives the same meshes.

use std::collections::BTreeMap;
use std::ops::Range;
use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Vec3};

use crate::carry::{CarriedMesh, Drift};
use crate::config::{Method, Topology, TopologyOptions};
use crate::error::PipelineError;
use crate::finish::Finish;
use crate::methods::{FrameInput, Mesher, MethodOutput};
use crate::records::TopologyFrame;

/// What every carrier of a run shares: the options and the template's and Gaussians'
/// bindings.
#[derive(Clone, Copy, Debug)]
pub struct CarryContext<'a> {
    /// `--topology` and its thresholds.
    pub options: &'a TopologyOptions,
    /// The (welded) template's triangles, which `FrameInput::positions` are the corners of.
    pub triangles: &'a [[u32; 3]],
    /// Each Gaussian's template triangle.
    pub gaussian_triangles: &'a [u32],
    /// Every Gaussian's deformed mean this frame (local, as the positions).
    pub all_means: &'a [Vec3],
    /// The mean template edge: the unit of `--hop-distance`, and how near the key mesh a
    /// Gaussian must be to probe it.
    pub mean_edge: f64,
    /// What is done to each mesh made (decimation, colours): before a key is bound.
    pub finish: &'a Finish,
}

/// One method's topology state.
#[derive(Debug)]
pub struct Carrier {
    topology: Topology,
    /// The current key frame and its mesh bound to the template.
    key: Option<(usize, Arc<CarriedMesh>)>,
    /// The frame this carrier saw last.
    last: Option<usize>,
    /// The track's first key (frame 0's mesh) bound, kept for the rig (module `rig`).
    first: Option<Arc<CarriedMesh>>,
    /// Every key made since [`Carrier::keep_keys`], by key frame (`None`: not kept).
    kept: Option<BTreeMap<usize, Arc<CarriedMesh>>>,
}

impl Carrier {
    /// A carrier of `topology` that has seen no frame.
    #[must_use]
    pub fn new(topology: Topology) -> Self {
        Self {
            topology,
            key: None,
            last: None,
            first: None,
            kept: None,
        }
    }

    /// Keeps every key this carrier makes from now on (replaying or not), so that a carried
    /// frame can be placed again later (module `carried_frames`).
    pub fn keep_keys(&mut self) {
        self.kept.get_or_insert_with(BTreeMap::new);
    }

    /// The keys kept since [`Carrier::keep_keys`], by key frame.
    #[must_use]
    pub fn kept_keys(&self) -> Option<&BTreeMap<usize, Arc<CarriedMesh>>> {
        self.kept.as_ref()
    }

    /// `carried` becomes the key of `frame` (and is kept when keys are).
    fn set_key(&mut self, frame: usize, carried: CarriedMesh) {
        let carried = Arc::new(carried);
        if let Some(kept) = &mut self.kept {
            kept.insert(frame, Arc::clone(&carried));
        }
        self.key = Some((frame, carried));
    }

    /// The track's first key mesh bound to the template, once this carrier has made it.
    #[must_use]
    pub fn first_key(&self) -> Option<&CarriedMesh> {
        self.first.as_deref()
    }

    /// The frames this carrier must see (in order, [`Carrier::frame`] with `replay`) before
    /// it can give `frame`: none per frame; the track's first frame (the key) for `fixed`;
    /// for `adaptive` every frame since the last it saw, or since the track's first.
    #[must_use]
    pub fn history(&self, frame: usize) -> Range<usize> {
        match self.topology {
            Topology::PerFrame => frame..frame,
            Topology::Fixed if self.key.is_some() || frame == 0 => frame..frame,
            Topology::Fixed => 0..1,
            Topology::Adaptive => match self.last {
                Some(l) if l < frame => l + 1..frame,
                _ => 0..frame,
            },
        }
    }

    /// The mesh of `input.frame`: meshed by `mesher`, or the key mesh carried. `replay`:
    /// the frame is only seen to decide keys (no mesh is returned unless one was made).
    ///
    /// # Errors
    /// The mesher's; a key that cannot be bound ([`PipelineError::Carry`]).
    pub fn frame(
        &mut self,
        method: Method,
        mesher: &mut Mesher,
        input: &FrameInput<'_>,
        context: &CarryContext<'_>,
        replay: bool,
    ) -> Result<Option<(MethodOutput, Option<TopologyFrame>)>, PipelineError> {
        let frame = input.frame;
        if matches!(self.last, Some(l) if l >= frame) && self.topology == Topology::Adaptive {
            // Going back (a frame asked again): start over from the track's first key.
            self.key = None;
        }
        self.last = Some(frame);
        if self.topology == Topology::PerFrame {
            return Ok((!replay)
                .then(|| mesh(method, mesher, input, context))
                .transpose()?
                .map(|o| (o, None)));
        }
        let start = Instant::now();
        let Some((key, carried)) = &self.key else {
            // The track's first key.
            let output = mesh(method, mesher, input, context)?;
            let carried = bind(method, frame, &output, input, context)?;
            let record = TopologyFrame {
                key: frame,
                hops: 0.0,
                stretched: 0.0,
                offset: 0.0,
                moved: 0.0,
                farthest: Some(carried.farthest()),
            };
            self.set_key(frame, carried);
            self.first = self.key.as_ref().map(|(_, k)| Arc::clone(k));
            return Ok(Some((output, Some(record))));
        };
        let key = *key;
        if replay && self.topology == Topology::Fixed {
            return Ok(None);
        }
        let mut vertices = Vec::new();
        carried.place(input.positions, context.triangles, &mut vertices);
        let tolerance = context.options.hop_distance * context.mean_edge;
        let drift = carried.drift(&vertices, input.means, tolerance);
        if self.topology == Topology::Adaptive && drifted(method, &drift, context) {
            let output = mesh(method, mesher, input, context)?;
            let carried = bind(method, frame, &output, input, context)?;
            let record = TopologyFrame {
                farthest: Some(carried.farthest()),
                ..record(frame, drift)
            };
            self.set_key(frame, carried);
            return Ok(Some((output, Some(record))));
        }
        if replay {
            return Ok(None);
        }
        let mesh = carried
            .mesh(vertices)
            .map_err(|cause| PipelineError::Carry {
                frame,
                method,
                key,
                cause,
            })?;
        let output = MethodOutput {
            mesh,
            ms: start.elapsed().as_secs_f64() * 1e3,
            render_ms: None,
            delaunay: None,
            simplify: None,
        };
        Ok(Some((output, Some(record(key, drift)))))
    }
}

/// `mesher`'s mesh of `input`, finished (decimated, coloured) as the run asks.
fn mesh(
    method: Method,
    mesher: &mut Mesher,
    input: &FrameInput<'_>,
    context: &CarryContext<'_>,
) -> Result<MethodOutput, PipelineError> {
    let mut output = mesher.mesh(input)?;
    context.finish.apply(method, &mut output, input)?;
    Ok(output)
}

/// Whether a frame carried with `drift` starts a new key (`adaptive`): too many probes hop,
/// too much area stretches, the probes' distances to the carried mesh changed too much on
/// average, or (tsdf, which samples a grid and a rig fixed in space, with `--key-motion`) they
/// moved too far.
fn drifted(method: Method, drift: &Drift, context: &CarryContext<'_>) -> bool {
    let o = context.options;
    drift.hops > o.key_hops
        || drift.stretched > o.key_stretch
        || drift.offset > o.key_offset * context.mean_edge
        || (method == Method::Tsdf
            && o.key_motion
                .is_some_and(|m| drift.moved > m * context.mean_edge))
}

/// The record of a frame carried from `key` with `drift`.
fn record(key: usize, drift: Drift) -> TopologyFrame {
    TopologyFrame {
        key,
        hops: drift.hops,
        stretched: drift.stretched,
        offset: drift.offset,
        moved: drift.moved,
        farthest: None,
    }
}

/// `output`'s mesh (of key frame `frame`) bound to the template of `input`.
fn bind(
    method: Method,
    frame: usize,
    output: &MethodOutput,
    input: &FrameInput<'_>,
    context: &CarryContext<'_>,
) -> Result<CarriedMesh, PipelineError> {
    CarriedMesh::bind(
        output.mesh.clone(),
        input.positions,
        context.triangles,
        context.all_means,
        context.gaussian_triangles,
        input.means,
        context.mean_edge,
    )
    .map_err(|cause| PipelineError::Carry {
        frame,
        method,
        key: frame,
        cause,
    })
}

/// The mean edge length of `triangles` over `positions` (each edge of each triangle counted,
/// as the Delaunay hop threshold's unit); 0 without triangles.
#[must_use]
pub fn mean_edge(positions: &[DVec3], triangles: &[[u32; 3]]) -> f64 {
    let (sum, n) = triangles.iter().fold((0.0, 0usize), |(s, n), t| {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        (
            s + (b - a).length() + (c - b).length() + (a - c).length(),
            n + 3,
        )
    });
    if n > 0 { sum / n as f64 } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_signal_starts_a_key_past_its_threshold_and_motion_only_for_tsdf() {
        let mut options = TopologyOptions::default();
        let finish = Finish::default();
        let still = Drift::default();
        let past = |f: fn(&mut Drift, f64), limit: f64| {
            let (mut below, mut above) = (still, still);
            f(&mut below, limit * 0.99);
            f(&mut above, limit * 1.01);
            (below, above)
        };
        let cases = [
            past(|d, v| d.hops = v, options.key_hops),
            past(|d, v| d.stretched = v, options.key_stretch),
            past(|d, v| d.offset = v, options.key_offset * 2.0),
        ];
        let (slow, fast) = past(|d, v| d.moved = v, 0.3 * 2.0);
        for motion in [None, Some(0.3)] {
            options.key_motion = motion;
            let context = CarryContext {
                options: &options,
                triangles: &[],
                gaussian_triangles: &[],
                all_means: &[],
                mean_edge: 2.0,
                finish: &finish,
            };
            for method in [Method::Tsdf, Method::Delaunay, Method::Alpha] {
                assert!(!drifted(method, &still, &context));
                for (below, above) in cases {
                    assert!(!drifted(method, &below, &context), "{method}: {below:?}");
                    assert!(drifted(method, &above, &context), "{method}: {above:?}");
                }
                assert!(!drifted(method, &slow, &context), "{method} {motion:?}");
                let tsdf_with_motion = method == Method::Tsdf && motion.is_some();
                assert_eq!(
                    drifted(method, &fast, &context),
                    tsdf_with_motion,
                    "{method}"
                );
            }
        }
    }
}
