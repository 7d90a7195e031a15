//! `links`: render LINKS-1 scenes on the host.

fn main() -> std::process::ExitCode {
    links_host::cli::main()
}
