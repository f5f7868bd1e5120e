fn main() -> std::process::ExitCode {
    spwi_agent::router::main()
}
