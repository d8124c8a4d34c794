//! INRIA 3DGS PLY reading and writing: bit-exact round trips in every encoding, extras, bindings,
//! 2DGS files, the LAM avatar subset, and clear errors on bad files.

use std::path::Path;

use trisplat_geometry::TriId;
use trisplat_geometry::rng::Rng;
use trisplat_splat::glam::Vec3;
use trisplat_splat::ply::{
    PlyEncoding, PlyError, PlyWriteOptions, read_gaussians, read_gaussians_from_bytes,
    write_gaussians, write_gaussians_to,
};
use trisplat_splat::{
    Binding, BindingEncoding, ExtraProperty, GaussianError, GaussianParts, GaussianSet,
    ParameterSpace, PropertyValues, ScaleDims,
};

const ENCODINGS: [PlyEncoding; 3] = [
    PlyEncoding::BinaryLittleEndian,
    PlyEncoding::BinaryBigEndian,
    PlyEncoding::Ascii,
];

fn random_set(n: usize, degree: u8, seed: u64) -> GaussianParts {
    let mut rng = Rng::new(seed);
    // Values spanning many binades, including subnormals and extremes, to catch any rounding.
    let mut f = move || {
        let m = rng.uniform_f32() * 2.0 - 1.0;
        let e = rng.below(60) as i32 - 30;
        m * 2f32.powi(e)
    };
    let k = (degree as usize + 1).pow(2);
    GaussianParts {
        means: (0..n).map(|_| Vec3::new(f(), f(), f())).collect(),
        log_scales: (0..n)
            .map(|_| Vec3::new(f(), f(), f()).clamp_length_max(30.0))
            .collect(),
        scale_dims: ScaleDims::Three,
        rotations: (0..n).map(|_| [f() + 2.0, f(), f(), f()]).collect(),
        opacity_logits: (0..n).map(|_| f()).collect(),
        sh_degree: degree,
        sh: (0..n * 3 * k).map(|_| f()).collect(),
        ..GaussianParts::default()
    }
}

fn with_extras(mut p: GaussianParts) -> GaussianParts {
    let n = p.means.len();
    p.extras = vec![
        ExtraProperty {
            name: "nx".into(),
            values: PropertyValues::F32((0..n).map(|i| i as f32 * 1e-7).collect()),
        },
        ExtraProperty {
            name: "transform".into(),
            values: PropertyValues::F64(
                (0..n)
                    .map(|i| (i as f64).sqrt() * 1e-300 + f64::MAX * 0.5)
                    .collect(),
            ),
        },
        ExtraProperty {
            name: "label".into(),
            values: PropertyValues::U8((0..n).map(|i| (i * 37 % 256) as u8).collect()),
        },
        ExtraProperty {
            name: "tag".into(),
            values: PropertyValues::I16((0..n).map(|i| -(i as i16) * 7).collect()),
        },
        ExtraProperty {
            name: "weird".into(),
            values: PropertyValues::F32(
                (0..n)
                    .map(|i| match i % 4 {
                        0 => f32::INFINITY,
                        1 => f32::MIN_POSITIVE / 8.0,
                        2 => -0.0,
                        _ => f32::MAX,
                    })
                    .collect(),
            ),
        },
    ];
    p
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_bit_identical(a: &GaussianSet, b: &GaussianSet) {
    assert_eq!(a.len(), b.len());
    let flat = |s: &GaussianSet| -> Vec<u32> {
        let mut v = Vec::new();
        for (i, m) in s.means().iter().enumerate() {
            v.extend(bits(&m.to_array()));
            let ls = s.log_scales()[i].to_array();
            v.extend(bits(&ls[..s.scale_dims().count()]));
            v.extend(bits(&s.rotations()[i]));
        }
        v.extend(bits(s.opacity_logits()));
        v.extend(bits(s.sh()));
        v
    };
    assert_eq!(flat(a), flat(b));
    assert_eq!(a.sh_degree(), b.sh_degree());
    assert_eq!(a.scale_dims(), b.scale_dims());
    assert_eq!(a.binding(), b.binding());
    assert_eq!(a.space(), b.space());
    assert_eq!(a.extras().len(), b.extras().len());
    for (x, y) in a.extras().iter().zip(b.extras()) {
        assert_eq!(x.name, y.name);
        assert_eq!(x.values.scalar_type(), y.values.scalar_type());
        for i in 0..x.values.len() {
            let (p, q) = (x.values.get_f64(i).unwrap(), y.values.get_f64(i).unwrap());
            assert_eq!(p.to_bits(), q.to_bits(), "{} {i}", x.name);
        }
    }
}

fn to_bytes(set: &GaussianSet, encoding: PlyEncoding) -> Vec<u8> {
    let mut out = Vec::new();
    write_gaussians_to(&mut out, set, &PlyWriteOptions { encoding }).unwrap();
    out
}

fn read(bytes: &[u8]) -> Result<GaussianSet, PlyError> {
    read_gaussians_from_bytes(bytes, Path::new("mem.ply"))
}

#[test]
fn round_trips_are_bit_identical_in_every_encoding() {
    for degree in 0..=3 {
        let set = GaussianSet::try_new(with_extras(random_set(97, degree, degree as u64))).unwrap();
        for enc in ENCODINGS {
            let bytes = to_bytes(&set, enc);
            let back = read(&bytes).unwrap();
            assert_bit_identical(&set, &back);
            // Writing what was read reproduces the file byte for byte.
            assert_eq!(to_bytes(&back, enc), bytes, "{enc:?} degree {degree}");
            // And converting between encodings loses nothing.
            for other in ENCODINGS {
                let again = read(&to_bytes(&back, other)).unwrap();
                assert_bit_identical(&set, &again);
            }
        }
    }
}

#[test]
fn bindings_round_trip_as_float_and_integer() {
    for encoding in [
        BindingEncoding::Float,
        BindingEncoding::Integer(trisplat_splat::ScalarType::I32),
        BindingEncoding::Integer(trisplat_splat::ScalarType::U16),
    ] {
        let mut p = random_set(50, 1, 9);
        p.binding = Some(Binding {
            triangles: (0..50).map(|i| TriId(i * 1000 % 60_000)).collect(),
            encoding,
        });
        p.space = ParameterSpace::Local;
        let set = GaussianSet::try_new(p).unwrap();
        for enc in ENCODINGS {
            let bytes = to_bytes(&set, enc);
            let text = String::from_utf8_lossy(&bytes[..bytes.len().min(2000)]).to_string();
            match encoding {
                BindingEncoding::Float => assert!(text.contains("property float binding_0\n")),
                _ => assert!(text.contains(" binding\n")),
            }
            let back = read(&bytes).unwrap();
            assert_eq!(back.space(), ParameterSpace::Local);
            assert_bit_identical(&set, &back);
        }
    }
    // A triangle index that the stored type cannot hold is refused before writing.
    let mut p = random_set(2, 0, 1);
    p.binding = Some(Binding {
        triangles: vec![TriId(3), TriId(1 << 25)],
        encoding: BindingEncoding::Float,
    });
    let set = GaussianSet::new_unchecked(p);
    let dir = tempfile::tempdir().unwrap();
    let err = write_gaussians(&dir.path().join("g.ply"), &set, &PlyWriteOptions::default());
    assert!(matches!(
        err,
        Err(PlyError::BindingNotRepresentable { index: 1, .. })
    ));
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn surfel_files_have_two_scales() {
    let mut p = random_set(10, 0, 4);
    p.scale_dims = ScaleDims::Two;
    for s in &mut p.log_scales {
        s.z = 0.0;
    }
    let set = GaussianSet::try_new(p).unwrap();
    let bytes = to_bytes(&set, PlyEncoding::BinaryLittleEndian);
    let header = String::from_utf8_lossy(&bytes[..400]).to_string();
    assert!(header.contains("scale_1") && !header.contains("scale_2"));
    let back = read(&bytes).unwrap();
    assert_eq!(back.scale_dims(), ScaleDims::Two);
    assert_bit_identical(&set, &back);
    assert_eq!(back.scale(3).z, 0.0);
}

/// A hand-written ascii file: properties in an unusual order, comments, CRLF line ends,
/// an element before `vertex` and one after, extras between the standard properties.
const SHUFFLED: &str = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\n\
element camera 1\r\nproperty float fx\r\n\
element vertex 2\r\nproperty float rot_3\r\nproperty float opacity\r\nproperty uchar red\r\n\
property float z\r\nproperty float y\r\nproperty float x\r\nproperty float f_dc_2\r\n\
property float f_dc_1\r\nproperty float f_dc_0\r\nproperty float scale_1\r\nproperty float scale_0\r\n\
property float rot_0\r\nproperty float rot_1\r\nproperty float rot_2\r\nproperty double binding_0\r\n\
property float scale_2\r\n\
element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
500\r\n\
0.5 -1 200 3 2 1 0.3 0.2 0.1 -2 -3 1 0 0 5 -4\r\n\
0 2.5 7 6 5 4 1e-30 0 -0 0.25 0.125 0 1 0 0 -29.5\r\n\
3 0 1 2\r\n";

#[test]
fn properties_are_found_by_name_in_any_order() {
    let set = read(SHUFFLED.as_bytes()).unwrap();
    assert_eq!(set.len(), 2);
    assert_eq!(set.means()[0], Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(set.rotations()[0], [1.0, 0.0, 0.0, 0.5]);
    assert_eq!(set.opacity_logits(), &[-1.0, 2.5]);
    assert_eq!(set.sh_coeffs(0), &[0.1, 0.2, 0.3]);
    assert_eq!(set.log_scales()[1], Vec3::new(0.125, 0.25, -29.5));
    assert_eq!(set.binding().unwrap().triangles, vec![TriId(5), TriId(0)]);
    assert_eq!(set.space(), ParameterSpace::Local);
    assert_eq!(
        set.extra("red").unwrap().values,
        PropertyValues::U8(vec![200, 7])
    );
    // Written back in the file's own order (the binding as float, the standard format).
    let out = String::from_utf8(to_bytes(&set, PlyEncoding::Ascii)).unwrap();
    let order: Vec<&str> = out
        .lines()
        .filter_map(|l| l.strip_prefix("property "))
        .map(|l| l.rsplit(' ').next().unwrap())
        .collect();
    assert_eq!(
        order,
        [
            "rot_3",
            "opacity",
            "red",
            "z",
            "y",
            "x",
            "f_dc_2",
            "f_dc_1",
            "f_dc_0",
            "scale_1",
            "scale_0",
            "rot_0",
            "rot_1",
            "rot_2",
            "binding_0",
            "scale_2"
        ]
    );
    assert!(
        out.contains("\n0.5 -1 200 3 2 1 0.3 0.2 0.1 -2 -3 1 0 0 5 -4\n"),
        "{out}"
    );
    assert_bit_identical(&set, &read(out.as_bytes()).unwrap());
}

#[test]
fn lam_avatar_subset_reads_with_tiny_scales() {
    let path = trisplat_fixtures::path("splat/lam_offset_subset.ply");
    let set = read_gaussians(&path).unwrap();
    assert_eq!(set.len(), 500);
    assert_eq!(set.sh_degree(), 0);
    assert!(set.binding().is_none());
    assert_eq!(
        set.extras()
            .iter()
            .map(|e| e.name.as_str())
            .collect::<Vec<_>>(),
        ["nx", "ny", "nz"]
    );
    let min_log = set
        .log_scales()
        .iter()
        .map(|s| s.min_element())
        .fold(f32::INFINITY, f32::min);
    assert!(min_log < -29.0, "{min_log}");
    for i in 0..set.len() {
        let s = set.scale(i);
        assert!(s.min_element() > 0.0 && s.is_finite(), "Gaussian {i}: {s}");
        let cov = set.covariance(i);
        assert!(cov.is_finite());
        let o = set.opacity(i);
        assert!((0.0..=1.0).contains(&o));
    }
    // Byte-identical rewrite of a real file.
    let original = std::fs::read(&path).unwrap();
    assert_eq!(to_bytes(&set, PlyEncoding::BinaryLittleEndian), original);
}

fn header(count: &str, extra_props: &str) -> String {
    format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {count}\n\
         property float x\nproperty float y\nproperty float z\n\
         property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n{extra_props}\
         property float opacity\nproperty float scale_0\nproperty float scale_1\nproperty float scale_2\n\
         property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n"
    )
}

fn row(values: [f32; 14]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

const GOOD_ROW: [f32; 14] = [
    0.0, 0.0, 0.0, 0.5, 0.5, 0.5, 0.0, -1.0, -1.0, -1.0, 1.0, 0.0, 0.0, 0.0,
];

#[test]
fn bad_files_give_clear_errors() {
    // Truncated body: the header says 3, two rows and a half are present.
    let mut bytes = header("3", "").into_bytes();
    bytes.extend(row(GOOD_ROW));
    bytes.extend(row(GOOD_ROW));
    bytes.extend(&row(GOOD_ROW)[..20]);
    let err = read(&bytes).unwrap_err();
    assert!(matches!(err, PlyError::Malformed(_)), "{err:?}");
    assert_eq!(
        err.to_string(),
        "mem.ply: element vertex: the header declares 3 rows but the rest of the file can hold \
         at most 2 (truncated file or wrong count)"
    );
    // An absurd count is an error, not an allocation.
    let mut bytes = header("18446744073709551615", "").into_bytes();
    bytes.extend(row(GOOD_ROW));
    let err = read(&bytes).unwrap_err();
    assert!(err.to_string().contains("can hold at most 1"), "{err}");
    let mut ascii = header("4000000000000", "").replace("binary_little_endian", "ascii");
    ascii.push_str("0 0 0 0 0 0 0 0 0 0 1 0 0 0\n");
    let err = read(ascii.as_bytes()).unwrap_err();
    assert!(matches!(err, PlyError::Malformed(_)), "{err:?}");
    assert!(err.to_string().contains("element vertex"), "{err}");
    // NaN mean and zero quaternion name the Gaussian.
    let mut nan = GOOD_ROW;
    nan[1] = f32::NAN;
    let mut zero_q = GOOD_ROW;
    zero_q[10] = 0.0;
    for (bad, want) in [
        (
            nan,
            GaussianError::NonFinite {
                index: 1,
                field: "mean",
            },
        ),
        (zero_q, GaussianError::ZeroQuaternion { index: 1 }),
    ] {
        let mut bytes = header("2", "").into_bytes();
        bytes.extend(row(GOOD_ROW));
        bytes.extend(row(bad));
        let err = read(&bytes).unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("mem.ply: Gaussian 1: "), "{text}");
        assert!(matches!(err, PlyError::Invalid { source, .. } if source == want));
    }
    // f_rest counts other than 0, 9, 24, 45.
    let rest: String = (0..10)
        .map(|i| format!("property float f_rest_{i}\n"))
        .collect();
    assert!(matches!(
        read(header("0", &rest).as_bytes()),
        Err(PlyError::BadProperty { .. })
    ));
    // Missing property, no end_header, not a PLY, unknown format.
    let no_opacity = header("0", "").replace("property float opacity\n", "");
    assert!(matches!(
        read(no_opacity.as_bytes()),
        Err(PlyError::MissingProperty { name, .. }) if name == "opacity"
    ));
    for (bytes, at) in [
        (&b"ply\nformat ascii 1.0\n"[..], "header line"),
        (b"solid cube\n", "header line 1"),
        (b"", "header line 1"),
        (
            b"ply\nformat binary_middle_endian 1.0\nend_header\n",
            "header line 2",
        ),
    ] {
        let err = read(bytes).unwrap_err();
        assert!(matches!(err, PlyError::Malformed(_)), "{err:?}");
        assert!(
            err.to_string().starts_with(&format!("mem.ply: {at}")),
            "{err}"
        );
    }
    // Fractional or negative bindings.
    let mut bytes = header("1", "property float binding_0\n").into_bytes();
    let mut r = row(GOOD_ROW);
    r.splice(24..24, 1.5f32.to_le_bytes());
    bytes.extend(r);
    assert!(matches!(
        read(&bytes),
        Err(PlyError::BadBinding { index: 0, .. })
    ));
    // Both binding encodings at once.
    let both = header("0", "property float binding_0\nproperty int binding\n");
    assert!(matches!(
        read(both.as_bytes()),
        Err(PlyError::BadProperty { .. })
    ));
    // Ascii garbage names the Gaussian and property.
    let mut ascii = header("1", "").replace("binary_little_endian", "ascii");
    ascii.push_str("0 0 zero 0 0 0 0 0 0 0 1 0 0 0\n");
    let err = read(ascii.as_bytes()).unwrap_err();
    assert_eq!(
        err.to_string(),
        "mem.ply: vertex 0: `zero` is not a valid float for `z`"
    );
    // Missing file.
    assert!(matches!(
        read_gaussians(Path::new("/nonexistent/g.ply")),
        Err(PlyError::Io { .. })
    ));
}

#[test]
fn every_truncation_is_an_error_never_a_panic() {
    let set = GaussianSet::try_new(with_extras(random_set(5, 1, 11))).unwrap();
    for enc in ENCODINGS {
        let bytes = to_bytes(&set, enc);
        for len in 0..bytes.len() {
            let cut = &bytes[..len];
            // Ascii files cut at a line end can be valid with fewer digits; binary never is.
            let result = read(cut);
            if enc != PlyEncoding::Ascii {
                assert!(result.is_err(), "{enc:?} cut at {len} read fine");
            }
        }
    }
}

#[test]
fn atomic_write_replaces_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.ply");
    std::fs::write(&path, b"old").unwrap();
    let set = GaussianSet::try_new(random_set(20, 2, 5)).unwrap();
    write_gaussians(&path, &set, &PlyWriteOptions::default()).unwrap();
    assert_bit_identical(&set, &read_gaussians(&path).unwrap());
    // A folder that does not exist: error, nothing written.
    let bad = dir.path().join("missing/g.ply");
    assert!(matches!(
        write_gaussians(&bad, &set, &PlyWriteOptions::default()),
        Err(PlyError::Write(_))
    ));
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn random_bodies_never_panic(body in proptest::collection::vec(any::<u8>(), 0..400),
                                     count in 0usize..40, ascii in any::<bool>()) {
            let mut bytes = header(&count.to_string(), "property uchar label\n");
            if ascii {
                bytes = bytes.replace("binary_little_endian", "ascii");
            }
            let mut bytes = bytes.into_bytes();
            bytes.extend(body);
            let _ = read(&bytes);
        }

        #[test]
        fn random_headers_never_panic(text in "[a-z_0-9 \n]{0,300}") {
            let _ = read(format!("ply\n{text}").as_bytes());
        }
    }
}

#[test]
fn standard_properties_in_other_types_are_converted() {
    // x, y, z as double and opacity as uchar (a file from another tool): the general
    // column path, big-endian.
    let head = "ply\nformat binary_big_endian 1.0\nelement vertex 2\n\
        property double x\nproperty double y\nproperty double z\nproperty uchar opacity\n\
        property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n\
        property float scale_0\nproperty float scale_1\nproperty float scale_2\n\
        property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n\
        end_header\n";
    let mut bytes = head.as_bytes().to_vec();
    for g in 0..2u8 {
        for v in [0.1f64, -2.5, 1e10] {
            bytes.extend((v * f64::from(g + 1)).to_be_bytes());
        }
        bytes.push(200 + g);
        for v in [0.5f32, 0.25, 0.125, -1.0, -2.0, -3.0, 1.0, 0.0, 0.0, 0.0] {
            bytes.extend(v.to_be_bytes());
        }
    }
    let set = read(&bytes).unwrap();
    assert_eq!(set.means()[1], Vec3::new(0.2, -5.0, 2e10));
    assert_eq!(set.opacity_logits(), &[200.0, 201.0]);
    assert_eq!(set.log_scales()[0], Vec3::new(-1.0, -2.0, -3.0));
    assert_eq!(set.sh_coeffs(1), &[0.5, 0.25, 0.125]);
}
