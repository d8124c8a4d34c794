//! The neural appearance weights file: a round trip, and clear errors naming the file for files
//! that are not one or do not match.

use std::collections::HashMap;
use std::path::Path;

use safetensors::SafeTensors;
use safetensors::tensor::TensorView;
use trisplat_splat::neural::{
    Aabb, NeuralAppearance, NeuralConfig, read_weights, weights_path, write_weights,
};

fn tiny() -> NeuralConfig {
    NeuralConfig {
        levels: 2,
        features_per_level: 2,
        log2_table_size: 6,
        base_resolution: 2,
        growth: 3.0,
        hidden: 5,
        feature_width: 4,
    }
}

fn model() -> NeuralAppearance<f32> {
    let aabb = Aabb {
        lo: [-1.0, -2.0, 0.5],
        hi: [1.0, 0.25, 3.0],
    };
    NeuralAppearance::new(tiny(), aabb, 4).unwrap()
}

/// Rewrites `path` with `edit` applied to its metadata and `drop` tensor left out.
fn rewrite(path: &Path, edit: impl Fn(&mut HashMap<String, String>), drop: Option<&str>) {
    let bytes = std::fs::read(path).unwrap();
    let (_, header) = SafeTensors::read_metadata(&bytes).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let mut meta = header.metadata().clone().unwrap();
    edit(&mut meta);
    let tensors: Vec<(String, TensorView)> = st
        .tensors()
        .into_iter()
        .filter(|(n, _)| Some(n.as_str()) != drop)
        .collect();
    let out = safetensors::serialize(tensors, Some(meta)).unwrap();
    std::fs::write(path, out).unwrap();
}

#[test]
fn weights_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = weights_path(&dir.path().join("head.ply"));
    assert_eq!(path.file_name().unwrap(), "head.safetensors");
    let m = model();
    write_weights(&path, &m, 123).unwrap();
    let back = read_weights(&path, 123).unwrap();
    assert_eq!(back, m);
    // The header is what the format says: an 8-byte little-endian length, then JSON.
    let bytes = std::fs::read(&path).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    assert_eq!(
        header["geometry_mlp.0.weight"]["shape"],
        serde_json::json!([5, 11])
    );
    assert_eq!(header["color_mlp.2.bias"]["dtype"], "F32");
    assert_eq!(header["__metadata__"]["gaussians"], "123");
    // No temporary file is left beside it.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn mismatched_files_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.safetensors");
    let shown = path.display().to_string();
    write_weights(&path, &model(), 10).unwrap();

    let e = read_weights(&path, 11).unwrap_err().to_string();
    assert!(
        e.contains(&shown) && e.contains("fitted for 10 Gaussians, the PLY has 11"),
        "{e}"
    );

    rewrite(&path, |m| drop(m.insert("hidden".into(), "6".into())), None);
    let e = read_weights(&path, 10).unwrap_err().to_string();
    assert!(
        e.contains(&shown) && e.contains("'geometry_mlp.0.weight'") && e.contains("[6, 11]"),
        "{e}"
    );

    write_weights(&path, &model(), 10).unwrap();
    rewrite(&path, |_| {}, Some("hash_grid.level1"));
    let e = read_weights(&path, 10).unwrap_err().to_string();
    assert!(
        e.contains(&shown) && e.contains("'hash_grid.level1' missing"),
        "{e}"
    );

    write_weights(&path, &model(), 10).unwrap();
    rewrite(
        &path,
        |m| drop(m.insert("format".into(), "other".into())),
        None,
    );
    let e = read_weights(&path, 10).unwrap_err().to_string();
    assert!(e.contains(&shown) && e.contains("format 'other'"), "{e}");

    std::fs::write(&path, b"\x10\0\0\0\0\0\0\0{not json").unwrap();
    let e = read_weights(&path, 10).unwrap_err().to_string();
    assert!(
        e.contains(&shown) && e.contains("not a safetensors file"),
        "{e}"
    );

    let e = read_weights(&dir.path().join("missing.safetensors"), 10)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("missing.safetensors") && e.contains("cannot read"),
        "{e}"
    );

    // A write into a folder that does not exist fails and leaves nothing.
    let nowhere = dir.path().join("no/such/w.safetensors");
    assert!(write_weights(&nowhere, &model(), 10).is_err());
    assert!(!nowhere.exists());
}
