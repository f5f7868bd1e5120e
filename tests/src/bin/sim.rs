//! `spwi-sim`, built inside the test package so tests can run its command line.

fn main() -> std::process::ExitCode {
    spwi_sim::cli::main()
}
