//! AFL target `gltf`: see `trisplat_tests::fuzz_harness::Target::Gltf`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::Gltf.run(data);
    });
}
