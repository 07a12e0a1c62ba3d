//! `bridge-sim` (alias `cargo sim`): see `host-tests/SIM.md` and [`host_tests::sim`].

fn main() -> std::process::ExitCode {
    host_tests::sim::cli::main()
}
