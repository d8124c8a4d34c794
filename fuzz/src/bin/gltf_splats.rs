//! AFL target `gltf_splats`: see `trisplat_tests::fuzz_harness::Target::GltfSplats`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::GltfSplats.run(data);
    });
}
