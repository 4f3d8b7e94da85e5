//! Where a server's settings come from besides its files: the `GRIDSCADA_*`
//! environment variables (applied by `gridscada_config::apply_env`) and the
//! command line's `--http` and `--data`, shared by `demo` and `serve`.
//! Precedence, highest first: command line, environment, file.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use gridscada_config::Plant;

/// The process environment, as `apply_env` reads it. A variable whose value
/// is not UTF-8 counts as set, with that value shown lossily (it will not
/// parse), rather than as silently unset.
pub fn env(name: &str) -> Option<String> {
    std::env::var_os(name).map(|v| v.to_string_lossy().into_owned())
}

/// Loads a plant configuration for a command that runs it or writes to its
/// database (`serve`, `user add --config`): the files, checked, then the
/// `GRIDSCADA_*` environment. Logs which variables were applied (names
/// only) and the configuration's warnings.
pub fn load_for_server(path: &Path) -> anyhow::Result<Plant> {
    let mut plant =
        gridscada_config::load_path(path).map_err(|d| diagnostics("the configuration", d))?;
    let applied = gridscada_config::apply_env(&mut plant, &env)
        .map_err(|d| diagnostics("the GRIDSCADA_* environment", d))?;
    if !applied.is_empty() {
        tracing::info!(variables = %applied.join(", "), "settings from the environment");
    }
    for w in &plant.warnings {
        tracing::warn!("{w}");
    }
    Ok(plant)
}

/// The command line's `--http ADDR` and `--data DIR` over a plant's
/// settings (`serve`); `None` keeps what the file and environment say.
pub fn apply_flags(
    plant: &mut Plant,
    http: Option<String>,
    data: Option<PathBuf>,
) -> anyhow::Result<()> {
    if let Some(h) = http {
        listen_addr(&h, "--http")?;
        *plant.server.http.get_mut() = h;
    }
    if let Some(d) = data {
        plant.data_dir = d;
    }
    Ok(())
}

/// A listen address, or an error naming where it came from (`origin`: a
/// flag, a variable or a setting).
pub fn listen_addr(text: &str, origin: &str) -> anyhow::Result<SocketAddr> {
    text.parse()
        .with_context(|| format!("{origin} '{text}' is not an address like 127.0.0.1:8080"))
}

/// Configuration problems as one error, every problem on its own line.
pub fn diagnostics(what: &str, diags: Vec<gridscada_config::Diagnostic>) -> anyhow::Error {
    let lines: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
    anyhow!(
        "{what} has {} problem(s); not starting:\n{}",
        diags.len(),
        lines.join("\n")
    )
}
