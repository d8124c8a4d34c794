//! Marching cubes over a sparse [`BlockGrid`]: welded vertices, closed where every cell is
//! observed, faces toward the outside (value ≥ 0: free space for a TSDF).
//!
//! A cell is the cube between voxels `g` and `g + (1, 1, 1)`. Cells with any unobserved corner
//! (weight 0) are skipped, as Open3D's legacy `ExtractTriangleMesh` does. A corner is *inside*
//! when its value is < 0. Each crossed grid edge gets exactly one vertex, keyed by the edge
//! (its low voxel and axis), so neighbouring cells and blocks share it; the vertex lies where
//! the linear interpolation of the two values is zero, kept [`VERTEX_EDGE_MARGIN`] of a voxel
//! away from either end so that no triangle collapses to zero area (which the clean-up would
//! remove, opening a hole). The case table and its face rule are described in
//! [`crate::mc_tables`].
//!
//! Two passes run in parallel over blocks: the first creates the vertices of the edges each
//! block owns (those whose low voxel it holds) that at least one fully observed cell uses; the
//! second emits the triangles of the cells whose low corner it holds. Vertices and triangles
//! are numbered block by block in the grid's block order, so the mesh does not depend on the
//! thread count.

use glam::{DVec3, IVec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;

use crate::block_grid::{BLOCK, BLOCK_VOXELS, BlockGrid, local_coords, local_index};
use crate::mc_tables::{CORNERS, EDGES, TABLE, crossed_edges};

/// Vertices are placed at least this fraction of a voxel away from the ends of their edge
/// (see the module docs). Open3D places them exactly at the interpolated zero; the difference
/// is at most 0.001 voxel and only where a corner value is within 0.1% of zero.
pub const VERTEX_EDGE_MARGIN: f64 = 1e-3;

/// Blocks per parallel work item.
const BLOCKS_PER_TASK: usize = 4;

/// Storage offsets of the next voxel along x, y and z inside one block.
const AXIS_STRIDES: [usize; 3] = [1, BLOCK as usize, (BLOCK * BLOCK) as usize];

/// Position of the centre block in [`Neighborhood::ids`].
const CENTRE: usize = 13;

/// Storage offsets of the 8 cell corners from the low corner inside one block.
const CORNER_OFFSETS: [usize; 8] = {
    let mut out = [0usize; 8];
    let mut c = 0;
    while c < 8 {
        let b = BLOCK as usize;
        out[c] = (c & 1) + b * ((c >> 1) & 1) + b * b * ((c >> 2) & 1);
        c += 1;
    }
    out
};

/// The blocks around one block: `ids[(dx + 1) + 3 (dy + 1) + 9 (dz + 1)]` for offsets in
/// `-1..=1`.
struct Neighborhood {
    ids: [Option<u32>; 27],
}

impl Neighborhood {
    fn of(grid: &BlockGrid, key: IVec3) -> Self {
        let mut ids = [None; 27];
        for (i, id) in ids.iter_mut().enumerate() {
            let offset = IVec3::new(i as i32 % 3, (i as i32 / 3) % 3, i as i32 / 9) - 1;
            *id = grid.lookup.get(&(key + offset)).copied();
        }
        Self { ids }
    }

    /// Storage slot of the voxel at local coordinates `l` (each in `-8..16`) relative to the
    /// centre block, `None` when that block is not allocated.
    #[inline]
    fn slot(&self, l: IVec3) -> Option<usize> {
        let (block, local) = split(l);
        let i = (block.x + 1) + 3 * (block.y + 1) + 9 * (block.z + 1);
        let b = self.ids[i as usize]? as usize;
        Some(b * BLOCK_VOXELS + local_index(local))
    }

    /// `(block id, local index)` of the voxel at local coordinates `l`.
    #[inline]
    fn owner(&self, l: IVec3) -> Option<(usize, usize)> {
        let (block, local) = split(l);
        let i = (block.x + 1) + 3 * (block.y + 1) + 9 * (block.z + 1);
        Some((self.ids[i as usize]? as usize, local_index(local)))
    }
}

/// Local coordinates relative to the centre block split into the block offset (floor
/// division by [`BLOCK`], a power of two: an arithmetic shift) and the coordinates inside it.
#[inline]
fn split(l: IVec3) -> (IVec3, IVec3) {
    const SHIFT: u32 = BLOCK.trailing_zeros();
    const _: () = assert!(BLOCK.count_ones() == 1, "BLOCK must be a power of two");
    (l >> SHIFT, l & IVec3::splat(BLOCK - 1))
}

/// The eight corner values of the cell whose low corner is at local coordinates `l`, or
/// `None` when a corner is unobserved.
#[inline]
fn cell_values(grid: &BlockGrid, hood: &Neighborhood, l: IVec3) -> Option<[f32; 8]> {
    let mut f = [0.0f32; 8];
    if l.cmpge(IVec3::ZERO).all() && l.cmplt(IVec3::splat(BLOCK - 1)).all() {
        // Fast path: the whole cell is inside the centre block.
        let base = hood.ids[CENTRE]? as usize * BLOCK_VOXELS + local_index(l);
        for (c, offset) in CORNER_OFFSETS.iter().enumerate() {
            let s = base + offset;
            if grid.weight[s] == 0.0 {
                return None;
            }
            f[c] = grid.value[s];
        }
        return Some(f);
    }
    for (c, offset) in CORNERS.iter().enumerate() {
        let s = hood.slot(l + IVec3::from_array(offset.map(i32::from)))?;
        if grid.weight[s] == 0.0 {
            return None;
        }
        f[c] = grid.value[s];
    }
    Some(f)
}

/// The case index of corner values (bit c set when corner c is inside).
#[inline]
fn case_of(f: &[f32; 8]) -> u8 {
    f.iter()
        .enumerate()
        .fold(0u8, |acc, (c, &v)| acc | (u8::from(v < 0.0) << c))
}

/// Fraction along an edge where the linear interpolation of `fa` (at 0) and `fb` (at 1) is
/// zero, kept within [`VERTEX_EDGE_MARGIN`] of the ends. The values have different signs.
#[inline]
fn crossing(fa: f32, fb: f32) -> f64 {
    let (fa, fb) = (f64::from(fa), f64::from(fb));
    (fa / (fa - fb)).clamp(VERTEX_EDGE_MARGIN, 1.0 - VERTEX_EDGE_MARGIN)
}

/// The vertices one block owns: sorted edge keys (`local * 3 + axis`) and their positions and
/// colours.
#[derive(Default)]
struct BlockVertices {
    keys: Vec<u16>,
    positions: Vec<DVec3>,
    colors: Vec<[f32; 4]>,
}

/// Pass 1 for block `b` (see the module docs).
fn block_vertices(grid: &BlockGrid, b: usize) -> BlockVertices {
    let key = grid.keys[b];
    let hood = Neighborhood::of(grid, key);
    let mut out = BlockVertices::default();
    let base = b * BLOCK_VOXELS;
    for local in 0..BLOCK_VOXELS {
        let s0 = base + local;
        if grid.weight[s0] == 0.0 {
            continue;
        }
        let f0 = grid.value[s0];
        let l = local_coords(local);
        for axis in 0..3 {
            let step = IVec3::AXES[axis];
            // The far end is in this block unless `l` is on its high face.
            let s1 = if l[axis] + 1 < BLOCK {
                s0 + AXIS_STRIDES[axis]
            } else {
                match hood.slot(l + step) {
                    Some(s1) => s1,
                    None => continue,
                }
            };
            if grid.weight[s1] == 0.0 {
                continue;
            }
            let f1 = grid.value[s1];
            if (f0 < 0.0) == (f1 < 0.0) {
                continue;
            }
            // Used when one of the four cells around the edge is fully observed: their low
            // corners are l minus 0 or 1 on each of the two other axes.
            let (i, j) = match axis {
                0 => (1, 2),
                1 => (0, 2),
                _ => (0, 1),
            };
            let used = (0..4).any(|k| {
                let mut low = l;
                low[i] -= k & 1;
                low[j] -= (k >> 1) & 1;
                cell_values(grid, &hood, low).is_some()
            });
            if !used {
                continue;
            }
            let t = crossing(f0, f1);
            let g = key * BLOCK + l;
            let p = grid.position(g) + DVec3::AXES[axis] * (t * grid.voxel);
            out.keys.push((local * 3 + axis) as u16);
            out.positions.push(p);
            if let Some(color) = &grid.color {
                let (c0, c1) = (color[s0], color[s1]);
                let mix = |k: usize| ((1.0 - t) * f64::from(c0[k]) + t * f64::from(c1[k])) as f32;
                out.colors.push([mix(0), mix(1), mix(2), 1.0]);
            }
        }
    }
    out
}

/// Pass 2 for block `b`: the triangles of its cells, with global vertex ids.
fn block_triangles(
    grid: &BlockGrid,
    b: usize,
    vertices: &[BlockVertices],
    offsets: &[u32],
) -> Vec<[u32; 3]> {
    let key = grid.keys[b];
    let hood = Neighborhood::of(grid, key);
    let mut out = Vec::new();
    for local in 0..BLOCK_VOXELS {
        if grid.weight[b * BLOCK_VOXELS + local] == 0.0 {
            continue;
        }
        let l = local_coords(local);
        let Some(f) = cell_values(grid, &hood, l) else {
            continue;
        };
        let case = case_of(&f);
        if case == 0 || case == 255 {
            continue;
        }
        let mut ids = [u32::MAX; 12];
        let mut missing = false;
        let mut crossed = crossed_edges(case);
        while crossed != 0 {
            let e = crossed.trailing_zeros() as usize;
            crossed &= crossed - 1;
            let (low, _, axis) = EDGES[e];
            let corner = IVec3::from_array(CORNERS[usize::from(low)].map(i32::from));
            let id = hood.owner(l + corner).and_then(|(owner, owner_local)| {
                let edge_key = (owner_local * 3 + usize::from(axis)) as u16;
                let v = &vertices[owner];
                let i = v.keys.binary_search(&edge_key).ok()?;
                Some(offsets[owner] + i as u32)
            });
            match id {
                Some(id) => ids[e] = id,
                None => missing = true,
            }
        }
        // Pass 1 made a vertex for every edge of a fully observed cell; a miss would be a bug,
        // and skipping the cell is the safe answer.
        if missing {
            debug_assert!(false, "marching cubes: missing vertex in block {key}");
            continue;
        }
        for t in TABLE[usize::from(case)].triangles() {
            out.push(t.map(|e| ids[usize::from(e)]));
        }
    }
    out
}

/// Extracts the zero level set of `grid` (see the module docs). The mesh carries vertex
/// colours when the grid does; it may be empty.
#[must_use]
pub fn marching_cubes(grid: &BlockGrid) -> TriMesh {
    let n = grid.block_count();
    let vertices: Vec<BlockVertices> = (0..n)
        .into_par_iter()
        .with_min_len(BLOCKS_PER_TASK)
        .map(|b| block_vertices(grid, b))
        .collect();
    let mut offsets = Vec::with_capacity(n);
    let mut total = 0u64;
    for v in &vertices {
        offsets.push(total as u32);
        total += v.keys.len() as u64;
    }
    // More than u32::MAX vertices cannot be indexed; a grid that large does not fit in memory
    // anyway (each vertex needs a crossed edge of allocated blocks), so this is not reachable
    // in practice. Keep the mesh empty rather than wrap.
    if total > u64::from(u32::MAX) {
        return TriMesh::default();
    }
    let triangles: Vec<[u32; 3]> = (0..n)
        .into_par_iter()
        .with_min_len(BLOCKS_PER_TASK)
        .map(|b| block_triangles(grid, b, &vertices, &offsets))
        .flatten_iter()
        .collect();
    let mut positions = Vec::with_capacity(total as usize);
    let mut colors = Vec::with_capacity(if grid.color.is_some() {
        total as usize
    } else {
        0
    });
    for v in vertices {
        positions.extend(v.positions);
        colors.extend(v.colors);
    }
    let mesh = TriMesh::new_unchecked(positions, triangles);
    if grid.color.is_some() {
        // Same length as the positions by construction.
        mesh.clone().with_colors(colors).unwrap_or(mesh)
    } else {
        mesh
    }
}

/// Marching cubes on a dense array: sample `(i, j, k)` of the x-fastest `dims` array sits at
/// `origin + (i, j, k) * spacing`; non-finite samples are unobserved (cells touching them are
/// skipped). `None` when `values.len()` does not match `dims`.
#[must_use]
pub fn marching_cubes_dense(
    values: &[f32],
    dims: [usize; 3],
    origin: DVec3,
    spacing: f64,
) -> Option<TriMesh> {
    BlockGrid::from_dense(values, dims, origin, spacing).map(|g| marching_cubes(&g))
}

#[cfg(test)]
mod tests {
    use super::*;
    use trisplat_geometry::topology::{boundary_edges, non_manifold_edges};

    fn sphere_field(n: usize, r: f64) -> Vec<f32> {
        let c = (n as f64 - 1.0) / 2.0;
        let mut v = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let p = DVec3::new(x as f64, y as f64, z as f64) - c;
                    v.push((p.length() - r) as f32);
                }
            }
        }
        v
    }

    #[test]
    fn sphere_is_closed_and_outward() {
        let n = 21;
        let mesh = marching_cubes_dense(&sphere_field(n, 6.3), [n; 3], DVec3::ZERO, 0.1).unwrap();
        assert!(mesh.triangle_count() > 100);
        assert!(boundary_edges(mesh.triangles()).is_empty());
        assert!(non_manifold_edges(mesh.triangles()).is_empty());
        let volume = mesh.signed_volume();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.63f64.powi(3);
        assert!((volume - exact).abs() < 0.03 * exact, "{volume} vs {exact}");
        // Every vertex lies on the sphere to within the linear-interpolation error.
        let c = DVec3::splat(1.0);
        for p in mesh.positions() {
            let r = (*p - c).length();
            assert!((r - 0.63).abs() < 0.01, "{r}");
        }
    }

    #[test]
    fn random_fields_give_closed_manifolds() {
        // Random signs inside a box whose border is outside: every case and every ambiguous
        // face occurs, and the surface must be closed with every edge used exactly twice.
        let n = 12;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for round in 0..20 {
            let mut v = vec![1.0f32; n * n * n];
            for z in 1..n - 1 {
                for y in 1..n - 1 {
                    for x in 1..n - 1 {
                        state ^= state << 13;
                        state ^= state >> 7;
                        state ^= state << 17;
                        let u = (state >> 40) as f32 / (1u64 << 24) as f32;
                        v[x + n * (y + n * z)] = u - 0.5 + 0.1 * (round % 3) as f32;
                    }
                }
            }
            let mesh = marching_cubes_dense(&v, [n; 3], DVec3::ZERO, 1.0).unwrap();
            assert!(mesh.triangle_count() > 0);
            assert!(boundary_edges(mesh.triangles()).is_empty(), "round {round}");
            assert!(
                non_manifold_edges(mesh.triangles()).is_empty(),
                "round {round}"
            );
            assert!(mesh.signed_volume() > 0.0);
            assert!(
                mesh.report().is_clean(),
                "round {round}: {:?}",
                mesh.report()
            );
        }
    }

    #[test]
    fn unobserved_cells_are_skipped() {
        let n = 21;
        let mut v = sphere_field(n, 6.3);
        let full = marching_cubes_dense(&v, [n; 3], DVec3::ZERO, 1.0).unwrap();
        // Hide one voxel on the surface: the cells around it disappear, leaving a hole.
        let i = 10 + n * (10 + n * 4);
        assert!(v[i].abs() < 1.0);
        v[i] = f32::NAN;
        let holed = marching_cubes_dense(&v, [n; 3], DVec3::ZERO, 1.0).unwrap();
        assert!(holed.triangle_count() < full.triangle_count());
        assert!(!boundary_edges(holed.triangles()).is_empty());
        // No vertex is left without a triangle.
        let mut used = vec![false; holed.vertex_count()];
        for t in holed.triangles() {
            for &k in t {
                used[k as usize] = true;
            }
        }
        assert!(used.iter().all(|&u| u));
    }

    #[test]
    fn exact_zero_corners_keep_positive_areas() {
        // A plane through a layer of samples (values exactly 0): no triangle may collapse.
        let n = 10;
        let mut v = Vec::new();
        for z in 0..n {
            for _y in 0..n {
                for _x in 0..n {
                    v.push(z as f32 - 4.0);
                }
            }
        }
        let mesh = marching_cubes_dense(&v, [n; 3], DVec3::ZERO, 1.0).unwrap();
        assert!(mesh.triangle_count() > 0);
        assert!(mesh.triangle_areas().iter().all(|&a| a > 0.0));
    }

    #[test]
    fn empty_and_mismatched_inputs() {
        assert_eq!(
            marching_cubes_dense(&[], [0, 0, 0], DVec3::ZERO, 1.0)
                .unwrap()
                .triangle_count(),
            0
        );
        assert!(marching_cubes_dense(&[1.0; 7], [2, 2, 2], DVec3::ZERO, 1.0).is_none());
        let all_nan = vec![f32::NAN; 27];
        assert_eq!(
            marching_cubes_dense(&all_nan, [3; 3], DVec3::ZERO, 1.0)
                .unwrap()
                .triangle_count(),
            0
        );
    }
}
