//! The reader harnesses shared by the AFL targets in `fuzz/` and the smoke test
//! `tests/tests/fuzz_smoke.rs`: each takes arbitrary bytes, runs one reader on them and returns
//! whether the reader accepted them. The property checked is that a reader returns `Ok` or
//! `Err`: a panic, an abort, a hang or an unbounded allocation is a bug in the reader.
//!
//! Readers that take bytes are called directly. The glTF readers open a path (external
//! buffers are resolved against the file's folder), so their input is written to a file in a
//! per-process folder under `/dev/shm` (else the system temporary folder), beside copies of
//! the small external buffers the seed corpus refers to.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use trisplat_geometry::animation::{Clip, GltfTemplate, WeightsTrack};
use trisplat_geometry::io::{ObjVertices, gltf, obj, parse_npy, ply};
use trisplat_geometry::{parse_cameras_json, parse_transforms_json};

/// One fuzzed reader.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// geometry's PLY core and its mesh mapping (`parse_ply` + `ply_to_mesh`, `ply_to_points`).
    PlyMesh,
    /// splat's INRIA Gaussian PLY reader (`read_gaussians_from_bytes`).
    PlyGaussians,
    /// `parse_obj` in its three vertex modes.
    Obj,
    /// The static glTF/GLB mesh reader (`io::gltf::read_gltf`) and its base-colour reader
    /// (`io::read_gltf_base_color`).
    Gltf,
    /// The animated template loader (`GltfTemplate::open`, its first clip) and frame 0.
    GltfAnimated,
    /// 3DGS `cameras.json` and NeRF `transforms.json` readers.
    CamerasJson,
    /// The ARKit/LAM expression weights reader (`WeightsTrack::parse`).
    ExpressionJson,
    /// `.npy` arrays (`parse_npy`).
    Npy,
    /// splat's SPZ reader (`decode_spz`), on the bytes and, when they are neither gzip nor a
    /// version-4 header, on them gzip-wrapped (so mutations of a decompressed payload reach
    /// the parser behind the checksum).
    Spz,
    /// splat's glTF reader of `KHR_gaussian_splatting` primitives (`read_gltf_gaussians`).
    GltfSplats,
}

impl Target {
    /// Every target, in the order of `fuzz/README.md`.
    pub const ALL: [Self; 10] = [
        Self::PlyMesh,
        Self::PlyGaussians,
        Self::Obj,
        Self::Gltf,
        Self::GltfAnimated,
        Self::CamerasJson,
        Self::ExpressionJson,
        Self::Npy,
        Self::Spz,
        Self::GltfSplats,
    ];

    /// The target's name: its AFL binary and its folders `fuzz/corpus/<name>` and
    /// `fuzz/regressions/<name>`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::PlyMesh => "ply_mesh",
            Self::PlyGaussians => "ply_gaussians",
            Self::Obj => "obj",
            Self::Gltf => "gltf",
            Self::GltfAnimated => "gltf_animated",
            Self::CamerasJson => "cameras_json",
            Self::ExpressionJson => "expression_json",
            Self::Npy => "npy",
            Self::Spz => "spz",
            Self::GltfSplats => "gltf_splats",
        }
    }

    /// Runs the target's reader on `data`; `true` when it accepted the input.
    #[must_use]
    pub fn run(self, data: &[u8]) -> bool {
        match self {
            Self::PlyMesh => ply_mesh(data),
            Self::PlyGaussians => ply_gaussians(data),
            Self::Obj => obj(data),
            Self::Gltf => gltf_static(data),
            Self::GltfAnimated => gltf_animated(data),
            Self::CamerasJson => cameras_json(data),
            Self::ExpressionJson => expression_json(data),
            Self::Npy => npy(data),
            Self::Spz => spz(data),
            Self::GltfSplats => gltf_splats(data),
        }
    }
}

/// PLY as a mesh and as a point cloud.
#[must_use]
pub fn ply_mesh(data: &[u8]) -> bool {
    let path = Path::new("fuzz.ply");
    match ply::parse_ply(path, data) {
        Ok(doc) => {
            let mesh = ply::ply_to_mesh(path, &doc).is_ok();
            let points = ply::ply_to_points(path, &doc).is_ok();
            mesh || points
        }
        Err(_) => false,
    }
}

/// PLY as INRIA 3DGS Gaussians.
#[must_use]
pub fn ply_gaussians(data: &[u8]) -> bool {
    trisplat_splat::ply::read_gaussians_from_bytes(data, Path::new("fuzz.ply")).is_ok()
}

/// OBJ in every vertex mode.
#[must_use]
pub fn obj(data: &[u8]) -> bool {
    let path = Path::new("fuzz.obj");
    let mut ok = false;
    for mode in [
        ObjVertices::Positions,
        ObjVertices::SplitSeams,
        ObjVertices::Auto,
    ] {
        ok |= obj::parse_obj(path, data, mode).is_ok();
    }
    ok
}

/// The static glTF/GLB reader, then the base-colour reader (materials, PNG/JPEG images,
/// corner uvs) on the same file; whether the mesh was read.
#[must_use]
pub fn gltf_static(data: &[u8]) -> bool {
    let path = input_file(data);
    let read = gltf::read_gltf(&path).is_ok();
    let _ = trisplat_geometry::io::read_gltf_base_color(&path);
    read
}

/// The animated template loader: open with the first clip (if any), then frame 0.
#[must_use]
pub fn gltf_animated(data: &[u8]) -> bool {
    match GltfTemplate::open(&input_file(data), &Clip::FirstIfAny) {
        Ok(template) => template.evaluate_at(0.0).is_ok(),
        Err(_) => false,
    }
}

/// Both camera readers (`transforms.json` with a default image size, so frames without `w`/`h`
/// get as far as the cameras).
#[must_use]
pub fn cameras_json(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    let cameras = parse_cameras_json(Path::new("cameras.json"), text).is_ok();
    let transforms =
        parse_transforms_json(Path::new("transforms.json"), text, Some((64, 48))).is_ok();
    cameras || transforms
}

/// The ARKit/LAM weights reader.
#[must_use]
pub fn expression_json(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    WeightsTrack::parse(text, Path::new("expression.json")).is_ok()
}

/// `.npy` arrays.
#[must_use]
pub fn npy(data: &[u8]) -> bool {
    parse_npy(Path::new("fuzz.npy"), data).is_ok()
}

/// SPZ bytes, and a raw payload gzip-wrapped.
#[must_use]
pub fn spz(data: &[u8]) -> bool {
    use trisplat_splat::spz::{SpzReadOptions, decode_spz};
    let path = Path::new("fuzz.spz");
    let options = SpzReadOptions::default();
    let direct = decode_spz(data, path, &options).is_ok();
    if data.starts_with(&[0x1f, 0x8b]) || data.starts_with(b"NGSP") {
        return direct;
    }
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    let wrapped = std::io::Write::write_all(&mut gz, data)
        .and_then(|()| gz.finish())
        .is_ok_and(|bytes| decode_spz(&bytes, path, &options).is_ok());
    direct || wrapped
}

/// glTF/GLB Gaussians (`KHR_gaussian_splatting`).
#[must_use]
pub fn gltf_splats(data: &[u8]) -> bool {
    trisplat_splat::gltf_splat::read_gltf_gaussians(&input_file(data)).is_ok()
}

/// External buffers of the seed corpus's `.gltf` files, copied beside the fuzzed input.
const BESIDE: [&str; 4] = [
    "gltf/AnimatedMorphCube/AnimatedMorphCube.bin",
    "gltf/MorphPrimitivesTest/MorphPrimitivesTest.bin",
    "gltf/SimpleMorph/simpleMorphAnimation.bin",
    "gltf/SimpleMorph/simpleMorphGeometry.bin",
];

/// The per-process folder of the glTF inputs, made (with the beside buffers) on first use.
fn work_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let shm = Path::new("/dev/shm");
        let base = if shm.is_dir() {
            shm.to_path_buf()
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("trisplat-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir)
            .unwrap_or_else(|e| panic!("cannot make {}: {e}", dir.display()));
        for rel in BESIDE {
            let from = trisplat_fixtures::path(rel);
            let name = from.file_name().expect("fixture file name");
            // A missing fixture only means fewer seeds reach the accessors.
            let _ = std::fs::copy(&from, dir.join(name));
        }
        dir
    })
}

/// Writes `data` as the glTF input (`.glb` when it has the GLB magic) and returns its path.
fn input_file(data: &[u8]) -> PathBuf {
    let name = if data.starts_with(b"glTF") {
        "input.glb"
    } else {
        "input.gltf"
    };
    let path = work_dir().join(name);
    std::fs::write(&path, data).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    path
}

/// Removes this process's glTF work folder (the smoke test calls it at the end).
pub fn remove_work_dir() {
    let _ = std::fs::remove_dir_all(work_dir());
}
