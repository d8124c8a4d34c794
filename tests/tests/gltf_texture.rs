//! The glTF base-colour reader (`io::gltf_material`): a 4 x 4 PNG made here, stored in a buffer
//! view (GLB), a data URI and a relative file; bad input is an error naming the file and the
//! element, never a panic; CesiumMan's uv seams survive welding in the per-corner uvs.

use std::path::Path;

use base64::Engine as _;
use serde_json::{Value, json};
use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate};
use trisplat_geometry::cleanup::weld_vertices;
use trisplat_geometry::glam::Vec2;
use trisplat_geometry::io::gltf::{glb_from_parts, gltf_text_from_parts};
use trisplat_geometry::io::{IoError, read_gltf_base_color, read_mesh};
use trisplat_geometry::texture::{Filter, Wrap};

/// Texel (i, j): red i / 3, green j / 3 (exact in 8 bits: 85 × i), blue 0.2, alpha 1.
fn png_4x4() -> Vec<u8> {
    let img = image::RgbaImage::from_fn(4, 4, |i, j| {
        image::Rgba([(85 * i) as u8, (85 * j) as u8, 51, 255])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .expect("png");
    out.into_inner()
}

const UVS: [[f32; 2]; 4] = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];

/// A unit quad (2 triangles) with TEXCOORD_0 = `UVS`, material 0 textured by image 0 through
/// sampler 0 (CLAMP_TO_EDGE / MIRRORED_REPEAT, NEAREST); `image` is images[0]. When `png_view`
/// is set the PNG is appended to the buffer as buffer view 3.
fn quad(image: Value, png_view: bool) -> (Value, Vec<u8>) {
    let mut bin = Vec::new();
    for p in [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ] {
        p.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
    }
    for uv in UVS {
        uv.iter()
            .for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
    }
    for i in [0u32, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let mut views = vec![
        json!({"buffer": 0, "byteOffset": 0, "byteLength": 48}),
        json!({"buffer": 0, "byteOffset": 48, "byteLength": 32}),
        json!({"buffer": 0, "byteOffset": 80, "byteLength": 24}),
    ];
    if png_view {
        let png = png_4x4();
        views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": png.len()}));
        bin.extend_from_slice(&png);
    }
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "TEXCOORD_0": 1},
            "indices": 2,
            "material": 0
        }]}],
        "materials": [{"pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0},
            "baseColorFactor": [1.0, 0.5, 1.0, 1.0]
        }}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"wrapS": 33071, "wrapT": 33648, "magFilter": 9728}],
        "images": [image],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5125, "count": 6, "type": "SCALAR"}
        ],
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    (doc, bin)
}

fn write_gltf(path: &Path, doc: Value, bin: &[u8]) {
    std::fs::write(path, gltf_text_from_parts(doc, bin)).expect("write");
}

#[test]
fn base_color_from_buffer_view_data_uri_and_file() {
    let dir = tempfile::tempdir().expect("tmp");
    // Buffer view, in a GLB.
    let (doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    let glb = dir.path().join("view.glb");
    std::fs::write(&glb, glb_from_parts(&glb, &doc, bin).expect("glb")).expect("write");
    // Data URI (no mimeType: the bytes say PNG).
    let uri = format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(png_4x4())
    );
    let (doc, bin) = quad(json!({ "uri": uri }), false);
    let data_uri = dir.path().join("data_uri.gltf");
    write_gltf(&data_uri, doc, &bin);
    // A file beside the glTF, its name percent-encoded in the URI.
    std::fs::write(dir.path().join("tex ture.png"), png_4x4()).expect("png");
    let (doc, bin) = quad(json!({"uri": "tex%20ture.png"}), false);
    let file = dir.path().join("file.gltf");
    write_gltf(&file, doc, &bin);

    for path in [&glb, &data_uri, &file] {
        let base = read_gltf_base_color(path).unwrap_or_else(|e| panic!("{e}"));
        let mesh = read_mesh(path).expect("mesh");
        assert_eq!(base.triangle_count(), mesh.triangle_count());
        assert!(base.has_texture());
        let m = &base.materials()[0];
        assert_eq!(m.factor, [1.0, 0.5, 1.0, 1.0]);
        let tex = m.texture.as_ref().expect("textured");
        assert_eq!((tex.texture.width(), tex.texture.height()), (4, 4));
        assert_eq!(tex.sampler.wrap_u, Wrap::ClampToEdge);
        assert_eq!(tex.sampler.wrap_v, Wrap::MirroredRepeat);
        assert_eq!(tex.sampler.filter, Filter::Nearest);
        // The first PNG row is v in 0..1/4: texel (i, j) as made, top row first.
        assert_eq!(tex.texture.texel(1, 2), [1.0 / 3.0, 2.0 / 3.0, 0.2, 1.0]);
        // Corner uvs in the triangles' corner order (0 1 2, 0 2 3).
        let uv = |k: usize| Vec2::from_array(UVS[k]);
        assert_eq!(base.corner_uvs(0), [uv(0), uv(1), uv(2)]);
        assert_eq!(base.corner_uvs(1), [uv(0), uv(2), uv(3)]);
        // The colour at corner 3 (uv (0, 0)): texel (0, 0) times the factor in linear.
        let c = base.rgb_at(1, [0.0, 0.0, 1.0]);
        assert_eq!([c[0], c[1]], [0.0, 0.0]);
        assert!((c[2] - 0.2).abs() < 1e-6, "{c:?}");
    }
}

/// The error of reading `doc` (with `bin`) as a .gltf in `dir`.
fn error_of(dir: &Path, name: &str, doc: Value, bin: &[u8]) -> String {
    let path = dir.join(name);
    write_gltf(&path, doc, bin);
    let e = read_gltf_base_color(&path).expect_err("refused");
    let text = e.to_string();
    assert!(text.contains(name), "names the file: {text}");
    text
}

#[test]
fn bad_textures_are_clear_errors() {
    let dir = tempfile::tempdir().expect("tmp");
    let d = dir.path();
    // A missing image file.
    let (doc, bin) = quad(json!({"uri": "nowhere.png"}), false);
    let path = d.join("missing.gltf");
    write_gltf(&path, doc, &bin);
    let e = read_gltf_base_color(&path).expect_err("missing");
    assert!(matches!(e, IoError::MissingReference { .. }), "{e}");
    assert!(e.to_string().contains("nowhere.png"), "{e}");
    // Bytes that are no PNG.
    let junk = format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(b"\x89PNG\r\n\x1a\nnot really")
    );
    let (doc, bin) = quad(json!({ "uri": junk }), false);
    let e = error_of(d, "junk.gltf", doc, &bin);
    assert!(e.contains("image 0: cannot decode PNG"), "{e}");
    // Bytes that are no JPEG.
    let (doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/jpeg"}), true);
    let e = error_of(d, "not_jpeg.gltf", doc, &bin);
    assert!(e.contains("image 0: cannot decode JPEG"), "{e}");
    // Another format.
    let (doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/webp"}), true);
    let e = error_of(d, "webp.gltf", doc, &bin);
    assert!(e.contains("image 0") && e.contains("image/webp"), "{e}");
    // A PNG whose header claims 100000 x 100000 pixels: refused before decoding.
    let mut huge = png_4x4();
    huge[16..20].copy_from_slice(&100_000u32.to_be_bytes());
    huge[20..24].copy_from_slice(&100_000u32.to_be_bytes());
    let mut crc = flate2::Crc::new();
    crc.update(&huge[12..29]);
    huge[29..33].copy_from_slice(&crc.sum().to_be_bytes());
    let uri = format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&huge)
    );
    let (doc, bin) = quad(json!({ "uri": uri }), false);
    let e = error_of(d, "huge.gltf", doc, &bin);
    assert!(e.contains("image 0") && e.contains("over the limit"), "{e}");
    // Another uv set; a texture transform.
    let (mut doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["texCoord"] = json!(1);
    let e = error_of(d, "texcoord1.gltf", doc, &bin);
    assert!(e.contains("material 0") && e.contains("TEXCOORD_1"), "{e}");
    let (mut doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] =
        json!({"KHR_texture_transform": {"scale": [2.0, 2.0]}});
    let e = error_of(d, "transform.gltf", doc, &bin);
    assert!(e.contains("KHR_texture_transform"), "{e}");
    // A textured primitive without TEXCOORD_0, or with one of the wrong count.
    let (mut doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    doc["meshes"][0]["primitives"][0]["attributes"]
        .as_object_mut()
        .expect("attributes")
        .remove("TEXCOORD_0");
    let e = error_of(d, "no_uv.gltf", doc, &bin);
    assert!(
        e.contains("mesh 0 primitive 0") && e.contains("TEXCOORD_0"),
        "{e}"
    );
    let (mut doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    doc["accessors"][1]["count"] = json!(3);
    let e = error_of(d, "uv_count.gltf", doc, &bin);
    assert!(
        e.contains("mesh 0 primitive 0") && e.contains("3 entries"),
        "{e}"
    );
    // A NaN uv.
    let (doc, mut bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    bin[48 + 8..48 + 12].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = error_of(d, "nan_uv.gltf", doc, &bin);
    assert!(e.contains("accessor 1"), "{e}");
}

#[test]
fn an_untextured_file_has_the_default_material() {
    let dir = tempfile::tempdir().expect("tmp");
    let (mut doc, bin) = quad(json!({"bufferView": 3, "mimeType": "image/png"}), true);
    doc["meshes"][0]["primitives"][0]
        .as_object_mut()
        .expect("primitive")
        .remove("material");
    let path = dir.path().join("plain.gltf");
    write_gltf(&path, doc, &bin);
    let base = read_gltf_base_color(&path).expect("read");
    assert!(!base.has_texture());
    assert_eq!(base.rgb_at(0, [1.0, 0.0, 0.0]), [1.0, 1.0, 1.0]);
}

#[test]
fn cesium_man_corner_uvs_keep_the_seams_that_welding_merges() {
    let path = trisplat_fixtures::path("anim/CesiumMan.glb");
    let base = read_gltf_base_color(&path).expect("base colour");
    let stored = read_mesh(&path).expect("mesh");
    let template = GltfTemplate::open(&path, &Clip::None).expect("template");
    // The same triangles as the static reader and the animated template.
    assert_eq!(base.triangle_count(), stored.triangle_count());
    assert_eq!(template.rest().triangles(), stored.triangles());
    let uvs = stored.uvs().expect("CesiumMan has TEXCOORD_0");
    for (t, tri) in stored.triangles().iter().enumerate() {
        assert_eq!(
            base.corner_uvs(t),
            tri.map(|v| uvs[v as usize]),
            "triangle {t}"
        );
    }
    // Welded by position, the template keeps the base colour; its per-vertex uvs are those
    // of each welded vertex's first copy, wrong on the other side of a seam, where the
    // corner uvs still hold each side's own.
    let welded_template = template
        .rest()
        .clone()
        .with_base_color(std::sync::Arc::new(base.clone()))
        .expect("fits");
    let (welded, _) = weld_vertices(&welded_template, 0.0);
    assert!(welded.vertex_count() < stored.vertex_count());
    let kept = welded.base_color().expect("welding keeps the base colour");
    let (stored_welded, _) = weld_vertices(&stored, 0.0);
    let welded_uvs = stored_welded.uvs().expect("uvs");
    let mut seam_corners = 0;
    for (t, tri) in stored_welded.triangles().iter().enumerate() {
        for k in 0..3 {
            if welded_uvs[tri[k] as usize] != kept.corner_uvs(t)[k] {
                seam_corners += 1;
            }
        }
    }
    println!("{seam_corners} corners whose welded vertex uv is another copy's");
    assert!(seam_corners > 100, "{seam_corners}");
}
