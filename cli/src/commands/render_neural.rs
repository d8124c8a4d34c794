//! `trisplat render` with a neural appearance: the weights beside the PLY
//! (`<name>.safetensors`) or `--weights FILE` give each Gaussian's colour and opacity per
//! camera, baked into a degree-0 SH copy of the set for the renderer.

use std::path::{Path, PathBuf};

use trisplat_geometry::glam::DVec3;
use trisplat_splat::GaussianSet;
use trisplat_splat::neural::{
    Appearance, NeuralAppearance, NeuralInputs, Workspace, bake_set, forward, inputs_from_set,
    read_weights, weights_path,
};

/// A loaded model and its reused buffers.
pub struct NeuralRender {
    path: PathBuf,
    model: NeuralAppearance<f32>,
    inputs: NeuralInputs,
    app: Appearance<f32>,
    ws: Workspace<f32>,
}

impl NeuralRender {
    /// The model for `set` (read from `ply`, its coordinates `origin` away from the world's):
    /// `weights` if given, else `<name>.safetensors` beside `ply` if it exists, else none.
    ///
    /// # Errors
    /// A weights file that cannot be read or does not match the PLY (named).
    pub fn open(
        weights: Option<&Path>,
        ply: &Path,
        set: &GaussianSet,
        origin: DVec3,
    ) -> anyhow::Result<Option<Self>> {
        let beside = weights_path(ply);
        let path = match weights {
            Some(p) => p,
            None if beside.is_file() => &beside,
            None => return Ok(None),
        };
        let model = read_weights(path, set.len())?;
        let mut inputs = NeuralInputs::default();
        inputs_from_set(set, origin, model.aabb(), &mut inputs)
            .map_err(|e| anyhow::anyhow!("{}: {e}", ply.display()))?;
        Ok(Some(Self {
            path: path.to_path_buf(),
            model,
            inputs,
            app: Appearance::default(),
            ws: Workspace::default(),
        }))
    }

    /// The weights file the model was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `set` with the model's colour and opacity as seen from `camera` (world position).
    pub fn bake(&mut self, set: &GaussianSet, camera: DVec3) -> GaussianSet {
        forward(
            &self.model,
            &self.inputs,
            camera,
            &mut self.app,
            &mut self.ws,
        );
        bake_set(set, &self.app)
    }
}
