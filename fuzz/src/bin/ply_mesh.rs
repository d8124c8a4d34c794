//! AFL target `ply_mesh`: see `trisplat_tests::fuzz_harness::Target::PlyMesh`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::PlyMesh.run(data);
    });
}
