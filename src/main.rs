fn main() -> std::process::ExitCode {
    pathtracer::cli::main()
}
