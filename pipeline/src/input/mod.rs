//! Reading the inputs: the template (`template`), its animation (`animation`), the Gaussians,
//! bound or bound here (`gaussians`), and the frame range (`frames`).

mod animation;
mod frames;
mod gaussians;
mod template;

pub use animation::{
    Animation, AnimationSource, animation_label, clip_of, open_template_and_animation,
};
pub use frames::{parse_frames, shard_frames};
pub use gaussians::{GaussianSource, bind_here, check_set, deform_mode, read_bound};
pub use template::{SCALE_MISMATCH, WeldedTemplate, check_scale, check_topology, read_template};

#[cfg(test)]
mod tests;
