//! The public face of [`IncrementalDelaunay`]: construction from the rest template and the
//! canonical means, the accessors, and the per-frame [`IncrementalDelaunay::update`] that
//! chooses between an incremental step and a rebuild.

use std::time::Instant;

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::spatial::{MAX_COORDINATE, TriangleBvh};

use super::auto_rebuild::AutoRebuild;
use super::chart::ChartFrame;
use super::error::DelaunayError;
use super::options::DelaunayOptions;
use super::rebuild::unit_normal;
use super::state::IncrementalDelaunay;
use super::stats::FrameStats;

/// The first point that is not finite or exceeds [`MAX_COORDINATE`] is an error. Chunks are
/// scanned without early exit (a branch-free pass the compiler vectorises; rayon's
/// `position_first` per point cost more than the update it guards), and the offending index
/// is looked up only in the first bad chunk.
fn check_coordinates<P: Coordinates>(
    points: &[P],
    what: &'static str,
) -> Result<(), DelaunayError> {
    const CHUNK: usize = 4096;
    let bad = |p: &P| !p.within_limit();
    let chunk = points
        .par_chunks(CHUNK)
        .position_first(|c| c.iter().fold(false, |any, p| any | bad(p)));
    match chunk.and_then(|c| {
        let start = c * CHUNK;
        points[start..].iter().position(bad).map(|i| start + i)
    }) {
        Some(index) => Err(DelaunayError::BadCoordinate { what, index }),
        None => Ok(()),
    }
}

/// Points whose coordinates [`check_coordinates`] checks: template vertices (f64) and
/// Gaussian means (f32).
trait Coordinates: Sync {
    /// Finite and at most [`MAX_COORDINATE`] in magnitude (`max_element` skips NaN, hence the
    /// separate finiteness test).
    fn within_limit(&self) -> bool;
}

impl Coordinates for Vec3 {
    fn within_limit(&self) -> bool {
        self.is_finite() & (self.abs().max_element() <= MAX_COORDINATE)
    }
}

impl Coordinates for DVec3 {
    fn within_limit(&self) -> bool {
        self.is_finite() & (self.abs().max_element() <= f64::from(MAX_COORDINATE))
    }
}

impl IncrementalDelaunay {
    /// A mesher for `rest` (the canonical template) and Gaussians whose canonical means (their
    /// world-space means with the template at rest) are `canonical_means`. Nothing is meshed
    /// until the first [`IncrementalDelaunay::update`].
    ///
    /// # Errors
    /// [`DelaunayError::NoTriangles`], [`DelaunayError::BadTriangle`],
    /// [`DelaunayError::InvalidOption`], [`DelaunayError::BadCoordinate`],
    /// [`DelaunayError::TooMany`].
    pub fn new(
        rest: &TriMesh,
        canonical_means: &[Vec3],
        options: DelaunayOptions,
    ) -> Result<Self, DelaunayError> {
        let o = &options;
        if !(o.hop_threshold.is_finite() && o.hop_threshold >= 0.0) {
            return Err(DelaunayError::InvalidOption {
                name: "hop_threshold",
            });
        }
        if !(o.interior_margin > 0.0 && o.interior_margin < 1.0 / 3.0) {
            return Err(DelaunayError::InvalidOption {
                name: "interior_margin",
            });
        }
        if !(o.degenerate_tol.is_finite() && o.degenerate_tol >= 0.0) {
            return Err(DelaunayError::InvalidOption {
                name: "degenerate_tol",
            });
        }
        let positions = rest.positions();
        let triangles = rest.triangles().to_vec();
        if triangles.is_empty() {
            return Err(DelaunayError::NoTriangles);
        }
        let vertex_count = positions.len();
        for (triangle, t) in triangles.iter().enumerate() {
            if let Some(&vertex) = t.iter().find(|&&v| v as usize >= vertex_count) {
                return Err(DelaunayError::BadTriangle {
                    triangle,
                    vertex,
                    vertex_count,
                });
            }
        }
        let count = vertex_count + canonical_means.len();
        if u32::try_from(count).is_err() || u32::try_from(triangles.len()).is_err() {
            return Err(DelaunayError::TooMany { count });
        }
        check_coordinates(positions, "template vertex")?;
        check_coordinates(canonical_means, "canonical mean")?;
        let rest_corners: Vec<[DVec3; 3]> = triangles
            .par_iter()
            .map(|t| t.map(|v| positions[v as usize]))
            .collect();
        let frames = rest_corners
            .par_iter()
            .map(|&v| ChartFrame::new(v, o.degenerate_tol))
            .collect();
        let rest_normals = rest_corners.par_iter().map(|&v| unit_normal(v)).collect();
        let edge_sum: f64 = rest_corners
            .iter()
            .map(|v| (v[1] - v[0]).length() + (v[2] - v[1]).length() + (v[0] - v[2]).length())
            .sum();
        let mean_edge = edge_sum / (3 * triangles.len()) as f64;
        let diagonal = rest.bounds().map_or(0.0, |b| b.diagonal());
        let rest_bvh = TriangleBvh::from_triangles(positions, &triangles)?;
        let canonical: Vec<DVec3> = canonical_means.iter().map(|p| p.as_dvec3()).collect();
        let rest_nearest = canonical
            .par_iter()
            .with_min_len(256)
            .map(|&q| {
                rest_bvh
                    .nearest_below(q, (f64::INFINITY, u32::MAX))
                    .map_or(0, |(_, t)| t)
            })
            .collect();
        Ok(Self {
            options,
            triangles,
            vertex_count,
            rest_corners,
            rest_normals,
            frames,
            canonical,
            rest_nearest,
            hop_distance: o.hop_threshold * mean_edge,
            diagonal,
            assigned: Vec::new(),
            anchors: Vec::new(),
            members: Vec::new(),
            charts: Vec::new(),
            previous: Vec::new(),
            bvh: None,
            flat: Vec::new(),
            vertices: Vec::new(),
            states: Vec::new(),
            certified: false,
            updates: 0,
            since_rebuild: 0,
            auto: AutoRebuild::default(),
        })
    }

    /// The options.
    #[must_use]
    pub fn options(&self) -> &DelaunayOptions {
        &self.options
    }

    /// Number of Gaussians.
    #[must_use]
    pub fn gaussian_count(&self) -> usize {
        self.canonical.len()
    }

    /// Number of charts (template triangles).
    #[must_use]
    pub fn chart_count(&self) -> usize {
        self.triangles.len()
    }

    /// The chart (template triangle) of each Gaussian after the last update (empty before).
    #[must_use]
    pub fn assignment(&self) -> &[u32] {
        &self.assigned
    }

    /// Vertex positions after the last update: deformed template vertices, then one vertex per
    /// Gaussian (empty before the first update).
    #[must_use]
    pub fn vertices(&self) -> &[DVec3] {
        &self.vertices
    }

    /// The mesh's triangles after the last update, chart by chart.
    #[must_use]
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        let total = self.charts.iter().map(|c| c.triangles.len()).sum();
        let mut out = vec![[0u32; 3]; total];
        // One destination slice per chart, filled in parallel.
        let mut rest = out.as_mut_slice();
        let mut parts = Vec::with_capacity(self.charts.len());
        for c in &self.charts {
            let (head, tail) = rest.split_at_mut(c.triangles.len());
            parts.push(head);
            rest = tail;
        }
        parts
            .into_par_iter()
            .zip(self.charts.par_iter())
            .with_min_len(256)
            .for_each(|(dst, c)| dst.copy_from_slice(&c.triangles));
        out
    }

    /// The triangles of chart (template triangle) `t` after the last update; empty for a
    /// triangle that does not exist or before the first update.
    #[must_use]
    pub fn chart_triangles(&self, t: usize) -> &[[u32; 3]] {
        self.charts.get(t).map_or(&[], |c| c.triangles.as_slice())
    }

    /// The mesh after the last update (vertices and triangles as above).
    #[must_use]
    pub fn mesh(&self) -> TriMesh {
        // Vertices were checked finite and triangles index them.
        TriMesh::new_unchecked(self.vertices.clone(), self.triangles())
    }

    /// Triangulates every chart from scratch for the current assignment, without changing
    /// anything: the reference the incremental result must equal.
    #[must_use]
    pub fn triangulate_all(&self) -> Vec<[u32; 3]> {
        let members = self.members_from_assignment();
        let charts = self.triangulate_charts(
            &(0..self.triangles.len() as u32).collect::<Vec<_>>(),
            &members,
        );
        charts.into_iter().flat_map(|c| c.triangles).collect()
    }

    /// Moves to a new frame: `positions` are the deformed template vertices, `means` the
    /// deformed Gaussian means (e.g. from `trisplat_splat::Deformer::deform_geometry`). The first update, and
    /// every [`DelaunayOptions::rebuild_every`]-th, rebuilds from scratch; the others
    /// re-triangulate only the charts that Gaussians left or entered.
    ///
    /// # Errors
    /// [`DelaunayError::Count`] for arrays of the wrong length, [`DelaunayError::BadCoordinate`]
    /// for non-finite or huge coordinates; the state is unchanged then.
    pub fn update(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        let start = Instant::now();
        self.check_frame(positions, means)?;
        let period = self.options.rebuild_every;
        let scheduled = self.bvh.is_none() || (period > 0 && self.since_rebuild >= period);
        let automatic = self.options.auto_rebuild && self.auto.rebuilds_left > 0;
        let mut stats = if scheduled || automatic {
            if automatic {
                self.auto.rebuilds_left -= 1;
            }
            let stats = self.rebuild_now(positions, means)?;
            self.auto.rebuild_ms = start.elapsed().as_secs_f64() * 1e3;
            stats
        } else {
            // Judged only when the Gaussians came with certificates (not right after a
            // rebuild, which leaves none).
            let judged = self.certified;
            let stats = self.step(positions, means)?;
            if self.options.auto_rebuild && judged {
                let costly = self.auto.costly(
                    &stats,
                    start.elapsed().as_secs_f64() * 1e3,
                    self.options.hop_threshold == 0.0,
                    self.canonical.len(),
                    self.triangles.len(),
                );
                self.auto.judge(costly);
            }
            stats
        };
        stats.frame = self.updates;
        self.updates += 1;
        stats.unmeshed = self.charts.iter().map(|c| c.unmeshed as usize).sum();
        stats.millis = start.elapsed().as_secs_f64() * 1e3;
        Ok(stats)
    }

    /// Rebuilds from scratch at this frame (as the first update does), whatever the period.
    ///
    /// # Errors
    /// As [`IncrementalDelaunay::update`].
    pub fn rebuild(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        self.bvh = None;
        self.update(positions, means)
    }

    fn check_frame(&self, positions: &[DVec3], means: &[Vec3]) -> Result<(), DelaunayError> {
        if positions.len() != self.vertex_count {
            return Err(DelaunayError::Count {
                what: "deformed template",
                expected: self.vertex_count,
                got: positions.len(),
            });
        }
        if means.len() != self.canonical.len() {
            return Err(DelaunayError::Count {
                what: "deformed means",
                expected: self.canonical.len(),
                got: means.len(),
            });
        }
        check_coordinates(positions, "deformed vertex")?;
        check_coordinates(means, "deformed mean")
    }
}
