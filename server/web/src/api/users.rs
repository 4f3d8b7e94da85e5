//! Users and screen access (administrators), and changing one's own password.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_config::Role;
use gridscada_store::{NewUser, UserSummary};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::audit;
use crate::auth::{self, Principal};
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

type JsonBody<T> = Result<Json<T>, axum::extract::rejection::JsonRejection>;

fn body<T>(b: JsonBody<T>) -> ApiResult<T> {
    b.map(|Json(v)| v)
        .map_err(|e| ApiError::bad_request(e.body_text()))
}

/// Every user.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UserList {
    #[schema(value_type = Vec<shapes::User>)]
    pub users: Vec<UserSummary>,
}

#[utoipa::path(get, path = "/api/users", tag = "users", summary = "List users",
    responses((status = 200, description = "OK", body = inline(UserList))))]
pub async fn list(State(s): State<WebState>) -> ApiResult<Json<UserList>> {
    let users: Vec<UserSummary> = s.store.users().await?.iter().map(|u| u.summary()).collect();
    Ok(Json(UserList { users }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewUserBody {
    #[schema(min_length = 1, max_length = 64)]
    pub name: String,
    #[schema(value_type = shapes::Role)]
    pub role: Role,
    /// Defaults to the role's name.
    pub group: Option<String>,
    /// Generated and returned once when absent.
    #[schema(min_length = 10)]
    pub password: Option<String>,
}

/// A user, with the generated password when none was given.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreatedUser {
    #[schema(value_type = shapes::User)]
    pub user: UserSummary,
    /// The generated password, when none was given (shown once)
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = String, required = false)]
    pub password: Option<String>,
}

/// A user.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OneUser {
    #[schema(value_type = shapes::User)]
    pub user: UserSummary,
}

pub fn check_user_name(name: &str) -> ApiResult<()> {
    if !gridscada_config::is_account_name(name) {
        return Err(ApiError::bad_request(
            "a user name needs 1 to 64 printable characters, without spaces at either end",
        ));
    }
    Ok(())
}

/// The user named `name`, or 404.
async fn existing_user(s: &WebState, name: &str) -> ApiResult<gridscada_store::User> {
    s.store
        .user(name)
        .await?
        .ok_or_else(|| ApiError::not_found(format!("no user named '{name}'")))
}

/// Group names follow the same rule as user names.
fn check_group_name(group: &str) -> ApiResult<()> {
    check_user_name(group)
        .map_err(|_| ApiError::bad_request("a group name needs 1 to 64 printable characters"))
}

#[utoipa::path(post, path = "/api/users", tag = "users", summary = "Create a user",
    request_body = NewUserBody,
    responses((status = 201, description = "Created", body = inline(CreatedUser)),
        (status = 400), (status = 409), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn create(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    b: JsonBody<NewUserBody>,
) -> ApiResult<(StatusCode, Json<CreatedUser>)> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let b = body(b)?;
    check_user_name(&b.name)?;
    let group = b.group.unwrap_or_else(|| b.role.label().to_string());
    check_group_name(&group)?;
    let (password, generated) = match b.password {
        Some(p) => {
            auth::check_password_strength(&p).map_err(ApiError::bad_request)?;
            (p, false)
        }
        None => (auth::generate_password(), true),
    };
    let hash = s
        .auth
        .passwords
        .hash(password.clone())
        .await
        .map_err(|e| ApiError::new(StatusCode::TOO_MANY_REQUESTS, "busy", e))?;
    let user = s
        .store
        .create_user(&NewUser {
            name: b.name.clone(),
            role: b.role,
            password_hash: hash,
            group,
            created_at: s.clock.now(),
        })
        .await?;
    audit(
        &s,
        &who,
        "user",
        "users",
        format!(
            "{} created user '{}' as {}",
            who.audit_name(),
            user.name,
            user.role.label()
        ),
    )
    .await;
    let out = CreatedUser {
        user: user.summary(),
        password: generated.then_some(password),
    };
    Ok((StatusCode::CREATED, Json(out)))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UpdateBody {
    #[schema(value_type = Option<shapes::Role>)]
    pub role: Option<Role>,
    pub group: Option<String>,
    pub blocked: Option<bool>,
}

fn busy() -> ApiError {
    ApiError::new(
        StatusCode::TOO_MANY_REQUESTS,
        "busy",
        "the server is busy checking passwords; try again in a few seconds",
    )
}

/// A user as a change would leave them: role, blocked, group; `None` when
/// deleted.
type After = Option<(Role, bool, String)>;

/// Refuses a change that would leave no administrator who can log in and
/// open the users screen. `after` says what the change makes of each user;
/// `screens` overrides one group's screens (a screen-access change). The
/// caller holds `auth.admin_guard` from this check through the change.
async fn keep_a_user_manager(
    s: &WebState,
    after: impl Fn(&gridscada_store::User) -> After,
    screens: Option<(&str, &[String])>,
) -> ApiResult<()> {
    for u in s.store.users().await? {
        let Some((role, blocked, group)) = after(&u) else {
            continue;
        };
        if role != Role::Administrator || blocked {
            continue;
        }
        let manages = match screens {
            Some((g, list)) if g == group => list.iter().any(|x| x == "users"),
            _ => s
                .screens_of(&group, role)
                .await
                .iter()
                .any(|x| x == "users"),
        };
        if manages {
            return Ok(());
        }
    }
    Err(ApiError::conflict(
        "this would leave no administrator who can log in and manage users; create or enable another administrator first",
    ))
}

fn unchanged(u: &gridscada_store::User) -> After {
    Some((u.role, u.blocked, u.group.clone()))
}

#[utoipa::path(patch, path = "/api/users/{name}", tag = "users",
    summary = "Change a user's role, group or blocked state",
    params(("name" = String, Path, description = "User name", min_length = 1)),
    request_body = UpdateBody,
    responses((status = 200, description = "OK", body = inline(OneUser)),
        (status = 400), (status = 404), (status = 409), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn update(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(name): Path<String>,
    b: JsonBody<UpdateBody>,
) -> ApiResult<Json<OneUser>> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let b = body(b)?;
    existing_user(&s, &name).await?;
    // Validate everything before changing anything: no partial updates.
    if let Some(group) = &b.group {
        check_group_name(group)?;
    }
    let _guard = s.auth.admin_guard.lock().await;
    keep_a_user_manager(
        &s,
        |u| {
            if u.name != name {
                return unchanged(u);
            }
            Some((
                b.role.unwrap_or(u.role),
                b.blocked.unwrap_or(u.blocked),
                b.group.clone().unwrap_or_else(|| u.group.clone()),
            ))
        },
        None,
    )
    .await?;
    let mut changes = vec![];
    if let Some(role) = b.role {
        s.store.set_user_role(&name, role).await?;
        s.auth.sessions.forget_role_change(&name, role);
        changes.push(format!("role {}", role.label()));
    }
    if let Some(group) = &b.group {
        s.store.set_user_group(&name, group).await?;
        changes.push(format!("group {group}"));
    }
    if let Some(blocked) = b.blocked {
        s.store.set_user_blocked(&name, blocked).await?;
        if blocked {
            s.auth.sessions.forget_user(&name, None);
        }
        changes.push(if blocked {
            "blocked".into()
        } else {
            "unblocked".into()
        });
    }
    audit(
        &s,
        &who,
        "user",
        "users",
        format!(
            "{} changed user '{name}': {}",
            who.audit_name(),
            changes.join(", ")
        ),
    )
    .await;
    let user = existing_user(&s, &name).await?;
    Ok(Json(OneUser {
        user: user.summary(),
    }))
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeleteBody {
    /// Must repeat the user's name: deleting is explicit.
    pub confirm: String,
}

#[utoipa::path(delete, path = "/api/users/{name}", tag = "users",
    summary = "Delete a user (confirm by repeating the name)",
    params(("name" = String, Path, description = "User name", min_length = 1)),
    request_body = DeleteBody,
    responses((status = 204, description = "Deleted"), (status = 400), (status = 404), (status = 409), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn remove(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(name): Path<String>,
    b: JsonBody<DeleteBody>,
) -> ApiResult<StatusCode> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let b = body(b).map_err(|_| {
        ApiError::bad_request(format!(
            "deleting a user needs confirmation: send {{\"confirm\": \"{name}\"}}"
        ))
    })?;
    if b.confirm != name {
        return Err(ApiError::bad_request(format!(
            "confirmation does not match: send {{\"confirm\": \"{name}\"}}"
        )));
    }
    existing_user(&s, &name).await?;
    let _guard = s.auth.admin_guard.lock().await;
    keep_a_user_manager(
        &s,
        |u| if u.name == name { None } else { unchanged(u) },
        None,
    )
    .await?;
    s.store.delete_user(&name).await?;
    s.auth.sessions.forget_user(&name, None);
    audit(
        &s,
        &who,
        "user",
        "users",
        format!("{} deleted user '{name}'", who.audit_name()),
    )
    .await;
    Ok(StatusCode::NO_CONTENT)
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PasswordBody {
    pub password: String,
    /// Required when changing one's own password.
    pub current_password: Option<String>,
}

#[utoipa::path(post, path = "/api/users/{name}/password", tag = "users",
    summary = "Change a password (own: with current_password; others': administrators)",
    params(("name" = String, Path, description = "User name", min_length = 1)),
    request_body = PasswordBody,
    responses((status = 204, description = "Changed"), (status = 400), (status = 404), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn password(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(name): Path<String>,
    headers: axum::http::HeaderMap,
    b: JsonBody<PasswordBody>,
) -> ApiResult<StatusCode> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let b = body(b)?;
    let own = who.user.as_deref() == Some(name.as_str());
    if !own && who.role < Role::Administrator {
        return Err(ApiError::forbidden(
            "only administrators may change another user's password",
        ));
    }
    let user = existing_user(&s, &name).await?;
    if own {
        let current = b.current_password.clone().unwrap_or_default();
        let ok = s
            .auth
            .passwords
            .verify(current, user.password_hash.clone())
            .await
            .map_err(|_| busy())?;
        if !ok {
            return Err(ApiError::forbidden("the current password is wrong"));
        }
    }
    auth::check_password_strength(&b.password).map_err(ApiError::bad_request)?;
    let hash = s
        .auth
        .passwords
        .hash(b.password)
        .await
        .map_err(|e| ApiError::new(StatusCode::TOO_MANY_REQUESTS, "busy", e))?;
    // Own password: every other session of this user ends (a stolen one
    // among them); this one goes on. Another's: all of theirs end. The
    // store ends them with the change.
    let mine = own
        .then(|| {
            auth::token_from_cookies(
                headers
                    .get(axum::http::header::COOKIE)
                    .and_then(|v| v.to_str().ok()),
            )
        })
        .flatten();
    let keep = mine.as_deref().map(gridscada_store::SessionKey::of_token);
    s.store
        .set_password_hash(&name, &hash, s.clock.now(), keep.as_ref())
        .await?;
    s.auth.sessions.forget_user(&name, mine.as_deref());
    audit(
        &s,
        &who,
        "user",
        "users",
        format!("{} changed the password of '{name}'", who.audit_name()),
    )
    .await;
    Ok(StatusCode::NO_CONTENT)
}

/// The screens a group may open, and every screen it could.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GroupScreens {
    pub group: String,
    pub screens: Vec<String>,
    #[schema(value_type = Vec<shapes::Screen>)]
    pub available: Vec<String>,
}

#[utoipa::path(get, path = "/api/groups/{group}/screens", tag = "users", summary = "A group's screens",
    params(("group" = String, Path, min_length = 1)),
    responses((status = 200, description = "OK", body = inline(GroupScreens)), (status = 400)))]
pub async fn group_screens(
    State(s): State<WebState>,
    Path(group): Path<String>,
) -> ApiResult<Json<GroupScreens>> {
    let role = role_named(&group);
    let screens = s.screens_of(&group, role).await;
    let available: Vec<String> = s.catalog().into_iter().map(|e| e.id).collect();
    Ok(Json(GroupScreens {
        group,
        screens,
        available,
    }))
}

/// The role a group is named after; other groups have a guest's defaults.
fn role_named(group: &str) -> Role {
    Role::parse(group).unwrap_or(Role::Guest)
}

#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ScreensBody {
    #[schema(value_type = Vec<shapes::Screen>)]
    pub screens: Vec<String>,
}

/// The screens a group may open.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GroupScreensSet {
    pub group: String,
    #[schema(value_type = Vec<shapes::Screen>)]
    pub screens: Vec<String>,
}

#[utoipa::path(put, path = "/api/groups/{group}/screens", tag = "users", summary = "Set a group's screens",
    params(("group" = String, Path, min_length = 1)),
    request_body = ScreensBody,
    responses((status = 200, description = "OK", body = inline(GroupScreensSet)), (status = 400),
        (status = 409, description = "Conflict: the change would leave no administrator able to manage users"), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn set_group_screens(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(group): Path<String>,
    b: JsonBody<ScreensBody>,
) -> ApiResult<Json<GroupScreensSet>> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let b = body(b)?;
    check_group_name(&group)?;
    if let Some(bad) = b
        .screens
        .iter()
        .find(|x| !crate::access::screen_exists(&s.plant, &s.screens, x))
    {
        let known: Vec<String> = s.catalog().into_iter().map(|e| e.id).collect();
        return Err(ApiError::bad_request(format!(
            "unknown screen '{}'; this plant's screens are {}",
            bad.escape_debug(),
            known.join(", ")
        )));
    }
    let _guard = s.auth.admin_guard.lock().await;
    keep_a_user_manager(&s, unchanged, Some((&group, &b.screens))).await?;
    s.store.set_group_screens(&group, &b.screens).await?;
    audit(
        &s,
        &who,
        "config",
        "users",
        format!(
            "{} set the screens of group '{group}' to {}",
            who.audit_name(),
            b.screens.join(", ")
        ),
    )
    .await;
    Ok(Json(GroupScreensSet {
        group,
        screens: b.screens,
    }))
}
