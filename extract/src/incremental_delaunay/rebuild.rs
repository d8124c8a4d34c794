//! Meshing the charts: the assignment from scratch at a rebuild, each Gaussian's anchor in its
//! chart, re-triangulating the charts Gaussians left or entered (with each chart's cache of
//! recent meshes), and placing the output vertices.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::spatial::TriangleBvh;

use super::certify::is_flat;
use super::chart::{ChartMesh, triangulate};
use super::error::DelaunayError;
use super::options::Lift;
use super::state::{Anchor, CACHED_MESHES, CachedChart, IncrementalDelaunay, SPARE_CAPACITY};
use super::stats::FrameStats;

/// Per triangle of the BVH: flat in the sense of [`FLAT_RATIO`](super::FLAT_RATIO) (see `certify::is_flat`).
pub(super) fn flat_triangles(bvh: &TriangleBvh) -> Vec<bool> {
    (0..bvh.triangle_count())
        .into_par_iter()
        .with_min_len(1024)
        .map(|t| bvh.corners(t).is_none_or(is_flat))
        .collect()
}

impl IncrementalDelaunay {
    pub(super) fn rebuild_now(
        &mut self,
        positions: &[DVec3],
        means: &[Vec3],
    ) -> Result<FrameStats, DelaunayError> {
        let bvh = TriangleBvh::from_triangles(positions, &self.triangles)?;
        self.flat = flat_triangles(&bvh);
        let seeds = &self.rest_nearest;
        self.assigned = means
            .par_iter()
            .zip(seeds.par_iter())
            .with_min_len(256)
            .map(|(m, &seed)| {
                let q = m.as_dvec3();
                let (d2, _) = bvh.distance_sq(q, seed);
                bvh.nearest_below(q, (d2, seed)).map_or(seed, |(_, t)| t)
            })
            .collect();
        self.anchors = (0..self.canonical.len())
            .into_par_iter()
            .with_min_len(256)
            .map(|i| self.anchor(i, self.assigned[i]))
            .collect();
        self.members = self.members_from_assignment();
        let all: Vec<u32> = (0..self.triangles.len() as u32).collect();
        self.charts = self.triangulate_charts(&all, &self.members);
        self.bvh = Some(bvh);
        // Certificates and cached chart meshes describe the previous state; the next update
        // makes new ones (and a run of rebuilds holds none).
        self.certified = false;
        self.states = Vec::new();
        self.previous = Vec::new();
        self.since_rebuild = 1;
        self.lift(positions, means);
        Ok(FrameStats {
            rebuilt: true,
            charts_redone: all.len(),
            searches: means.len(),
            ..FrameStats::default()
        })
    }

    /// Canonical placement of Gaussian `i` in chart `t`: barycentric weights of its canonical
    /// mean projected onto the rest triangle's plane (negative outside the triangle) and its
    /// signed distance from that plane; for a degenerate rest triangle, the weights of the
    /// nearest point and no offset.
    pub(super) fn anchor(&self, i: usize, t: u32) -> Anchor {
        let (Some(v), Some(p), Some(n)) = (
            self.rest_corners.get(t as usize),
            self.canonical.get(i),
            self.rest_normals.get(t as usize),
        ) else {
            return Anchor::default();
        };
        let degenerate = self.frames.get(t as usize).is_none_or(|f| f.degenerate);
        if !degenerate {
            let (e1, e2, d) = (v[1] - v[0], v[2] - v[0], *p - v[0]);
            let big_n = e1.cross(e2);
            let n2 = big_n.length_squared();
            let b1 = d.cross(e2).dot(big_n) / n2;
            let b2 = e1.cross(d).dot(big_n) / n2;
            let bary = [1.0 - b1 - b2, b1, b2];
            if bary.iter().all(|b| b.is_finite()) {
                return Anchor {
                    bary,
                    offset: d.dot(*n),
                };
            }
        }
        let (_, bary) = trisplat_geometry::spatial::closest_point_on_triangle(*p, v[0], v[1], v[2]);
        Anchor { bary, offset: 0.0 }
    }

    pub(super) fn members_from_assignment(&self) -> Vec<Vec<u32>> {
        // Allocated in chart order with a little room for Gaussians hopping in: the lists
        // then lie in memory roughly in the order the hop search reads them.
        let mut counts = vec![0usize; self.triangles.len()];
        for &t in &self.assigned {
            if let Some(c) = counts.get_mut(t as usize) {
                *c += 1;
            }
        }
        let mut members: Vec<Vec<u32>> = counts
            .into_iter()
            .map(|c| Vec::with_capacity(c + SPARE_CAPACITY))
            .collect();
        for (i, &t) in self.assigned.iter().enumerate() {
            if let Some(list) = members.get_mut(t as usize) {
                list.push(i as u32);
            }
        }
        members
    }

    pub(super) fn triangulate_charts(
        &self,
        charts: &[u32],
        members: &[Vec<u32>],
    ) -> Vec<ChartMesh> {
        charts
            .par_iter()
            .with_min_len(16)
            .map(|&t| self.triangulate_chart(t as usize, &members[t as usize]))
            .collect()
    }

    /// Triangulates chart `t` holding the Gaussians `list`.
    fn triangulate_chart(&self, t: usize, list: &[u32]) -> ChartMesh {
        let offset = self.vertex_count as u32;
        let members: Vec<(u32, [f64; 3])> = list
            .iter()
            .map(|&g| (offset + g, self.anchors[g as usize].bary))
            .collect();
        let margin = self.options.interior_margin;
        triangulate(&self.frames[t], self.triangles[t], &members, margin)
    }

    /// New meshes for the charts `dirty`, whose meshes were made from the member lists
    /// `before`. A chart's mesh depends only on its member list (canonical coordinates depend
    /// only on the Gaussian and the chart), so a chart whose list is back to what it was
    /// before one of its last changes (most hops at hop threshold 0 are a Gaussian near a tie going
    /// back) takes that mesh again instead of being triangulated.
    pub(super) fn remesh(&mut self, dirty: &[u32], before: Vec<Vec<u32>>) {
        self.previous.resize_with(self.charts.len(), Vec::new);
        let fresh: Vec<Result<usize, ChartMesh>> = dirty
            .par_iter()
            .with_min_len(16)
            .map(|&t| {
                let t = t as usize;
                let list = &self.members[t];
                match self.previous[t].iter().position(|p| p.members == *list) {
                    Some(slot) => Ok(slot),
                    None => Err(self.triangulate_chart(t, list)),
                }
            })
            .collect();
        for ((&t, members), fresh) in dirty.iter().zip(before).zip(fresh) {
            let t = t as usize;
            let cache = &mut self.previous[t];
            let mesh = match fresh {
                Ok(slot) => cache.remove(slot).mesh,
                Err(mesh) => mesh,
            };
            let old = std::mem::replace(&mut self.charts[t], mesh);
            // Most recent first; the oldest falls out.
            cache.insert(0, CachedChart { members, mesh: old });
            cache.truncate(CACHED_MESHES);
        }
    }

    pub(super) fn lift(&mut self, positions: &[DVec3], means: &[Vec3]) {
        let nv = self.vertex_count;
        self.vertices.resize(nv + means.len(), DVec3::ZERO);
        let (template, gaussians) = self.vertices.split_at_mut(nv);
        template.copy_from_slice(positions);
        match self.options.lift {
            Lift::Means => gaussians
                .par_iter_mut()
                .zip(means.par_iter())
                .with_min_len(4096)
                .for_each(|(out, m)| *out = m.as_dvec3()),
            Lift::Surface => {
                let tris = &self.triangles;
                gaussians
                    .par_iter_mut()
                    .zip(self.assigned.par_iter().zip(self.anchors.par_iter()))
                    .with_min_len(1024)
                    .for_each(|(out, (&t, anchor))| {
                        let v = tris[t as usize].map(|k| positions[k as usize]);
                        let p = v[0] * anchor.bary[0]
                            + v[1] * anchor.bary[1]
                            + v[2] * anchor.bary[2]
                            + unit_normal(v) * anchor.offset;
                        *out = p;
                    });
            }
        }
    }
}

/// Unit normal of a triangle (zero when it is degenerate).
pub(super) fn unit_normal(v: [DVec3; 3]) -> DVec3 {
    (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero()
}
