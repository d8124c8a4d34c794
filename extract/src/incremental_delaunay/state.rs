//! The state of an [`IncrementalDelaunay`] between frames: the mesher itself, each chart's
//! certificates and cached meshes, each Gaussian's place in its chart.

use glam::DVec3;
use trisplat_geometry::spatial::TriangleBvh;

use super::auto_rebuild::AutoRebuild;
use super::certify::{Certificate, Competitors, Snapshot};
use super::chart::{ChartFrame, ChartMesh};
use super::options::DelaunayOptions;

/// Meshes each chart keeps of the member lists it held before (see
/// `IncrementalDelaunay::remesh`).
pub(super) const CACHED_MESHES: usize = 3;

/// Room left in each chart's member and certificate lists for Gaussians hopping in, so that
/// they are rarely moved away from their neighbours in memory.
pub(super) const SPARE_CAPACITY: usize = 4;

/// A chart's certificate state.
#[derive(Clone, Debug, Default)]
pub(super) struct ChartState {
    /// Certificates of the chart's members, in the order of its member list.
    pub(super) certificates: Vec<Certificate>,
    /// Their competitors' side, in the same order.
    pub(super) competitors: Vec<Competitors>,
    /// The neighbourhood snapshot the certificates refer to.
    pub(super) snapshot: Option<Snapshot>,
}

impl ChartState {
    /// `len` members without certificates and no snapshot.
    pub(super) fn empty(len: usize) -> Self {
        let mut certificates = Vec::with_capacity(len + SPARE_CAPACITY);
        certificates.resize(len, Certificate::NONE);
        let mut competitors = Vec::with_capacity(len + SPARE_CAPACITY);
        competitors.resize(len, Competitors::NONE);
        Self {
            certificates,
            competitors,
            snapshot: None,
        }
    }

    /// Drops member `k`'s certificate (the member left the chart).
    pub(super) fn remove(&mut self, k: usize) {
        if k < self.certificates.len() {
            self.certificates.remove(k);
            self.competitors.remove(k);
        }
    }

    /// Makes room for a member without a certificate at `k` (a Gaussian hopped in).
    pub(super) fn insert_empty(&mut self, k: usize) {
        if k <= self.certificates.len() {
            self.certificates.insert(k, Certificate::NONE);
            self.competitors.insert(k, Competitors::NONE);
        }
    }

    /// Forgets every certificate (`len` members).
    pub(super) fn clear(&mut self, len: usize) {
        self.certificates.clear();
        self.certificates.resize(len, Certificate::NONE);
        self.competitors.clear();
        self.competitors.resize(len, Competitors::NONE);
    }
}

/// A chart mesh kept for when the chart holds the same Gaussians again.
#[derive(Clone, Debug)]
pub(super) struct CachedChart {
    /// The chart's members when the mesh was made.
    pub(super) members: Vec<u32>,
    pub(super) mesh: ChartMesh,
}

/// Per-Gaussian placement in its chart.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Anchor {
    /// Barycentric weights of the canonical mean's projection onto the rest chart triangle's
    /// plane (not shrunk; negative outside the triangle).
    pub(super) bary: [f64; 3],
    /// Signed distance of the canonical mean from that plane (along the unit normal).
    pub(super) offset: f64,
}

/// Incremental Delaunay mesh of bound Gaussians over an animated template (see the module
/// documentation).
#[derive(Debug)]
pub struct IncrementalDelaunay {
    pub(super) options: DelaunayOptions,
    pub(super) triangles: Vec<[u32; 3]>,
    pub(super) vertex_count: usize,
    pub(super) rest_corners: Vec<[DVec3; 3]>,
    pub(super) rest_normals: Vec<DVec3>,
    pub(super) frames: Vec<ChartFrame>,
    pub(super) canonical: Vec<DVec3>,
    /// Nearest rest triangle of each canonical mean (seeds the rebuild searches).
    pub(super) rest_nearest: Vec<u32>,
    /// Hop threshold in world units.
    pub(super) hop_distance: f64,
    /// Bounding-box diagonal of the rest template (margins of the motion filter).
    pub(super) diagonal: f64,
    // State after the last update.
    pub(super) assigned: Vec<u32>,
    pub(super) anchors: Vec<Anchor>,
    pub(super) members: Vec<Vec<u32>>,
    pub(super) charts: Vec<ChartMesh>,
    /// Per chart: its last [`CACHED_MESHES`] meshes before the current one, most recent
    /// first, with the member lists they were made from.
    pub(super) previous: Vec<Vec<CachedChart>>,
    /// The deformed template's triangles, refitted every frame, rebuilt with the charts.
    pub(super) bvh: Option<TriangleBvh>,
    /// Per triangle of the deformed template: flat in the sense of [`FLAT_RATIO`](super::FLAT_RATIO).
    pub(super) flat: Vec<bool>,
    pub(super) vertices: Vec<DVec3>,
    /// Per chart: its snapshot and its members' certificates (module `certify`), in the
    /// order of `members`; valid only while `certified`.
    pub(super) states: Vec<ChartState>,
    /// Whether `states` belong to the current state (false after a
    /// rebuild, which does not compute them: the next update does).
    pub(super) certified: bool,
    pub(super) updates: usize,
    pub(super) since_rebuild: usize,
    pub(super) auto: AutoRebuild,
}
