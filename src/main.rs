fn main() {
    std::process::exit(stagelight::cli::main());
}
