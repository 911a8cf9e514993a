//! The `umbrasweep` command line: bake, cells, merge, validate, gen, bench, inspect, report.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod cli_bake;
mod cli_bench;
mod cli_cells;
mod cli_gen;
mod cli_inspect;
mod cli_merge;
mod cli_progress;
mod cli_report;
mod cli_validate;

#[derive(Parser, Debug)]
#[command(
    name = "umbrasweep",
    version,
    about = "Conservative PVS baking with extended projections"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Bake the potentially visible set of every view cell of a scene.
    Bake(Box<cli_bake::BakeArgs>),
    /// Find view cells automatically (above walkable floors, or in a box); write a cells file.
    Cells(cli_cells::CellsArgs),
    /// Check a PVS against ray-sampled ground truth (exit 0: no false cull, 1: false culls).
    Validate(cli_validate::ValidateArgs),
    /// Generate a test scene (forest, city, boxfield) as OBJ, with matching view cells.
    Gen(cli_gen::GenArgs),
    /// Bake and validate a fixed set of scenes with each backend and print one table.
    Bench(cli_bench::BenchArgs),
    /// Summarise a binary PVS file, list a cell's objects, or print it as JSON.
    Inspect(cli_inspect::InspectArgs),
    /// Join the shard files of one `bake --shard I/N` run into one PVS (.json or .pvs).
    Merge(cli_merge::MergeArgs),
    /// Write a static HTML report of a PVS: top-down picture, per-cell table, plane previews.
    Report(cli_report::ReportArgs),
}

/// Mesa's Vulkan drivers print "XDG_RUNTIME_DIR is invalid or not set in the environment"
/// on stderr when the adapter probe (`--backend auto`) looks for a Wayland display and the
/// variable is missing (servers, containers, CI). We never open a window: a private, empty
/// folder for this run silences the probe. Returns the folder (removed when dropped).
fn quiet_display_probe() -> Option<tempfile::TempDir> {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return None;
    }
    let dir = tempfile::Builder::new()
        .prefix("umbrasweep-runtime-")
        .tempdir()
        .ok()?;
    // SAFETY: called in `main` right after parsing the arguments, before any other thread
    // exists.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", dir.path()) };
    Some(dir)
}

fn main() -> ExitCode {
    // Parse first: `--help`, `--version` and usage errors end the process inside the parser,
    // which would leave the probe's folder behind.
    let cli = Cli::parse();
    let _runtime_dir = quiet_display_probe();
    let result = match &cli.command {
        Command::Bake(a) => cli_bake::run(a).map(|_| 0),
        Command::Cells(a) => cli_cells::run(a).map(|_| 0),
        Command::Validate(a) => cli_validate::run(a),
        Command::Gen(a) => cli_gen::run(a).map(|_| 0),
        Command::Bench(a) => cli_bench::run(a).map(|_| 0),
        Command::Inspect(a) => cli_inspect::run(a).map(|_| 0),
        Command::Report(a) => cli_report::run(a).map(|_| 0),
        Command::Merge(a) => cli_merge::run(a).map(|_| 0),
    };
    match result {
        Ok(code) => ExitCode::from(code as u8),
        Err(e) => {
            // The message, then each cause not already spelled out in it.
            let mut msg = e.to_string();
            for cause in e.chain().skip(1) {
                let c = cause.to_string();
                if !msg.contains(&c) {
                    msg = format!("{msg}: {c}");
                }
            }
            eprintln!("error: {msg}");
            ExitCode::from(2)
        }
    }
}
