//! Helpers shared by the splat crate's integration tests.

use glam::{DVec3, Quat, Vec3};
use trisplat_geometry::Camera;
use trisplat_splat::GaussianSet;
use trisplat_splat::{GaussianParts, ParameterSpace, ScaleDims, logit};

/// World-space Gaussians (SH degree 0, black) with these means, rotations, log-scales and
/// opacities.
pub fn world_set(
    means: &[Vec3],
    rotations: &[Quat],
    log_scales: &[Vec3],
    opacities: &[f32],
) -> GaussianSet {
    let n = means.len();
    GaussianSet::try_new(GaussianParts {
        means: means.to_vec(),
        log_scales: log_scales.to_vec(),
        scale_dims: ScaleDims::Three,
        rotations: rotations.iter().map(|q| [q.w, q.x, q.y, q.z]).collect(),
        opacity_logits: opacities.iter().map(|&o| logit(o)).collect(),
        sh_degree: 0,
        sh: vec![0.0; 3 * n],
        binding: None,
        material: None,
        space: ParameterSpace::World,
        extras: Vec::new(),
        property_order: None,
    })
    .expect("valid set")
}

/// A square camera of `size` pixels at the origin looking down +z (y down), 40° field of view.
pub fn camera(size: u32) -> Camera {
    Camera::look_at("c", DVec3::ZERO, DVec3::Z, DVec3::NEG_Y, (size, size), 40.0).expect("camera")
}
