//! AFL target `ply_gaussians`: see `trisplat_tests::fuzz_harness::Target::PlyGaussians`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::PlyGaussians.run(data);
    });
}
