//! The CPU splatting renderer (SPEC §5): 3DGS EWA splatting with gsplat's rules, 2DGS surfels,
//! and perspective-aware evaluation; rgb, alpha, expected/median depth and normal maps.
//! (Being built; the module list is fixed so its parts can be written side by side.)

pub mod perspective;
pub mod surfel;
