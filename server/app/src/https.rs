//! Serving the HMI and API over plain HTTP or, with `[server.tls]`, over
//! HTTPS with the optional redirect listener, and reloading the certificate
//! on SIGHUP.

use std::future::Future;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;

use anyhow::{anyhow, Context};
use gridscada_config::Plant;
use gridscada_store::NewEvent;
use gridscada_tagdb::Clock;
use gridscada_web::tls::Https;
use tokio::sync::mpsc;

use crate::sinks;

type ServerFuture = Pin<Box<dyn Future<Output = std::io::Result<()>> + Send>>;

/// The listeners of a running server.
pub struct Listening {
    /// The URL the HMI is reached by (`http://…` or `https://…`), trailing `/`.
    pub url: String,
    /// The plain-HTTP address that redirects to HTTPS, if any.
    pub redirect: Option<SocketAddr>,
    /// Runs the listeners; ends only when one fails.
    pub server: ServerFuture,
    /// The certificate in use, for [`reload_on_sighup`].
    pub https: Option<Https>,
}

/// Reads the certificate and key of `[server.tls]` (if any), or says which
/// file is wrong and why. Done before anything else starts.
pub fn load(plant: &Plant) -> anyhow::Result<Option<Https>> {
    plant
        .tls
        .as_ref()
        .map(|files| Https::load(files).map_err(|e| anyhow!("{e}")))
        .transpose()
}

/// Binds `http` for `web` (HTTPS with `https`) and the redirect listener now, so a bind
/// error is reported before the URL is printed.
pub async fn listen(
    plant: &Plant,
    http: SocketAddr,
    web: gridscada_web::WebState,
    https: Option<Https>,
) -> anyhow::Result<Listening> {
    let connections = web.connections.clone();
    let router = gridscada_web::router(web);
    let Some(https) = https else {
        let (local, server) = gridscada_web::bind(http, router, connections)
            .await
            .with_context(|| format!("cannot listen on {http}"))?;
        return Ok(Listening {
            url: format!("http://{local}/"),
            redirect: None,
            server: Box::pin(server),
            https: None,
        });
    };
    let (local, server) = gridscada_web::tls::bind_tls(http, router, &https, connections.clone())
        .await
        .with_context(|| format!("cannot listen on {http}"))?;
    let redirect_to = plant.tls.as_ref().and_then(|t| t.redirect_http);
    let (redirect, server): (Option<SocketAddr>, ServerFuture) = match redirect_to {
        None => (None, Box::pin(server)),
        Some(addr) => {
            let (redirect, plain) =
                gridscada_web::tls::bind_redirect(addr, local.port(), &plant.server, connections)
                    .await
                    .with_context(|| {
                        format!("cannot listen on {addr} ([server.tls] redirect_http)")
                    })?;
            let both = async move {
                tokio::select! {
                    r = server => r,
                    r = plain => r,
                }
            };
            (Some(redirect), Box::pin(both))
        }
    };
    Ok(Listening {
        url: format!("https://{local}/"),
        redirect,
        server,
        https: Some(https),
    })
}

/// On each SIGHUP, reads the certificate and key again. New connections use
/// the new pair; a pair that does not load is refused (logged, and recorded
/// as an event) and the one in use keeps serving. Without TLS the signal is
/// still caught: `systemctl reload` must never stop a plain-HTTP server
/// (SIGHUP's default action ends the process, and systemd counts that as a
/// clean exit, so it would not restart it).
pub fn reload_on_sighup(
    https: Option<Https>,
    events: mpsc::Sender<NewEvent>,
    clock: Arc<dyn Clock>,
) {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        let mut hup = match signal(SignalKind::hangup()) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "no SIGHUP handler: the certificate reloads only on restart");
                return;
            }
        };
        tokio::spawn(async move {
            while hup.recv().await.is_some() {
                let Some(https) = &https else {
                    tracing::info!("SIGHUP: nothing to reload (no [server.tls])");
                    let _ = events
                        .send(sinks::system_event(
                            clock.as_ref(),
                            "server",
                            "reload",
                            "reload asked (SIGHUP): nothing to reload without [server.tls]"
                                .to_string(),
                        ))
                        .await;
                    continue;
                };
                let cert = https.files().cert.display().to_string();
                let message = match https.reload() {
                    Ok(()) => {
                        tracing::info!(cert = %cert, "TLS certificate reloaded");
                        format!("TLS certificate reloaded from {cert}")
                    }
                    Err(e) => {
                        tracing::error!(error = %e, "TLS reload refused; the previous certificate keeps serving");
                        format!("TLS reload refused, the previous certificate keeps serving: {e}")
                    }
                };
                let _ = events
                    .send(sinks::system_event(
                        clock.as_ref(),
                        "server",
                        "tls",
                        message,
                    ))
                    .await;
            }
        });
    }
    #[cfg(not(unix))]
    let _ = (https, events, clock);
}
