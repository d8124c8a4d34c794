//! AFL target `expression_json`: see `trisplat_tests::fuzz_harness::Target::ExpressionJson`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::ExpressionJson.run(data);
    });
}
