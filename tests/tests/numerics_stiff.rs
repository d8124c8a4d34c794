//! The stiff-case suite (docs/numerics.md, issue #18 item 2): sliver and needle triangles,
//! triangles collapsing to zero area, near-identity and near-reflection Jacobians, Gaussians with
//! scale ratios up to 1e8 and log-scales down to −23, surfels with a zero scale, the W2 gate
//! between nearly singular and nearly equal covariances, circumradii, Delaunay and alpha shapes of
//! co-spherical / co-circular points, and TSDF fusion at grazing angles.
//!
//! References: `fixtures/data/reference/stiff/*.json`, written by
//! `tests/reference/ref_stiff.py` with mpmath at 50 digits; each group also carries the error of
//! a naive float32 implementation (numpy, the textbook formula). Every operation's worst error
//! is checked against a stated bound; run with `--nocapture` to print the table that
//! docs/numerics.md shows.
//!
//! Errors, as in the script: `rel` = |x − r| / |r|; vectors and matrices: the largest entry
//! error over the largest reference entry; scales: relative per nonzero reference scale (|s| /
//! r₀ for a zero one); TSDF values: absolute (tsdf is in units of the truncation), 1 for a voxel
//! left unobserved; surface crossings: distance to the exact plane in voxels. Inputs are the
//! exact `f64` values of the fixture (`f32`-exact where the function takes `f32` data).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use glam::{DMat3, DVec3, IVec3, Vec3};
use serde_json::Value;
use trisplat_extract::alpha_shape::{alpha_shape_from_delaunay, circumradius};
use trisplat_extract::delaunay3d::Delaunay3d;
use trisplat_extract::tsdf::{DepthImage, Frame, TsdfParams, TsdfVolume};
use trisplat_geometry::{Camera, TriId, TriMesh};
use trisplat_splat::polar_rotation;
use trisplat_splat::{
    Binding, BindingEncoding, GaussianParts, GaussianSet, ParameterSpace, ScaleDims,
};
use trisplat_splat::{
    CanonicalTriangle, Convention, FrameOptions, deformation_gradient, edge_matrix, frame,
    gaussian_avatars_frame, transform_normal,
};
use trisplat_splat::{
    DeformMode, Deformer, FrameHold, rotation_and_scales, rotation_and_scales_svd,
};
use trisplat_splat::{bures_sq, w2_sq};

/// Unit roundoff of `f64` (2⁻⁵³).
const U64: f64 = f64::EPSILON / 2.0;

// ------------------------------------------------------------------ fixture reading

fn load(name: &str) -> Value {
    let path = trisplat_fixtures::path(&format!("reference/stiff/{name}.json"));
    let text = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let json: Value = serde_json::from_slice(&text).unwrap();
    assert_eq!(json["digits"], 50, "references at 50 digits");
    json
}

fn groups(json: &Value) -> &Vec<Value> {
    json["groups"].as_array().unwrap()
}

/// A number given as a decimal string (inputs: exact; references: 25 digits).
fn num(v: &Value) -> f64 {
    let s = v.as_str().unwrap_or_else(|| panic!("not a string: {v}"));
    s.parse().unwrap_or_else(|e| panic!("{s}: {e}"))
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(num).collect()
}

fn v3(v: &Value) -> DVec3 {
    DVec3::from_slice(&nums(v))
}

fn m3(v: &Value) -> DMat3 {
    DMat3::from_cols_slice(&nums(v))
}

fn tri(v: &Value) -> [DVec3; 3] {
    let a = v.as_array().unwrap();
    [v3(&a[0]), v3(&a[1]), v3(&a[2])]
}

/// Corners given as f32 decimals (the deformers' templates are f32 data), exactly.
fn tri32(v: &Value) -> [DVec3; 3] {
    let a = v.as_array().unwrap();
    [0, 1, 2].map(|k| Vec3::from_slice(&f32s(&a[k])).as_dvec3())
}

fn f32s(v: &Value) -> Vec<f32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap().parse().unwrap())
        .collect()
}

// ------------------------------------------------------------------ errors

fn rel(x: f64, r: f64) -> f64 {
    if x.is_finite() {
        (x - r).abs() / r.abs()
    } else {
        f64::NAN
    }
}

/// Largest entry error over the largest reference entry.
fn arr_rel(x: &[f64], r: &[f64]) -> f64 {
    assert_eq!(x.len(), r.len());
    if !x.iter().all(|v| v.is_finite()) {
        return f64::NAN;
    }
    let big = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let err = x
        .iter()
        .zip(r)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    err / big
}

/// Scales: relative per nonzero reference, |s| / r₀ for a zero reference.
fn scales_rel(x: &[f64], r: &[f64]) -> f64 {
    if !x.iter().all(|v| v.is_finite()) {
        return f64::NAN;
    }
    x.iter().zip(r).fold(0.0f64, |m, (a, b)| {
        m.max(if *b > 0.0 {
            (a - b).abs() / b
        } else {
            a.abs() / r[0]
        })
    })
}

fn max_err(errs: &[f64]) -> f64 {
    if errs.iter().any(|e| e.is_nan()) {
        f64::NAN
    } else {
        errs.iter().fold(0.0f64, |m, e| m.max(*e))
    }
}

// ------------------------------------------------------------------ tallies and the table

#[derive(Default)]
struct Tally {
    worst: f64,
    nan: usize,
    count: usize,
}

impl Tally {
    fn add(&mut self, err: f64) {
        self.count += 1;
        if err.is_nan() {
            self.nan += 1;
        } else {
            self.worst = self.worst.max(err);
        }
    }
}

/// Worst errors per (op, quantity, case), in fixture order.
#[derive(Default)]
struct Report {
    rows: Vec<(String, String, String)>,
    tallies: BTreeMap<(String, String, String), Tally>,
    naive: BTreeMap<(String, String, String), String>,
}

impl Report {
    fn add(&mut self, op: &str, quantity: &str, group: &Value, err: f64) {
        let case = group["case"].as_str().unwrap().to_owned();
        let key = (op.to_owned(), quantity.to_owned(), case);
        if !self.tallies.contains_key(&key) {
            self.rows.push(key.clone());
            let naive = &group["naive_f32"][naive_quantity(quantity)];
            self.naive.insert(key.clone(), naive_cell(naive));
        }
        self.tallies.entry(key).or_default().add(err);
    }

    /// Prints the table and asserts every bound; panics listing every row over its bound.
    fn check(&self, title: &str) {
        let mut out = String::new();
        let mut failures = Vec::new();
        writeln!(out, "\n### {title}\n").unwrap();
        writeln!(
            out,
            "| operation | quantity | case | trisplat worst | naive f32 worst | bound |"
        )
        .unwrap();
        writeln!(out, "|---|---|---|---|---|---|").unwrap();
        for key in &self.rows {
            let t = &self.tallies[key];
            let b = bound(&key.0, &key.1, &key.2);
            let ours = if t.nan > 0 {
                format!("NaN in {}/{}", t.nan, t.count)
            } else {
                sci(t.worst)
            };
            writeln!(
                out,
                "| `{}` | {} | {} | {} | {} | {} |",
                key.0,
                key.1,
                key.2,
                ours,
                self.naive[key],
                sci(b)
            )
            .unwrap();
            assert!(t.count > 0);
            if t.nan > 0 || t.worst > b {
                failures.push(format!("{key:?}: {ours} > {}", sci(b)));
            }
        }
        println!("{out}");
        assert!(
            failures.is_empty(),
            "over the bound:\n{}",
            failures.join("\n")
        );
    }
}

/// The naive column's quantity for ours (the `_svd` rows share the group's naive numbers; the
/// collapse rows show how many naive frames were NaN).
fn naive_quantity(quantity: &str) -> &str {
    match quantity {
        "non-finite outputs" => "nan",
        q => q,
    }
}

fn naive_cell(v: &Value) -> String {
    if v.is_null() {
        return "—".into();
    }
    let worst: f64 = num(&v["worst"]);
    let (nan, count) = (v["nan"].as_u64().unwrap(), v["count"].as_u64().unwrap());
    match nan {
        0 => sci(worst),
        n if n == count => format!("NaN in {n}/{count}"),
        n => format!("{} (NaN in {n}/{count})", sci(worst)),
    }
}

fn sci(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.fract() == 0.0 && x.abs() < 1e6 {
        format!("{x}")
    } else {
        format!("{x:.1e}")
    }
}

// ------------------------------------------------------------------ bounds

/// The asserted bound of each (operation, quantity, case). `U64` is the unit roundoff of f64.
/// Each bound is the error the algorithm should have by its analysis, with a factor of 10-100
/// for the constants (the comment gives the scaling); a bound that has to grow means a change
/// in behaviour, not noise (the inputs are fixed, so the measured errors are deterministic).
fn bound(op: &str, quantity: &str, case: &str) -> f64 {
    let has = |s: &str| case.contains(s);
    // The aspect ratio L/h of the sliver cases (1 otherwise).
    let aspect = if has("h/L=1e-9") {
        1e9
    } else if has("h/L=1e-6") {
        1e6
    } else if has("h/L=1e-3") {
        1e3
    } else {
        1.0
    };
    match (op, quantity) {
        // Frames: the normal of a sliver is a cross product of nearly parallel edges, accurate to
        // ~u·L/h (inherent: rounding the edge differences alone perturbs it that much). Needles
        // lose nothing: the normal crosses the first edge with the shorter of the other two.
        ("frame_gaussian_avatars" | "frame_surfhead", _) => 100.0 * U64 * aspect,
        // E(v): the third column n/√|n| halves the digits the normal loses: ~u·√(L/h).
        ("edge_matrix", _) => 100.0 * U64 * aspect.sqrt(),
        // J = E(d) E(c)⁻¹: ~u·κ(E(c)) (κ ~ L/h for a sliver canonical), and ~u·√(L/h) from the
        // third column of a nearly collapsed deformed triangle.
        ("deformation_gradient", _) => {
            if has("on a sliver") || has("near collapse") {
                10.0 * U64 * 1e3
            } else {
                1e3 * U64
            }
        }
        // cof(J)·n needs no inverse and no det J ≠ 0; its 2×2 minors cancel to ~u·σ₁/σ₂
        // relative (σ₂ the middle singular value of J): 1e-12 at σ₂ = 1e-4, a few u otherwise.
        // For a J singular to rounding the orientation is compared up to sign (the computed
        // sign of det J is noise there).
        ("transform_normal", _) => {
            if has("1e8") {
                10.0 * U64 * 1e4
            } else {
                1e3 * U64
            }
        }
        // One-sided Jacobi: every σ to ~u·κ(L D⁻¹) relative, D the column norms of L = J R S
        // (Demmel–Veselić), i.e. to a few ulps whatever the scales when J is well conditioned,
        // and ~u·κ(J) = 1e-7 for a J with σ_min = 1e-9 (rounding L's entries alone perturbs
        // σ_min that much); covariance entries to ~u of the largest.
        // nalgebra's SVD (`_svd`, the test reference in splat/src/deform.rs): on these
        // column-graded L (ratios to 1e10) its Householder bidiagonalisation keeps the small σ as
        // well as Jacobi does, so the same bounds. (It does not on the two-sided grading of
        // W2's L2ᵀ L1: see `bures_sq`.)
        ("rotation_and_scales" | "rotation_and_scales_svd", "sigma") => {
            if has("nearly singular") {
                10.0 * U64 * 1e9
            } else {
                1e3 * U64
            }
        }
        ("rotation_and_scales" | "rotation_and_scales_svd", "cov" | "normal") => 100.0 * U64,
        // Scaled Newton polar iteration: forward error ~u·κ(Q), κ(Q) = 2σ₁/(σ₂+σ₃) (2e3 at
        // condition 1e6, ~2 when only σ₃ is small); `None` exactly for det ≤ 0 (error 0 or 1).
        ("polar_rotation", _) => {
            if has("None") {
                0.0
            } else if has("1e6") {
                10.0 * U64 * 2e3
            } else {
                1e3 * U64
            }
        }
        // Binding mode, end to end (f32 outputs): the output quaternion and log-scales are
        // stored in f32, so the covariance is only as good as an f32 rotation (~6e-8 per entry,
        // a few 1e-7 after products) and each scale as an f32 log-scale (|ln s| ≤ 27 here: half
        // an ulp is 1e-6 in s). Means: f32 products (`Mat3A`), ~1e-7.
        ("deform_binding", "mean") => 1e-6,
        ("deform_binding", "cov" | "sigma") => 1e-5,
        // Jacobian mode, end to end: the f32 lane kernel within its documented tolerances
        // (covariance 1e-5 of the largest entry, log-scales 1e-5: lanes::COVARIANCE_TOL,
        // LOG_SCALE_TOL), or the f64 factorisation for ill-conditioned triangles and scale
        // spreads beyond e^24; outputs in f32. Means as in binding mode.
        ("deform_jacobian", "mean") => 1e-6,
        ("deform_jacobian", "cov" | "sigma") => 1e-5,
        // W2 by the explicit residual: B² of a pair that differs by δ is ~δ²|L|², and the
        // residual L1 − L2·U is formed from entries of size |L|, so its relative error is ~u/δ
        // (the conditioning of B² itself under rounding of the inputs). The trace form in f32
        // subtracts numbers of size |L|² and keeps nothing below δ ~ 1e-4.
        ("bures_sq" | "w2_sq", _) => ["1e-4", "1e-6", "1e-8", "1e-12"]
            .iter()
            .find(|d| has(&format!("delta = {d}")))
            .map_or(1e3 * U64, |d| 100.0 * U64 / d.parse::<f64>().unwrap()),
        // Circumradius relative to the first vertex: ~u/f for a sliver whose fourth point is f
        // (relative) off the circle of the other three; offsets cost nothing (differences are
        // taken first).
        ("circumradius", _) => {
            if has("1e-6 off") || has("sliver 1e-6") {
                100.0 * U64 * 1e6
            } else if has("1e-3 off") {
                100.0 * U64 * 1e3
            } else {
                100.0 * U64
            }
        }
        // Combinatorial checks: exact; circumradii of co-spherical sets and volumes to a few u.
        ("delaunay3d", "circumradius" | "volume") => 100.0 * U64,
        ("delaunay3d" | "alpha_shape", _) => 0.0,
        // TSDF values are stored in f32: half an ulp of |tsdf| < 1 is 6e-8; the arithmetic is
        // f64 (voxel centres far from the origin included).
        ("tsdf", "tsdf") => 1e-7,
        // Zero crossings against the exact plane: the exact-arithmetic rule puts them up to
        // 0.18 voxel off (the depth of the pixel nearest the voxel's projection, not of its own
        // ray: pixel quantisation, not arithmetic), so this bounds the method; per crossing,
        // trisplat differs from the exact rule by the f32 storage of the two values only
        // (6e-8 / |a - b| ≈ 3e-7 voxel).
        ("tsdf", "crossing") => 0.2,
        ("tsdf", "crossing − exact rule's") => 1e-6,
        // Collapse policy: the held frame is the last valid one (rotations compared through
        // f32 quaternions, means moved by the f32 centroid shift), no non-finite output, flags
        // and held counts exactly where the area is 0.
        ("collapse", "held rotation − last valid (rad)") => 1e-6,
        ("collapse", "held mean − last valid moved (abs)") => 1e-6,
        ("collapse", _) => 0.0,
        _ => panic!("no bound for {op} / {quantity} / {case}"),
    }
}

// ------------------------------------------------------------------ frames and Jacobians

#[test]
fn triangle_frames_and_jacobians() {
    let json = load("frames");
    let o = FrameOptions::default();
    let mut report = Report::default();
    for g in groups(&json) {
        let op = g["op"].as_str().unwrap();
        for inst in g["instances"].as_array().unwrap() {
            let r = &inst["ref"];
            match op {
                "frame_gaussian_avatars" | "frame_surfhead" => {
                    let conv = if op == "frame_surfhead" {
                        Convention::SurfHead
                    } else {
                        Convention::GaussianAvatars
                    };
                    let f = frame(conv, tri(&inst["v"]), &o);
                    assert_eq!(f.degenerate, r["degenerate"].as_bool().unwrap(), "{inst}");
                    let err = max_err(&[
                        arr_rel(&f.rotation.to_cols_array(), &nums(&r["rotation"])),
                        rel(f.scale, num(&r["scale"])),
                        arr_rel(&f.origin.to_array(), &nums(&r["origin"])),
                    ]);
                    report.add(op, "frame", g, err);
                }
                "edge_matrix" => {
                    let e = edge_matrix(tri(&inst["v"]));
                    report.add(op, "e", g, arr_rel(&e.to_cols_array(), &nums(&r["e"])));
                }
                "deformation_gradient" => {
                    let (c, d) = (tri(&inst["canonical"]), tri(&inst["deformed"]));
                    let j = deformation_gradient(c, d, &o);
                    assert_eq!(j.degenerate, r["degenerate"].as_bool().unwrap());
                    let pre = CanonicalTriangle::new(c, &o).gradient(d, &o);
                    let want = nums(&r["j"]);
                    let err = max_err(&[
                        arr_rel(&j.matrix.to_cols_array(), &want),
                        arr_rel(&pre.to_cols_array(), &want),
                    ]);
                    report.add(op, "j", g, err);
                }
                "transform_normal" => {
                    let got = transform_normal(m3(&inst["j"]), v3(&inst["n"]));
                    let want = nums(&r["normal"]);
                    let err = got.map_or(f64::NAN, |n| {
                        let err = arr_rel(&n.to_array(), &want);
                        // det J within rounding of 0: its computed sign, and the normal's
                        // orientation, are noise (docs/numerics.md).
                        if g["sign_free"].as_bool().unwrap() {
                            err.min(arr_rel(&(-n).to_array(), &want))
                        } else {
                            err
                        }
                    });
                    report.add(op, "normal", g, err);
                }
                _ => panic!("unknown op {op}"),
            }
        }
    }
    assert_eq!(report.rows.len(), 41, "every group of frames.json measured");
    report.check("Triangle frames, edge matrices, deformation gradients, normals");
}

// ------------------------------------------------------------------ covariances

/// A one-triangle template and a set of Gaussians bound to it, deformed to `deformed`.
/// The corners are f32-exact in the fixture, so the template's storage is exact.
fn deform_one(
    mode: DeformMode,
    canonical: [DVec3; 3],
    deformed: [DVec3; 3],
    gaussians: &[Value],
    surfel: bool,
) -> GaussianSet {
    // Mesh vertices are f64: the corners go in as the fixture gives them.
    let (template, set) = one_triangle_set(canonical, gaussians, surfel);
    Deformer::new(&template, mode)
        .deform(&set, &deformed)
        .unwrap()
}

/// The fixture's Gaussians bound to one triangle whose rest shape is `canonical` (2D surfels
/// when `surfel`).
fn one_triangle_set(
    canonical: [DVec3; 3],
    gaussians: &[Value],
    surfel: bool,
) -> (TriMesh, GaussianSet) {
    let template = TriMesh::new(canonical.to_vec(), vec![[0, 1, 2]]);
    let n = gaussians.len();
    let vec3 = |v: &Value| Vec3::from_slice(&f32s(v));
    let set = GaussianSet::try_new(GaussianParts {
        means: gaussians.iter().map(|g| vec3(&g["mean"])).collect(),
        log_scales: gaussians.iter().map(|g| vec3(&g["log_scale"])).collect(),
        scale_dims: if surfel {
            ScaleDims::Two
        } else {
            ScaleDims::Three
        },
        rotations: gaussians
            .iter()
            .map(|g| f32s(&g["rot"]).try_into().unwrap())
            .collect(),
        opacity_logits: vec![0.0; n],
        sh: vec![0.0; 3 * n],
        binding: Some(Binding {
            triangles: vec![TriId(0); n],
            encoding: BindingEncoding::Float,
        }),
        space: ParameterSpace::Local,
        ..GaussianParts::default()
    })
    .unwrap();
    (template, set)
}

/// Covariance of an output Gaussian in f64 from its stored (f32) rotation and log-scales, and
/// its scales (0 for a surfel's flat axis).
fn output_covariance(set: &GaussianSet, i: usize) -> (DMat3, [f64; 3]) {
    let r = set.rotation_matrix(i);
    let ls = set.log_scales()[i].as_dvec3();
    let mut s = [ls.x.exp(), ls.y.exp(), ls.z.exp()];
    if set.scale_dims() == ScaleDims::Two {
        s[2] = 0.0;
    }
    let a = DMat3::from_cols(r.x_axis * s[0], r.y_axis * s[1], r.z_axis * s[2]);
    (a * a.transpose(), s)
}

#[test]
fn covariances_factorisations_and_deformers() {
    let json = load("covariance");
    let mut report = Report::default();
    for g in groups(&json) {
        let op = g["op"].as_str().unwrap();
        for inst in g["instances"].as_array().unwrap() {
            let r = &inst["ref"];
            match op {
                "rotation_and_scales" => {
                    let l = m3(&inst["l"]);
                    for (name, f) in [
                        ("rotation_and_scales", rotation_and_scales as fn(DMat3) -> _),
                        ("rotation_and_scales_svd", rotation_and_scales_svd),
                    ] {
                        let (u, s) = f(l);
                        assert!((u.determinant() - 1.0).abs() < 1e-12, "{name}: proper");
                        report.add(
                            name,
                            "sigma",
                            g,
                            scales_rel(&s.to_array(), &nums(&r["sigma"])),
                        );
                        let back = u * DMat3::from_diagonal(s * s) * u.transpose();
                        report.add(
                            name,
                            "cov",
                            g,
                            arr_rel(&back.to_cols_array(), &nums(&r["cov"])),
                        );
                        if !r["normal"].is_null() {
                            // |sin| of the angle between the flat axis and the reference normal.
                            let sin = u.z_axis.cross(v3(&r["normal"]).normalize()).length();
                            report.add(name, "normal", g, sin);
                        }
                    }
                }
                "polar_rotation" => {
                    let got = polar_rotation(m3(&inst["a"]));
                    let err = match (got, r["q"].is_null()) {
                        (None, true) => 0.0,
                        (Some(_), true) => 1.0,
                        (None, false) => f64::NAN,
                        (Some(q), false) => arr_rel(&q.to_cols_array(), &nums(&r["q"])),
                    };
                    report.add(op, "q", g, err);
                }
                "deform_binding" | "deform_jacobian" => {
                    let mode = if op == "deform_binding" {
                        DeformMode::Binding
                    } else {
                        DeformMode::Jacobian
                    };
                    let surfel = inst["surfel"].as_bool().unwrap();
                    let gs = inst["gaussians"].as_array().unwrap();
                    let out = deform_one(
                        mode,
                        tri32(&inst["canonical"]),
                        tri32(&inst["deformed"]),
                        gs,
                        surfel,
                    );
                    for (i, want) in r.as_array().unwrap().iter().enumerate() {
                        let mean = out.means()[i].as_dvec3().to_array();
                        report.add(op, "mean", g, arr_rel(&mean, &nums(&want["mean"])));
                        let (cov, mut s) = output_covariance(&out, i);
                        report.add(
                            op,
                            "cov",
                            g,
                            arr_rel(&cov.to_cols_array(), &nums(&want["cov"])),
                        );
                        let mut ws = nums(&want["sigma"]);
                        if mode == DeformMode::Jacobian {
                            // Output scales are sorted (shortest last), as the reference's.
                            let k = if surfel { 2 } else { 3 };
                            s[..k].sort_by(|a, b| b.total_cmp(a));
                        }
                        if surfel {
                            ws.truncate(2);
                        }
                        report.add(op, "sigma", g, scales_rel(&s[..ws.len()], &ws));
                    }
                }
                _ => panic!("unknown op {op}"),
            }
        }
    }
    // 15 factorisation groups x 2 functions x (sigma, cov) + 2 surfel groups x 2 normals,
    // 5 polar groups, 24 deformer groups x (mean, cov, sigma).
    assert_eq!(report.rows.len(), 15 * 2 * 2 + 2 * 2 + 5 + 24 * 3);
    report.check("Covariances: factorisations, polar rotation, deformers end to end");
}

// ------------------------------------------------------------------ W2

#[test]
fn wasserstein_gate() {
    let json = load("w2");
    let mut report = Report::default();
    for g in groups(&json) {
        for inst in g["instances"].as_array().unwrap() {
            let (l1, l2) = (m3(&inst["l1"]), m3(&inst["l2"]));
            let r = &inst["ref"];
            report.add(
                "bures_sq",
                "bures_sq",
                g,
                rel(bures_sq(l1, l2), num(&r["bures_sq"])),
            );
            let w = w2_sq(v3(&inst["mu1"]), l1, v3(&inst["mu2"]), l2);
            report.add("w2_sq", "w2_sq", g, rel(w, num(&r["w2_sq"])));
        }
    }
    assert_eq!(report.rows.len(), 14);
    report.check("The W2 gate");
}

// ------------------------------------------------------------------ alpha shapes, Delaunay

#[test]
fn circumradii_delaunay_and_alpha_shapes() {
    let json = load("alpha");
    let mut report = Report::default();
    for g in groups(&json) {
        let op = g["op"].as_str().unwrap();
        for inst in g["instances"].as_array().unwrap() {
            match op {
                "circumradius" => {
                    let p: Vec<[f64; 3]> = inst["p"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|x| v3(x).to_array())
                        .collect();
                    let r = circumradius(p.try_into().unwrap());
                    report.add(op, "r", g, rel(r, num(&inst["ref"]["r"])));
                }
                "delaunay_alpha" => delaunay_set(&mut report, g, inst),
                _ => panic!("unknown op {op}"),
            }
        }
    }
    report.check("Circumradii, Delaunay and alpha shapes");
}

/// One co-spherical / co-circular set: a valid tetrahedralisation (exact predicates, brute-force
/// empty spheres), the hull face count, circumradii of every tetrahedron against the sphere's
/// radius, alpha shapes just above and below that radius, the volume of the tetrahedra.
fn delaunay_set(report: &mut Report, g: &Value, inst: &Value) {
    let name = inst["name"].as_str().unwrap();
    let points: Vec<[f64; 3]> = inst["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| v3(x).to_array())
        .collect();
    let d = Delaunay3d::from_f64(points).unwrap();
    let violations = d.sanity_check(true);
    report.add(
        "delaunay3d",
        "sanity_check violations",
        g,
        violations.len() as f64,
    );
    let hull = inst["hull_faces"].as_u64().unwrap() as usize;
    let hull_mismatch = d.hull_face_count().abs_diff(hull);
    report.add(
        "delaunay3d",
        "hull faces − expected",
        g,
        hull_mismatch as f64,
    );
    let pts = d.points();
    let tets = d.tetrahedra();
    let radii: Vec<f64> = tets
        .iter()
        .map(|t| circumradius(t.map(|v| pts[v as usize])))
        .collect();
    if hull == 0 {
        assert!(tets.is_empty() && d.dimension() < 3, "{name}");
    }
    assert!(
        radii.iter().all(|r| !r.is_nan()),
        "{name}: NaN circumradius"
    );
    if !inst["radius"].is_null() {
        let radius = num(&inst["radius"]);
        for &r in &radii {
            report.add("delaunay3d", "circumradius", g, rel(r, radius));
        }
        // Just above the common circumradius every tetrahedron is kept and the shape is the
        // hull; just below, nothing.
        let above = alpha_shape_from_delaunay(&d, radius * (1.0 + 1e-9)).unwrap();
        let below = alpha_shape_from_delaunay(&d, radius * (1.0 - 1e-9)).unwrap();
        let wrong = above.mesh.triangles().len().abs_diff(hull)
            + above.kept_tetrahedra.abs_diff(tets.len())
            + below.mesh.triangles().len()
            + below.kept_tetrahedra;
        report.add(
            "alpha_shape",
            "faces at R(1 ± 1e-9) − expected",
            g,
            wrong as f64,
        );
    }
    if !inst["volume"].is_null() {
        let volume: f64 = tets
            .iter()
            .map(|t| {
                // Shewchuk's orient3d(a, b, c, e) = (a - e) · ((b - e) × (c - e)) > 0.
                let [a, b, c, e] = t.map(|v| DVec3::from_array(pts[v as usize]));
                (a - e).dot((b - e).cross(c - e)) / 6.0
            })
            .sum();
        report.add("delaunay3d", "volume", g, rel(volume, num(&inst["volume"])));
    }
}

// ------------------------------------------------------------------ TSDF

#[test]
fn tsdf_at_grazing_angles() {
    let json = load("tsdf");
    let mut report = Report::default();
    for g in groups(&json) {
        let inst = &g["instances"][0];
        let cam = &inst["camera"];
        let (w, h) = (
            cam["width"].as_u64().unwrap() as u32,
            cam["height"].as_u64().unwrap() as u32,
        );
        let f = num(&cam["f"]);
        let camera = Camera::try_new(
            0,
            "stiff",
            w,
            h,
            (f, f),
            (num(&cam["cx"]), num(&cam["cy"])),
            DMat3::IDENTITY,
            v3(&cam["position"]),
        )
        .unwrap();
        let depth = DepthImage::try_new(w, h, f32s(&inst["depth"])).unwrap();
        let (voxel, trunc) = (num(&inst["voxel"]), num(&inst["trunc"]));
        let mut volume = TsdfVolume::new(
            TsdfParams {
                voxel,
                trunc,
                depth_trunc: f64::INFINITY,
            },
            false,
        )
        .unwrap();
        volume
            .integrate(&[Frame {
                camera: &camera,
                depth: &depth,
                color: None,
            }])
            .unwrap();
        let grid = volume.grid();
        let ivec = |v: &Value| {
            let a: Vec<i32> = v
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_i64().unwrap() as i32)
                .collect();
            IVec3::from_slice(&a)
        };
        // Observed once, with the rule's value.
        let value = |k: IVec3| match grid.voxel_value(k) {
            Some((v, 1.0)) => Some(f64::from(v)),
            _ => None,
        };
        for vx in inst["voxels"].as_array().unwrap() {
            let err = value(ivec(&vx["g"])).map_or(1.0, |v| (v - num(&vx["tsdf"])).abs());
            report.add("tsdf", "tsdf", g, err);
        }
        // Zero crossings along z (marching cubes' vertices on those edges) against the plane.
        let normal = v3(&inst["plane"]["normal"]);
        let point = v3(&inst["plane"]["point"]);
        for c in inst["crossings"].as_array().unwrap() {
            let lo = ivec(&c["lo"]);
            let hi = lo + IVec3::Z;
            let err = match (value(lo), value(hi)) {
                (Some(a), Some(b)) if (a > 0.0) != (b > 0.0) => {
                    let z = (f64::from(lo.z) + 0.5 + a / (a - b)) * voxel;
                    let at = DVec3::new(
                        (f64::from(lo.x) + 0.5) * voxel,
                        (f64::from(lo.y) + 0.5) * voxel,
                        z,
                    );
                    normal.dot(at - point).abs() / voxel
                }
                _ => f64::NAN,
            };
            report.add("tsdf", "crossing", g, err);
            let rule = num(&c["rule_crossing_error"]);
            report.add("tsdf", "crossing − exact rule's", g, (err - rule).abs());
        }
        let mesh = volume.extract_mesh();
        assert!(mesh.positions().iter().all(|p| p.is_finite()));
    }
    report.check("TSDF fusion of a plane at grazing angles");
}

// ------------------------------------------------------------------ collapse policy

/// The policy of docs/numerics.md: a collapsed triangle is flagged, keeps its last valid frame
/// (rotation and scale, or `M = J k_c R_c`; its centroid follows the collapse), never gives
/// NaN, and a run that starts at the collapse (filling its hold from earlier frames) gives what
/// a run through every frame gives.
#[test]
fn collapse_to_zero_area_keeps_the_last_valid_frame() {
    let json = load("collapse");
    let mut report = Report::default();
    let o = FrameOptions::default();
    let g = &groups(&json)[0];
    for inst in g["instances"].as_array().unwrap() {
        let name = inst["name"].as_str().unwrap();
        let canonical = tri32(&inst["canonical"]);
        let flags: Vec<bool> = inst["degenerate"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b.as_bool().unwrap())
            .collect();
        let frames: Vec<[DVec3; 3]> = inst["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(tri32)
            .collect();
        let t: Vec<f64> = nums(&inst["t"]);
        let at = t.iter().position(|&x| x == 1.0).unwrap();
        assert!(
            flags[at] && !flags[at - 1],
            "{name}: the fixture collapses at t = 1"
        );
        let (template, set) =
            one_triangle_set(canonical, inst["gaussians"].as_array().unwrap(), false);
        for mode in [DeformMode::Binding, DeformMode::Jacobian] {
            let deformer = Deformer::new(&template, mode);
            let mut hold = FrameHold::new();
            let mut outputs = Vec::new();
            let mut bad = 0usize;
            for (k, v) in frames.iter().enumerate() {
                let f = gaussian_avatars_frame(*v, &o);
                report.add(
                    "collapse",
                    "degenerate flag − expected",
                    g,
                    usize::from(f.degenerate != flags[k]) as f64,
                );
                let (out, collapsed) = deformer.deform_held(&set, v.as_ref(), &mut hold).unwrap();
                report.add(
                    "collapse",
                    "held count − expected",
                    g,
                    collapsed.held.abs_diff(usize::from(flags[k])) as f64,
                );
                let finite = out.means().iter().all(|m| m.is_finite())
                    && out.log_scales().iter().all(|s| s.is_finite())
                    && out.rotations().iter().flatten().all(|q| q.is_finite());
                bad += usize::from(!finite);
                outputs.push(out);
            }
            report.add("collapse", "non-finite outputs", g, bad as f64);
            // At the collapse: the rotations and scales of t = 0.9999, the means moved with the
            // centroid only.
            let (before, collapsed) = (&outputs[at - 1], &outputs[at]);
            let centroid = |v: &[DVec3; 3]| ((v[0] + v[1] + v[2]) / 3.0).as_vec3();
            let shift = centroid(&frames[at]) - centroid(&frames[at - 1]);
            for i in 0..set.len() {
                let turn = before.rotation(i).angle_between(collapsed.rotation(i));
                report.add("collapse", "held rotation − last valid (rad)", g, turn);
                let ds = (before.log_scales()[i] - collapsed.log_scales()[i])
                    .abs()
                    .max_element();
                report.add("collapse", "held log-scale − last valid", g, f64::from(ds));
                let dm = (before.means()[i] + shift - collapsed.means()[i]).length();
                report.add(
                    "collapse",
                    "held mean − last valid moved (abs)",
                    g,
                    f64::from(dm),
                );
            }
            // Starting at the collapse with an empty hold, filled from the frame before.
            let mut fresh = FrameHold::new();
            let wanted = deformer.degenerate_triangles(frames[at].as_ref()).unwrap();
            assert_eq!(wanted, vec![0], "{name} {mode:?}");
            let left = deformer
                .fill_hold(frames[at - 1].as_ref(), &mut fresh, &wanted)
                .unwrap();
            assert!(left.is_empty(), "{name} {mode:?}");
            let (resumed, _) = deformer
                .deform_held(&set, frames[at].as_ref(), &mut fresh)
                .unwrap();
            assert_eq!(
                &resumed, collapsed,
                "{name} {mode:?}: a run started at the collapse"
            );
            // Without a hold (the stateless call) the fallback frame: print how far it turns.
            if mode == DeformMode::Binding {
                let stateless = deformer.deform(&set, frames[at].as_ref()).unwrap();
                println!(
                    "collapse '{name}': the fallback frame would turn the Gaussian {:.2}° at t = 1; the held frame turns it {:.2}°",
                    before
                        .rotation(0)
                        .angle_between(stateless.rotation(0))
                        .to_degrees(),
                    before
                        .rotation(0)
                        .angle_between(collapsed.rotation(0))
                        .to_degrees(),
                );
            }
        }
    }
    report.check("Triangles collapsing to zero area");
}
