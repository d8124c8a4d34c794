//! Relightable Gaussians as HRAvatar (CVPR 2025) defines them: per-Gaussian material attributes
//! ([`Material`]) and their split-sum shading under an equirectangular environment map
//! (docs/conventions.md §3, §5 "Relighting").
//!
//! Files, from the callers down: `maps` (writing the material maps) ─► `relight` (materials
//! edited, shaded per Gaussian per view, composited by [`crate::render`]) ─► `shade`
//! ([`Environment`]: one point's split sum) ─► `irradiance` (9-coefficient SH), `prefilter`
//! (GGX mip chain), `brdf` (the integration table); `backward` differentiates the shading
//! through each Gaussian's normal (quaternion) and view (mean), `lookup_grad` the map lookups
//! by direction; `env_grad` ([`EnvGrad`]) gathers the gradient with respect to the environment
//! and carries it back through the prefiltering to the map's texels. `attributes` is a leaf:
//! [`crate::GaussianSet`] holds a [`Material`].

pub(crate) mod attributes;
mod backward;
mod brdf;
mod env_grad;
mod irradiance;
mod lookup_grad;
mod maps;
mod prefilter;
mod relight;
mod shade;

pub use attributes::{
    DEFAULT_F0, DEFAULT_ROUGHNESS, Material, PLY_ALBEDO, PLY_REFLECTANCE, PLY_ROUGHNESS,
};
pub use backward::{
    NormalTrace, color_grads_from_sh, normal_of, relit_backward, relit_env_backward, shade_params,
};
pub use brdf::{BRDF_TABLE_SAMPLES, BRDF_TABLE_SIZE, BrdfTable};
pub use env_grad::EnvGrad;
pub use irradiance::Irradiance;
pub use maps::{MATERIAL_KINDS, material_image_files, write_material_maps};
pub use prefilter::{LEVEL_WIDTHS, LEVELS, MIRROR_WIDTH, SOURCE_WIDTHS, SpecularChain, prefilter};
pub use relight::{
    MaterialEdits, MaterialGrads, MaterialMaps, Relit, RelitRender, effective_material,
    material_grads, render_relit, shade_gaussians, with_colors,
};
pub use shade::{EnvOptions, Environment, IRRADIANCE_WIDTH, Shading, ShadingGrad};
