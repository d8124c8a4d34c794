//! Perspective-aware (TGA) evaluation of Gaussians along pixel rays (in progress).
