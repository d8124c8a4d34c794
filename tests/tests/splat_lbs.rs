//! `lbs` deformation on Khronos skinned models: the skinning data reproduces the evaluated
//! vertices, and Gaussians placed at vertices follow the skinned vertices.

use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate};
use trisplat_geometry::rng::Rng;
use trisplat_splat::Convention;
use trisplat_splat::LbsDeformer;
use trisplat_splat::attach;
use trisplat_splat::glam::{DMat3, DQuat, DVec3, Vec3};
use trisplat_splat::{GaussianParts, GaussianSet};

/// Gaussians at vertices against skinned vertices, relative to the model's bounding-box
/// diagonal: f32 storage of the local parameters and of the outputs.
const FOLLOW_TOL: f64 = 1e-5;

/// Skinning data applied in f64 against the evaluator's f32 output, relative to the diagonal.
const SKINNING_TOL: f64 = 1e-6;

fn times(template: &GltfTemplate) -> Vec<f64> {
    let d = template.duration();
    // Keys, between keys, and past the end.
    vec![0.0, 0.013, d * 0.37, d * 0.5 + 0.0071, d, d + 0.5]
}

fn diagonal(template: &GltfTemplate) -> f64 {
    template.rest().bounds().expect("bounds").diagonal()
}

fn world_at_vertices(template: &GltfTemplate) -> GaussianSet {
    let p = template.rest().positions();
    let n = p.len();
    let mut rng = Rng::new(3);
    let mut u = || rng.uniform_f32() - 0.5;
    GaussianSet::try_new(GaussianParts {
        means: p.iter().map(|v| v.as_vec3()).collect(),
        log_scales: (0..n).map(|_| Vec3::new(u(), u(), u()) - 4.0).collect(),
        rotations: (0..n).map(|_| [u() + 1.0, u(), u(), u()]).collect(),
        opacity_logits: vec![0.0; n],
        sh: vec![0.0; 3 * n],
        ..GaussianParts::default()
    })
    .expect("valid set")
}

fn check(file: &str) {
    let path = trisplat_fixtures::path(file);
    let template = GltfTemplate::open(&path, &Clip::Index(0)).expect("open");
    assert!(template.is_skinned(), "{file}");
    let diag = diagonal(&template);
    let skin = template.skinning();
    // The palette reproduces the evaluator (no morph targets in these models).
    for t in times(&template) {
        let want = template.evaluate_at(t).expect("evaluate");
        let palette = template.palette_at(Some(t)).expect("palette");
        let mut worst = 0.0f64;
        for (v, w) in want.iter().enumerate() {
            let mut p = DVec3::ZERO;
            for (k, weight) in skin.influences(v) {
                p += weight * palette[k].transform_point3(skin.base_positions[v]);
            }
            worst = worst.max((p - w).length() / diag);
        }
        assert!(worst < SKINNING_TOL, "{file} t={t}: {worst}");
    }
    // Gaussians at the vertices follow them.
    let rest = template.rest();
    let world = world_at_vertices(&template);
    let bound = attach(&world, rest, Convention::GaussianAvatars).expect("attach");
    let rig = LbsDeformer::new(
        &bound,
        rest,
        &skin,
        &template.palette_at(None).expect("rest"),
    )
    .expect("rig");
    // At rest the rig gives the world set back.
    let at_rest = rig
        .deform(&bound, &template.palette_at(None).expect("rest"), None)
        .expect("deform");
    let mut worst_rest = 0.0f64;
    for (a, b) in at_rest.means().iter().zip(world.means()) {
        worst_rest = worst_rest.max((a.as_dvec3() - b.as_dvec3()).length() / diag);
    }
    assert!(worst_rest < FOLLOW_TOL, "{file} rest: {worst_rest}");
    let mut worst = 0.0f64;
    let mut worst_rot = 0.0f64;
    for t in times(&template) {
        let want = template.evaluate_at(t).expect("evaluate");
        let palette = template.palette_at(Some(t)).expect("palette");
        let moved = rig.deform(&bound, &palette, None).expect("deform");
        for (v, w) in want.iter().enumerate() {
            let d = (moved.means()[v].as_dvec3() - w).length() / diag;
            worst = worst.max(d);
            // A vertex bound to one joint turns with it: R = polar(P_t P_rest⁻¹) R_rest.
            let infl: Vec<(usize, f64)> = skin.influences(v).collect();
            if infl.len() == 1 {
                let rel = palette[infl[0].0]
                    * template.palette_at(None).expect("rest")[infl[0].0].inverse();
                let lin = DMat3::from_cols(
                    rel.x_axis.truncate(),
                    rel.y_axis.truncate(),
                    rel.z_axis.truncate(),
                );
                let q_joint =
                    DQuat::from_mat3(&trisplat_splat::polar_rotation(lin).expect("rotation"));
                let [rw, rx, ry, rz] = at_rest.rotations()[v].map(f64::from);
                let want_q = q_joint * DQuat::from_xyzw(rx, ry, rz, rw);
                let [gw, gx, gy, gz] = moved.rotations()[v].map(f64::from);
                let got = DQuat::from_xyzw(gx, gy, gz, gw);
                worst_rot = worst_rot.max(1.0 - got.dot(want_q).abs());
            }
        }
    }
    println!("{file}: vertices followed to {worst:.2e} of the diagonal, rotations {worst_rot:.1e}");
    assert!(worst < FOLLOW_TOL, "{file}: {worst}");
    assert!(worst_rot < FOLLOW_TOL, "{file}: {worst_rot}");
}

#[test]
fn gaussians_at_vertices_follow_cesium_man() {
    check("anim/CesiumMan.glb");
}

#[test]
fn gaussians_at_vertices_follow_rigged_simple() {
    check("gltf/RiggedSimple.glb");
}

#[test]
fn gaussians_at_vertices_follow_rigged_figure() {
    check("anim/RiggedFigure.glb");
}

#[test]
fn bad_palettes_are_errors() {
    let path = trisplat_fixtures::path("gltf/RiggedSimple.glb");
    let template = GltfTemplate::open(&path, &Clip::Index(0)).expect("open");
    let rest = template.rest();
    let bound = attach(
        &world_at_vertices(&template),
        rest,
        Convention::GaussianAvatars,
    )
    .expect("attach");
    let skin = template.skinning();
    let palette = template.palette_at(None).expect("rest");
    let rig = LbsDeformer::new(&bound, rest, &skin, &palette).expect("rig");
    assert!(rig.deform(&bound, &palette[1..], None).is_err());
    let mut nan = palette.clone();
    nan[0].x_axis.x = f64::NAN;
    assert!(rig.deform(&bound, &nan, None).is_err());
    assert!(LbsDeformer::new(&bound, rest, &skin, &nan).is_err());
    // Adaptive scale needs the frame's vertices.
    let adaptive = rig.with_adaptive_scale(rest);
    assert!(adaptive.deform(&bound, &palette, None).is_err());
    let same = adaptive
        .deform(&bound, &palette, Some(rest.positions()))
        .expect("deform");
    // At rest every area ratio is 1: scales unchanged.
    let plain = LbsDeformer::new(&bound, rest, &skin, &palette)
        .expect("rig")
        .deform(&bound, &palette, None)
        .expect("deform");
    assert_eq!(same.log_scales(), plain.log_scales());
}
