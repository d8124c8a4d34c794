//! AFL target `spz`: see `trisplat_tests::fuzz_harness::Target::Spz`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::Spz.run(data);
    });
}
