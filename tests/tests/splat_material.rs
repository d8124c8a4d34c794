//! HRAvatar's material attributes (albedo, roughness, F0): read and written in INRIA PLY under
//! HRAvatar's names, refused when out of range or incomplete, and kept by every path that
//! copies per-Gaussian arrays (select, clone, split, prune, binding, deformation in both modes,
//! unbinding to world, change of axes).

use trisplat_geometry::TriMesh;
use trisplat_geometry::rng::Rng;
use trisplat_splat::glam::{DMat3, DVec3, Vec3};
use trisplat_splat::material::Material;
use trisplat_splat::ply::{PlyWriteOptions, read_gaussians, write_gaussians};
use trisplat_splat::{
    Convention, DeformMode, Deformer, GaussianParts, GaussianSet, ParameterSpace, SplitOptions,
    attach, change_axes, clone_selected, prune, split_selected,
};

fn material(n: usize, seed: u64) -> Material {
    let mut rng = Rng::new(seed);
    let mut u = move || rng.uniform_f32();
    Material {
        albedo: (0..n).map(|_| [u(), u(), u()]).collect(),
        roughness: (0..n).map(|_| u()).collect(),
        f0: (0..n).map(|_| u()).collect(),
    }
}

/// `n` world Gaussians with a material; Gaussian `i`'s albedo red channel encodes `i`.
fn world_set(n: usize) -> GaussianSet {
    let mut rng = Rng::new(5);
    let mut u = move || rng.uniform_f32() * 2.0 - 1.0;
    let mut m = material(n, 9);
    for (i, a) in m.albedo.iter_mut().enumerate() {
        a[0] = i as f32 / n as f32;
    }
    GaussianSet::try_new(GaussianParts {
        means: (0..n).map(|_| Vec3::new(u(), u(), u())).collect(),
        log_scales: (0..n)
            .map(|_| Vec3::new(u() - 3.0, u() - 3.0, u() - 4.0))
            .collect(),
        rotations: (0..n).map(|_| [u() + 2.0, u(), u(), u()]).collect(),
        opacity_logits: vec![1.0; n],
        sh: vec![0.1; 3 * n],
        material: Some(m),
        ..GaussianParts::default()
    })
    .unwrap()
}

/// The material of output Gaussian `j` is the one of input `sources[j]`.
fn assert_carried(from: &GaussianSet, to: &GaussianSet, sources: &[usize], what: &str) {
    let (a, b) = (from.material().unwrap(), to.material().expect(what));
    assert_eq!(b.albedo.len(), to.len(), "{what}");
    for (j, &i) in sources.iter().enumerate() {
        assert_eq!(b.albedo[j], a.albedo[i], "{what}: albedo of {j}");
        assert_eq!(b.roughness[j], a.roughness[i], "{what}: roughness of {j}");
        assert_eq!(b.f0[j], a.f0[i], "{what}: F0 of {j}");
    }
}

#[test]
fn ply_round_trip_under_hravatar_names() {
    let dir = tempfile::tempdir().unwrap();
    let set = world_set(50);
    for (k, encoding) in [
        trisplat_splat::ply::PlyEncoding::BinaryLittleEndian,
        trisplat_splat::ply::PlyEncoding::Ascii,
    ]
    .into_iter()
    .enumerate()
    {
        let path = dir.path().join(format!("m{k}.ply"));
        write_gaussians(&path, &set, &PlyWriteOptions { encoding }).unwrap();
        let text = String::from_utf8_lossy(&std::fs::read(&path).unwrap()).into_owned();
        for name in [
            "albedo_0",
            "albedo_1",
            "albedo_2",
            "roughness",
            "reflectance",
        ] {
            assert!(text.contains(&format!("property float {name}\n")), "{name}");
        }
        let back = read_gaussians(&path).unwrap();
        assert_eq!(back.material(), set.material(), "{encoding:?}");
        assert!(back.extras().is_empty(), "material columns are not extras");
    }
    // Without a material nothing is written.
    let mut plain = set.clone();
    plain.set_material(None).unwrap();
    let path = dir.path().join("plain.ply");
    write_gaussians(&path, &plain, &PlyWriteOptions::default()).unwrap();
    assert!(read_gaussians(&path).unwrap().material().is_none());
}

#[test]
fn bad_materials_are_refused_naming_file_and_gaussian() {
    let dir = tempfile::tempdir().unwrap();
    let set = world_set(4);
    // Out of range: written by hand through the extras (the set itself refuses it).
    let mut parts = set.clone().into_parts();
    let mut m = parts.material.take().unwrap();
    m.roughness[2] = 1.5;
    let mut probe = set.clone();
    assert!(probe.set_material(Some(m.clone())).is_err());
    assert_eq!(
        probe.material(),
        set.material(),
        "unchanged after a refusal"
    );
    parts.extras = vec![
        extra("albedo_0", m.albedo.iter().map(|a| a[0]).collect()),
        extra("albedo_1", m.albedo.iter().map(|a| a[1]).collect()),
        extra("albedo_2", m.albedo.iter().map(|a| a[2]).collect()),
        extra("roughness", m.roughness.clone()),
        extra("reflectance", m.f0.clone()),
    ];
    let bad = GaussianSet::try_new(parts.clone()).unwrap();
    let path = dir.path().join("bad.ply");
    write_gaussians(&path, &bad, &PlyWriteOptions::default()).unwrap();
    let err = read_gaussians(&path).unwrap_err().to_string();
    assert!(
        err.contains("bad.ply") && err.contains("Gaussian 2") && err.contains("roughness 1.5"),
        "{err}"
    );
    // Incomplete: roughness without the others.
    parts.extras.retain(|e| e.name == "roughness");
    parts.extras[0].values = trisplat_splat::PropertyValues::F32(vec![0.5; 4]);
    let partial = GaussianSet::try_new(parts).unwrap();
    let path = dir.path().join("partial.ply");
    write_gaussians(&path, &partial, &PlyWriteOptions::default()).unwrap();
    let err = read_gaussians(&path).unwrap_err().to_string();
    assert!(
        err.contains("partial.ply") && err.contains("albedo_0"),
        "{err}"
    );
}

fn extra(name: &str, values: Vec<f32>) -> trisplat_splat::ExtraProperty {
    trisplat_splat::ExtraProperty {
        name: name.into(),
        values: trisplat_splat::PropertyValues::F32(values),
    }
}

#[test]
fn materials_survive_densify_prune_bind_deform_and_axes() {
    let n = 40;
    let set = world_set(n);
    let picks = [3, 3, 0, 39, 17];
    assert_carried(&set, &set.select(&picks), &picks, "select");
    let mask: Vec<bool> = (0..n).map(|i| i % 3 == 0).collect();
    let c = clone_selected(&set, &mask, None).unwrap();
    assert_carried(&set, &c.set, &c.sources, "clone");
    let s = split_selected(&set, &mask, &SplitOptions::default(), None).unwrap();
    assert_carried(&set, &s.set, &s.sources, "split");
    let p = prune(&set, &mask, None).unwrap();
    assert_carried(&set, &p.result.set, &p.result.sources, "prune");
    let all: Vec<usize> = (0..n).collect();
    let turned = change_axes(&set, DMat3::from_rotation_x(0.4));
    assert_carried(&set, &turned, &all, "change of axes");

    // Bind to a mesh, deform it in both modes: the materials ride along.
    let mesh = TriMesh::new(
        vec![
            DVec3::new(-2.0, -2.0, 0.0),
            DVec3::new(2.0, -2.0, 0.0),
            DVec3::new(0.0, 2.0, 0.5),
            DVec3::new(0.0, 0.0, 2.0),
        ],
        vec![[0, 1, 2], [0, 1, 3], [1, 2, 3]],
    );
    let bound = attach(&set, &mesh, Convention::GaussianAvatars).unwrap();
    assert_carried(&set, &bound, &all, "attach");
    let moved: Vec<DVec3> = mesh
        .positions()
        .iter()
        .map(|p| DVec3::new(p.x * 1.2, p.y + 0.1 * p.z, p.z))
        .collect();
    for mode in [DeformMode::Binding, DeformMode::Jacobian] {
        let out = Deformer::new(&mesh, mode).deform(&bound, &moved).unwrap();
        assert_eq!(out.space(), ParameterSpace::World);
        assert_carried(&set, &out, &all, &format!("deform {mode:?}"));
    }
    // A bound set written and read back keeps binding and material together.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bound.ply");
    write_gaussians(&path, &bound, &PlyWriteOptions::default()).unwrap();
    let back = read_gaussians(&path).unwrap();
    assert_eq!(back.material(), bound.material());
    assert_eq!(
        back.binding().map(|b| b.triangles.len()),
        Some(n),
        "binding kept"
    );
}
