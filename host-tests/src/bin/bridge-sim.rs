//! `bridge-sim` (alias `cargo sim`): see the README (section "bridge-sim") and [`host_tests::sim`].

fn main() -> std::process::ExitCode {
    host_tests::sim::cli::main()
}
