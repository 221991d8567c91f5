fn main() -> std::process::ExitCode {
    visobjd::cli::main()
}
