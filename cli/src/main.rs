//! The `trisplat` binary: see the library crate for the commands.

fn main() -> std::process::ExitCode {
    trisplat_cli::main()
}
