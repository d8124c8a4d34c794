//! The base-colour texture of CesiumMan against Pillow 13.0.0 (libjpeg-turbo) and scipy
//! 1.17.1 (`tests/reference/ref_texture.py`, fixture `reference/texture/cesium_man.json`): the
//! decoded size, 200 texels as decoded, and 200 bilinear REPEAT lookups (inside 0..1, outside
//! it, at and within half a texel of the edges).
//!
//! JPEG decoders may differ: the image crate decodes with zune-jpeg, Pillow with
//! libjpeg-turbo, and the standard leaves the inverse DCT's rounding and the chroma
//! upsampling to the decoder. Measured once on the whole image (our decode rounded to 8 bits
//! against Pillow's, 3 × 1024² values): 0.23% differ, 6,430 by 1 code, 944 by 2, 7 by 3, none
//! by more; at the fixture's points, at most 1 code. The tolerance is 3.5 codes, just above
//! the image's maximum, so that any lookup may land on the worst texels. The lookup itself
//! (the same texels, f32 against f64) differs by less than 1e-6.

use serde_json::Value;
use trisplat_geometry::glam::Vec2;
use trisplat_geometry::io::read_gltf_base_color;
use trisplat_geometry::texture::{Filter, Wrap};

/// Largest difference allowed between our texel values and Pillow's, per channel in 0..1.
const MAX_DECODE_DIFF: f32 = 3.5 / 255.0;

fn rows(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|r| {
            r.as_array()
                .expect("row")
                .iter()
                .map(|x| x.as_f64().expect("number"))
                .collect()
        })
        .collect()
}

#[test]
fn cesium_man_texture_matches_pillow_and_scipy() {
    let doc: Value = serde_json::from_str(
        &std::fs::read_to_string(trisplat_fixtures::path("reference/texture/cesium_man.json"))
            .expect("fixture"),
    )
    .expect("json");
    let started = std::time::Instant::now();
    let base = read_gltf_base_color(&trisplat_fixtures::path("anim/CesiumMan.glb")).expect("read");
    println!(
        "read and decoded in {:.1} ms",
        started.elapsed().as_secs_f64() * 1e3
    );
    assert!(base.has_texture());
    let m = base.materials()[0]
        .texture
        .as_ref()
        .expect("material 0 is textured");
    let texture = &m.texture;
    assert_eq!(
        u64::from(texture.width()),
        doc["width"].as_u64().expect("width")
    );
    assert_eq!(
        u64::from(texture.height()),
        doc["height"].as_u64().expect("height")
    );
    // The file's sampler: REPEAT both ways, LINEAR magnification.
    assert_eq!(
        (m.sampler.wrap_u, m.sampler.wrap_v),
        (Wrap::Repeat, Wrap::Repeat)
    );
    assert_eq!(m.sampler.filter, Filter::Linear);

    let mut worst_texel = 0.0f32;
    for (ij, want) in rows(&doc["texel_ij"]).iter().zip(rows(&doc["texel_rgba"])) {
        #[expect(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            reason = "indices"
        )]
        let ours = texture.texel(ij[0] as u32, ij[1] as u32);
        for ch in 0..4 {
            worst_texel = worst_texel.max((ours[ch] - want[ch] as f32).abs());
        }
    }
    let mut worst_lookup = 0.0f32;
    for (uv, want) in rows(&doc["uv"]).iter().zip(rows(&doc["rgba"])) {
        #[expect(
            clippy::cast_possible_truncation,
            reason = "the fixture's uvs are f32 values"
        )]
        let uv = Vec2::new(uv[0] as f32, uv[1] as f32);
        let ours = texture.sample(uv, m.sampler);
        for ch in 0..4 {
            let d = (ours[ch] - want[ch] as f32).abs();
            assert!(
                d <= MAX_DECODE_DIFF,
                "uv {uv:?} channel {ch}: {ours:?} vs {want:?}"
            );
            worst_lookup = worst_lookup.max(d);
        }
    }
    println!(
        "max difference to Pillow: texels {worst_texel} ({:.2} codes), lookups {worst_lookup} \
         ({:.2} codes)",
        worst_texel * 255.0,
        worst_lookup * 255.0
    );
    assert!(worst_texel <= MAX_DECODE_DIFF);
}
