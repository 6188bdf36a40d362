//! `custom-parts`: the `troupe` command with this crate's sensor driver and actor
//! registered beside troupe's (`custom-parts run examples/custom_parts/scenario.toml`).

fn main() -> std::process::ExitCode {
    troupe_sims::cli::main_with(troupe_custom_parts::registry())
}
