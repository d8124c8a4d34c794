//! Plain point clouds read without the general document: a binary PLY whose only rows are
//! `vertex` rows of `float` properties `x y z`, optionally `nx ny nz` (what `trisplat sample`
//! and most scanners' point exports write), decoded straight from the file's bytes into the
//! cloud's f32 vectors, in parallel. The general path builds six typed columns, widens the
//! positions to f64 and narrows them again; the values and errors are the same.

use std::path::Path;

use glam::Vec3;
use rayon::prelude::*;

use super::header::{Header, PropKind, parse_header};
use super::model::{PlyEncoding, ScalarType};
use super::read::count_limit_error;
use crate::io::error::IoError;
use crate::points::PointCloud;

/// Rows decoded per parallel task.
const ROWS_PER_TASK: usize = 1 << 14;

/// Where each property sits in a vertex row, in bytes.
struct Layout {
    stride: usize,
    position: [usize; 3],
    normal: Option<[usize; 3]>,
}

impl Layout {
    /// The layout of a plain cloud, or `None` when `header` describes anything else: ascii,
    /// another property or type, another element with rows, part of a normal.
    fn of(header: &Header) -> Option<(Self, usize)> {
        if header.encoding == PlyEncoding::Ascii {
            return None;
        }
        let (vertex, others) = header.elements.split_first()?;
        if vertex.name != "vertex" || others.iter().any(|e| e.count > 0) {
            return None;
        }
        let names = ["x", "y", "z", "nx", "ny", "nz"];
        let mut at = [None; 6];
        for (k, prop) in vertex.props.iter().enumerate() {
            if !matches!(prop.kind, PropKind::Scalar(ScalarType::F32)) {
                return None;
            }
            let slot = names.iter().position(|&n| n == prop.name)?;
            if at[slot].replace(4 * k).is_some() {
                return None;
            }
        }
        let position = [at[0]?, at[1]?, at[2]?];
        let normal = match at[3..] {
            [Some(x), Some(y), Some(z)] => Some([x, y, z]),
            [None, None, None] => None,
            _ => return None,
        };
        let stride = 4 * vertex.props.len();
        Some((
            Self {
                stride,
                position,
                normal,
            },
            vertex.count,
        ))
    }
}

/// The points (and normals) of `bytes`, the whole of the PLY file `path`, when it is a plain
/// cloud (see the module docs); `Ok(None)` for any other PLY, which the general reader
/// ([`super::parse_ply`] then [`super::ply_to_points`]) reads.
///
/// # Errors
/// [`IoError::Malformed`] for a header the general reader refuses too, a vertex count the
/// body cannot hold, or a coordinate or normal that is not finite (naming the vertex, as the
/// general reader does).
pub fn read_plain_points(path: &Path, bytes: &[u8]) -> Result<Option<PointCloud>, IoError> {
    let header = parse_header(path, bytes)?;
    let Some((layout, count)) = Layout::of(&header) else {
        return Ok(None);
    };
    let body = &bytes[header.body_start..];
    let possible = body.len() / layout.stride;
    if count > possible {
        return Err(count_limit_error(path, &header.elements[0], possible));
    }
    let rows = &body[..count * layout.stride];
    let big_endian = header.encoding == PlyEncoding::BinaryBigEndian;
    let read = move |row: &[u8], at: [usize; 3]| {
        // Three plain calls: `[_; 3]::map` was not inlined (33 instructions a value).
        #[inline(always)]
        fn float(row: &[u8], o: usize, big_endian: bool) -> f32 {
            let word = [row[o], row[o + 1], row[o + 2], row[o + 3]];
            if big_endian {
                f32::from_be_bytes(word)
            } else {
                f32::from_le_bytes(word)
            }
        }
        Vec3::new(
            float(row, at[0], big_endian),
            float(row, at[1], big_endian),
            float(row, at[2], big_endian),
        )
    };
    let column = |at: [usize; 3]| -> Vec<Vec3> {
        rows.par_chunks_exact(layout.stride)
            .with_min_len(ROWS_PER_TASK)
            .map(|row| read(row, at))
            .collect()
    };
    let (positions, normals) =
        rayon::join(|| column(layout.position), || layout.normal.map(column));
    // The general reader's messages: coordinates widened to f64, normals as f32.
    let bad = |i: usize, what: String| {
        IoError::malformed(path, format!("vertex {i}"), format!("non-finite {what}"))
    };
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        let p = positions[i].as_dvec3();
        return Err(bad(i, format!("coordinate ({}, {}, {})", p.x, p.y, p.z)));
    }
    if let Some(n) = &normals
        && let Some(i) = n.iter().position(|p| !p.is_finite())
    {
        let p = n[i];
        return Err(bad(i, format!("normal ({}, {}, {})", p.x, p.y, p.z)));
    }
    let cloud = PointCloud::new_unchecked(positions);
    Ok(Some(match normals {
        Some(n) => cloud
            .with_normals(n)
            .map_err(|e| IoError::malformed(path, "element vertex", e.to_string()))?,
        None => cloud,
    }))
}

#[cfg(test)]
mod tests {
    use super::super::{parse_ply, ply_to_points};
    use super::*;

    /// A PLY of `count` vertex rows with the given property lines and little-endian f32 rows
    /// (`values`, row after row), and an optional trailing header line.
    fn file(encoding: &str, props: &[&str], count: usize, values: &[f32], extra: &str) -> Vec<u8> {
        let mut text = format!("ply\nformat {encoding} 1.0\nelement vertex {count}\n");
        for p in props {
            text.push_str(&format!("property {p}\n"));
        }
        text.push_str(extra);
        text.push_str("end_header\n");
        let mut bytes = text.into_bytes();
        for v in values {
            if encoding == "binary_big_endian" {
                bytes.extend(v.to_be_bytes());
            } else {
                bytes.extend(v.to_le_bytes());
            }
        }
        bytes
    }

    fn values(rows: usize, width: usize) -> Vec<f32> {
        (0..rows * width)
            .map(|i| (i as f32 * 0.37).sin() * 1e3 + if i % 5 == 0 { -0.0 } else { 0.0 })
            .collect()
    }

    /// The plain reader's cloud is the general reader's, to the bit, whatever the byte order,
    /// property order and presence of normals (and in parallel: more rows than one task).
    #[test]
    fn plain_clouds_equal_the_general_readers() {
        let path = Path::new("plain.ply");
        let rows = 3 * ROWS_PER_TASK + 7;
        let xyz = ["float x", "float y", "float z"];
        let normals = [
            "float x", "float y", "float z", "float nx", "float ny", "float nz",
        ];
        let shuffled = [
            "float nz", "float y", "float nx", "float x", "float ny", "float z",
        ];
        for encoding in ["binary_little_endian", "binary_big_endian"] {
            for props in [&xyz[..], &normals[..], &shuffled[..]] {
                let bytes = file(encoding, props, rows, &values(rows, props.len()), "");
                let plain = read_plain_points(path, &bytes)
                    .expect("valid")
                    .expect("a plain cloud");
                let doc = parse_ply(path, &bytes).expect("valid");
                let (general, _) = ply_to_points(path, &doc).expect("valid");
                assert_eq!(plain, general, "{encoding} {props:?}");
                let bits = |c: &PointCloud| -> Vec<[u32; 3]> {
                    let all = c.positions().iter().chain(c.normals().unwrap_or(&[]));
                    all.map(|p| p.to_array().map(f32::to_bits)).collect()
                };
                assert_eq!(bits(&plain), bits(&general), "{encoding} {props:?}");
                assert_eq!(plain.normals().is_some(), props.len() == 6);
            }
        }
    }

    /// Anything but a plain cloud is left to the general reader.
    #[test]
    fn other_files_are_left_to_the_general_reader() {
        let path = Path::new("other.ply");
        let xyz = ["float x", "float y", "float z"];
        let cases: [(&str, Vec<&str>, &str); 6] = [
            (
                "binary_little_endian",
                vec!["double x", "double y", "double z"],
                "",
            ),
            (
                "binary_little_endian",
                vec!["float x", "float y", "float z", "float nx"],
                "",
            ),
            (
                "binary_little_endian",
                vec!["float x", "float y", "float z", "uchar red"],
                "",
            ),
            ("binary_little_endian", vec!["float x", "float y"], ""),
            (
                "binary_little_endian",
                xyz.to_vec(),
                "element face 1\nproperty list uchar int vertex_indices\n",
            ),
            (
                "binary_little_endian",
                vec!["float x", "float x", "float z"],
                "",
            ),
        ];
        for (encoding, props, extra) in cases {
            let bytes = file(encoding, &props, 2, &values(2, props.len()), extra);
            assert!(
                read_plain_points(path, &bytes)
                    .expect("readable header")
                    .is_none(),
                "{props:?} {extra}"
            );
        }
        let ascii = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
        assert!(read_plain_points(path, ascii).expect("valid").is_none());
        // An empty face element does not make a mesh.
        let bytes = file(
            "binary_little_endian",
            &xyz,
            2,
            &values(2, 3),
            "element face 0\nproperty list uchar int vertex_indices\n",
        );
        assert!(read_plain_points(path, &bytes).expect("valid").is_some());
    }

    /// Truncated bodies and non-finite values are errors naming the element or vertex, as
    /// the general reader's.
    #[test]
    fn bad_plain_clouds_are_errors_naming_the_vertex() {
        let path = Path::new("bad.ply");
        let props = [
            "float x", "float y", "float z", "float nx", "float ny", "float nz",
        ];
        let mut bytes = file("binary_little_endian", &props, 3, &values(3, 6), "");
        bytes.truncate(bytes.len() - 1);
        let err = read_plain_points(path, &bytes).expect_err("truncated");
        assert!(err.to_string().contains("element vertex"), "{err}");
        assert!(err.to_string().contains("at most 2"), "{err}");
        for (at, what) in [(7, "coordinate"), (16, "normal")] {
            let mut v = values(3, 6);
            v[at] = if at == 7 { f32::NAN } else { f32::INFINITY };
            let bytes = file("binary_little_endian", &props, 3, &v, "");
            let err = read_plain_points(path, &bytes).expect_err("non-finite");
            let general = ply_to_points(path, &parse_ply(path, &bytes).expect("parses"))
                .expect_err("non-finite");
            assert_eq!(err.to_string(), general.to_string());
            assert!(
                err.to_string().contains(&format!("vertex {}", at / 6)),
                "{err}"
            );
            assert!(err.to_string().contains(what), "{err}");
        }
    }
}
