//! # gridscada: the server binary
//!
//! **Owns:** the command line, logging, loading the configuration and wiring the
//! components together ([`runtime`]). It holds no domain logic of its own: each
//! subcommand hands its work to the crate that owns it.

mod cert;
mod data;
mod demo_plant;
mod dispatch_cmd;
mod https;
mod logging;
mod opcua_cmd;
mod pair;
mod replay;
mod reports_cmd;
mod runtime;
mod scl_cmd;
mod settings;
mod sinks;
mod users;

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
        /// Simulate this plant configuration (gridscada.toml or its folder)
        /// instead of the embedded demo plant: every device runs as a
        /// simulator on loopback, for commissioning before the plant exists.
        #[arg(long, conflicts_with = "scenario")]
        config: Option<PathBuf>,
        /// Drive the plant with a scenario (its plant replaces the embedded
        /// one), on a clock compressed by --speed, for watching and training.
        #[arg(long)]
        scenario: Option<PathBuf>,
        /// Plant seconds per wall second while a scenario runs.
        #[arg(long, default_value_t = 1.0, requires = "scenario")]
        speed: f64,
        /// Publish the plant as a Sparkplug B edge node to this broker
        /// (mqtt://host:port), group "gridscada".
        #[arg(long, value_name = "URL")]
        mqtt: Option<String>,
        /// The edge node id with --mqtt.
        #[arg(long, value_name = "ID", default_value = runtime::northbound::DEMO_NODE, requires = "mqtt")]
        mqtt_node: String,
        /// With --mqtt: birth only while this primary host application's
        /// STATE says online, and buffer while it is offline (Sparkplug 3.0).
        #[arg(long, value_name = "ID", requires = "mqtt")]
        mqtt_primary_host: Option<String>,
        /// Serve OPC UA on this loopback port (every endpoint, the demo's
        /// accounts; see docs/NORTHBOUND.md).
        #[arg(long, value_name = "PORT")]
        opcua: Option<u16>,
        /// Leave this device (by name) out of the simulation: gridscada
        /// reaches it on its configured address, e.g. a real RTU beside
        /// simulated panels. Repeat for several.
        #[arg(long = "real-device", value_name = "DEVICE")]
        real_devices: Vec<String>,
    },
    /// Replay a scenario through the whole stack (simulators, Modbus poller,
    /// alarms, historian, fault isolation, dispatch) faster than real time,
    /// and report. Exit 0 when every expectation holds, 1 when one fails,
    /// 2 when the scenario cannot be read or run.
    Replay {
        /// The scenario file (see docs/SCENARIOS.md).
        file: PathBuf,
        /// Plant seconds per wall second, on a scaled clock.
        #[arg(long, conflicts_with = "max")]
        speed: Option<f64>,
        /// As fast as the stack goes, on a virtual clock that advances when
        /// everything is idle (deterministic). The default.
        #[arg(long)]
        max: bool,
        /// Write the JSON report here.
        #[arg(long)]
        report: Option<PathBuf>,
        /// Write the HTML report (one file, no external assets) here.
        #[arg(long)]
        html: Option<PathBuf>,
        /// Keep the run's database in this folder (default: a temporary one).
        #[arg(long)]
        data: Option<PathBuf>,
        /// Skip the second run with the rule-based dispatch (no cost comparison).
        #[arg(long)]
        no_compare: bool,
    },
    /// Run against a real plant configuration. GRIDSCADA_* environment
    /// variables replace its secrets and addresses (docs/CONFIGURATION.md);
    /// the flags below replace both.
    Serve {
        /// The main configuration file (gridscada.toml) or its folder.
        #[arg(long)]
        config: PathBuf,
        /// HTTP bind address of the HMI and API, instead of [server] http.
        #[arg(long)]
        http: Option<String>,
        /// Data folder (SQLite database, local state), instead of [server]
        /// data_dir; a relative path is taken from the working directory.
        #[arg(long)]
        data: Option<PathBuf>,
    },
    /// Validate a configuration and report every problem with its location.
    Check {
        /// The main configuration file or its folder.
        #[arg(default_value = ".")]
        path: PathBuf,
        /// The main configuration file, as `serve --config` and `user add
        /// --config` take it (instead of PATH).
        #[arg(long, conflicts_with = "path")]
        config: Option<PathBuf>,
    },
    /// Run the simulated plant alone, as Modbus servers on the configured
    /// addresses, for third-party clients and commissioning.
    Sim {
        /// A plant configuration; the embedded demo plant by default.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Manage users.
    User {
        #[command(subcommand)]
        command: UserCommand,
    },
    /// Microgrid dispatch tools.
    Dispatch {
        #[command(subcommand)]
        command: DispatchCommand,
    },
    /// Make the report of a day (YYYY-MM-DD) or a month (YYYY-MM), UTC,
    /// from the database, into the data folder's reports/ (HTML, CSV and
    /// JSON), as the schedule and the Reports screen do.
    Report {
        /// The day or month.
        period: String,
        #[command(flatten)]
        at: UserTable,
    },
    /// TLS certificates for HTTPS ([server.tls]).
    Cert {
        #[command(subcommand)]
        command: CertCommand,
    },
    /// The OPC UA server's client certificates ([opcua], docs/NORTHBOUND.md).
    Opcua {
        #[command(subcommand)]
        command: OpcuaCommand,
    },
    /// IEC 61850 SCL files (docs/IEC61850.md).
    Scl {
        #[command(subcommand)]
        command: SclCommand,
    },
}

#[derive(Subcommand)]
enum SclCommand {
    /// Write a tag file per IED of an SCL file (SCD, CID or ICD): its
    /// statuses, measurands, counters and controllable objects, with types,
    /// units and control models, and its report control blocks; and a
    /// main file to run them when OUT has none.
    Import {
        /// The SCL file.
        file: PathBuf,
        /// Only this IED (repeat for more); all by default.
        #[arg(long = "ied")]
        ieds: Vec<String>,
        /// The folder to write into.
        #[arg(long, default_value = ".")]
        out: PathBuf,
        /// The least role that may operate the imported controls.
        #[arg(long, default_value = "operator")]
        write_role: String,
        /// IED=host:port, instead of the SCL's address (repeatable).
        #[arg(long = "address")]
        addresses: Vec<String>,
        /// Replace tag files (and screens) that exist.
        #[arg(long)]
        force: bool,
        /// Also draw a screen per bay of the SCL's Substation section (per
        /// IED where it has none): the switches with Open and Close, then
        /// the measurands and statuses, into OUT/screens/.
        #[arg(long)]
        screens: bool,
    },
}

#[derive(Subcommand)]
enum OpcuaCommand {
    /// Trust a client certificate (DER or PEM; a file from the store's
    /// rejected/ folder or one the client's maker gave): copy it into
    /// trusted/ under the name the server looks for, remove it from
    /// rejected/, and print its subject and thumbprint. A running server
    /// accepts the client at its next connection.
    Trust {
        file: PathBuf,
        #[command(flatten)]
        at: UserTable,
    },
    /// List the trusted and rejected client certificates: subject,
    /// thumbprint, validity, file.
    List {
        #[command(flatten)]
        at: UserTable,
    },
}

#[derive(Subcommand)]
enum CertCommand {
    /// Write a self-signed certificate (cert.pem) and its private key
    /// (key.pem, mode 0600) for a first start over HTTPS, and print the
    /// [server.tls] lines to add.
    SelfSigned {
        /// A host name or IP address the certificate is valid for; repeat
        /// for more. Default: localhost, 127.0.0.1, ::1 and this machine's
        /// name.
        #[arg(long = "host", value_name = "NAME|IP")]
        hosts: Vec<String>,
        /// Days of validity.
        #[arg(long, default_value_t = 365)]
        days: u32,
        /// Folder to write to; default: the --config folder, else the
        /// working directory.
        #[arg(long)]
        out: Option<PathBuf>,
        /// The configuration (gridscada.toml or its folder) to write beside.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Replace existing cert.pem and key.pem.
        #[arg(long)]
        force: bool,
    },
}

#[derive(Subcommand)]
enum UserCommand {
    /// Create a user. The password is read from standard input when piped
    /// (at least 10 characters, at most 1024 bytes); otherwise one is
    /// generated and printed once.
    Add {
        /// The user's login name.
        name: String,
        /// display (a wall display: views only, its session never idles
        /// out), guest (views only), operator (acknowledges alarms, operates
        /// breakers in manual mode, writes operator tags), supervisor (also
        /// switches modes, shelves alarms, writes supervisor tags) or
        /// administrator (also manages users, screen access and screens).
        #[arg(long, value_parser = parse_role)]
        role: gridscada_config::Role,
        /// Screen-access group; the role's name by default.
        #[arg(long)]
        group: Option<String>,
        #[command(flatten)]
        at: UserTable,
    },
    /// List the users: name, role, screen-access group, blocked.
    List {
        #[command(flatten)]
        at: UserTable,
    },
    /// Set a user's password: read from standard input when piped, otherwise
    /// generated and printed once. Every session of the user ends.
    Password {
        name: String,
        #[command(flatten)]
        at: UserTable,
    },
    /// Block a user: they cannot log in, and their sessions end.
    Block {
        name: String,
        #[command(flatten)]
        at: UserTable,
    },
    /// Unblock a user.
    Unblock {
        name: String,
        #[command(flatten)]
        at: UserTable,
    },
    /// Change a user's role; their sessions under the old role end.
    Role {
        name: String,
        #[arg(long, value_parser = parse_role)]
        role: gridscada_config::Role,
        #[command(flatten)]
        at: UserTable,
    },
    /// Delete a user and their sessions.
    Delete {
        name: String,
        #[command(flatten)]
        at: UserTable,
    },
}

/// Which plant a `user`, `report` or `opcua` command works on.
#[derive(clap::Args)]
struct UserTable {
    /// The plant (the file `serve` runs): its database, data folder and
    /// [opcua] store.
    #[arg(long, conflicts_with = "data")]
    config: Option<PathBuf>,
    /// The demo's data folder (when not using --config).
    #[arg(long, default_value = "gridscada-data")]
    data: PathBuf,
}

impl UserTable {
    fn target(self) -> users::Target {
        match self.config {
            Some(c) => users::Target::Config(c),
            None => users::Target::DemoData(self.data),
        }
    }
}

#[derive(Subcommand)]
enum DispatchCommand {
    /// Solve a dispatch problem given as JSON (FILE, or - for stdin) and print
    /// the solution. Exit code 0 optimal, 1 bad input, 2 infeasible, 3 solver failure.
    Solve { file: String },
}

fn parse_role(s: &str) -> Result<gridscada_config::Role, String> {
    use gridscada_config::Role;
    match s {
        "admin" => Ok(Role::Administrator),
        other => Role::parse(other).ok_or_else(|| {
            format!(
                "'{other}' is not a role; use display, guest, operator, supervisor or administrator"
            )
        }),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    logging::init(cli.log_json);
    match cli.command {
        Command::Check { path, config } => check(config.as_deref().unwrap_or(&path)),
        Command::Demo {
            http,
            data,
            config,
            scenario,
            speed,
            mqtt,
            mqtt_node,
            mqtt_primary_host,
            opcua,
            real_devices,
        } => {
            let live = match scenario {
                Some(file) => match replay::LiveScenario::load(&file, speed) {
                    Ok(l) => Some(Box::new(l) as Box<dyn runtime::LiveDriver>),
                    Err(e) => {
                        eprintln!("{e:#}");
                        return ExitCode::from(2);
                    }
                },
                None => None,
            };
            let mqtt = mqtt.map(|broker| runtime::northbound::DemoMqtt {
                broker,
                node: mqtt_node,
                primary_host: mqtt_primary_host,
            });
            runtime::block_on(runtime::demo(
                http,
                data,
                config,
                live,
                mqtt,
                opcua,
                real_devices,
            ))
        }
        Command::Replay {
            file,
            speed,
            max: _,
            report,
            html,
            data,
            no_compare,
        } => {
            let pace = match speed {
                Some(s) if s.is_finite() && s > 0.0 && s <= 100_000.0 => replay::Pace::Scaled(s),
                Some(s) => {
                    eprintln!("error: --speed {s}: need 0 < speed <= 100000");
                    return ExitCode::from(2);
                }
                None => replay::Pace::Max,
            };
            replay::replay(replay::ReplayArgs {
                file,
                pace,
                report,
                html,
                data,
                no_compare,
            })
        }
        Command::Serve { config, http, data } => {
            runtime::block_on(runtime::serve(config, http, data))
        }
        Command::Sim { config } => runtime::block_on(runtime::sim(config)),
        Command::User { command } => {
            let work = async move {
                match command {
                    UserCommand::Add {
                        name,
                        role,
                        group,
                        at,
                    } => users::add(name, role, group, at.target()).await,
                    UserCommand::List { at } => users::list(at.target()).await,
                    UserCommand::Password { name, at } => {
                        users::change(name, users::Change::Password, at.target()).await
                    }
                    UserCommand::Block { name, at } => {
                        users::change(name, users::Change::Blocked(true), at.target()).await
                    }
                    UserCommand::Unblock { name, at } => {
                        users::change(name, users::Change::Blocked(false), at.target()).await
                    }
                    UserCommand::Role { name, role, at } => {
                        users::change(name, users::Change::Role(role), at.target()).await
                    }
                    UserCommand::Delete { name, at } => {
                        users::change(name, users::Change::Delete, at.target()).await
                    }
                }
            };
            runtime::block_on(async move { runtime::report(work.await) })
        }
        Command::Dispatch {
            command: DispatchCommand::Solve { file },
        } => ExitCode::from(dispatch_cmd::run_solve(&file).clamp(0, 255) as u8),
        Command::Report { period, at } => runtime::block_on(async move {
            runtime::report(reports_cmd::run(period, at.target()).await)
        }),
        Command::Opcua { command } => {
            let done = match command {
                OpcuaCommand::Trust { file, at } => opcua_cmd::trust(&file, at.target()),
                OpcuaCommand::List { at } => opcua_cmd::list(at.target()),
            };
            match done {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: {e:#}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Scl {
            command:
                SclCommand::Import {
                    file,
                    ieds,
                    out,
                    write_role,
                    addresses,
                    force,
                    screens,
                },
        } => match scl_cmd::import(scl_cmd::Import {
            file,
            ieds,
            out,
            write_role,
            addresses,
            force,
            screens,
        }) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::FAILURE
            }
        },
        Command::Cert {
            command:
                CertCommand::SelfSigned {
                    hosts,
                    days,
                    out,
                    config,
                    force,
                },
        } => match cert::self_signed(cert::SelfSigned {
            hosts,
            days,
            out,
            config,
            force,
        }) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e:#}");
                ExitCode::FAILURE
            }
        },
    }
}

/// `gridscada check`: the files, then the `GRIDSCADA_*` environment as
/// `serve` would apply it; warnings are printed and do not fail the check.
fn check(path: &std::path::Path) -> ExitCode {
    let loaded = gridscada_config::load_path(path).and_then(|mut plant| {
        let applied = gridscada_config::apply_env(&mut plant, &settings::env)?;
        if !applied.is_empty() {
            println!("settings from the environment: {}", applied.join(", "));
        }
        Ok(plant)
    });
    match loaded {
        Ok(plant) => {
            for w in &plant.warnings {
                eprintln!("{w}");
            }
            let mut problems = runtime::check_screens(&plant);
            problems.extend(runtime::check_exports(&plant));
            // The certificate and key are read as `serve` would.
            if let Err(e) = https::load(&plant) {
                problems.push(format!("{e:#}"));
            }
            if !problems.is_empty() {
                for p in &problems {
                    eprintln!("{p}");
                }
                eprintln!("{} problem(s) found", problems.len());
                return ExitCode::FAILURE;
            }
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
