//! `/metrics`: the OpenMetrics text exposition, encoded by `prometheus-client`.
//!
//! The web layer counts its own HTTP figures and reads the alarm engine; the
//! application adds the rest (poller, historian) through a [`MetricsSource`],
//! so this crate needs no knowledge of Modbus or the store's writer.
//!
//! Figures are read when scraped: a source calls [`Prom::gauge`],
//! [`Prom::counter`] or [`Prom::histogram`] in any order, and [`Prom`] groups
//! the samples by family, so each family is one `# HELP`/`# TYPE` followed by
//! all of its samples, as the format requires.

mod process;

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use axum::extract::{Request, State};
use axum::http::Method;
use axum::middleware::Next;
use axum::response::Response;
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{
    DescriptorEncoder, EncodeLabelValue, EncodeMetric, LabelValueEncoder,
};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::metrics::MetricType;
use prometheus_client::registry::Registry;

pub use process::render as render_process;

/// The content type of the exposition.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// A histogram read at scrape time: each bucket's upper bound (the last one
/// infinite) with the observations in it (not cumulative), and their sum.
pub struct HistogramSample<'a> {
    pub buckets: &'a [(f64, u64)],
    pub sum: f64,
}

/// The figures of one scrape, grouped by family.
#[derive(Default)]
pub struct Prom {
    families: Vec<Buffered>,
    index: HashMap<String, usize>,
}

enum Samples {
    Gauge(Vec<(Labels, f64)>),
    Counter(Vec<(Labels, f64)>),
    Histogram(Vec<HistogramBuf>),
    /// A metric that encodes itself (the HTTP latency family).
    Live(Box<dyn EncodeMetric + Send + Sync>),
}

struct Buffered {
    /// Without the `_total` of a counter: the encoder adds it.
    name: String,
    help: String,
    samples: Samples,
}

type Labels = Vec<(String, Escaped)>;

/// One histogram series: labels, sum, count and per-bucket counts.
type HistogramBuf = (Labels, f64, u64, Vec<(f64, u64)>);

/// No exemplars: their label set type.
type NoLabels = Vec<(String, Escaped)>;

impl Prom {
    fn family(&mut self, name: &str, help: &str, empty: impl FnOnce() -> Samples) -> &mut Samples {
        let i = match self.index.get(name) {
            Some(&i) => i,
            None => {
                self.families.push(Buffered {
                    name: name.to_string(),
                    help: help.to_string(),
                    samples: empty(),
                });
                self.index.insert(name.to_string(), self.families.len() - 1);
                self.families.len() - 1
            }
        };
        &mut self.families[i].samples
    }

    pub fn gauge(&mut self, name: &str, help: &str, labels: &[(&str, &str)], value: f64) {
        if let Samples::Gauge(v) = self.family(name, help, || Samples::Gauge(Vec::new())) {
            v.push((owned(labels), value));
        } else {
            debug_assert!(false, "{name} declared twice with different types");
        }
    }

    /// `name` may end in `_total` (it is the sample's name) or not.
    pub fn counter(&mut self, name: &str, help: &str, labels: &[(&str, &str)], value: f64) {
        let name = name.strip_suffix("_total").unwrap_or(name);
        if let Samples::Counter(v) = self.family(name, help, || Samples::Counter(Vec::new())) {
            v.push((owned(labels), value));
        } else {
            debug_assert!(false, "{name} declared twice with different types");
        }
    }

    pub fn histogram(
        &mut self,
        name: &str,
        help: &str,
        labels: &[(&str, &str)],
        h: &HistogramSample<'_>,
    ) {
        let count = h.buckets.iter().map(|b| b.1).sum();
        // The encoder marks the last bucket `+Inf` by `f64::MAX`.
        let buckets = h
            .buckets
            .iter()
            .map(|&(le, n)| (if le.is_finite() { le } else { f64::MAX }, n))
            .collect();
        if let Samples::Histogram(v) = self.family(name, help, || Samples::Histogram(Vec::new())) {
            v.push((owned(labels), h.sum, count, buckets));
        } else {
            debug_assert!(false, "{name} declared twice with different types");
        }
    }

    fn live(&mut self, name: &str, help: &str, metric: Box<dyn EncodeMetric + Send + Sync>) {
        if !self.index.contains_key(name) {
            self.family(name, help, move || Samples::Live(metric));
        }
    }

    /// The exposition text, ending in `# EOF`.
    pub fn finish(self) -> String {
        let mut registry = Registry::default();
        registry.register_collector(Box::new(Scrape(self)));
        let mut out = String::new();
        // Writing into a String cannot fail.
        let _ = prometheus_client::encoding::text::encode(&mut out, &registry);
        out
    }
}

fn owned(labels: &[(&str, &str)]) -> Labels {
    labels
        .iter()
        .map(|(k, v)| (k.to_string(), Escaped(v.to_string())))
        .collect()
}

/// A label value, escaped on the way out: device names come from
/// configuration and may hold quotes, backslashes or newlines, which the
/// encoder writes as they are.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct Escaped(String);

impl EncodeLabelValue for Escaped {
    fn encode(&self, encoder: &mut LabelValueEncoder) -> Result<(), std::fmt::Error> {
        use std::fmt::Write as _;
        for c in self.0.chars() {
            match c {
                '\\' => encoder.write_str("\\\\")?,
                '"' => encoder.write_str("\\\"")?,
                '\n' => encoder.write_str("\\n")?,
                c => encoder.write_char(c)?,
            }
        }
        Ok(())
    }
}

/// One scrape's figures as a `prometheus-client` collector.
struct Scrape(Prom);

impl std::fmt::Debug for Scrape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Scrape({} families)", self.0.families.len())
    }
}

impl Collector for Scrape {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        for f in &self.0.families {
            let kind = match &f.samples {
                Samples::Gauge(_) => MetricType::Gauge,
                Samples::Counter(_) => MetricType::Counter,
                Samples::Histogram(_) => MetricType::Histogram,
                Samples::Live(m) => m.metric_type(),
            };
            let mut family = encoder.encode_descriptor(&f.name, &f.help, None, kind)?;
            match &f.samples {
                // A family without labels has one sample, written bare (a
                // sample of an empty label set would be written `name{}`).
                Samples::Gauge(v) if v.len() == 1 && v[0].0.is_empty() => {
                    ConstGauge::new(v[0].1).encode(family)?;
                }
                Samples::Counter(v) if v.len() == 1 && v[0].0.is_empty() => {
                    ConstCounter::new(v[0].1).encode(family)?;
                }
                Samples::Gauge(v) => {
                    for (labels, value) in v {
                        ConstGauge::new(*value).encode(family.encode_family(labels)?)?;
                    }
                }
                Samples::Counter(v) => {
                    for (labels, value) in v {
                        ConstCounter::new(*value).encode(family.encode_family(labels)?)?;
                    }
                }
                Samples::Histogram(v) => {
                    for (labels, sum, count, buckets) in v {
                        family
                            .encode_family(labels)?
                            .encode_histogram::<NoLabels>(*sum, *count, buckets, None)?;
                    }
                }
                Samples::Live(m) => m.encode(family)?,
            }
        }
        Ok(())
    }
}

/// Figures the application adds to `/metrics` and `/healthz`.
pub trait MetricsSource: Send + Sync {
    fn render(&self, out: &mut Prom);

    /// Field I/O and historian at a glance, for `/healthz`.
    fn health(&self) -> StackHealth {
        StackHealth::default()
    }
}

/// What `/healthz` reports beside the store.
#[derive(Default)]
pub struct StackHealth {
    /// `None` where no field I/O runs.
    pub field_io: Option<FieldIoHealth>,
    /// `None` where no historian runs.
    pub historian: Option<HistorianHealth>,
}

pub struct FieldIoHealth {
    pub total: usize,
    /// The devices that do not answer, by name.
    pub not_good: Vec<String>,
}

pub struct HistorianHealth {
    /// Samples waiting to be written.
    pub queued: u64,
    pub capacity: u64,
    /// Samples dropped since start because the buffer was full.
    pub dropped: u64,
    /// The buffer overflowed and has not drained below half since.
    pub overflow: bool,
}

/// Upper bounds of the HTTP latency buckets, seconds.
const HTTP_BUCKETS: [f64; 12] = [
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0,
];

/// Route template, method and status class: every value comes from a
/// bounded set, so the number of series stays bounded whatever clients send.
type HttpLabels = [(&'static str, &'static str); 3];

/// HTTP request counters and latency.
pub struct HttpMetrics {
    by_class: [AtomicU64; 5],
    duration_us: AtomicU64,
    latency: Family<HttpLabels, Histogram>,
}

impl Default for HttpMetrics {
    fn default() -> Self {
        HttpMetrics {
            by_class: Default::default(),
            duration_us: AtomicU64::new(0),
            latency: Family::new_with_constructor(|| Histogram::new(HTTP_BUCKETS)),
        }
    }
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
        out.live(
            "gridscada_http_request_duration_seconds",
            "Time to answer an HTTP request, by route template, method and status class \
             (WebSocket sessions excluded).",
            Box::new(self.latency.clone()),
        );
    }
}

/// The route template a request matched, filled in by the route's own layer
/// ([`mark_route`]) and read by [`count`] outside the router.
#[derive(Clone, Default)]
pub struct MatchedRoute(Arc<OnceLock<&'static str>>);

/// Tells [`count`] which route answered (a layer on each route of the table).
pub async fn mark_route(template: &'static str, req: Request, next: Next) -> Response {
    if let Some(m) = req.extensions().get::<MatchedRoute>() {
        let _ = m.0.set(template);
    }
    next.run(req).await
}

/// Counts and times every response.
pub async fn count(State(m): State<Arc<HttpMetrics>>, mut req: Request, next: Next) -> Response {
    let started = Instant::now();
    let method = method_label(req.method());
    let route = MatchedRoute::default();
    req.extensions_mut().insert(route.clone());
    let resp = next.run(req).await;
    let class = (resp.status().as_u16() / 100).clamp(1, 5) as usize - 1;
    m.by_class[class].fetch_add(1, Ordering::Relaxed);
    if resp.status() != axum::http::StatusCode::SWITCHING_PROTOCOLS {
        let elapsed = started.elapsed();
        m.duration_us
            .fetch_add(elapsed.as_micros() as u64, Ordering::Relaxed);
        // The HMI's files and unknown paths share one series.
        let route = route.0.get().copied().unwrap_or("(other)");
        const CLASSES: [&str; 5] = ["1xx", "2xx", "3xx", "4xx", "5xx"];
        m.latency
            .get_or_create(&[
                ("route", route),
                ("method", method),
                ("status", CLASSES[class]),
            ])
            .observe(elapsed.as_secs_f64());
    }
    resp
}

/// Methods outside the standard set share one label value.
fn method_label(m: &Method) -> &'static str {
    match *m {
        Method::GET => "GET",
        Method::HEAD => "HEAD",
        Method::POST => "POST",
        Method::PUT => "PUT",
        Method::PATCH => "PATCH",
        Method::DELETE => "DELETE",
        Method::OPTIONS => "OPTIONS",
        _ => "other",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn families_are_grouped_whatever_the_order_of_samples() {
        let mut p = Prom::default();
        p.counter("a_total", "A.", &[("device", "x")], 1.0);
        p.gauge("b", "B.", &[], 2.0);
        p.counter("a_total", "A.", &[("device", "y\"z")], 3.0);
        p.histogram(
            "h_seconds",
            "H.",
            &[("device", "x")],
            &HistogramSample {
                buckets: &[(0.1, 2), (1.0, 1), (f64::INFINITY, 1)],
                sum: 4.5,
            },
        );
        let text = p.finish();
        assert_eq!(
            text,
            "# HELP a A.\n# TYPE a counter\n\
             a_total{device=\"x\"} 1.0\n\
             a_total{device=\"y\\\"z\"} 3.0\n\
             # HELP b B.\n# TYPE b gauge\nb 2.0\n\
             # HELP h_seconds H.\n# TYPE h_seconds histogram\n\
             h_seconds_sum{device=\"x\"} 4.5\n\
             h_seconds_count{device=\"x\"} 4\n\
             h_seconds_bucket{le=\"0.1\",device=\"x\"} 2\n\
             h_seconds_bucket{le=\"1.0\",device=\"x\"} 3\n\
             h_seconds_bucket{le=\"+Inf\",device=\"x\"} 4\n\
             # EOF\n",
            "{text}"
        );
    }
}

/// The cost of a scrape at 50 devices on 5 links (10 000 tags change
/// nothing here: the series are per device, link and route, not per tag).
/// `cargo test -p gridscada-web --lib scrape_cost -- --ignored --nocapture`
#[cfg(test)]
mod bench {
    use super::*;

    fn render(out: &mut Prom, http: &HttpMetrics) {
        let buckets: Vec<(f64, u64)> = HTTP_BUCKETS
            .iter()
            .copied()
            .chain([f64::INFINITY])
            .map(|b| (b, 7))
            .collect();
        for d in 0..50 {
            let name = format!("PANEL{}.IO{}", d / 5, d % 5);
            let l = [("device", name.as_str())];
            out.gauge(
                "gridscada_device_connected",
                "1 while the device answers.",
                &l,
                1.0,
            );
            for c in [
                "requests",
                "errors",
                "timeouts",
                "exceptions",
                "writes",
                "scans",
                "late_scans",
                "overruns",
            ] {
                out.counter(
                    &format!("gridscada_poll_{c}_total"),
                    "Counter.",
                    &l,
                    12345.0,
                );
            }
            out.gauge(
                "gridscada_poll_response_seconds",
                "Last round trip.",
                &l,
                0.0042,
            );
            out.histogram(
                "gridscada_poll_round_trip_seconds",
                "Round trips.",
                &l,
                &HistogramSample {
                    buckets: &buckets,
                    sum: 1.5,
                },
            );
        }
        http.render(out);
        process::render(out);
    }

    #[test]
    #[ignore = "a measurement, not a check"]
    fn scrape_cost() {
        let http = HttpMetrics::default();
        for route in 0..60 {
            let route: &'static str = Box::leak(format!("/api/route{route}").into_boxed_str());
            http.latency
                .get_or_create(&[("route", route), ("method", "GET"), ("status", "2xx")])
                .observe(0.003);
        }
        let n = 200;
        let started = Instant::now();
        let mut len = 0;
        for _ in 0..n {
            let mut p = Prom::default();
            render(&mut p, &http);
            len = p.finish().len();
        }
        let each = started.elapsed() / n;
        println!("scrape at 50 devices, 60 HTTP series: {each:?} each, {len} bytes");
    }
}
