//! The fitter's L1 and SSIM against scikit-image 0.25.2 and scipy 1.17.1
//! (`tests/reference/ref_ssim.py`, fixture `reference/fit_loss/ssim.json`).
//!
//! Our SSIM is 3DGS's (zero padding, mean over every pixel). scikit-image filters with reflect
//! padding and crops 5 pixels, so its map is compared where padding plays no part (pixels at
//! least 5 from the border) and its mean with the mean of our map over the same pixels; the
//! zero-padded mean over the whole image is compared with the script's scipy evaluation.

mod reference_json;

use reference_json::floats;
use serde_json::Value;
use trisplat_splat::fit::loss::{Ssim, l1};

/// f64 against f64: the same formulas in another order, rounding only.
const MAX_ABS_ERR_F64: f64 = 1e-12;
/// The f32 images (the production path) against the f64 reference.
const MAX_ABS_ERR_F32: f64 = 1e-5;

#[test]
fn l1_and_ssim_match_scikit_image() {
    let path = trisplat_fixtures::path("reference/fit_loss/ssim.json");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    for case in doc["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let n = |k: &str| case[k].as_u64().unwrap() as usize;
        let (h, w, c) = (n("height"), n("width"), n("channels"));
        let pred = floats(&case["pred"]);
        let target = floats(&case["target"]);
        let mut grad = vec![0.0; pred.len()];
        let ours = l1(&pred, &target, 0.0, &mut grad);
        let want = case["l1"].as_f64().unwrap();
        println!("{name}: l1 {ours} vs {want}");
        assert!((ours - want).abs() < MAX_ABS_ERR_F64);

        let mut ssim = Ssim::new(w, h);
        let full = ssim.ssim(&pred, &target, c, 0.0, None);
        let want = case["zero_pad_mssim"].as_f64().unwrap();
        println!("{name}: zero-padded SSIM {full} vs {want}");
        assert!((full - want).abs() < MAX_ABS_ERR_F64);

        let sk_map = floats(&case["skimage_map"]);
        let (mut worst, mut sum, mut count) = (0.0f64, 0.0, 0usize);
        for ch in 0..c {
            let map = ssim.map(&pred, &target, c, ch);
            for i in 5..h - 5 {
                for j in 5..w - 5 {
                    let ours = map[i * w + j];
                    worst = worst.max((ours - sk_map[(i * w + j) * c + ch]).abs());
                    sum += ours;
                    count += 1;
                }
            }
        }
        let cropped = sum / count as f64;
        let want = case["skimage_mssim"].as_f64().unwrap();
        println!("{name}: interior map max error {worst:.2e}; cropped mean {cropped} vs {want}");
        assert!(worst < MAX_ABS_ERR_F64);
        assert!((cropped - want).abs() < MAX_ABS_ERR_F64);

        let p32: Vec<f32> = pred.iter().map(|&v| v as f32).collect();
        let t32: Vec<f32> = target.iter().map(|&v| v as f32).collect();
        let full32 = ssim.ssim(&p32, &t32, c, 0.0, None);
        assert!(
            (full32 - full).abs() < MAX_ABS_ERR_F32,
            "{name}: f32 {full32}"
        );
    }
}
