//! What every projection (3DGS, 2DGS surfels, perspective-aware) needs of a pinhole camera,
//! precomputed once per render.

use glam::{DMat3, DVec3};
use trisplat_geometry::Camera;

/// What every projection needs of a pinhole camera, precomputed once.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pinhole {
    pub(crate) w2c: DMat3,
    pub(crate) position: DVec3,
    pub(crate) fx: f64,
    pub(crate) fy: f64,
    pub(crate) cx: f64,
    pub(crate) cy: f64,
    pub(crate) width: f64,
    pub(crate) height: f64,
}

impl Pinhole {
    /// The pinhole of `camera`.
    pub(crate) fn of(camera: &Camera) -> Self {
        Self {
            w2c: camera.world_to_camera_rotation(),
            position: camera.position(),
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            width: f64::from(camera.width),
            height: f64::from(camera.height),
        }
    }
}
