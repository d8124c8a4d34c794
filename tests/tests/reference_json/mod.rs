//! Reading the reference scripts' JSON (tests/reference/*.py) and comparing against it, shared by
//! the reference tests.

// Each test uses the parts its reference needs.
#![allow(dead_code)]

use serde_json::Value;

/// A JSON array of numbers.
pub fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("a JSON array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

/// A JSON array of `N`-number rows.
pub fn rows<const N: usize>(v: &Value) -> Vec<[f64; N]> {
    v.as_array()
        .expect("a JSON array of rows")
        .iter()
        .map(|r| floats(r).try_into().expect("a row of the stated length"))
        .collect()
}

/// `max |ours − reference| / max |reference|` (the absolute error where the reference is all
/// zero).
pub fn max_rel(ours: &[f64], reference: &[f64]) -> f64 {
    assert_eq!(ours.len(), reference.len());
    let scale = reference.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let err = ours
        .iter()
        .zip(reference)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    if scale > 0.0 { err / scale } else { err }
}
