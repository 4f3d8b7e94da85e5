//! Wiring: builds the tag database from the plant configuration, starts the
//! components and the HTTP server, and stops them on Ctrl-C.

use std::future::Future;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, Context};
use gridscada_config::Plant;
use gridscada_tagdb::TagDb;

use crate::demo_plant;

pub fn block_on(fut: impl Future<Output = ExitCode>) -> ExitCode {
    match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt.block_on(fut),
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            ExitCode::FAILURE
        }
    }
}

fn report(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// `gridscada demo`: the embedded plant, on loopback.
pub async fn demo(http: String, data: PathBuf) -> ExitCode {
    report(demo_inner(http, data).await)
}

async fn demo_inner(http: String, data: PathBuf) -> anyhow::Result<()> {
    let plant = demo_plant::load().map_err(|diags| {
        let lines: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
        anyhow!("the embedded demo plant is invalid:\n{}", lines.join("\n"))
    })?;
    let addr: SocketAddr = http
        .parse()
        .with_context(|| format!("--http '{http}' is not an address like 127.0.0.1:8080"))?;
    run(plant, addr, &data, "demo").await
}

/// `gridscada serve`: a real plant configuration. Refuses to start on any
/// configuration problem.
pub async fn serve(config: PathBuf) -> ExitCode {
    report(serve_inner(config).await)
}

async fn serve_inner(config: PathBuf) -> anyhow::Result<()> {
    let plant = gridscada_config::load_path(&config).map_err(|diags| {
        let lines: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
        anyhow!(
            "the configuration has {} problem(s); not starting:\n{}",
            diags.len(),
            lines.join("\n")
        )
    })?;
    let addr: SocketAddr = plant
        .server
        .http
        .get_ref()
        .parse()
        .context("[server] http is not a socket address")?;
    let data = PathBuf::from(&plant.server.data_dir);
    run(plant, addr, &data, "serve").await
}

async fn run(plant: Plant, http: SocketAddr, data: &Path, mode: &str) -> anyhow::Result<()> {
    std::fs::create_dir_all(data)
        .with_context(|| format!("cannot create the data folder {}", data.display()))?;
    let db = Arc::new(TagDb::new(plant.tag_metas()).context("building the tag database")?);
    tracing::info!(
        tags = db.len(),
        devices = plant.devices.len(),
        mode,
        "tag database ready"
    );

    let state = gridscada_web::WebState {
        db: db.clone(),
        started: Instant::now(),
    };
    let (local, server) = gridscada_web::bind(http, gridscada_web::router(state))
        .await
        .with_context(|| format!("cannot listen on {http}"))?;

    println!("gridscada {mode} is running.");
    println!("  HMI and API: http://{local}/");
    println!("  Health:      http://{local}/healthz");
    println!("  Data folder: {}", data.display());
    println!("Press Ctrl-C to stop.");

    tokio::select! {
        r = server => r.context("HTTP server failed")?,
        _ = tokio::signal::ctrl_c() => tracing::info!("Ctrl-C: stopping"),
    }
    Ok(())
}
