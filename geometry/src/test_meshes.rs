//! Meshes shared by the unit tests.

/// The eight outward-wound triangles of the octahedron with vertices `+x, -x, +y, -y, +z, -z`
/// (in that order).
pub(crate) const OCTAHEDRON_TRIANGLES: [[u32; 3]; 8] = [
    [0, 2, 4],
    [2, 1, 4],
    [1, 3, 4],
    [3, 0, 4],
    [2, 0, 5],
    [1, 2, 5],
    [3, 1, 5],
    [0, 3, 5],
];
