fn main() -> std::process::ExitCode {
    pathtracer::app::main()
}
