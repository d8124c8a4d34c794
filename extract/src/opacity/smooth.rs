//! The median field's settled surface made smooth: Taubin smoothing (Open3D's rule: λ = 1/2
//! then μ = -0.53 per iteration, inverse-distance weights over the 1-ring, Jacobi steps) of the
//! vertices that settling moved, the others held. Settling moves each vertex on its own, onto
//! the median depth, so neighbouring vertices land up to a tetrahedron's resolution apart
//! along the normal: a saw-tooth that adds area and turns normals. Vertices that did not
//! settle (thin layers and rims that keep the margin) are held, so thin parts are not shrunk.

use glam::DVec3;
use trisplat_geometry::smoothing::{DEFAULT_LAMBDA, DEFAULT_MU, taubin_held};

/// `vertices` after `iterations` Taubin iterations over the 1-rings of `triangles`, moving only
/// the vertices whose `free` is true (the rest are held, and still pull their neighbours):
/// `geometry::smoothing::taubin_held` with Open3D's λ and μ. Deterministic: every step reads
/// only the previous iterate.
pub(crate) fn taubin_free(
    vertices: Vec<DVec3>,
    triangles: &[[u32; 3]],
    free: &[bool],
    iterations: u32,
) -> Vec<DVec3> {
    taubin_held(
        vertices,
        triangles,
        free,
        iterations,
        DEFAULT_LAMBDA,
        DEFAULT_MU,
    )
}
