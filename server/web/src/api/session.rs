//! Log in, log out, and who am I.

use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Json};
use gridscada_config::Role;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::audit;
use crate::auth::{self, Principal};
use crate::command::{check_login, LoginRefused};
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Login {
    pub username: String,
    pub password: String,
}

/// The same answer for an unknown user, a wrong password and a blocked user,
/// so that a failed login does not reveal which names exist.
fn refused() -> ApiError {
    ApiError::new(
        StatusCode::UNAUTHORIZED,
        "invalid_credentials",
        "invalid username or password",
    )
}

#[utoipa::path(post, path = "/api/session", tag = "session",
    summary = "Log in (rotates the session cookie)",
    request_body = Login,
    responses(
        (status = 200, description = "Logged in; sets the session cookie", body = SessionView,
            headers(("Set-Cookie" = String))),
        (status = 400),
        (status = 401, description = "Invalid username or password (the same answer whatever was wrong)"),
        (status = 403),
        (status = 429, description = "Too many failed logins"),
    ))]
pub async fn login(
    State(s): State<WebState>,
    Extension(client): Extension<crate::ClientInfo>,
    headers: HeaderMap,
    body: Result<Json<Login>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Response> {
    let Json(login) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    // The real client, behind a trusted proxy too (crate::proxy).
    let ip = client.ip;
    let name = login.username.trim().to_string();
    let user = check_login(&s, &name, login.password, ip, "web")
        .await
        .map_err(|e| match e {
            LoginRefused::Invalid => refused(),
            LoginRefused::Throttled(wait) => ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "throttled",
                format!(
                    "too many failed logins; try again in {} s",
                    wait.as_secs().max(1)
                ),
            ),
            LoginRefused::Busy => ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "busy",
                "the server is busy checking other logins; try again in a few seconds",
            ),
            LoginRefused::Store(e) => e.into(),
        })?;
    let previous =
        auth::token_from_cookies(headers.get(header::COOKIE).and_then(|v| v.to_str().ok()));
    // Stored before the cookie is sent, so the session outlives a restart.
    let recorded = recorded_client(ip, &headers);
    let token = s
        .auth
        .sessions
        .create(&user.name, user.role, previous.as_deref(), recorded)
        .await?;
    let screens = s.screens_of(&user.group, user.role).await;
    let who = Principal {
        user: Some(user.name.clone()),
        role: user.role,
        group: Some(user.group.clone()),
        screens,
    };
    // What the store says of the user now, for a database outage (Auth::last_known).
    s.auth
        .last_known
        .lock()
        .insert(user.name.clone(), who.clone());
    audit(
        &s,
        &who,
        "login",
        "web",
        format!("{} logged in from {ip}", user.name),
    )
    .await;
    let body = session_body(&s, &who);
    Ok((
        [(
            header::SET_COOKIE,
            auth::session_cookie(
                &token,
                s.auth.secure_cookies || client.https,
                &s.plant.server.base_path(),
            ),
        )],
        Json(body),
    )
        .into_response())
}

/// Who the caller is, and when the session idles out.
#[derive(Serialize, ToSchema)]
#[schema(as = Session)]
#[serde(deny_unknown_fields)]
pub struct SessionView {
    pub authenticated: bool,
    #[schema(required = true)]
    pub user: Option<String>,
    #[schema(value_type = shapes::Role)]
    pub role: Role,
    #[schema(required = true)]
    pub group: Option<String>,
    pub screens: Vec<String>,
    /// Seconds without activity before the session ends (the live
    /// connection counts while its screen is visible); null: never, or not
    /// logged in.
    #[schema(required = true)]
    pub idle_timeout_s: Option<u64>,
    /// How long before an idle expiry the HMI warns, in seconds.
    pub warn_s: u64,
    /// Whether this server is one of a redundant pair: only then does
    /// `/api/pair` describe it (a server alone answers that 404).
    pub pair: bool,
    /// How the HMI shows numbers and dates (`[hmi]`).
    pub hmi: HmiSettings,
}

/// The plant's display settings, read by the HMI before it shows a screen.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct HmiSettings {
    /// Decimals of an analog value whose tag sets none
    #[schema(minimum = 0, maximum = 6)]
    pub decimals: u8,
    /// The order of a date's parts; times are 24-hour
    #[schema(value_type = shapes::DateFormat, inline)]
    pub date_format: &'static str,
}

fn session_body(s: &WebState, p: &Principal) -> SessionView {
    let policy = s.auth.sessions.policy();
    SessionView {
        authenticated: p.is_logged_in(),
        user: p.user.clone(),
        role: p.role,
        group: p.group.clone(),
        screens: p.screens.clone(),
        idle_timeout_s: p
            .is_logged_in()
            .then(|| policy.expiry(p.role).idle.map(|d| d.as_secs()))
            .flatten(),
        warn_s: policy.warn.as_secs(),
        pair: s.components.pair.is_some(),
        hmi: HmiSettings {
            decimals: s.plant.hmi.decimals(),
            date_format: s.plant.hmi.date_format.get_ref().pattern(),
        },
    }
}

#[utoipa::path(get, path = "/api/session", tag = "session", summary = "Who am I",
    responses((status = 200, description = "OK", body = SessionView)))]
pub async fn current(
    State(s): State<WebState>,
    Extension(p): Extension<Principal>,
) -> Json<SessionView> {
    Json(session_body(&s, &p))
}

#[utoipa::path(delete, path = "/api/session", tag = "session", summary = "Log out",
    responses(
        (status = 204, description = "Logged out; the cookie is cleared",
            headers(("Set-Cookie" = String))),
        (status = 403),
    ))]
pub async fn logout(
    State(s): State<WebState>,
    Extension(p): Extension<Principal>,
    Extension(client): Extension<crate::ClientInfo>,
    headers: HeaderMap,
) -> Response {
    if let Some(token) =
        auth::token_from_cookies(headers.get(header::COOKIE).and_then(|v| v.to_str().ok()))
    {
        s.auth.sessions.end(&token).await;
    }
    if p.is_logged_in() {
        audit(
            &s,
            &p,
            "logout",
            "web",
            format!("{} logged out", p.audit_name()),
        )
        .await;
    }
    (
        StatusCode::NO_CONTENT,
        [(
            header::SET_COOKIE,
            auth::clear_cookie(
                s.auth.secure_cookies || client.https,
                &s.plant.server.base_path(),
            ),
        )],
    )
        .into_response()
}

/// An earlier ticket to end with this one.
#[derive(Deserialize, Default, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TicketRequest {
    pub previous: Option<String>,
}

/// A failover ticket (see [`auth::Sessions::create_ticket`]).
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Ticket {
    pub ticket: String,
    /// Seconds it may be claimed in, at most (never after the session's
    /// own absolute end).
    pub expires_s: u64,
}

/// The HMI of a redundant pair keeps a ticket so that, when it moves to the
/// other server (another host, which the session cookie is not sent to),
/// the operator stays logged in.
#[utoipa::path(post, path = "/api/session/handover", tag = "session",
    summary = "A ticket that carries this login to another server of the pair",
    request_body = TicketRequest,
    responses((status = 200, description = "OK", body = Ticket), (status = 400), (status = 401)))]
pub async fn handover(
    State(s): State<WebState>,
    Extension(p): Extension<Principal>,
    headers: HeaderMap,
    body: Result<Json<TicketRequest>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<Ticket>> {
    let Json(request) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let token = auth::token_from_cookies(headers.get(header::COOKIE).and_then(|v| v.to_str().ok()));
    // Issued from the caller's own session; an earlier ticket is ended only
    // if that session issued it.
    let ticket = match (p.is_logged_in(), token) {
        (true, Some(token)) => {
            s.auth
                .sessions
                .create_ticket(&token, request.previous.as_deref())
                .await?
        }
        _ => None,
    };
    let Some((ticket, expires_at)) = ticket else {
        return Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "unauthenticated",
            "log in first",
        ));
    };
    let left_ms = expires_at.as_millis() - gridscada_tagdb::Timestamp::now_utc().as_millis();
    Ok(Json(Ticket {
        ticket,
        expires_s: u64::try_from(left_ms / 1000).unwrap_or(0),
    }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Claim {
    pub ticket: String,
}

/// Ends the ticket and starts an ordinary session of its user here: the
/// HMI's first call on the server it moved to in a failover.
#[utoipa::path(post, path = "/api/session/handover/claim", tag = "session",
    summary = "Log in with a failover ticket from another server of the pair",
    request_body = Claim,
    responses(
        (status = 204, description = "Logged in; sets the session cookie",
            headers(("Set-Cookie" = String))),
        (status = 400),
        (status = 401, description = "No such ticket, or it has expired or was used, or the session that issued it ended"),
    ))]
pub async fn claim(
    State(s): State<WebState>,
    Extension(client): Extension<crate::ClientInfo>,
    headers: HeaderMap,
    body: Result<Json<Claim>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Response> {
    let Json(claim) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    let recorded = recorded_client(client.ip, &headers);
    // Good once; the new session ends when the one that issued the ticket
    // would have.
    let Some((token, user)) = s
        .auth
        .sessions
        .claim_ticket(&claim.ticket, recorded)
        .await?
    else {
        return Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "invalid_ticket",
            "the failover ticket is unknown, expired, already used or its session ended: log in",
        ));
    };
    let who = Principal {
        user: Some(user.user.clone()),
        role: user.role,
        group: None,
        screens: Vec::new(),
    };
    audit(
        &s,
        &who,
        "login",
        "web",
        format!(
            "{} logged in from {} with a failover ticket of another server of the pair",
            user.user, client.ip
        ),
    )
    .await;
    Ok((
        StatusCode::NO_CONTENT,
        [(
            header::SET_COOKIE,
            auth::session_cookie(
                &token,
                s.auth.secure_cookies || client.https,
                &s.plant.server.base_path(),
            ),
        )],
    )
        .into_response())
}

/// What a new session records of its client: the address and the browser.
fn recorded_client(ip: std::net::IpAddr, headers: &HeaderMap) -> auth::Client {
    auth::Client {
        address: Some(ip.to_string()),
        user_agent: headers
            .get(header::USER_AGENT)
            .and_then(|v| v.to_str().ok())
            .map(str::to_string),
    }
}
