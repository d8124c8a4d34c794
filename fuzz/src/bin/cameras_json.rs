//! AFL target `cameras_json`: see `trisplat_tests::fuzz_harness::Target::CamerasJson`.

fn main() {
    afl::fuzz!(|data: &[u8]| {
        let _ = trisplat_tests::fuzz_harness::Target::CamerasJson.run(data);
    });
}
