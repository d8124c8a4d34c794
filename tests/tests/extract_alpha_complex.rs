//! The alpha complex (`extract::alpha_complex`, CGAL's GENERAL rule, and the boundary of its
//! solid) against an independent
//! reference (`tests/reference/ref_alpha_complex.py`: scipy's Qhull Delaunay and a brute-force
//! emptiness test of each triangle's smallest circumsphere against every point): the same
//! output triangles as sets of sorted index triples and the same piece count. Triangles the
//! reference marks as within 1e-9 of a tie are left out on both sides (there are none in the
//! stored cases).

use std::collections::BTreeSet;

use glam::Vec3;
use serde::Deserialize;
use trisplat_extract::alpha_complex::{
    AlphaComplex, AlphaSearch, Surface, smallest_connected_alpha,
};
use trisplat_extract::delaunay3d::Delaunay3d;
use trisplat_geometry::io::read_points;

#[derive(Deserialize)]
struct Reference {
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    input: String,
    alpha: f64,
    triangles: Vec<u32>,
    pieces: usize,
    solid: Vec<u32>,
    solid_pieces: usize,
    ties: Vec<u32>,
}

fn load(name: &str) -> Vec<Vec3> {
    let path = trisplat_fixtures::path(&format!("reference/alpha/{name}"));
    read_points(&path)
        .expect("fixture points")
        .positions()
        .to_vec()
}

fn triples(flat: &[u32]) -> BTreeSet<[u32; 3]> {
    flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect()
}

#[test]
fn complex_matches_the_reference() {
    let path = trisplat_fixtures::path("reference/alpha/complex.json");
    let text = std::fs::read_to_string(&path).expect("reference JSON");
    let reference: Reference = serde_json::from_str(&text).expect("valid reference JSON");
    assert!(reference.cases.len() >= 4);
    for case in &reference.cases {
        let points = load(&case.input);
        let delaunay = Delaunay3d::new(&points).expect("finite points");
        let complex = AlphaComplex::new(&delaunay);
        let shape = complex
            .shape(case.alpha, Surface::General)
            .expect("valid alpha");
        let ties = triples(&case.ties);
        let ours: BTreeSet<[u32; 3]> = shape
            .mesh
            .triangles()
            .iter()
            .map(|t| {
                let mut v = t.map(|i| shape.vertex_ids[i as usize]);
                v.sort_unstable();
                v
            })
            .filter(|t| !ties.contains(t))
            .collect();
        let theirs: BTreeSet<[u32; 3]> = triples(&case.triangles)
            .into_iter()
            .filter(|t| !ties.contains(t))
            .collect();
        // No triangle is output twice.
        assert_eq!(
            ours.len() + ties.len().min(shape.mesh.triangle_count() - ours.len()),
            shape.mesh.triangle_count()
        );
        let missing: Vec<_> = theirs.difference(&ours).take(5).collect();
        let extra: Vec<_> = ours.difference(&theirs).take(5).collect();
        assert!(
            missing.is_empty() && extra.is_empty(),
            "{} alpha {}: {} vs {} triangles; missing {missing:?}, extra {extra:?}",
            case.input,
            case.alpha,
            ours.len(),
            theirs.len()
        );
        if ties.is_empty() {
            assert_eq!(
                complex.pieces(case.alpha, Surface::General),
                case.pieces,
                "{}",
                case.input
            );
            // The solid's boundary: the same oriented triangles (each rotated to start at its
            // smallest input index) and pieces.
            let solid = complex
                .shape(case.alpha, Surface::Solid)
                .expect("valid alpha");
            let ours: BTreeSet<[u32; 3]> = solid
                .mesh
                .triangles()
                .iter()
                .map(|t| {
                    let v = t.map(|i| solid.vertex_ids[i as usize]);
                    let k = (0..3).min_by_key(|&k| v[k]).unwrap_or(0);
                    [v[k], v[(k + 1) % 3], v[(k + 2) % 3]]
                })
                .collect();
            assert_eq!(ours.len(), solid.mesh.triangle_count());
            assert_eq!(
                ours,
                triples(&case.solid),
                "{} alpha {}: solid boundary",
                case.input,
                case.alpha
            );
            assert_eq!(
                complex.pieces(case.alpha, Surface::Solid),
                case.solid_pieces,
                "{}",
                case.input
            );
        }
    }
}

#[test]
fn search_stops_at_the_first_connected_alpha_on_real_samples() {
    // 2000 samples of Spot: the reference says 0.04 is 141 pieces and 0.08 one piece.
    let points = load("spot_samples.ply");
    let delaunay = Delaunay3d::new(&points).expect("finite points");
    let complex = AlphaComplex::new(&delaunay);
    let search = AlphaSearch {
        floor: 0.04,
        ceiling: 0.08,
        steps_per_doubling: 4,
        max_pieces: 1,
        surface: Surface::General,
    };
    let choice = smallest_connected_alpha(&complex, &search).expect("valid search");
    assert!(choice.met);
    assert_eq!(choice.pieces, 1);
    assert_eq!(choice.tried[0], (0.04, 141));
    assert!(choice.alpha <= 0.08 && choice.alpha > 0.04);
    // A target no α on the ladder meets gives the α with the fewest pieces, flagged.
    let narrow = AlphaSearch {
        floor: 0.02,
        ceiling: 0.04,
        ..search
    };
    let choice = smallest_connected_alpha(&complex, &narrow).expect("valid search");
    assert!(!choice.met);
    let fewest = choice.tried.iter().map(|t| t.1).min().expect("tried");
    assert_eq!(choice.pieces, fewest);
}
