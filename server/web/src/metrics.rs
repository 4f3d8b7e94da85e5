//! `/metrics`: Prometheus text exposition.
//!
//! The web layer counts its own HTTP figures and reads the alarm engine; the
//! application adds the rest (poller, historian) through a [`MetricsSource`],
//! so this crate needs no knowledge of Modbus or the store's writer.

use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::Response;

/// Writes metric families in the text format.
#[derive(Default)]
pub struct Prom {
    out: String,
    declared: std::collections::HashSet<String>,
}

impl Prom {
    fn declare(&mut self, name: &str, kind: &str, help: &str) {
        if self.declared.insert(name.to_string()) {
            let _ = writeln!(self.out, "# HELP {name} {help}\n# TYPE {name} {kind}");
        }
    }

    fn sample(&mut self, name: &str, labels: &[(&str, &str)], value: f64) {
        let _ = write!(self.out, "{name}");
        if !labels.is_empty() {
            let parts: Vec<String> = labels
                .iter()
                .map(|(k, v)| format!("{k}=\"{}\"", escape(v)))
                .collect();
            let _ = write!(self.out, "{{{}}}", parts.join(","));
        }
        let _ = writeln!(self.out, " {value}");
    }

    pub fn gauge(&mut self, name: &str, help: &str, labels: &[(&str, &str)], value: f64) {
        self.declare(name, "gauge", help);
        self.sample(name, labels, value);
    }

    pub fn counter(&mut self, name: &str, help: &str, labels: &[(&str, &str)], value: f64) {
        self.declare(name, "counter", help);
        self.sample(name, labels, value);
    }

    pub fn finish(self) -> String {
        self.out
    }
}

/// Label values may hold quotes, backslashes and newlines (device names come
/// from configuration).
fn escape(v: &str) -> String {
    v.replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

/// Figures the application adds to `/metrics`.
pub trait MetricsSource: Send + Sync {
    fn render(&self, out: &mut Prom);
}

/// HTTP request counters, by status class.
#[derive(Default)]
pub struct HttpMetrics {
    by_class: [AtomicU64; 5],
    duration_us: AtomicU64,
}

impl HttpMetrics {
    pub fn render(&self, out: &mut Prom) {
        for (i, c) in self.by_class.iter().enumerate() {
            let class = format!("{}xx", i + 1);
            out.counter(
                "gridscada_http_requests_total",
                "HTTP requests answered, by status class.",
                &[("class", &class)],
                c.load(Ordering::Relaxed) as f64,
            );
        }
        out.counter(
            "gridscada_http_request_seconds_total",
            "Time spent answering HTTP requests (WebSocket sessions excluded).",
            &[],
            self.duration_us.load(Ordering::Relaxed) as f64 / 1e6,
        );
    }
}

/// Counts every response.
pub async fn count(State(m): State<Arc<HttpMetrics>>, req: Request, next: Next) -> Response {
    let started = Instant::now();
    let resp = next.run(req).await;
    let class = (resp.status().as_u16() / 100).clamp(1, 5) as usize - 1;
    m.by_class[class].fetch_add(1, Ordering::Relaxed);
    if resp.status() != axum::http::StatusCode::SWITCHING_PROTOCOLS {
        m.duration_us
            .fetch_add(started.elapsed().as_micros() as u64, Ordering::Relaxed);
    }
    resp
}
