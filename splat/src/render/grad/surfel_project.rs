//! The 2DGS surfel projection of one Gaussian in `f64` ([`project`]: the activations, then
//! [`crate::render::surfel::project_with`], the renderer's own function) and its
//! vector-Jacobian product ([`project_vjp`]): gradients of the surfel's screen quantities (the
//! rows of `M = K [Tu Tv p]`, the low-pass filter's centre, opacity, colour, normal) carried
//! back to the raw parameters.
//!
//! Held fixed, as in the 3DGS path: the culling (near/far, opacity below 1/255, empty tile
//! rectangle), the screen box, the normal's sign flip towards the camera and the colour's
//! `max(·, 0)` where it clamps. The third log-scale is not used by a surfel: its gradient is 0.

use glam::{DMat3, DVec2, DVec3};
use trisplat_geometry::mesh_render::NormalFrame;

use super::params::DiffParams;
use super::project::{
    ColorTrace, ParamGrad, color, color_vjp, normalized, quaternion_vjp, rotation_matrix, sigmoid,
};
use crate::render::composite::ALPHA_THRESHOLD;
use crate::render::surfel::{SurfelSplat, View, project_with};

/// One projected surfel's screen quantities, in `f64`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SurfelScreen {
    /// Per-pixel data (rows, filter centre, opacity, near plane), as the plain renderer's.
    pub splat: SurfelSplat,
    /// Box radius in pixels (hbb1's).
    pub radius: f64,
    /// Camera z of the centre (the sort key).
    pub depth: f64,
    /// Colour.
    pub color: [f64; 3],
    /// Unit normal facing the camera, in the requested frame.
    pub normal: DVec3,
}

/// Gradients of a loss with respect to one surfel's screen quantities.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct SurfelScreenGrad {
    /// d/d rows `Tu`, `Tv`, `Tw` of `M`.
    pub rows: [DVec3; 3],
    /// d/d the low-pass filter's centre.
    pub center: DVec2,
    pub opacity: f64,
    pub color: [f64; 3],
    pub normal: DVec3,
}

impl SurfelScreenGrad {
    /// From a (tile, splat) slot: rows (9), centre (2), opacity, colour (3), normal (3).
    pub(crate) fn from_slot(s: &[f64; SURFEL_SLOT]) -> Self {
        Self {
            rows: [
                DVec3::new(s[0], s[1], s[2]),
                DVec3::new(s[3], s[4], s[5]),
                DVec3::new(s[6], s[7], s[8]),
            ],
            center: DVec2::new(s[9], s[10]),
            opacity: s[11],
            color: [s[12], s[13], s[14]],
            normal: DVec3::new(s[15], s[16], s[17]),
        }
    }
}

/// Values per (tile, surfel) slot (see [`SurfelScreenGrad::from_slot`]).
pub(crate) const SURFEL_SLOT: usize = 18;

/// One Gaussian's activated surfel parameters.
struct Activated {
    mean: DVec3,
    qn: [f64; 4],
    qnorm: f64,
    rot: DMat3,
    scale: DVec2,
    sig: f64,
}

fn activate<P: DiffParams + ?Sized>(p: &P, i: usize) -> Activated {
    let (qn, qnorm) = normalized(p.rotation(i));
    let ls = p.log_scale(i);
    Activated {
        mean: p.mean(i),
        qn,
        qnorm,
        rot: rotation_matrix(qn),
        scale: DVec2::new(ls.x.exp(), ls.y.exp()),
        sig: sigmoid(p.opacity_logit(i)),
    }
}

/// The camera-space third axis and the sign that turns it to face the camera (z ≤ 0).
fn facing(v: &View, rot: &DMat3) -> (DVec3, f64) {
    let n = v.cam.w2c * rot.z_axis;
    if n.z < 0.0 { (n, 1.0) } else { (-n, -1.0) }
}

fn trace<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    v: &View,
    frame: NormalFrame,
) -> Option<(SurfelScreen, Activated, ColorTrace)> {
    let a = activate(p, i);
    if a.sig.is_nan() || a.sig < f64::from(ALPHA_THRESHOLD) {
        return None;
    }
    let s = project_with(v, a.mean, a.rot, a.scale, a.sig)?;
    let (n_camera, _) = facing(v, &a.rot);
    let normal = match frame {
        NormalFrame::Camera => n_camera,
        NormalFrame::World => v.cam.w2c.transpose() * n_camera,
    };
    let (color, color_trace) = color(p, i, v.cam.position);
    let screen = SurfelScreen {
        splat: s.splat,
        radius: s.radius,
        depth: s.depth,
        color,
        normal,
    };
    Some((screen, a, color_trace))
}

/// Projects Gaussian `i` as a surfel (module documentation); `None` when culled (before the
/// tile test, which the caller does). The values equal those of
/// [`crate::render::surfel::project_surfels`] up to the `f32` rounding of its activations.
pub(crate) fn project<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    v: &View,
    frame: NormalFrame,
) -> Option<SurfelScreen> {
    trace(p, i, v, frame).map(|(s, _, _)| s)
}

/// Carries the screen gradient `g` of surfel `i` back to its raw parameters; also returns the
/// gradient with respect to the surfel's position on screen in pixels (`means2d`: a shift of
/// its whole image, `M ← [[1, 0, δx], [0, 1, δy], [0, 0, 1]] M`, which moves the filter centre
/// by `δ` too). `None` if the projection culls it.
pub(crate) fn project_vjp<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    v: &View,
    frame: NormalFrame,
    g: &SurfelScreenGrad,
) -> Option<(ParamGrad, [f64; 2])> {
    let (s, a, color_trace) = trace(p, i, v, frame)?;
    let [ru, rv, rw] = s.splat.rows;
    let center = s.splat.center;
    let mut g_rows = g.rows;
    let means2d = [
        g.rows[0].dot(rw) + g.center.x,
        g.rows[1].dot(rw) + g.center.y,
    ];

    // Filter centre = (f·(Tu∘Tw), f·(Tv∘Tw)) with f = sign / d, d = sign·(Tw∘Tw).
    let sign = DVec3::new(1.0, 1.0, -1.0);
    let d = sign.dot(rw * rw);
    let f = sign / d;
    let gc = g.center;
    g_rows[0] += gc.x * f * rw;
    g_rows[1] += gc.y * f * rw;
    g_rows[2] += gc.x * f * ru + gc.y * f * rv;
    let g_d = -(gc.x * center.x + gc.y * center.y) / d;
    g_rows[2] += 2.0 * g_d * sign * rw;

    // Rows → columns of M: column m = (Tu[m], Tv[m], Tw[m]).
    let [gu, gv, gw] = g_rows;
    let column = |m: usize| DVec3::new(gu[m], gv[m], gw[m]);
    // Column = K c with K c = (fx c.x + cx c.z, fy c.y + cy c.z, c.z).
    let through_k = |g: DVec3| {
        DVec3::new(
            v.cam.fx * g.x,
            v.cam.fy * g.y,
            v.cam.cx * g.x + v.cam.cy * g.y + g.z,
        )
    };
    let (g_tu, g_tv, g_t) = (
        through_k(column(0)),
        through_k(column(1)),
        through_k(column(2)),
    );

    // Tu = W R e_x s_u, Tv = W R e_y s_v, p = W (mean − camera), n = ±W R e_z.
    let wt = v.cam.w2c.transpose();
    let (g_axis_u, g_axis_v) = (wt * g_tu, wt * g_tv);
    let (_, flip) = facing(v, &a.rot);
    let g_axis_n = flip
        * match frame {
            NormalFrame::Camera => wt * g.normal,
            NormalFrame::World => g.normal,
        };
    let g_r = [g_axis_u * a.scale.x, g_axis_v * a.scale.y, g_axis_n];
    let scale_grad = |axis: DVec3, g: DVec3, scale: f64| {
        if scale > 0.0 {
            axis.dot(g) * scale
        } else {
            0.0
        }
    };
    let mut out = ParamGrad {
        mean: [0.0; 3],
        log_scale: [
            scale_grad(a.rot.x_axis, g_axis_u, a.scale.x),
            scale_grad(a.rot.y_axis, g_axis_v, a.scale.y),
            0.0,
        ],
        rotation: quaternion_vjp(a.qn, a.qnorm, g_r),
        opacity_logit: g.opacity * a.sig * (1.0 - a.sig),
        sh: [0.0; 48],
    };
    let g_mean = wt * g_t + color_vjp(&color_trace, g.color, &mut out.sh);
    out.mean = g_mean.to_array();
    // Degenerate surfels (edge-on, vanishing scales) can overflow: no gradient rather than NaN.
    let finite = out.mean.iter().all(|x| x.is_finite())
        && out.log_scale.iter().all(|x| x.is_finite())
        && out.rotation.iter().all(|x| x.is_finite())
        && out.opacity_logit.is_finite()
        && out.sh.iter().all(|x| x.is_finite())
        && means2d.iter().all(|x| x.is_finite());
    finite.then_some((out, means2d))
}
