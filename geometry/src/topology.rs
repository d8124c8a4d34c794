//! Connectivity of a triangle mesh: unique edges, edge-to-triangle incidence, 1-ring vertex
//! adjacency, boundary edges and edge-connected triangle clusters.

use std::collections::HashMap;

use rayon::slice::ParallelSliceMut;

use crate::mesh::TriMesh;

/// An undirected edge as a sorted vertex pair `(low, high)`.
pub type Edge = (u32, u32);

/// Sorted key of the edge between `a` and `b`.
#[inline]
#[must_use]
pub fn edge_key(a: u32, b: u32) -> Edge {
    if a < b { (a, b) } else { (b, a) }
}

/// The three undirected edges of a triangle, skipping edges whose ends coincide.
pub fn triangle_edges(tri: [u32; 3]) -> impl Iterator<Item = Edge> {
    let [a, b, c] = tri;
    [(a, b), (b, c), (c, a)]
        .into_iter()
        .filter(|(x, y)| x != y)
        .map(|(x, y)| edge_key(x, y))
}

/// For each undirected edge, the triangles that use it (in triangle order).
#[must_use]
pub fn edge_triangles(triangles: &[[u32; 3]]) -> HashMap<Edge, Vec<u32>> {
    let mut map: HashMap<Edge, Vec<u32>> = HashMap::with_capacity(triangles.len() * 3 / 2);
    for (t, &tri) in triangles.iter().enumerate() {
        for e in triangle_edges(tri) {
            let list = map.entry(e).or_default();
            // A triangle with a repeated edge (a, a, b style) must not count twice.
            if list.last() != Some(&(t as u32)) {
                list.push(t as u32);
            }
        }
    }
    map
}

/// Every use of an edge by a triangle as `(edge, triangle)`, sorted (so the triangles of one
/// edge are adjacent, in triangle order); a triangle that repeats an edge uses it once.
/// Sorting a flat list is several times faster than hashing edges on large meshes (a 640k-face
/// TSDF head).
#[must_use]
pub fn sorted_edge_uses(triangles: &[[u32; 3]]) -> Vec<(Edge, u32)> {
    let mut uses: Vec<(Edge, u32)> = triangles
        .iter()
        .enumerate()
        .flat_map(|(t, &tri)| triangle_edges(tri).map(move |e| (e, t as u32)))
        .collect();
    uses.par_sort_unstable();
    uses.dedup();
    uses
}

/// The edges of `uses` ([`sorted_edge_uses`]) with the number of triangles using each.
fn edge_counts(uses: &[(Edge, u32)]) -> impl Iterator<Item = (Edge, usize)> + '_ {
    uses.chunk_by(|a, b| a.0 == b.0)
        .map(|run| (run[0].0, run.len()))
}

/// Unique undirected edges, sorted.
#[must_use]
pub fn unique_edges(triangles: &[[u32; 3]]) -> Vec<Edge> {
    let mut edges: Vec<Edge> = triangles.iter().flat_map(|&t| triangle_edges(t)).collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// Edges used by exactly one triangle, sorted.
#[must_use]
pub fn boundary_edges(triangles: &[[u32; 3]]) -> Vec<Edge> {
    edge_counts(&sorted_edge_uses(triangles))
        .filter(|&(_, n)| n == 1)
        .map(|(e, _)| e)
        .collect()
}

/// Edges used by more than two triangles, sorted.
#[must_use]
pub fn non_manifold_edges(triangles: &[[u32; 3]]) -> Vec<Edge> {
    edge_counts(&sorted_edge_uses(triangles))
        .filter(|&(_, n)| n > 2)
        .map(|(e, _)| e)
        .collect()
}

/// 1-ring vertex adjacency in compressed sparse row form: the neighbours of vertex `v` are
/// Symmetric adjacency lists of `count` nodes from undirected `pairs`, in compressed form:
/// `(offsets, adjacent)` with node `v`'s neighbours at `adjacent[offsets[v]..offsets[v + 1]]`,
/// in the order of `pairs` (each pair adds `b` to `a`'s list and `a` to `b`'s).
///
/// # Panics
/// If a pair names a node `>= count`.
#[must_use]
pub fn adjacency_lists(count: usize, pairs: &[(u32, u32)]) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; count + 1];
    for &(a, b) in pairs {
        offsets[a as usize + 1] += 1;
        offsets[b as usize + 1] += 1;
    }
    for i in 1..offsets.len() {
        offsets[i] += offsets[i - 1];
    }
    let mut fill = offsets.clone();
    let mut adjacent = vec![0u32; pairs.len() * 2];
    for &(a, b) in pairs {
        adjacent[fill[a as usize] as usize] = b;
        fill[a as usize] += 1;
        adjacent[fill[b as usize] as usize] = a;
        fill[b as usize] += 1;
    }
    (offsets, adjacent)
}

/// `neighbors[offsets[v]..offsets[v + 1]]`, sorted and unique.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VertexAdjacency {
    offsets: Vec<u32>,
    neighbors: Vec<u32>,
}

impl VertexAdjacency {
    /// Builds the adjacency of `vertex_count` vertices from the triangles' edges.
    ///
    /// # Panics
    /// If a triangle index is `>= vertex_count` (a [`crate::TriMesh`] never has one).
    #[must_use]
    pub fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        let edges = unique_edges(triangles);
        let (offsets, mut neighbors) = adjacency_lists(vertex_count, &edges);
        for v in 0..vertex_count {
            neighbors[offsets[v] as usize..offsets[v + 1] as usize].sort_unstable();
        }
        Self { offsets, neighbors }
    }

    /// Neighbours of vertex `v`, sorted.
    #[inline]
    #[must_use]
    pub fn neighbors(&self, v: usize) -> &[u32] {
        &self.neighbors[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
}

/// Edge-connected triangle clusters, as Open3D's `cluster_connected_triangles`: two triangles
/// are in one cluster when they share an edge (sharing only a vertex does not connect them).
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleClusters {
    /// Cluster index of every triangle. Clusters are numbered by their first triangle.
    pub cluster_of: Vec<u32>,
    /// Number of triangles in each cluster.
    pub sizes: Vec<usize>,
    /// Surface area of each cluster (f64 sum).
    pub areas: Vec<f64>,
}

impl TriangleClusters {
    /// Labels the edge-connected clusters of `mesh`.
    #[must_use]
    pub fn of(mesh: &TriMesh) -> Self {
        let triangles = mesh.triangles();
        let (areas, mut parent) = rayon::join(
            || mesh.triangle_areas(),
            || {
                let mut parent: Vec<u32> = (0..triangles.len() as u32).collect();
                for_each_edge(mesh.vertex_count(), triangles, |low, uses| {
                    join_edge(&mut parent, low, uses);
                });
                parent
            },
        );
        Self::labelled(&mut parent, &areas)
    }

    /// The clusters of a union-find forest over the triangles (`parent`, see [`join_edge`]),
    /// numbered by their first triangle, with `areas` (one per triangle) summed per cluster in
    /// triangle order.
    pub(crate) fn labelled(parent: &mut [u32], areas: &[f64]) -> Self {
        let mut label = vec![u32::MAX; parent.len()];
        let mut cluster_of = Vec::with_capacity(parent.len());
        let mut sizes = Vec::new();
        let mut cluster_areas = Vec::new();
        for (t, &area) in areas.iter().enumerate() {
            let root = find(parent, t as u32) as usize;
            if label[root] == u32::MAX {
                label[root] = sizes.len() as u32;
                sizes.push(0);
                cluster_areas.push(0.0);
            }
            let c = label[root];
            cluster_of.push(c);
            sizes[c as usize] += 1;
            cluster_areas[c as usize] += area;
        }
        Self {
            cluster_of,
            sizes,
            areas: cluster_areas,
        }
    }

    /// Number of clusters.
    #[must_use]
    pub fn count(&self) -> usize {
        self.sizes.len()
    }
}

/// One use of an undirected edge `{low, high}` (`low <= high`): a side of a triangle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct EdgeUse {
    /// The edge's higher vertex.
    pub high: u32,
    /// The triangle.
    pub triangle: u32,
    /// Whether the side runs `low -> high` (a side whose ends coincide runs both ways).
    pub forward: bool,
}

/// Calls `f(low, uses)` once per undirected edge with all its uses: every side `a -> b`,
/// `b -> c`, `c -> a` of every triangle (sides whose ends coincide included, so `[a, a, b]`
/// uses `{a, a}` once and `{a, b}` twice), edges in increasing `(low, high)` order, the uses of
/// one edge in triangle order.
///
/// One counting sort of the sides by their lower vertex, then a sort of each vertex's few
/// sides by their higher one: several times faster than sorting or hashing all the `3 x
/// triangles` sides (a 340k-triangle TSDF mesh).
///
/// # Panics
/// If a triangle index is `>= vertex_count` (a [`crate::TriMesh`] never has one).
pub(crate) fn for_each_edge(
    vertex_count: usize,
    triangles: &[[u32; 3]],
    mut f: impl FnMut(u32, &[EdgeUse]),
) {
    let sides = |[a, b, c]: [u32; 3]| [(a, b), (b, c), (c, a)];
    // `next[v]`: where the next side with lower vertex v goes; after the fill, the end of v's
    // sides (the start of v + 1's).
    let mut next = vec![0usize; vertex_count];
    for &t in triangles {
        for (x, y) in sides(t) {
            next[x.min(y) as usize] += 1;
        }
    }
    let mut start = 0;
    for n in &mut next {
        let count = *n;
        *n = start;
        start += count;
    }
    let mut uses = vec![EdgeUse::default(); start];
    for (t, &tri) in triangles.iter().enumerate() {
        for (x, y) in sides(tri) {
            let slot = &mut next[x.min(y) as usize];
            uses[*slot] = EdgeUse {
                high: x.max(y),
                triangle: t as u32,
                forward: x <= y,
            };
            *slot += 1;
        }
    }
    let mut begin = 0;
    for (low, &end) in next.iter().enumerate() {
        let around = &mut uses[begin..end];
        begin = end;
        // Stable: the uses of one edge stay in triangle order.
        around.sort_by_key(|u| u.high);
        for edge in around.chunk_by(|p, q| p.high == q.high) {
            f(low as u32, edge);
        }
    }
}

/// Joins, in the union-find forest `parent`, the triangles that use the edge `{low, high}`
/// (its `uses`), unless its ends coincide: the connection of [`TriangleClusters`].
#[inline]
pub(crate) fn join_edge(parent: &mut [u32], low: u32, uses: &[EdgeUse]) {
    if uses.len() > 1 && uses[0].high != low {
        for pair in uses.windows(2) {
            union(parent, pair[0].triangle, pair[1].triangle);
        }
    }
}

/// The triangles around each vertex: `(offsets, around)` with the triangles of vertex `v` at
/// `around[offsets[v]..offsets[v + 1]]`, in triangle order (a triangle that repeats a vertex
/// is listed there twice).
///
/// # Panics
/// If a triangle index is `>= vertex_count` (a [`crate::TriMesh`] never has one).
#[must_use]
pub fn triangles_around_vertices(
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> (Vec<u32>, Vec<u32>) {
    let mut offsets = vec![0u32; vertex_count + 1];
    for tri in triangles {
        for &v in tri {
            offsets[v as usize + 1] += 1;
        }
    }
    for i in 1..offsets.len() {
        offsets[i] += offsets[i - 1];
    }
    let mut fill = offsets.clone();
    let mut around = vec![0u32; triangles.len() * 3];
    for (t, tri) in triangles.iter().enumerate() {
        for &v in tri {
            around[fill[v as usize] as usize] = t as u32;
            fill[v as usize] += 1;
        }
    }
    (offsets, around)
}

fn find(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let grand = parent[parent[x as usize] as usize];
        parent[x as usize] = grand;
        x = grand;
    }
    x
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
        parent[hi as usize] = lo;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use glam::Vec3;

    fn two_squares() -> TriMesh {
        // Two unit squares sharing only vertex 2 (so two edge-clusters).
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(2.0, 2.0, 0.0),
            Vec3::new(1.0, 2.0, 0.0),
        ];
        TriMesh::new(p, vec![[0, 1, 2], [0, 2, 3], [2, 4, 5], [2, 5, 6]])
    }

    #[test]
    fn edges_boundary_and_adjacency() {
        let m = two_squares();
        assert_eq!(unique_edges(m.triangles()).len(), 10);
        assert_eq!(boundary_edges(m.triangles()).len(), 8);
        assert!(non_manifold_edges(m.triangles()).is_empty());
        let adj = VertexAdjacency::new(m.vertex_count(), m.triangles());
        assert_eq!(adj.neighbors(2), &[0, 1, 3, 4, 5, 6]);
        assert_eq!(adj.neighbors(1), &[0, 2]);
    }

    #[test]
    fn vertex_touching_squares_are_two_clusters() {
        let c = TriangleClusters::of(&two_squares());
        assert_eq!(c.count(), 2);
        assert_eq!(c.cluster_of, vec![0, 0, 1, 1]);
        assert_eq!(c.sizes, vec![2, 2]);
        assert!((c.areas[0] - 1.0).abs() < 1e-12 && (c.areas[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn non_manifold_edge_is_found() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::NEG_Y];
        let tris = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        assert_eq!(non_manifold_edges(&tris), vec![(0, 1)]);
        let m = TriMesh::new(p, tris);
        assert_eq!(TriangleClusters::of(&m).count(), 1);
    }

    /// Clusters by the definition: union over the sorted list of edge uses.
    fn clusters_by_edge_uses(m: &TriMesh) -> Vec<u32> {
        let mut parent: Vec<u32> = (0..m.triangle_count() as u32).collect();
        for run in sorted_edge_uses(m.triangles()).chunk_by(|a, b| a.0 == b.0) {
            for w in run.windows(2) {
                union(&mut parent, w[0].1, w[1].1);
            }
        }
        let mut label = vec![u32::MAX; parent.len()];
        let mut next = 0;
        (0..parent.len() as u32)
            .map(|t| {
                let root = find(&mut parent, t) as usize;
                if label[root] == u32::MAX {
                    label[root] = next;
                    next += 1;
                }
                label[root]
            })
            .collect()
    }

    #[test]
    fn clusters_match_the_edge_definition_on_random_soups() {
        // Few vertices, many triangles: shared edges, non-manifold fans, repeated vertices
        // ([a, a, b] has one edge, [a, a, a] none) and vertex-only contacts.
        let mut rng = crate::rng::Rng::new(7);
        for case in 0..200u32 {
            let vertices = 3 + case % 40;
            let p: Vec<Vec3> = (0..vertices)
                .map(|_| Vec3::new(rng.uniform_f32(), rng.uniform_f32(), rng.uniform_f32()))
                .collect();
            let tris: Vec<[u32; 3]> = (0..1 + case % 60)
                .map(|_| [0; 3].map(|_: u32| rng.below(vertices)))
                .collect();
            let m = TriMesh::new_unchecked(p, tris);
            assert_eq!(
                TriangleClusters::of(&m).cluster_of,
                clusters_by_edge_uses(&m),
                "case {case}"
            );
        }
    }

    #[test]
    fn empty_mesh() {
        let m = TriMesh::default();
        assert_eq!(TriangleClusters::of(&m).count(), 0);
        assert_eq!(VertexAdjacency::new(0, &[]).vertex_count(), 0);
    }
}
