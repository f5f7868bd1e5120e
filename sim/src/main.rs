//! `spwi-sim`: the simulated factory. All logic lives in the library.

fn main() -> std::process::ExitCode {
    spwi_sim::cli::main()
}
