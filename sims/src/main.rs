//! The `troupe` command line ([`troupe_sims::cli`], one module per subcommand).

fn main() -> std::process::ExitCode {
    troupe_sims::cli::main()
}
