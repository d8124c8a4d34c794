//! The 3DGS projection of one Gaussian in `f64` ([`project`], the same formulas and culling as
//! [`crate::render::project`]) and its vector-Jacobian product ([`project_vjp`]): gradients of the
//! screen quantities (mean, conic, opacity, depth, colour) carried back to the raw parameters.
//!
//! Non-differentiable choices are held fixed, as gsplat does: the screen box and the culling
//! tests; the Jacobian's frustum clamp passes no gradient to x (or y) where it clamps (its
//! z-dependence stays); the colour's `max(·, 0)` passes none where it clamps.

use glam::{DMat3, DVec3};

use super::params::DiffParams;
use crate::render::options::{RenderOptions, Rules};
pub(crate) use crate::render::project::View;
use crate::render::project::ewa_screen;
use crate::sh::sh_coeffs_per_channel;
use crate::sh::{SH_C1, SH_C2, SH_C3, sh_basis};

/// One projected Gaussian's screen quantities, in `f64`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Screen {
    /// Projected mean (pixels).
    pub mean: [f64; 2],
    /// Conic `(a, b, c)`.
    pub conic: [f64; 3],
    /// Opacity (× compensation when antialiased).
    pub opacity: f64,
    /// Camera z.
    pub depth: f64,
    /// Colour.
    pub color: [f64; 3],
    /// Screen box half sizes.
    pub radius: [f64; 2],
    /// Row-span coefficients (as [`crate::render::project::EwaSplat::span`]).
    pub span: [f32; 3],
}

/// Gradients of a loss with respect to one Gaussian's screen quantities.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct ScreenGrad {
    pub mean: [f64; 2],
    pub conic: [f64; 3],
    pub opacity: f64,
    pub depth: f64,
    pub color: [f64; 3],
}

/// Gradients with respect to one Gaussian's raw parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct ParamGrad {
    pub mean: [f64; 3],
    pub log_scale: [f64; 3],
    pub rotation: [f64; 4],
    pub opacity_logit: f64,
    pub sh: [f64; 48],
}

/// `1 / (1 + e^−x)` without overflow.
pub(crate) fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// The unit quaternion `[w, x, y, z]` of a raw one and its norm (identity and 0 for a zero or
/// non-finite one).
pub(crate) fn normalized(q: [f64; 4]) -> ([f64; 4], f64) {
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if norm > 0.0 && norm.is_finite() {
        (q.map(|v| v / norm), norm)
    } else {
        ([1.0, 0.0, 0.0, 0.0], 0.0)
    }
}

/// The rotation matrix of a unit quaternion `[w, x, y, z]`.
pub(crate) fn rotation_matrix([w, x, y, z]: [f64; 4]) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        ),
        DVec3::new(
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ),
        DVec3::new(
            2.0 * (x * z + w * y),
            2.0 * (y * z - w * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    )
}

/// The intermediate values of one projection that its vector-Jacobian product reuses.
struct Trace {
    t: DVec3,
    /// Whether x/z (y/z) lies inside the clamp.
    free_x: bool,
    free_y: bool,
    tx: f64,
    ty: f64,
    j0: DVec3,
    j1: DVec3,
    /// `W R S` (camera-space square root of the covariance).
    l: DMat3,
    rot: DMat3,
    qn: [f64; 4],
    qnorm: f64,
    scale: DVec3,
    a0: DVec3,
    a1: DVec3,
    /// `Σ2D` before the dilation.
    cov: [f64; 3],
    /// Dilated `Σ2D` and its determinant.
    dil: [f64; 3],
    det: f64,
    sig: f64,
    /// Antialiasing compensation (1 when off).
    comp: f64,
    color: ColorTrace,
}

/// What the colour's vector-Jacobian product reuses.
pub(crate) struct ColorTrace {
    dir: DVec3,
    degree: u8,
    basis: [f64; 16],
    /// Colour channels with `raw + 0.5 > 0` (not clamped).
    color_free: [bool; 3],
    /// The SH coefficients (file order).
    coeffs: [f64; 48],
}

/// Gaussian `i`'s colour `max(Σ sh_k Y_k(dir) + 0.5, 0)` seen from `position`
/// (`dir = mean − position`).
pub(crate) fn color<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    position: DVec3,
) -> ([f64; 3], ColorTrace) {
    let degree = p.sh_degree().min(3);
    let dir = p.mean(i) - position;
    let basis = sh_basis(degree, dir);
    let mut coeffs = [0.0; 48];
    p.sh_coeffs(i, &mut coeffs);
    let k = sh_coeffs_per_channel(degree);
    let mut color = [0.0; 3];
    let mut color_free = [false; 3];
    for c in 0..3 {
        let mut sum = coeffs[c] * basis[0];
        for (j, y) in basis.iter().enumerate().take(k).skip(1) {
            sum += coeffs[3 + c * (k - 1) + (j - 1)] * y;
        }
        color_free[c] = sum + 0.5 > 0.0;
        color[c] = (sum + 0.5).max(0.0);
    }
    let trace = ColorTrace {
        dir,
        degree,
        basis,
        color_free,
        coeffs,
    };
    (color, trace)
}

/// Carries the colour gradient `g` to the SH coefficients (written into `sh`) and returns its
/// part of the mean's gradient (through the view direction).
pub(crate) fn color_vjp(tr: &ColorTrace, g: [f64; 3], sh: &mut [f64; 48]) -> DVec3 {
    let degree = tr.degree;
    let k = sh_coeffs_per_channel(degree);
    let coeffs = &tr.coeffs;
    let mut g_basis = [0.0; 16];
    for c in 0..3 {
        if !tr.color_free[c] {
            continue;
        }
        let gc = g[c];
        sh[c] = gc * tr.basis[0];
        for (j, (gb, y)) in g_basis
            .iter_mut()
            .zip(&tr.basis)
            .enumerate()
            .take(k)
            .skip(1)
        {
            let idx = 3 + c * (k - 1) + (j - 1);
            sh[idx] = gc * y;
            *gb += gc * coeffs[idx];
        }
    }
    if degree == 0 {
        return DVec3::ZERO;
    }
    let len = tr.dir.length();
    if !(len > 0.0 && len.is_finite()) {
        return DVec3::ZERO;
    }
    let d = tr.dir / len;
    let dg = sh_basis_grad(degree, d);
    let mut g_d = DVec3::ZERO;
    for j in 1..k {
        g_d += DVec3::from_array(dg[j]) * g_basis[j];
    }
    (g_d - d * d.dot(g_d)) / len
}

/// Carries the gradient `g_r` of the rotation matrix of the unit quaternion `qn` (column `m` of
/// `g_r` is d loss / d column `m`) through `qn = q / |q|` to the raw quaternion of norm
/// `qnorm` (zero for a zero or non-finite quaternion, which [`normalized`] replaces).
pub(crate) fn quaternion_vjp(qn: [f64; 4], qnorm: f64, g_r: [DVec3; 3]) -> [f64; 4] {
    // g[r][c] = ∂L/∂R_rc = column c, row r.
    let gr = |r: usize, c: usize| g_r[c][r];
    let [qw, qx, qy, qz] = qn;
    let g_qn = [
        2.0 * (-qz * gr(0, 1) + qy * gr(0, 2) + qz * gr(1, 0) - qx * gr(1, 2) - qy * gr(2, 0)
            + qx * gr(2, 1)),
        2.0 * (-2.0 * qx * gr(1, 1) - 2.0 * qx * gr(2, 2)
            + qy * gr(0, 1)
            + qz * gr(0, 2)
            + qy * gr(1, 0)
            - qw * gr(1, 2)
            + qz * gr(2, 0)
            + qw * gr(2, 1)),
        2.0 * (-2.0 * qy * gr(0, 0) - 2.0 * qy * gr(2, 2)
            + qx * gr(0, 1)
            + qw * gr(0, 2)
            + qx * gr(1, 0)
            + qz * gr(1, 2)
            - qw * gr(2, 0)
            + qz * gr(2, 1)),
        2.0 * (-2.0 * qz * gr(0, 0) - 2.0 * qz * gr(1, 1) - qw * gr(0, 1)
            + qx * gr(0, 2)
            + qw * gr(1, 0)
            + qy * gr(1, 2)
            + qx * gr(2, 0)
            + qy * gr(2, 1)),
    ];
    if qnorm > 0.0 {
        let dot: f64 = (0..4).map(|m| qn[m] * g_qn[m]).sum();
        std::array::from_fn(|m| (g_qn[m] - qn[m] * dot) / qnorm)
    } else {
        [0.0; 4]
    }
}

/// Projects Gaussian `i` (module documentation); `None` when culled. The values equal those of
/// [`crate::render::project::project_ewa`] up to `f32` rounding of its inputs.
pub(crate) fn project<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    v: &View,
    o: &RenderOptions,
) -> Option<Screen> {
    trace(p, i, v, o).map(|(s, _)| s)
}

fn trace<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    v: &View,
    o: &RenderOptions,
) -> Option<(Screen, Trace)> {
    let mean = p.mean(i);
    let t = v.cam.w2c * (mean - v.cam.position);
    let z = t.z;
    if !(z > f64::from(o.near) && z < f64::from(o.far)) {
        return None;
    }
    let sig = sigmoid(p.opacity_logit(i));
    if sig <= 0.0 && o.rules == Rules::Gsplat {
        return None;
    }
    let (qn, qnorm) = normalized(p.rotation(i));
    let rot = rotation_matrix(qn);
    let scale = p.log_scale(i).exp();
    let l = v.cam.w2c
        * DMat3::from_cols(
            rot.x_axis * scale.x,
            rot.y_axis * scale.y,
            rot.z_axis * scale.z,
        );
    let e = ewa_screen(v, o, t, l, sig)?;
    let (color, color_trace) = self::color(p, i, v.cam.position);
    let screen = Screen {
        mean: e.mean,
        conic: e.conic,
        opacity: e.opacity,
        depth: z,
        color,
        radius: e.radius,
        span: e.span,
    };
    let trace = Trace {
        t,
        free_x: e.free[0],
        free_y: e.free[1],
        tx: e.tx,
        ty: e.ty,
        j0: e.j0,
        j1: e.j1,
        l,
        rot,
        qn,
        qnorm,
        scale,
        a0: e.a0,
        a1: e.a1,
        cov: e.cov,
        dil: e.dil,
        det: e.det,
        sig,
        comp: e.comp,
        color: color_trace,
    };
    Some((screen, trace))
}

/// Derivatives of the 16 SH basis values with respect to the unit direction `(x, y, z)` (the
/// polynomials of [`sh_basis`] differentiated term by term).
pub(crate) fn sh_basis_grad(degree: u8, d: DVec3) -> [[f64; 3]; 16] {
    let mut g = [[0.0; 3]; 16];
    if degree == 0 {
        return g;
    }
    let (x, y, z) = (d.x, d.y, d.z);
    g[1] = [0.0, -SH_C1, 0.0];
    g[2] = [0.0, 0.0, SH_C1];
    g[3] = [-SH_C1, 0.0, 0.0];
    if degree == 1 {
        return g;
    }
    g[4] = [SH_C2[0] * y, SH_C2[0] * x, 0.0];
    g[5] = [0.0, SH_C2[1] * z, SH_C2[1] * y];
    g[6] = [-2.0 * SH_C2[2] * x, -2.0 * SH_C2[2] * y, 4.0 * SH_C2[2] * z];
    g[7] = [SH_C2[3] * z, 0.0, SH_C2[3] * x];
    g[8] = [2.0 * SH_C2[4] * x, -2.0 * SH_C2[4] * y, 0.0];
    if degree == 2 {
        return g;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    g[9] = [SH_C3[0] * 6.0 * x * y, SH_C3[0] * 3.0 * (xx - yy), 0.0];
    g[10] = [SH_C3[1] * y * z, SH_C3[1] * x * z, SH_C3[1] * x * y];
    g[11] = [
        SH_C3[2] * -2.0 * x * y,
        SH_C3[2] * (4.0 * zz - xx - 3.0 * yy),
        SH_C3[2] * 8.0 * y * z,
    ];
    g[12] = [
        SH_C3[3] * -6.0 * x * z,
        SH_C3[3] * -6.0 * y * z,
        SH_C3[3] * (6.0 * zz - 3.0 * xx - 3.0 * yy),
    ];
    g[13] = [
        SH_C3[4] * (4.0 * zz - 3.0 * xx - yy),
        SH_C3[4] * -2.0 * x * y,
        SH_C3[4] * 8.0 * x * z,
    ];
    g[14] = [
        SH_C3[5] * 2.0 * x * z,
        SH_C3[5] * -2.0 * y * z,
        SH_C3[5] * (xx - yy),
    ];
    g[15] = [SH_C3[6] * 3.0 * (xx - yy), SH_C3[6] * -6.0 * x * y, 0.0];
    g
}

/// Carries the screen gradient `g` of Gaussian `i` back to its raw parameters (the projection
/// must not have culled it; `None` if it does now). Formulas in docs/conventions.md §5
/// "Gradients".
pub(crate) fn project_vjp<P: DiffParams + ?Sized>(
    p: &P,
    i: usize,
    v: &View,
    o: &RenderOptions,
    g: &ScreenGrad,
) -> Option<ParamGrad> {
    let (s, tr) = trace(p, i, v, o)?;
    let mut out = ParamGrad {
        mean: [0.0; 3],
        log_scale: [0.0; 3],
        rotation: [0.0; 4],
        opacity_logit: 0.0,
        sh: [0.0; 48],
    };
    let mut g_mean = DVec3::ZERO;

    // Colour → SH coefficients and the view direction.
    g_mean += color_vjp(&tr.color, g.color, &mut out.sh);

    // Opacity = sigmoid(logit) × compensation.
    out.opacity_logit = g.opacity * tr.comp * tr.sig * (1.0 - tr.sig);
    let [c00, c01, c11] = tr.cov;
    let [d00, _, d11] = tr.dil;
    let mut g_c00 = 0.0;
    let mut g_c01 = 0.0;
    let mut g_c11 = 0.0;
    if o.antialiased && tr.comp > 0.0 {
        // comp = sqrt(det_orig / det): d comp = comp/2 (d det_orig / det_orig − d det / det).
        let det_orig = c00 * c11 - c01 * c01;
        let h = 0.5 * g.opacity * tr.sig * tr.comp;
        g_c00 += h * (c11 / det_orig - d11 / tr.det);
        g_c11 += h * (c00 / det_orig - d00 / tr.det);
        g_c01 += h * (-2.0 * c01 / det_orig + 2.0 * c01 / tr.det);
    }

    // Conic K = Σ2D⁻¹: dK = −K dΣ K.
    let [a, b, c] = s.conic;
    let [ga, gb, gc] = g.conic;
    g_c00 -= ga * a * a + gb * a * b + gc * b * b;
    g_c11 -= ga * b * b + gb * b * c + gc * c * c;
    g_c01 -= 2.0 * ga * a * b + gb * (a * c + b * b) + 2.0 * gc * b * c;

    // Σ2D = [a0·a0, a0·a1; a0·a1, a1·a1] with a0 = Lᵀ j0, a1 = Lᵀ j1.
    let g_a0 = 2.0 * g_c00 * tr.a0 + g_c01 * tr.a1;
    let g_a1 = 2.0 * g_c11 * tr.a1 + g_c01 * tr.a0;
    let g_j0 = tr.l * g_a0;
    let g_j1 = tr.l * g_a1;
    // d/dL_ij of (Lᵀ j)_j' = j_i δ_jj': g_L = j0 g_a0ᵀ + j1 g_a1ᵀ (column m: j0 g_a0[m] + ...).
    let g_l = DMat3::from_cols(
        tr.j0 * g_a0.x + tr.j1 * g_a1.x,
        tr.j0 * g_a0.y + tr.j1 * g_a1.y,
        tr.j0 * g_a0.z + tr.j1 * g_a1.z,
    );
    // L = W R S.
    let g_m = v.cam.w2c.transpose() * g_l;
    let cols = [g_m.x_axis, g_m.y_axis, g_m.z_axis];
    let rcols = [tr.rot.x_axis, tr.rot.y_axis, tr.rot.z_axis];
    let sc = tr.scale.to_array();
    let mut g_r = [DVec3::ZERO; 3];
    for m in 0..3 {
        g_r[m] = cols[m] * sc[m];
        let g_s = rcols[m].dot(cols[m]);
        out.log_scale[m] = if sc[m] > 0.0 { g_s * sc[m] } else { 0.0 };
    }
    out.rotation = quaternion_vjp(tr.qn, tr.qnorm, g_r);

    // Camera-space mean t: the Jacobian, the projected mean and the depth.
    let (fx, fy) = (v.cam.fx, v.cam.fy);
    let z = tr.t.z;
    let (rz, rz2) = (1.0 / z, 1.0 / (z * z));
    let rz3 = rz2 * rz;
    let mut g_t = DVec3::ZERO;
    g_t.z += g_j0.x * (-fx * rz2) + g_j1.y * (-fy * rz2);
    g_t.z += g_j0.z * 2.0 * fx * tr.tx * rz3 + g_j1.z * 2.0 * fy * tr.ty * rz3;
    let g_tx = g_j0.z * (-fx * rz2);
    let g_ty = g_j1.z * (-fy * rz2);
    if tr.free_x {
        g_t.x += g_tx;
    } else {
        g_t.z += g_tx * tr.tx * rz;
    }
    if tr.free_y {
        g_t.y += g_ty;
    } else {
        g_t.z += g_ty * tr.ty * rz;
    }
    let [gu, gw] = g.mean;
    g_t.x += gu * fx * rz;
    g_t.y += gw * fy * rz;
    g_t.z -= (gu * fx * tr.t.x + gw * fy * tr.t.y) * rz2;
    g_t.z += g.depth;
    g_mean += v.cam.w2c.transpose() * g_t;
    out.mean = g_mean.to_array();
    Some(out)
}
