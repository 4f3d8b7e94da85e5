//! The route table: every API route with the permission it needs, in one
//! place. The router is built from this table, and the authorization tests are
//! generated from it, so a route without a rule cannot exist.

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderValue, Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::MethodRouter;
use std::sync::Arc;

use axum::Router;
use gridscada_config::Role;

use crate::api;
use crate::auth::{token_from_cookies, Principal};
use crate::error::ApiError;
use crate::openapi::{doc, Doc};
use crate::WebState;

/// What a route requires of its caller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Perm {
    /// Anyone, including anonymous clients.
    Public,
    /// Any logged-in user (Guest role or above).
    LoggedIn,
    /// A logged-in user whose group may open this screen.
    Screen(&'static str),
    /// At least this role.
    Role(Role),
    /// At least this role, and the screen.
    RoleScreen(Role, &'static str),
}

impl Perm {
    /// Whether `p` passes. The error says why not, in words for the operator.
    pub fn check(self, p: &Principal) -> Result<(), ApiError> {
        let logged_in = || {
            if p.is_logged_in() {
                Ok(())
            } else {
                Err(ApiError::unauthorized())
            }
        };
        let role = |r: Role| {
            if p.role >= r {
                Ok(())
            } else {
                Err(ApiError::forbidden(format!(
                    "this needs the {} role or above; you are {}",
                    r.label(),
                    p.role.label()
                )))
            }
        };
        let screen = |s: &str| {
            if p.may_open(s) {
                Ok(())
            } else {
                Err(ApiError::forbidden(format!(
                    "your group may not open the {s} screen"
                )))
            }
        };
        match self {
            Perm::Public => Ok(()),
            Perm::LoggedIn => logged_in(),
            Perm::Screen(s) => logged_in().and_then(|_| screen(s)),
            Perm::Role(r) => logged_in().and_then(|_| role(r)),
            Perm::RoleScreen(r, s) => logged_in().and_then(|_| role(r)).and_then(|_| screen(s)),
        }
    }
}

impl Perm {
    /// The screen the permission names, if any.
    pub fn screen(self) -> Option<&'static str> {
        match self {
            Perm::Screen(s) | Perm::RoleScreen(_, s) => Some(s),
            _ => None,
        }
    }
}

/// One route of the API.
pub struct Route {
    pub method: Method,
    pub path: &'static str,
    pub perm: Perm,
    /// Only present when the server runs simulators (`demo`, `replay`).
    pub sim_only: bool,
    /// A health probe: public, and answered without resolving the caller
    /// (its session cookie is not even read), so it never waits on the
    /// session store.
    pub probe: bool,
    handler: fn() -> MethodRouter<WebState>,
    /// Its OpenAPI operation: `doc::<api::module::__path_handler>`, from the
    /// handler's `#[utoipa::path]` annotation.
    pub doc: fn() -> Doc,
}

const fn r(
    method: Method,
    path: &'static str,
    perm: Perm,
    handler: fn() -> MethodRouter<WebState>,
    doc: fn() -> Doc,
) -> Route {
    Route {
        method,
        path,
        perm,
        sim_only: false,
        probe: false,
        handler,
        doc,
    }
}

/// A health probe ([`Route::probe`]).
const fn probe(
    path: &'static str,
    handler: fn() -> MethodRouter<WebState>,
    doc: fn() -> Doc,
) -> Route {
    Route {
        method: Method::GET,
        path,
        perm: Perm::Public,
        sim_only: false,
        probe: true,
        handler,
        doc,
    }
}

const fn sim(
    method: Method,
    path: &'static str,
    handler: fn() -> MethodRouter<WebState>,
    doc: fn() -> Doc,
) -> Route {
    // A trainer: an operator or above whose group may open the Simulation
    // screen (administrators' groups by default).
    Route {
        method,
        path,
        perm: Perm::RoleScreen(Role::Operator, crate::access::SIMULATION),
        sim_only: true,
        probe: false,
        handler,
        doc,
    }
}

use Role::{Administrator as Admin, Operator, Supervisor};

/// Every API route. Anything not listed here is the static HMI or 404.
pub fn table() -> Vec<Route> {
    use axum::routing::{delete, get, patch, post, put};
    vec![
        probe(
            "/healthz",
            || get(api::misc::healthz),
            doc::<api::misc::__path_healthz>,
        ),
        probe(
            "/readyz",
            || get(api::misc::readyz),
            doc::<api::misc::__path_readyz>,
        ),
        r(
            Method::GET,
            "/metrics",
            Perm::Public,
            || get(api::misc::metrics),
            doc::<api::misc::__path_metrics>,
        ),
        r(
            Method::GET,
            "/api/openapi.json",
            Perm::Public,
            || get(api::misc::openapi),
            doc::<api::misc::__path_openapi>,
        ),
        // Session.
        r(
            Method::POST,
            "/api/session",
            Perm::Public,
            || post(api::session::login),
            doc::<api::session::__path_login>,
        ),
        r(
            Method::GET,
            "/api/session",
            Perm::Public,
            || get(api::session::current),
            doc::<api::session::__path_current>,
        ),
        r(
            Method::DELETE,
            "/api/session",
            Perm::Public,
            || delete(api::session::logout),
            doc::<api::session::__path_logout>,
        ),
        // A redundant pair's failover: the login carried to the other server.
        r(
            Method::POST,
            "/api/session/handover",
            Perm::LoggedIn,
            || post(api::session::handover),
            doc::<api::session::__path_handover>,
        ),
        r(
            Method::POST,
            "/api/session/handover/claim",
            Perm::Public,
            || post(api::session::claim),
            doc::<api::session::__path_claim>,
        ),
        // Tags.
        r(
            Method::GET,
            "/api/tags",
            Perm::LoggedIn,
            || get(api::tags::list),
            doc::<api::tags::__path_list>,
        ),
        // Readable tags only (see access::Readable), checked in the handlers.
        r(
            Method::GET,
            "/api/tags/tree",
            Perm::LoggedIn,
            || get(api::tags::tree),
            doc::<api::tags::__path_tree>,
        ),
        r(
            Method::GET,
            "/api/tags/{name}",
            Perm::LoggedIn,
            || get(api::tags::one),
            doc::<api::tags::__path_one>,
        ),
        // The tag's own write_role is checked in the handler, on the server.
        r(
            Method::POST,
            "/api/tags/{name}/write",
            Perm::Role(Operator),
            || post(api::tags::write),
            doc::<api::tags::__path_write>,
        ),
        // The redundant pair (404 on a server alone).
        r(
            Method::GET,
            "/api/pair",
            Perm::LoggedIn,
            || get(api::pair::view),
            doc::<api::pair::__path_view>,
        ),
        // The sites on this server's database, for `site=` on the history.
        r(
            Method::GET,
            "/api/sites",
            Perm::LoggedIn,
            || get(api::pair::sites),
            doc::<api::pair::__path_sites>,
        ),
        // Devices.
        r(
            Method::GET,
            "/api/devices",
            Perm::Screen("devices"),
            || get(api::devices::list),
            doc::<api::devices::__path_list>,
        ),
        // Screens: the catalog, and the screens users draw.
        r(
            Method::GET,
            "/api/screens",
            Perm::LoggedIn,
            || get(api::screens::catalog),
            doc::<api::screens::__path_catalog>,
        ),
        // The screen's own access (or the editor's) is checked in the handler.
        r(
            Method::GET,
            "/api/screens/{id}",
            Perm::LoggedIn,
            || get(api::screens::one),
            doc::<api::screens::__path_one>,
        ),
        r(
            Method::PUT,
            "/api/screens/{id}",
            Perm::RoleScreen(Admin, "editor"),
            || put(api::screens::save),
            doc::<api::screens::__path_save>,
        ),
        r(
            Method::DELETE,
            "/api/screens/{id}",
            Perm::RoleScreen(Admin, "editor"),
            || delete(api::screens::remove),
            doc::<api::screens::__path_remove>,
        ),
        // Alarms.
        r(
            Method::GET,
            "/api/alarms",
            Perm::LoggedIn,
            || get(api::alarms::summary),
            doc::<api::alarms::__path_summary>,
        ),
        r(
            Method::POST,
            "/api/alarms/ack",
            Perm::Role(Operator),
            || post(api::alarms::ack),
            doc::<api::alarms::__path_ack>,
        ),
        r(
            Method::POST,
            "/api/alarms/{id}/shelve",
            Perm::Role(Supervisor),
            || post(api::alarms::shelve),
            doc::<api::alarms::__path_shelve>,
        ),
        r(
            Method::DELETE,
            "/api/alarms/{id}/shelve",
            Perm::Role(Supervisor),
            || delete(api::alarms::unshelve),
            doc::<api::alarms::__path_unshelve>,
        ),
        r(
            Method::POST,
            "/api/alarms/{id}/out-of-service",
            Perm::Role(Supervisor),
            || post(api::alarms::out_of_service),
            doc::<api::alarms::__path_out_of_service>,
        ),
        r(
            Method::DELETE,
            "/api/alarms/{id}/out-of-service",
            Perm::Role(Supervisor),
            || delete(api::alarms::in_service),
            doc::<api::alarms::__path_in_service>,
        ),
        r(
            Method::GET,
            "/api/alarms/history",
            Perm::Screen("alarms"),
            || get(api::alarms::history),
            doc::<api::alarms::__path_history>,
        ),
        r(
            Method::GET,
            "/api/alarms/history.csv",
            Perm::Screen("alarms"),
            || get(api::alarms::history_csv),
            doc::<api::alarms::__path_history_csv>,
        ),
        r(
            Method::GET,
            "/api/alarms/metrics",
            Perm::Screen("alarmkpi"),
            || get(api::alarms::metrics),
            doc::<api::alarms::__path_metrics>,
        ),
        // Reports: Supervisors and up, with the reports screen.
        r(
            Method::GET,
            "/api/reports",
            Perm::RoleScreen(Supervisor, "reports"),
            || get(api::reports::list),
            doc::<api::reports::__path_list>,
        ),
        r(
            Method::POST,
            "/api/reports",
            Perm::RoleScreen(Supervisor, "reports"),
            || post(api::reports::make),
            doc::<api::reports::__path_make>,
        ),
        r(
            Method::GET,
            "/api/reports/{id}/{format}",
            Perm::RoleScreen(Supervisor, "reports"),
            || get(api::reports::file),
            doc::<api::reports::__path_file>,
        ),
        // Events and trends.
        r(
            Method::GET,
            "/api/events",
            Perm::Screen("events"),
            || get(api::events::list),
            doc::<api::events::__path_list>,
        ),
        r(
            Method::GET,
            "/api/events.csv",
            Perm::Screen("events"),
            || get(api::events::csv),
            doc::<api::events::__path_csv>,
        ),
        r(
            Method::GET,
            "/api/trends",
            Perm::Screen("trends"),
            || get(api::trends::trend),
            doc::<api::trends::__path_trend>,
        ),
        r(
            Method::GET,
            "/api/trends.csv",
            Perm::Screen("trends"),
            || get(api::trends::csv),
            doc::<api::trends::__path_csv>,
        ),
        // Users and groups.
        r(
            Method::GET,
            "/api/users",
            Perm::RoleScreen(Admin, "users"),
            || get(api::users::list),
            doc::<api::users::__path_list>,
        ),
        r(
            Method::POST,
            "/api/users",
            Perm::RoleScreen(Admin, "users"),
            || post(api::users::create),
            doc::<api::users::__path_create>,
        ),
        r(
            Method::PATCH,
            "/api/users/{name}",
            Perm::RoleScreen(Admin, "users"),
            || patch(api::users::update),
            doc::<api::users::__path_update>,
        ),
        r(
            Method::DELETE,
            "/api/users/{name}",
            Perm::RoleScreen(Admin, "users"),
            || delete(api::users::remove),
            doc::<api::users::__path_remove>,
        ),
        // Own password for anyone; anyone else's for administrators (checked in the handler).
        r(
            Method::POST,
            "/api/users/{name}/password",
            Perm::LoggedIn,
            || post(api::users::password),
            doc::<api::users::__path_password>,
        ),
        r(
            Method::GET,
            "/api/groups/{group}/screens",
            Perm::RoleScreen(Admin, "users"),
            || get(api::users::group_screens),
            doc::<api::users::__path_group_screens>,
        ),
        r(
            Method::PUT,
            "/api/groups/{group}/screens",
            Perm::RoleScreen(Admin, "users"),
            || put(api::users::set_group_screens),
            doc::<api::users::__path_set_group_screens>,
        ),
        // Panels (fault isolation).
        r(
            Method::GET,
            "/api/panels",
            Perm::LoggedIn,
            || get(api::panels::list),
            doc::<api::panels::__path_list>,
        ),
        r(
            Method::GET,
            "/api/panels/{id}",
            Perm::LoggedIn,
            || get(api::panels::one),
            doc::<api::panels::__path_one>,
        ),
        r(
            Method::POST,
            "/api/panels/{id}/mode",
            Perm::Role(Supervisor),
            || post(api::panels::mode),
            doc::<api::panels::__path_mode>,
        ),
        r(
            Method::POST,
            "/api/panels/{id}/reset",
            Perm::Role(Operator),
            || post(api::panels::reset),
            doc::<api::panels::__path_reset>,
        ),
        r(
            Method::POST,
            "/api/panels/{id}/breakers/{breaker}",
            Perm::Role(Operator),
            || post(api::panels::breaker),
            doc::<api::panels::__path_breaker>,
        ),
        // The switching network.
        r(
            Method::GET,
            "/api/network",
            Perm::LoggedIn,
            || get(api::network::model),
            doc::<api::network::__path_model>,
        ),
        r(
            Method::GET,
            "/api/network/topology",
            Perm::LoggedIn,
            || get(api::network::topology),
            doc::<api::network::__path_topology>,
        ),
        r(
            Method::GET,
            "/api/switching/tags",
            Perm::LoggedIn,
            || get(api::network::tags),
            doc::<api::network::__path_tags>,
        ),
        r(
            Method::POST,
            "/api/switching/tags",
            Perm::Role(Operator),
            || post(api::network::place),
            doc::<api::network::__path_place>,
        ),
        r(
            Method::DELETE,
            "/api/switching/tags/{id}",
            Perm::Role(Operator),
            || delete(api::network::remove),
            doc::<api::network::__path_remove>,
        ),
        r(
            Method::GET,
            "/api/switching/selections",
            Perm::LoggedIn,
            || get(api::network::selections),
            doc::<api::network::__path_selections>,
        ),
        r(
            Method::POST,
            "/api/switching/selections",
            Perm::Role(Operator),
            || post(api::network::select),
            doc::<api::network::__path_select>,
        ),
        r(
            Method::POST,
            "/api/switching/selections/{id}/execute",
            Perm::Role(Operator),
            || post(api::network::execute),
            doc::<api::network::__path_execute>,
        ),
        r(
            Method::POST,
            "/api/switching/selections/{id}/override",
            Perm::Role(Supervisor),
            || post(api::network::override_selection),
            doc::<api::network::__path_override_selection>,
        ),
        r(
            Method::DELETE,
            "/api/switching/selections/{id}",
            Perm::Role(Operator),
            || delete(api::network::cancel),
            doc::<api::network::__path_cancel>,
        ),
        r(
            Method::GET,
            "/api/switching/programmes",
            Perm::LoggedIn,
            || get(api::programmes::list),
            doc::<api::programmes::__path_list>,
        ),
        r(
            Method::POST,
            "/api/switching/programmes",
            Perm::Role(Supervisor),
            || post(api::programmes::create),
            doc::<api::programmes::__path_create>,
        ),
        r(
            Method::GET,
            "/api/switching/programmes/{id}",
            Perm::LoggedIn,
            || get(api::programmes::one),
            doc::<api::programmes::__path_one>,
        ),
        r(
            Method::POST,
            "/api/switching/programmes/{id}/approve",
            Perm::Role(Supervisor),
            || post(api::programmes::approve),
            doc::<api::programmes::__path_approve>,
        ),
        r(
            Method::POST,
            "/api/switching/programmes/{id}/step",
            Perm::Role(Operator),
            || post(api::programmes::step),
            doc::<api::programmes::__path_step>,
        ),
        r(
            Method::POST,
            "/api/switching/programmes/{id}/state",
            Perm::Role(Operator),
            || post(api::programmes::set_state),
            doc::<api::programmes::__path_set_state>,
        ),
        r(
            Method::GET,
            "/api/network/preview",
            Perm::LoggedIn,
            || get(api::network::preview_operation),
            doc::<api::network::__path_preview_operation>,
        ),
        // Dispatch.
        r(
            Method::GET,
            "/api/dispatch",
            Perm::Screen("microgrid"),
            || get(api::dispatch::latest),
            doc::<api::dispatch::__path_latest>,
        ),
        r(
            Method::GET,
            "/api/dispatch/history",
            Perm::Screen("microgrid"),
            || get(api::dispatch::history),
            doc::<api::dispatch::__path_history>,
        ),
        r(
            Method::GET,
            "/api/dispatch/history.csv",
            Perm::Screen("microgrid"),
            || get(api::dispatch::history_csv),
            doc::<api::dispatch::__path_history_csv>,
        ),
        r(
            Method::GET,
            "/api/microgrid/units",
            Perm::Screen("microgrid"),
            || get(api::dispatch::units),
            doc::<api::dispatch::__path_units>,
        ),
        // Live push.
        r(
            Method::GET,
            "/api/live",
            Perm::LoggedIn,
            || get(api::live::upgrade),
            doc::<api::live::__path_upgrade>,
        ),
        // Simulation: demo and replay only.
        sim(
            Method::POST,
            "/api/sim/faults",
            || post(api::sim::inject_fault),
            doc::<api::sim::__path_inject_fault>,
        ),
        sim(
            Method::DELETE,
            "/api/sim/faults/{panel}/{zone}",
            || delete(api::sim::repair),
            doc::<api::sim::__path_repair>,
        ),
        sim(
            Method::POST,
            "/api/sim/devices/{device}/offline",
            || post(api::sim::offline),
            doc::<api::sim::__path_offline>,
        ),
        sim(
            Method::POST,
            "/api/sim/devices/{device}/online",
            || post(api::sim::online),
            doc::<api::sim::__path_online>,
        ),
        sim(
            Method::GET,
            "/api/sim/state",
            || get(api::sim::state),
            doc::<api::sim::__path_state>,
        ),
        sim(
            Method::PUT,
            "/api/sim/devices/{device}/link",
            || put(api::sim::link),
            doc::<api::sim::__path_link>,
        ),
        sim(
            Method::PUT,
            "/api/sim/zones/{panel}/{zone}/load",
            || put(api::sim::zone_load),
            doc::<api::sim::__path_zone_load>,
        ),
        sim(
            Method::PUT,
            "/api/sim/inputs/{input}",
            || put(api::sim::input),
            doc::<api::sim::__path_input>,
        ),
    ]
}

/// Builds the router from the table, each route behind its permission check.
pub fn build(state: WebState) -> Router {
    let with_sim = state.sim.is_some();
    state.screens.set_simulation(with_sim);
    let mut router: Router<WebState> = Router::new();
    let mut refused_sim_paths = std::collections::HashSet::new();
    for route in table() {
        if route.sim_only && !with_sim {
            // No simulator (`serve`): the path answers 404 with the reason,
            // to anyone, before any login check.
            if refused_sim_paths.insert(route.path) {
                router = router.route(route.path, axum::routing::any(api::sim::not_simulated));
            }
            continue;
        }
        let perm = route.perm;
        let template = route.path;
        let mut handler = (route.handler)();
        if !route.probe {
            handler = handler.route_layer(middleware::from_fn_with_state(
                state.clone(),
                move |s: State<WebState>, req: Request, next: Next| authorize(s, perm, req, next),
            ));
        }
        // Outside the check, so refused requests are timed by route too.
        let handler = handler.route_layer(middleware::from_fn(move |req: Request, next: Next| {
            crate::metrics::mark_route(template, req, next)
        }));
        router = router.route(route.path, handler);
    }
    let http_metrics = state.http_metrics.clone();
    let server = &state.plant.server;
    let origins = Arc::new(OriginPolicy::new(server));
    let proxies = Arc::new(crate::proxy::TrustedProxies::of_server(server));
    let base = server.base_path();
    let hsts = hsts_header(&state);
    let app = router
        .fallback(crate::hmi::serve)
        .layer(middleware::from_fn(json_errors))
        .layer(middleware::from_fn_with_state(
            http_metrics,
            crate::metrics::count,
        ))
        .layer(middleware::from_fn_with_state(origins, check_origin))
        // Outside the checks, so their refusals carry the headers too.
        .layer(middleware::from_fn_with_state(hsts, security_headers))
        .layer(tower_http::compression::CompressionLayer::new())
        .layer(middleware::from_fn_with_state(
            proxies,
            crate::proxy::client_info,
        ))
        .with_state(state);
    if base.is_empty() {
        return app;
    }
    // Under `[server] base_path`: the whole application, the prefix taken
    // off before it routes (so the route table stays as it is).
    Router::new()
        .fallback_service(app)
        .layer(middleware::from_fn_with_state(
            Arc::<str>::from(base),
            under_base,
        ))
}

/// Serves the application under its base path: `/scada/x` is routed as
/// `/x`, `/scada` is redirected to `/scada/` (the HMI's relative URLs need
/// the slash), anything else is not ours.
async fn under_base(State(base): State<Arc<str>>, mut req: Request, next: Next) -> Response {
    let path = req.uri().path();
    if path == &*base {
        let query = req.uri().query().map_or(String::new(), |q| format!("?{q}"));
        return (
            StatusCode::PERMANENT_REDIRECT,
            [(header::LOCATION, format!("{base}/{query}"))],
        )
            .into_response();
    }
    let Some(rest) = path.strip_prefix(&*base).filter(|r| r.starts_with('/')) else {
        return ApiError::not_found(format!("not found; gridscada is served under {base}/"))
            .into_response();
    };
    let rest = match req.uri().query() {
        Some(q) => format!("{rest}?{q}"),
        None => rest.to_string(),
    };
    let mut parts = req.uri().clone().into_parts();
    parts.path_and_query = rest.parse().ok();
    match axum::http::Uri::from_parts(parts) {
        Ok(uri) => *req.uri_mut() = uri,
        Err(_) => return ApiError::bad_request("unreadable request path").into_response(),
    }
    next.run(req).await
}

/// What [`check_origin`] holds requests against.
pub struct OriginPolicy {
    hosts: HostPolicy,
    /// `[server] public_origin`, normalised: when set, an unsafe request's
    /// Origin must be exactly this (the Host header is the proxy's).
    public_origin: Option<String>,
}

impl OriginPolicy {
    pub fn new(server: &gridscada_config::ServerConfig) -> Self {
        OriginPolicy {
            hosts: HostPolicy::of_server(server),
            public_origin: server.public_origin(),
        }
    }

    /// Whether an `Origin` (or a Referer's origin) is this server's: the
    /// public origin when one is set, otherwise the request's own host.
    fn ours(&self, origin: &str, host: &str) -> bool {
        match &self.public_origin {
            Some(public) => origin.trim_end_matches('/').eq_ignore_ascii_case(public),
            None => same_origin(origin, host),
        }
    }
}

/// The host names this server answers to: any IP address, `localhost`, and
/// the configured `[server] allowed_hosts`. A page on another name that
/// resolves here (DNS rebinding) is refused.
pub struct HostPolicy {
    names: Vec<String>,
}

impl HostPolicy {
    pub fn new(allowed: &[String]) -> Self {
        HostPolicy {
            names: allowed.iter().map(|h| h.to_ascii_lowercase()).collect(),
        }
    }

    /// `[server] allowed_hosts` and the host of `public_origin`.
    pub fn of_server(server: &gridscada_config::ServerConfig) -> Self {
        let mut names = server.allowed_hosts.clone();
        if let Some(o) = &server.public_origin() {
            names.push(gridscada_config::origin_host(o).to_string());
        }
        HostPolicy::new(&names)
    }

    /// Whether a `Host` header value (with or without port) is ours.
    pub fn allows(&self, host: &str) -> bool {
        let host = host.trim();
        // "[::1]:8080", "127.0.0.1:8080", "name:8080", "name".
        let name = if let Some(rest) = host.strip_prefix('[') {
            match rest.split_once(']') {
                Some((ip, _)) => return ip.parse::<std::net::Ipv6Addr>().is_ok(),
                None => return false,
            }
        } else {
            host.rsplit_once(':').map_or(host, |(n, port)| {
                if port.bytes().all(|b| b.is_ascii_digit()) {
                    n
                } else {
                    host
                }
            })
        };
        if name.parse::<std::net::IpAddr>().is_ok() {
            return true;
        }
        let name = name.trim_end_matches('.').to_ascii_lowercase();
        name == "localhost" || self.names.contains(&name)
    }
}

/// Resolves the caller and checks the route's permission. The principal goes
/// into the request's extensions for the handler.
async fn authorize(
    State(state): State<WebState>,
    perm: Perm,
    mut req: Request,
    next: Next,
) -> Response {
    let principal = state.principal(req.headers()).await;
    // A screen this plant does not have (the microgrid's, in a plant
    // without one) is absent rather than forbidden.
    if let Some(screen) = perm.screen() {
        if principal.is_logged_in()
            && !crate::access::screen_exists(&state.plant, &state.screens, screen)
        {
            return ApiError::not_found(format!("this plant has no {screen} screen"))
                .into_response();
        }
    }
    if let Err(e) = perm.check(&principal) {
        return e.into_response();
    }
    req.extensions_mut().insert(principal);
    next.run(req).await
}

/// Host and CSRF checks, on top of SameSite=Strict cookies:
/// - the `Host` must be one of ours ([`HostPolicy`]), on every request;
/// - an unsafe method or a WebSocket upgrade must come from our own origin:
///   its `Origin`, or without one its `Referer`, must name this host (or be
///   `[server] public_origin`, when set); a request that carries the session
///   cookie and neither header is refused (browsers always send one of
///   them; scripts must say where they are).
async fn check_origin(
    State(policy): State<Arc<OriginPolicy>>,
    req: Request,
    next: Next,
) -> Response {
    let headers = req.headers();
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .map(str::to_string)
        .or_else(|| req.uri().authority().map(|a| a.to_string()));
    let Some(host) = host.filter(|h| policy.hosts.allows(h)) else {
        return ApiError::new(
            StatusCode::MISDIRECTED_REQUEST,
            "unknown_host",
            "this server does not answer to that host name; add it to [server] allowed_hosts",
        )
        .into_response();
    };
    let unsafe_method = !matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS);
    let upgrade = headers
        .get(header::UPGRADE)
        .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"websocket"));
    if unsafe_method || upgrade {
        let origin = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok());
        let referer = headers.get(header::REFERER).and_then(|v| v.to_str().ok());
        let with_cookie =
            token_from_cookies(headers.get(header::COOKIE).and_then(|v| v.to_str().ok())).is_some();
        let refusal = match (origin, referer) {
            (Some(o), _) if !policy.ours(o, &host) => {
                Some("cross-site request refused (Origin does not match this server)")
            }
            (None, Some(r)) if !policy.ours(referer_origin(r), &host) => {
                Some("cross-site request refused (Referer does not match this server)")
            }
            (None, None) if with_cookie => Some(
                "request refused: a logged-in change must say where it comes from (Origin or Referer header)",
            ),
            _ => None,
        };
        if let Some(why) = refusal {
            return ApiError::forbidden(why).into_response();
        }
    }
    next.run(req).await
}

/// `scheme://host[:port]` of a URL.
fn referer_origin(url: &str) -> &str {
    let after_scheme = url.find("://").map_or(0, |i| i + 3);
    match url[after_scheme..].find(['/', '?', '#']) {
        Some(end) => &url[..after_scheme + end],
        None => url,
    }
}

fn same_origin(origin: &str, host: &str) -> bool {
    origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"))
        .is_some_and(|o| o.eq_ignore_ascii_case(host))
}

/// Axum's own rejections (a path segment or query string that does not
/// parse, a method the route lacks) answer in plain text; the API answers
/// every error as JSON `{error, detail}`, so they are rewrapped here. Their
/// text names only the offending input, never internals.
async fn json_errors(req: Request, next: Next) -> Response {
    let resp = next.run(req).await;
    let status = resp.status();
    let is_json = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|c| c.starts_with("application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return resp;
    }
    let (parts, body) = resp.into_parts();
    let reason = || {
        status
            .canonical_reason()
            .unwrap_or("request failed")
            .to_lowercase()
    };
    let detail = match axum::body::to_bytes(body, 4096).await {
        Ok(b) if !b.is_empty() && !status.is_server_error() => {
            String::from_utf8_lossy(&b).trim().to_string()
        }
        _ => reason(),
    };
    let code = match status {
        StatusCode::BAD_REQUEST | StatusCode::UNPROCESSABLE_ENTITY => "bad_request",
        StatusCode::NOT_FOUND => "not_found",
        StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
        StatusCode::PAYLOAD_TOO_LARGE => "payload_too_large",
        StatusCode::UNSUPPORTED_MEDIA_TYPE => "unsupported_media_type",
        StatusCode::UPGRADE_REQUIRED => "upgrade_required",
        s if s.is_server_error() => "internal",
        _ => "request_failed",
    };
    let mut out = ApiError::new(status, code, detail).into_response();
    // Keep headers such as `Allow` on a 405; the body's own headers are new.
    for (name, value) in parts.headers.iter() {
        if name != header::CONTENT_TYPE && name != header::CONTENT_LENGTH {
            out.headers_mut().insert(name.clone(), value.clone());
        }
    }
    out
}

/// `Strict-Transport-Security` when this server speaks HTTPS and
/// `[server.tls] hsts_max_age_s` is not 0.
fn hsts_header(state: &WebState) -> Option<HeaderValue> {
    let max_age = state
        .plant
        .tls
        .as_ref()
        .map_or(gridscada_config::DEFAULT_HSTS_MAX_AGE_S, |t| {
            t.hsts_max_age_s
        });
    (state.tls && max_age > 0)
        .then(|| HeaderValue::from_str(&format!("max-age={max_age}")).ok())
        .flatten()
}

/// Security headers on every response; API answers are never cached (they
/// carry plant state and user data).
async fn security_headers(
    State(hsts): State<Option<HeaderValue>>,
    req: Request,
    next: Next,
) -> Response {
    let path = req.uri().path();
    let dynamic =
        path.starts_with("/api/") || path == "/metrics" || path == "/healthz" || path == "/readyz";
    let mut resp = next.run(req).await;
    let failed = resp.status().is_client_error() || resp.status().is_server_error();
    let h = resp.headers_mut();
    if dynamic || failed {
        h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    }
    let set = |h: &mut HeaderMap, k: &'static str, v: &'static str| {
        h.insert(k, HeaderValue::from_static(v));
    };
    // A response with its own policy (a report page) keeps it.
    if !h.contains_key(header::CONTENT_SECURITY_POLICY) {
        set(
            h,
            "content-security-policy",
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; font-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'",
        );
    }
    set(h, "x-content-type-options", "nosniff");
    set(h, "x-frame-options", "DENY");
    set(h, "referrer-policy", "same-origin");
    set(h, "cross-origin-opener-policy", "same-origin");
    if let Some(hsts) = hsts {
        h.insert(header::STRICT_TRANSPORT_SECURITY, hsts);
    }
    resp
}

/// Marks a request the HMI made on its own, not for the user (`1`).
pub const BACKGROUND_HEADER: &str = "x-gridscada-background";

/// Resolving the caller from the session cookie.
impl WebState {
    pub async fn principal(&self, headers: &HeaderMap) -> Principal {
        let cookie = headers.get(header::COOKIE).and_then(|v| v.to_str().ok());
        let Some(token) = token_from_cookies(cookie) else {
            return Principal::anonymous();
        };
        // A request the HMI makes on its own while its screen is hidden (a
        // poll) is not activity: it must not keep an unwatched session alive.
        let background = headers
            .get(BACKGROUND_HEADER)
            .is_some_and(|v| v.as_bytes() == b"1");
        let session = if background {
            self.auth.sessions.user_untouched(&token).await
        } else {
            self.auth.sessions.user(&token).await
        };
        let Some(session) = session else {
            return Principal::anonymous();
        };
        // The user and their group's screens, as the store says now; in an
        // outage not waited for longer than `store_wait_ms`.
        let sessions = &self.auth.sessions;
        let (store, name) = (self.store.clone(), session.user.clone());
        let now = sessions
            .within_store_wait(async move {
                let Some(u) = store.user(&name).await? else {
                    return Ok(None);
                };
                let screens = store.group_screens(&u.group).await?;
                Ok(Some((u, screens)))
            })
            .await;
        match now {
            // The role is checked too: a change made by another process
            // (`gridscada user`, another server) ends the session here at
            // once, before the store's revocation reaches the cache.
            Ok(Some((u, screens))) if !u.blocked && u.role == session.role => {
                let screens = self.group_screens_or_defaults(screens, u.role);
                let who = Principal {
                    user: Some(u.name),
                    role: u.role,
                    group: Some(u.group),
                    screens,
                };
                self.auth
                    .last_known
                    .lock()
                    .insert(session.user.clone(), who.clone());
                who
            }
            Ok(_) => {
                // Deleted, blocked or given another role since login: the
                // session ends now.
                self.auth.last_known.lock().remove(&session.user);
                self.auth.sessions.end(&token).await;
                Principal::anonymous()
            }
            Err(e) => {
                // The database does not answer: the session (live in this
                // server's cache) keeps what the store last said of its
                // user, so the control room can still work; what they do
                // is audited through the spool.
                tracing::warn!(error = %e, "reading the session's user; using what the store last said");
                match self.auth.last_known.lock().get(&session.user) {
                    Some(who) if who.role == session.role => who.clone(),
                    _ => Principal::anonymous(),
                }
            }
        }
    }

    /// The screens of a group; a group never configured gets its role's defaults.
    pub async fn screens_of(&self, group: &str, role: Role) -> Vec<String> {
        let stored = self.store.group_screens(group).await.unwrap_or_default();
        self.group_screens_or_defaults(stored, role)
    }

    /// A group's stored screens, or its role's defaults if none are stored.
    fn group_screens_or_defaults(&self, stored: Vec<String>, role: Role) -> Vec<String> {
        if stored.is_empty() {
            crate::access::default_screens(&self.plant, &self.screens, role)
        } else {
            stored
        }
    }

    /// Every screen of the plant, in toolbar order.
    pub fn catalog(&self) -> Vec<crate::access::ScreenEntry> {
        crate::access::catalog(&self.plant, &self.screens)
    }

    /// The tags `who` may read.
    pub fn readable(&self, who: &Principal) -> crate::access::Readable {
        let mut r = crate::access::Readable::of(who, &self.plant, &self.screens);
        if who.screens.iter().any(|s| s == crate::access::NETWORK) {
            if let Some(v) = &self.components.network {
                r.add_network(&v.network);
            }
        }
        r
    }

    /// Whether tag `name` is in `who`'s area for writes: one they may read,
    /// or one `[server.access.GROUP] write` grants their group. (The tag's
    /// write role is checked on its own.)
    pub fn in_write_area(&self, who: &Principal, name: &str) -> bool {
        self.readable(who).may_read(name)
            || who
                .group
                .as_deref()
                .is_some_and(|g| self.plant.server.grants_write(g, name))
    }
}

/// 404 for unknown API paths, as JSON.
pub async fn api_not_found() -> Response {
    (
        StatusCode::NOT_FOUND,
        ApiError::not_found("no such API route"),
    )
        .into_response()
}
