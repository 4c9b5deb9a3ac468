//! The `mvad` command line: check, simulate and differentiate hybrid models written in
//! the `.hyb` language (see the language spec for the contract of every command, option,
//! JSON key and exit status).
//!
//! Exit status: 0 success; 1 the model ran and failed; 2 bad input (a located model
//! error, a bad option, a usage error).

mod cli;

fn main() -> std::process::ExitCode {
    cli::run(std::env::args_os(), |path, tables| {
        mvad::load::load_with_tables(path, tables).map_err(|e| e.to_string())
    })
}
