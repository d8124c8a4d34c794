//! `render`: the CPU splatting renderer (docs/conventions.md §5) to numpy images.

use pyo3::prelude::*;
use pyo3::types::PyDict;
use trisplat::geometry::mesh_render::NormalFrame;
use trisplat::splat::render::{DEFAULT_FAR, DEFAULT_NEAR};
use trisplat::splat::render::{
    Outputs, RenderMode, RenderOptions, Rules, SplatDepth, render as render_set,
};

use crate::arrays::image_out;
use crate::camera::Camera;
use crate::error;
use crate::gaussians::Gaussians;
use crate::threads;

/// The images asked for by name.
fn outputs(names: &[String]) -> PyResult<Outputs> {
    let mut outputs = Outputs {
        rgb: false,
        alpha: false,
        depth: false,
        median_depth: false,
        normal: false,
    };
    for name in names {
        let flag = match name.as_str() {
            "rgb" => &mut outputs.rgb,
            "alpha" => &mut outputs.alpha,
            "depth" => &mut outputs.depth,
            "median_depth" => &mut outputs.median_depth,
            "normal" => &mut outputs.normal,
            _ => {
                return Err(error::value(format!(
                    "output {name:?}: expected rgb, alpha, depth, median_depth or normal"
                )));
            }
        };
        *flag = true;
    }
    Ok(outputs)
}

/// Renders world-space ``gaussians`` seen by ``camera`` on the CPU and returns a dict of
/// float32 images, one per name in ``outputs``: ``rgb`` ``(H, W, 3)`` (background added with
/// weight 1 − alpha), ``alpha`` ``(H, W)``, ``depth`` ``(H, W)`` (expected z-depth, 0 where
/// nothing is hit), ``median_depth`` ``(H, W)`` (where the transmittance drops below 1/2),
/// ``normal`` ``(H, W, 3)`` (composited unit normals facing the camera, in ``normal_frame``
/// ``"world"`` or ``"camera"``).
///
/// ``mode``: ``"3dgs"`` (EWA splatting; ``rules`` ``"gsplat"`` or ``"original"``, the
/// original 3DGS rasterizer's), ``"2dgs"`` (surfels) or ``"perspective"``. Gaussians nearer
/// than ``near`` or beyond ``far`` are culled. ``splat_depth`` (3DGS mode): ``"mean"`` (each
/// splat at its mean's depth, as 3DGS) or ``"ray"`` (the point of highest density on the
/// pixel's ray, RaDe-GS/GOF; a flat Gaussian gives its own plane). The images do not depend on
/// the thread count.
#[pyfunction]
#[pyo3(signature = (gaussians, camera, outputs = vec!["rgb".to_owned(), "alpha".to_owned(), "depth".to_owned(), "normal".to_owned()], mode = "3dgs", rules = "gsplat", background = (0.0, 0.0, 0.0), near = DEFAULT_NEAR, far = DEFAULT_FAR, antialiased = false, normal_frame = "world", splat_depth = "mean"))]
#[expect(
    clippy::too_many_arguments,
    reason = "the renderer's options as keywords"
)]
pub fn render<'py>(
    py: Python<'py>,
    gaussians: &Gaussians,
    camera: &Camera,
    outputs: Vec<String>,
    mode: &str,
    rules: &str,
    background: (f32, f32, f32),
    near: f32,
    far: f32,
    antialiased: bool,
    normal_frame: &str,
    splat_depth: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let options = RenderOptions {
        mode: match mode {
            "3dgs" => RenderMode::Gaussian3d,
            "2dgs" => RenderMode::Surfel2d,
            "perspective" => RenderMode::Perspective,
            _ => {
                return Err(error::value(format!(
                    "mode {mode:?}: expected \"3dgs\", \"2dgs\" or \"perspective\""
                )));
            }
        },
        rules: match rules {
            "gsplat" => Rules::Gsplat,
            "original" => Rules::Original3dgs,
            _ => {
                return Err(error::value(format!(
                    "rules {rules:?}: expected \"gsplat\" or \"original\""
                )));
            }
        },
        antialiased,
        outputs: self::outputs(&outputs)?,
        background: [background.0, background.1, background.2],
        near,
        far,
        normal_frame: match normal_frame {
            "world" => NormalFrame::World,
            "camera" => NormalFrame::Camera,
            _ => {
                return Err(error::value(format!(
                    "normal_frame {normal_frame:?}: expected \"world\" or \"camera\""
                )));
            }
        },
        splat_depth: match splat_depth {
            "mean" => SplatDepth::Mean,
            "ray" => SplatDepth::Ray,
            _ => {
                return Err(error::value(format!(
                    "splat_depth {splat_depth:?}: expected \"mean\" or \"ray\""
                )));
            }
        },
        contribution: false,
    };
    let set = gaussians.to_rust(py)?;
    let camera = &camera.inner;
    let out = threads::detach(py, || render_set(&set, camera, &options))
        .map_err(|e| error::library(&e))?;
    let images = out.images;
    let (h, w) = (images.height as usize, images.width as usize);
    let dict = PyDict::new(py);
    for (name, image, channels) in [
        ("rgb", images.rgb, 3),
        ("alpha", images.alpha, 1),
        ("depth", images.depth, 1),
        ("median_depth", images.median_depth, 1),
        ("normal", images.normal, 3),
    ] {
        if let Some(values) = image {
            dict.set_item(name, image_out(py, values, (h, w, channels))?)?;
        }
    }
    Ok(dict)
}

/// Adds the functions of this module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(render, m)?)?;
    Ok(())
}
