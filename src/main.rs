fn main() -> std::process::ExitCode {
    pathtracer::app::cli::main()
}
