//! `spwi-router`, built inside the test package so process tests can spawn it.

fn main() -> std::process::ExitCode {
    spwi_agent::router::main()
}
