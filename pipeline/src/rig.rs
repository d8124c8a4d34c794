//! The template's rig moved onto a key mesh (`extract --targets rig`, docs/conventions.md §10):
//! each key vertex takes the skin weights and morph-target deltas of the template triangle it
//! is carried by ([`crate::carry`]), so the weights track (LAM: 51 ARKit targets and the head
//! joint's `head_pose`) plays the mesh in any glTF engine without per-frame vertex data.
//!
//! # The transfer
//! A key vertex is bound to template triangle `(a, b, c)` by `(u, v, w)`:
//! `x = a + u e1 + v e2 + w m` ([`place_on`]). In the rig's bind space (the template's stored
//! pose, [`TemplateRig`]) the vertex is that rule applied to the bind corners, and:
//! - **skin**: the corners' joint weights blended by the barycentric coordinates
//!   `(1 - u - v, u, v)` (negative ones, for a vertex beside its triangle, clamped to 0 and the
//!   rest renormalised), then the four largest kept and renormalised (glTF's `JOINTS_0`);
//! - **morph target k**: `place_on(corners + Δk) - place_on(corners)`, the vertex moved by the
//!   rule with the target fully on. In the plane of the triangle the rule is linear in the
//!   corners, so that part is exact for any weights; the offset `w` along `m = n / sqrt(|n|)`
//!   is not (the normal turns and scales with the corners), so the rig plays the normal offset
//!   of one target at weight 1 exactly and blends of targets to first order: the error grows
//!   with `|w|` times the change of the triangle's normal, which a linear rig cannot follow.
//!   Skinning is linear blend skinning of the blended weights: a vertex whose corners are
//!   skinned alike moves exactly as the carried vertex does under any rigid joint motion.
//!
//! A vertex that lies on a template vertex (barycentric `(1, 0, 0)`, `w = 0`) takes that
//! vertex's weights (when it has at most four) and deltas exactly, so it moves as the template.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use trisplat_geometry::TriMesh;
use trisplat_geometry::animation::{AnimationError, TemplateRig};
use trisplat_geometry::io::{IoError, RiggedMesh};

use crate::carry::place_on;

/// Why a rig cannot be made or written.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The template or its animation has no rig to transfer.
    #[error("{0}")]
    NoRig(String),
    /// The template's rig could not be read.
    #[error(transparent)]
    Template(#[from] AnimationError),
    /// A key vertex is bound to no triangle of the template.
    #[error(
        "key mesh vertex {vertex} is bound to template triangle {triangle}, which the template ({triangles} triangles) does not have"
    )]
    NoTriangle {
        /// The key mesh vertex.
        vertex: usize,
        /// Its triangle.
        triangle: u32,
        /// The template's triangle count.
        triangles: usize,
    },
    /// The key mesh, its binding and the template do not fit together.
    #[error("{0}")]
    Mismatch(String),
    /// A transferred value is not finite (a degenerate bind triangle).
    #[error("key mesh vertex {vertex}: the transferred {what} is not finite")]
    NotFinite {
        /// The key mesh vertex.
        vertex: usize,
        /// Position, weights or a target's delta.
        what: String,
    },
    /// The rig file could not be written or read back.
    #[error(transparent)]
    Io(#[from] IoError),
}

/// What one key vertex takes from its triangle.
struct Transferred {
    position: Vec3,
    joints: [u16; 4],
    weights: [f32; 4],
    /// `(target, delta)` for the targets that move it.
    deltas: Vec<(u32, Vec3)>,
}

/// The key mesh `key`, bound by `triangle`/`coords` ([`crate::carry::CarriedMesh::binding`])
/// to the template `triangles` (welded; welded vertex `v` is stored vertex `stored_of[v]`),
/// with `rig`'s skin and morph targets moved onto it (see the module docs).
///
/// # Errors
/// [`RigError::Mismatch`] when the binding does not cover the key's vertices or the rig has
/// another vertex count than the template; [`RigError::NoTriangle`] for a vertex bound to a
/// triangle the template lacks; [`RigError::NotFinite`]; [`RigError::NoRig`] for a rig with
/// more joints than `JOINTS_0` holds.
pub fn transfer(
    key: &TriMesh,
    binding: (&[u32], &[DVec3]),
    triangles: &[[u32; 3]],
    stored_of: &[u32],
    rig: &TemplateRig,
) -> Result<RiggedMesh, RigError> {
    let (triangle, coords) = binding;
    let n = key.vertex_count();
    if triangle.len() != n || coords.len() != n {
        return Err(RigError::Mismatch(format!(
            "the binding has {} triangles and {} coordinates for {n} key vertices",
            triangle.len(),
            coords.len()
        )));
    }
    if rig.offsets.len() != rig.positions.len() + 1 {
        return Err(RigError::Mismatch(
            "the rig's skin rows do not match its vertices".into(),
        ));
    }
    if let Some(v) = stored_of
        .iter()
        .find(|&&v| v as usize >= rig.positions.len())
    {
        return Err(RigError::Mismatch(format!(
            "the template's vertex {v} is past the rig's {} vertices",
            rig.positions.len()
        )));
    }
    if rig.joints.len() > usize::from(u16::MAX) + 1 {
        return Err(RigError::NoRig(format!(
            "{} joints: more than glTF's 16-bit JOINTS_0 holds",
            rig.joints.len()
        )));
    }
    // For each target, where each template vertex's delta is in its list (u32::MAX: none).
    let slots: Vec<Vec<u32>> = rig
        .targets
        .par_iter()
        .map(|t| {
            let mut slot = vec![u32::MAX; rig.positions.len()];
            for (i, &(v, _)) in t.deltas.iter().enumerate() {
                slot[v as usize] = i as u32;
            }
            slot
        })
        .collect();
    let rows: Vec<Transferred> = (0..n)
        .into_par_iter()
        .map(|i| transfer_vertex(i, triangle[i], coords[i], triangles, stored_of, rig, &slots))
        .collect::<Result<_, _>>()?;
    let mut targets: Vec<(String, Vec<(u32, Vec3)>)> = rig
        .targets
        .iter()
        .map(|t| (t.name.clone(), Vec::new()))
        .collect();
    let mut mesh = RiggedMesh {
        positions: Vec::with_capacity(n),
        triangles: key.triangles().to_vec(),
        joints: Vec::with_capacity(n),
        weights: Vec::with_capacity(n),
        targets: Vec::new(),
    };
    for (i, row) in rows.into_iter().enumerate() {
        mesh.positions.push(row.position);
        mesh.joints.push(row.joints);
        mesh.weights.push(row.weights);
        for (k, d) in row.deltas {
            targets[k as usize].1.push((i as u32, d));
        }
    }
    mesh.targets = targets;
    Ok(mesh)
}

/// One key vertex's transfer (see [`transfer`]).
fn transfer_vertex(
    vertex: usize,
    triangle: u32,
    uvw: DVec3,
    triangles: &[[u32; 3]],
    stored_of: &[u32],
    rig: &TemplateRig,
    slots: &[Vec<u32>],
) -> Result<Transferred, RigError> {
    let tri = triangles
        .get(triangle as usize)
        .ok_or(RigError::NoTriangle {
            vertex,
            triangle,
            triangles: triangles.len(),
        })?;
    let corners_id = tri.map(|w| stored_of.get(w as usize).copied());
    let [Some(a), Some(b), Some(c)] = corners_id else {
        return Err(RigError::Mismatch(format!(
            "template triangle {triangle} refers past the template's {} vertices",
            stored_of.len()
        )));
    };
    let ids = [a, b, c].map(|v| v as usize);
    let corners = ids.map(|v| rig.positions[v]);
    let rest = place_on(corners, uvw);
    let not_finite = |what: &str| RigError::NotFinite {
        vertex,
        what: what.to_owned(),
    };
    if !rest.is_finite() {
        return Err(not_finite("position"));
    }
    // Skin: barycentric blend of the corners' weights, clamped into the triangle.
    let mut bary = [1.0 - uvw.x - uvw.y, uvw.x, uvw.y].map(|b| b.max(0.0));
    let sum: f64 = bary.iter().sum();
    bary = if sum > 0.0 && sum.is_finite() {
        bary.map(|b| b / sum)
    } else {
        [1.0 / 3.0; 3]
    };
    let mut blend: Vec<(u32, f64)> = Vec::with_capacity(12);
    for (&v, &b) in ids.iter().zip(&bary) {
        if b == 0.0 {
            continue;
        }
        for &(j, w) in rig.influences_of(v) {
            match blend.iter_mut().find(|e| e.0 == j) {
                Some(e) => e.1 += b * w,
                None => blend.push((j, b * w)),
            }
        }
    }
    blend.sort_by(|x, y| y.1.total_cmp(&x.1).then(x.0.cmp(&y.0)));
    blend.truncate(4);
    let total: f64 = blend.iter().map(|e| e.1).sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(not_finite("joint weights"));
    }
    let mut joints = [0u16; 4];
    let mut weights = [0f32; 4];
    for (s, &(j, w)) in blend.iter().enumerate() {
        joints[s] = j as u16;
        weights[s] = (w / total) as f32;
    }
    // The largest weight takes the f32 rounding, so the four sum to 1 as stored.
    weights[0] = 1.0 - weights[1..].iter().sum::<f32>();
    // Morph targets: the vertex moved by the rule with each target fully on.
    let mut deltas = Vec::new();
    for (k, (target, slot)) in rig.targets.iter().zip(slots).enumerate() {
        let d = ids.map(|v| match slot[v] {
            u32::MAX => DVec3::ZERO,
            i => target.deltas[i as usize].1,
        });
        if d.iter().all(|d| *d == DVec3::ZERO) {
            continue;
        }
        let moved = place_on([0, 1, 2].map(|c| corners[c] + d[c]), uvw) - rest;
        if !moved.is_finite() {
            return Err(not_finite(&format!(
                "delta of morph target {}",
                target.name
            )));
        }
        let moved = moved.as_vec3();
        if moved != Vec3::ZERO {
            deltas.push((k as u32, moved));
        }
    }
    Ok(Transferred {
        position: rest.as_vec3(),
        joints,
        weights,
        deltas,
    })
}

#[cfg(test)]
mod tests {
    use glam::{DMat4, DQuat};
    use trisplat_geometry::animation::{AnimatedTemplate, Clip, GltfTemplate, RigNode, RigPose};
    use trisplat_geometry::io::{RigAnimation, write_rigged_glb};

    use super::*;

    /// A 3 x 3 grid of vertices (a quad of 8 triangles) skinned to a root and a bone at x = 1
    /// (weights by x), with two morph targets, turning the bone and playing the targets over
    /// three frames; written with the rig writer itself.
    fn template(dir: &Path) -> std::path::PathBuf {
        let positions: Vec<Vec3> = (0..9)
            .map(|i| Vec3::new((i % 3) as f32, (i / 3) as f32, 0.0))
            .collect();
        let mut triangles = Vec::new();
        for y in 0..2u32 {
            for x in 0..2u32 {
                let i = y * 3 + x;
                triangles.push([i, i + 1, i + 4]);
                triangles.push([i, i + 4, i + 3]);
            }
        }
        let joints = vec![[0u16, 1, 0, 0]; 9];
        let weights = positions
            .iter()
            .map(|p| [1.0 - p.x / 2.0, p.x / 2.0, 0.0, 0.0])
            .collect();
        let mesh = RiggedMesh {
            positions,
            triangles,
            joints,
            weights,
            targets: vec![
                ("bump".into(), vec![(4, Vec3::new(0.0, 0.0, 0.5))]),
                ("edge".into(), vec![(2, Vec3::X * 0.3), (5, Vec3::Y * 0.2)]),
            ],
        };
        let nodes = vec![
            RigNode {
                name: Some("root".into()),
                parent: None,
                trs: (DVec3::ZERO, DQuat::IDENTITY, DVec3::ONE),
            },
            RigNode {
                name: Some("bone".into()),
                parent: Some(0),
                trs: (DVec3::X, DQuat::IDENTITY, DVec3::ONE),
            },
        ];
        let poses: Vec<RigPose> = (0..3)
            .map(|f| {
                let turn = DQuat::from_rotation_z(0.4 * f64::from(f));
                RigPose {
                    locals: vec![nodes[0].trs, (DVec3::X, turn, DVec3::ONE)],
                    weights: vec![0.5 * f64::from(f), 1.0 - 0.3 * f64::from(f)],
                }
            })
            .collect();
        let path = dir.join("template.glb");
        let inverse_bind = vec![DMat4::IDENTITY, DMat4::from_translation(-DVec3::X)];
        write_rigged_glb(
            &path,
            &mesh,
            &RigAnimation {
                nodes: &nodes,
                joints: &[0, 1],
                inverse_bind: &inverse_bind,
                times: &[0.0, 0.5, 1.0],
                poses: &poses,
            },
        )
        .expect("template");
        path
    }

    use std::path::Path;

    #[test]
    fn vertices_on_template_vertices_move_as_the_template() {
        let dir = tempfile::tempdir().expect("dir");
        let t = GltfTemplate::open(&template(dir.path()), &Clip::Index(0))
            .expect("open")
            .with_fps(2.0);
        let rig = t.rig().expect("rig");
        assert_eq!((rig.joints.len(), rig.targets.len()), (2, 2));
        let welded = t.rest().clone();
        // Key vertices on template vertices 0, 4, 2, 5 (corners a, b, c of triangles 0 and 2)
        // and one off the surface, above triangle 0's interior.
        let key = TriMesh::new(vec![DVec3::ZERO; 5], vec![[0, 1, 2], [1, 3, 2], [0, 1, 4]]);
        let triangle = [0u32, 0, 2, 2, 0];
        let coords = [
            DVec3::ZERO,
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(0.3, 0.2, 0.1),
        ];
        let identity: Vec<u32> = (0..9).collect();
        let moved = transfer(
            &key,
            (&triangle, &coords),
            welded.triangles(),
            &identity,
            &rig,
        )
        .expect("transfer");
        // Template triangle 0 is [0, 1, 4], triangle 2 is [1, 2, 5].
        let on = [0usize, 4, 2, 5];
        let poses: Vec<RigPose> = (0..3)
            .map(|f| t.frame_rig_pose(f).expect("rig").expect("pose"))
            .collect();
        let path = dir.path().join("rig.glb");
        write_rigged_glb(
            &path,
            &moved,
            &RigAnimation {
                nodes: &rig.nodes,
                joints: &rig.joints,
                inverse_bind: &rig.inverse_bind,
                times: &[0.0, 0.5, 1.0],
                poses: &poses,
            },
        )
        .expect("write");
        let played = GltfTemplate::open(&path, &Clip::Index(0)).expect("read back");
        for f in 0..3 {
            let time = 0.5 * f as f64;
            let expected = t.evaluate_at(time).expect("template");
            let got = played.evaluate_at(time).expect("rig");
            for (k, &v) in on.iter().enumerate() {
                let d = (got[k] - expected[v]).length();
                assert!(d < 1e-6, "frame {f}, vertex {k}: {d}");
            }
            // The vertex off the surface: at frame 0 the joints rest and one target is fully
            // on, which the rig plays exactly (normal offset included); turned and blended,
            // its corners skinned differently, it is the linear rig's approximation.
            let corners = [0usize, 1, 4].map(|c| expected[c]);
            let carried = place_on(corners, coords[4]);
            let d = (got[4] - carried).length();
            let bound = if f == 0 { 1e-6 } else { 0.3 };
            assert!(d < bound, "frame {f}: {d}");
        }
    }

    #[test]
    fn bad_input_is_refused_by_name() {
        let dir = tempfile::tempdir().expect("dir");
        let t = GltfTemplate::open(&template(dir.path()), &Clip::None).expect("open");
        let rig = t.rig().expect("rig");
        let key = TriMesh::new(vec![DVec3::ZERO; 3], vec![[0, 1, 2]]);
        let identity: Vec<u32> = (0..9).collect();
        let e = transfer(
            &key,
            (&[0, 1, 99], &[DVec3::ZERO; 3]),
            t.rest().triangles(),
            &identity,
            &rig,
        )
        .expect_err("no triangle 99");
        assert!(
            matches!(
                e,
                RigError::NoTriangle {
                    vertex: 2,
                    triangle: 99,
                    ..
                }
            ),
            "{e}"
        );
        // A template without a skin or morph targets has no rig.
        let plain = dir.path().join("plain.glb");
        trisplat_geometry::io::write_mesh(&plain, t.rest(), Default::default()).expect("plain");
        let e = GltfTemplate::open(&plain, &Clip::None)
            .expect("open")
            .rig()
            .expect_err("no rig");
        assert!(e.to_string().contains("neither a skinned mesh"), "{e}");
        // A rig that cannot be written leaves no file.
        let mut moved = transfer(
            &key,
            (&[0, 0, 0], &[DVec3::ZERO, DVec3::X, DVec3::Y]),
            t.rest().triangles(),
            &identity,
            &rig,
        )
        .expect("transfer");
        moved.positions[1].x = f32::NAN;
        let path = dir.path().join("bad.glb");
        let pose = t.rig_pose(None, &|_, _| None, None);
        let e = write_rigged_glb(
            &path,
            &moved,
            &RigAnimation {
                nodes: &rig.nodes,
                joints: &rig.joints,
                inverse_bind: &rig.inverse_bind,
                times: &[0.0],
                poses: &[pose],
            },
        )
        .expect_err("NaN");
        assert!(e.to_string().contains("vertex 1"), "{e}");
        assert!(!path.exists());
    }
}
