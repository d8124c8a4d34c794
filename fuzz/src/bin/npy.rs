//! AFL target `npy`: see `trisplat_tests::fuzz_harness::Target::Npy`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::Npy.run(data);
    });
}
