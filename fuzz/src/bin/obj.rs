//! AFL target `obj`: see `trisplat_tests::fuzz_harness::Target::Obj`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::Obj.run(data);
    });
}
