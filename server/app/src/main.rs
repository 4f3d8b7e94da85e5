//! # gridscada: the server binary
//!
//! **Owns:** the command line, logging, loading the configuration and wiring the
//! components together ([`runtime`]). It holds no domain logic of its own: each
//! subcommand hands its work to the crate that owns it.

mod demo_plant;
mod logging;
mod runtime;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "gridscada",
    version,
    about = "SCADA/HMI for LV power distribution and renewable microgrids"
)]
struct Cli {
    /// Log as JSON lines instead of human-readable text. The level filter comes
    /// from RUST_LOG (e.g. RUST_LOG=info,gridscada_modbus=debug).
    #[arg(long, global = true)]
    log_json: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the demo plant on embedded defaults: simulated panels and microgrid on
    /// loopback, SQLite in the data folder, the HMI on localhost.
    Demo {
        /// HTTP bind address of the HMI and API.
        #[arg(long, default_value = "127.0.0.1:8080")]
        http: String,
        /// Data folder (SQLite database, generated credentials).
        #[arg(long, default_value = "gridscada-data")]
        data: PathBuf,
    },
    /// Run against a real plant configuration.
    Serve {
        /// The main configuration file (gridscada.toml) or its folder.
        #[arg(long)]
        config: PathBuf,
    },
    /// Validate a configuration and report every problem with its location.
    Check {
        /// The main configuration file or its folder.
        #[arg(default_value = ".")]
        path: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    logging::init(cli.log_json);
    match cli.command {
        Command::Check { path } => check(&path),
        Command::Demo { http, data } => runtime::block_on(runtime::demo(http, data)),
        Command::Serve { config } => runtime::block_on(runtime::serve(config)),
    }
}

fn check(path: &std::path::Path) -> ExitCode {
    match gridscada_config::load_path(path) {
        Ok(plant) => {
            println!(
                "{}: ok ({} devices, {} tags, {} panels{})",
                plant.main_path.display(),
                plant.devices.len(),
                plant.tags.len(),
                plant.panels.len(),
                if plant.microgrid.is_some() {
                    ", microgrid"
                } else {
                    ""
                }
            );
            ExitCode::SUCCESS
        }
        Err(diags) => {
            for d in &diags {
                eprintln!("{d}");
            }
            eprintln!("{} problem(s) found", diags.len());
            ExitCode::FAILURE
        }
    }
}
