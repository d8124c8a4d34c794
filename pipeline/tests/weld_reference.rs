//! `weld_vertices` against trimesh's `merge_vertices(merge_tex=True, merge_norm=True)` on the
//! skinned glTF fixtures (reference: `tests/reference/ref_weld.py` ->
//! `fixtures/data/reference/weld/weld.json`), and the pipeline's welded template: the
//! same vertex count and old-to-new map as trimesh, watertight and consistently wound.

use trisplat_geometry::cleanup::weld_vertices;
use trisplat_geometry::io::read_mesh;
use trisplat_pipeline::input::WeldedTemplate;
use trisplat_pipeline::metrics::is_watertight;

#[test]
fn weld_matches_trimesh_on_gltf_fixtures() {
    let path = trisplat_fixtures::path("reference/weld/weld.json");
    let text = std::fs::read_to_string(&path).expect("reference file");
    let doc: serde_json::Value = serde_json::from_str(&text).expect("json");
    let cases = doc["cases"].as_array().expect("cases");
    assert_eq!(cases.len(), 2);
    for case in cases {
        let file = case["file"].as_str().expect("file");
        let mesh = read_mesh(&trisplat_fixtures::path(file)).expect("read fixture");
        let count = |key: &str| case[key].as_u64().expect("count") as usize;
        assert_eq!(mesh.vertex_count(), count("vertices"), "{file}");
        assert_eq!(mesh.triangle_count(), count("triangles"), "{file}");
        // As stored, the seams leave the surface open.
        assert!(!is_watertight(&mesh), "{file}");
        let (welded, map) = weld_vertices(&mesh, 0.0);
        assert_eq!(welded.vertex_count(), count("welded_vertices"), "{file}");
        let expected: Vec<u32> = case["map"]
            .as_array()
            .expect("map")
            .iter()
            .map(|v| v.as_u64().expect("index") as u32)
            .collect();
        assert_eq!(map, expected, "{file}");
        assert_eq!(welded.triangle_count(), mesh.triangle_count(), "{file}");
        assert!(case["watertight"].as_bool().expect("flag"), "{file}");
        assert!(
            case["winding_consistent"].as_bool().expect("flag"),
            "{file}"
        );
        assert!(is_watertight(&welded), "{file}");
        // The pipeline's welded template is the same mesh.
        let w = WeldedTemplate::new(&mesh);
        assert_eq!(w.mesh, welded, "{file}");
        assert!(w.merged());
        assert_eq!(w.stored_vertices, mesh.vertex_count());
        let positions = w.positions(mesh.positions().to_vec()).expect("same count");
        assert_eq!(positions, welded.positions(), "{file}");
    }
}
