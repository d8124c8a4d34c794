//! The two glTF readers (issue #15: "the two glTF readers disagree on some files"): the static
//! reader (`io::gltf::read_gltf`, what `convert`, `eval` and friends read) and the animated
//! template (`GltfTemplate`, what `extract` and `deform` read), on the fixtures and 150 byte-flip
//! mutations of each:
//!
//! - the static reader accepts every file the template accepts (it reads a subset: skins,
//!   animations and morph targets are the template's alone, docs/conventions.md §9), so a file
//!   refused by `convert` is refused by `extract` too;
//! - where both accept, they give the same triangles and vertex count;
//! - for meshes without skins, the same positions as the template with its morph weights at
//!   zero (the static reader's pose, as trimesh's: node transforms applied, morph targets
//!   ignored; the template applies the default weights).

use std::path::{Path, PathBuf};

use trisplat_geometry::animation::AnimatedTemplate;
use trisplat_geometry::animation::{Clip, GltfTemplate};
use trisplat_geometry::io::gltf::read_gltf;
use trisplat_geometry::rng::Rng;

const SEEDS: [&str; 7] = [
    "gltf/AnimatedMorphCube/AnimatedMorphCube.gltf",
    "gltf/MorphPrimitivesTest/MorphPrimitivesTest.gltf",
    "gltf/SimpleMorph/SimpleMorph.gltf",
    "gltf/SimpleSkin.gltf",
    "gltf/RiggedSimple.glb",
    "anim/RiggedFigure.glb",
    "anim/SyntheticFeatures.gltf",
];

/// Variants of `data`: itself, and seeded byte flips (the mutations that keep most files
/// readable: a flipped byte in a buffer moves a vertex or an index, in JSON it often breaks it).
fn variants(data: &[u8], seed: u64, n: usize) -> Vec<Vec<u8>> {
    let mut rng = Rng::new(seed);
    let mut out = vec![data.to_vec()];
    for _ in 0..n {
        let mut d = data.to_vec();
        for _ in 0..1 + rng.below(3) {
            let i = rng.below(d.len() as u32) as usize;
            d[i] = rng.below(256) as u8;
        }
        out.push(d);
    }
    out
}

/// How the readers disagree on one file.
#[derive(Debug)]
#[expect(
    dead_code,
    reason = "the fields are read through Debug in the failure message"
)]
enum Disagreement {
    /// The template read a file the static reader refused.
    OnlyTheTemplateReads(String),
    /// The template opened the file but cannot evaluate its rest pose.
    TemplateCannotEvaluate(String),
    Topology,
    Positions(f64),
}

fn compare(path: &Path) -> Option<Disagreement> {
    let stat = read_gltf(path);
    let anim = GltfTemplate::open(path, &Clip::None);
    match (stat, anim) {
        (Err(e), Ok(_)) => Some(Disagreement::OnlyTheTemplateReads(e.to_string())),
        (_, Err(_)) => None,
        (Ok(s), Ok(a)) => {
            let rest = a.rest();
            if s.triangles() != rest.triangles() || s.vertex_count() != rest.vertex_count() {
                return Some(Disagreement::Topology);
            }
            if !a.is_skinned() {
                // The static reader's pose: node transforms, morph targets at weight zero.
                let unmorphed = match a.evaluate_with_weights(None, &|_, _| Some(0.0)) {
                    Ok(p) => p,
                    Err(e) => return Some(Disagreement::TemplateCannotEvaluate(e.to_string())),
                };
                let worst = s
                    .positions()
                    .iter()
                    .zip(&unmorphed)
                    .map(|(p, q)| (*p - *q).length() / p.length().max(1.0))
                    .fold(0.0, f64::max);
                if worst > 1e-6 {
                    return Some(Disagreement::Positions(worst));
                }
            }
            None
        }
    }
}

#[test]
fn both_gltf_readers_agree_on_fixtures_and_their_mutations() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut found = Vec::new();
    let mut cases = 0;
    for (k, seed) in SEEDS.iter().enumerate() {
        let src = trisplat_fixtures::path(seed);
        // External buffers next to the copies.
        for entry in std::fs::read_dir(src.parent().expect("folder")).expect("folder") {
            let p = entry.expect("entry").path();
            if p.extension().is_some_and(|e| e == "bin") {
                std::fs::copy(&p, dir.path().join(p.file_name().expect("name"))).expect("copy");
            }
        }
        let data = std::fs::read(&src).expect("fixture");
        let ext = src.extension().and_then(|e| e.to_str()).unwrap_or("gltf");
        for (i, v) in variants(&data, k as u64, 150).iter().enumerate() {
            let path: PathBuf = dir.path().join(format!("case_{k}_{i}.{ext}"));
            std::fs::write(&path, v).expect("write");
            cases += 1;
            if let Some(d) = compare(&path) {
                found.push(format!("{seed} variant {i}: {d:?}"));
            }
            let _ = std::fs::remove_file(&path);
        }
    }
    println!("{cases} files, {} disagreements", found.len());
    for f in found.iter().take(40) {
        println!("{f}");
    }
    assert!(found.is_empty(), "{} disagreements", found.len());
}
