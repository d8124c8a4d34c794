//! AFL target `gltf_animated`: see `trisplat_tests::fuzz_harness::Target::GltfAnimated`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::GltfAnimated.run(data);
    });
}
