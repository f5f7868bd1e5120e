//! `spwi-agent`: the daemon every robot runs. All logic lives in the library.

fn main() -> std::process::ExitCode {
    spwi_agent::cli::main()
}
