//! Screens: the plant's screen catalog for the caller, and the screens users
//! draw in the editor (read, save with a version check, delete). Every save
//! and delete is an audited event.

use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::{Extension, Json};
use gridscada_config::screen::{self, PlantView, Screen};
use gridscada_config::Role;
use gridscada_store::StoreError;
use gridscada_tagdb::ValueKind;
use serde::Serialize;
use utoipa::ToSchema;

use crate::access::ScreenEntry;
use crate::api::audit;
use crate::auth::Principal;
use crate::error::{ApiError, ApiResult};
use crate::openapi::shapes;
use crate::WebState;

#[derive(Serialize)]
pub struct CatalogEntry {
    #[serde(flatten)]
    pub entry: ScreenEntry,
    pub allowed: bool,
}

/// The screens of this plant in toolbar order. Administrators get every
/// screen (to grant access) with `allowed`; everyone else only theirs.
#[derive(Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Catalog {
    #[schema(value_type = Vec<shapes::CatalogEntry>, inline)]
    pub screens: Vec<CatalogEntry>,
}

#[utoipa::path(get, path = "/api/screens", tag = "screens",
    summary = "The plant's screens in toolbar order (all, with access, for administrators; the caller's own otherwise)",
    responses((status = 200, description = "OK", body = inline(Catalog))))]
pub async fn catalog(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
) -> Json<Catalog> {
    let admin = who.role >= Role::Administrator;
    let screens: Vec<CatalogEntry> = s
        .catalog()
        .into_iter()
        .map(|entry| CatalogEntry {
            allowed: who.may_open(&entry.id),
            entry,
        })
        .filter(|e| admin || e.allowed)
        .collect();
    Json(Catalog { screens })
}

/// Whether `who` may edit screens (the editor's permission).
fn may_edit(who: &Principal) -> bool {
    who.role >= Role::Administrator && who.may_open("editor")
}

fn no_such(id: &str) -> ApiError {
    ApiError::not_found(format!("no screen '{}'", id.escape_debug()))
}

const SCREEN_ID: &str = "The screen's id, without custom:";

#[utoipa::path(get, path = "/api/screens/{id}", tag = "screens", summary = "A screen drawn in the editor",
    params(("id" = String, Path, description = SCREEN_ID, min_length = 1)),
    responses((status = 200, description = "OK", body = shapes::UserScreen),
        (status = 404, description = "No such thing")))]
pub async fn one(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<String>,
) -> ApiResult<Json<Screen>> {
    let screen = s.screens.get(&id).ok_or_else(|| no_such(&id))?;
    if !(may_edit(&who) || who.may_open(&screen.access_id())) {
        return Err(ApiError::forbidden(format!(
            "your group may not open the screen '{}'",
            id.escape_debug()
        )));
    }
    Ok(Json((*screen).clone()))
}

/// What screen validation sees of the running plant.
struct View<'a>(&'a WebState);

impl PlantView for View<'_> {
    fn tag(&self, name: &str) -> Option<(ValueKind, bool)> {
        let id = self.0.db.id(name)?;
        let meta = self.0.db.meta(id)?;
        Some((meta.kind, self.0.write_role(name).is_some()))
    }
    fn has_panel(&self, id: &str) -> bool {
        self.0.plant.panels.iter().any(|p| p.id.get_ref() == id)
    }
}

/// Checks a screen against the running plant; the error lists every
/// problem, each naming the element and field.
pub fn check(s: &WebState, screen: &Screen) -> Result<(), Vec<String>> {
    let errs = screen.validate(&View(s));
    if errs.is_empty() {
        Ok(())
    } else {
        Err(errs)
    }
}

#[utoipa::path(put, path = "/api/screens/{id}", tag = "screens",
    summary = "Save a screen (version = the version loaded, 0 for a new one)",
    params(("id" = String, Path, description = SCREEN_ID, min_length = 1)),
    request_body = shapes::UserScreen,
    responses((status = 200, description = "OK", body = shapes::UserScreen), (status = 400),
        (status = 409, description = "Conflict: someone else changed it first, or the change would lock administrators out"), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn save(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<String>,
    body: Result<Json<Screen>, axum::extract::rejection::JsonRejection>,
) -> ApiResult<Json<Screen>> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    let Json(screen) = body.map_err(|e| ApiError::bad_request(e.body_text()))?;
    if screen.id != id {
        return Err(ApiError::bad_request(format!(
            "id: the body names '{}' but the path '{}'",
            screen.id.escape_debug(),
            id.escape_debug()
        )));
    }
    check(&s, &screen).map_err(|errs| ApiError::bad_request(errs.join("; ")))?;
    let saved = store_screen(&s, &screen, &who.audit_name()).await?;
    audit(
        &s,
        &who,
        "config",
        "screens",
        format!(
            "{} saved screen '{}' ({}) as version {}",
            who.audit_name(),
            saved.id,
            saved.name,
            saved.version
        ),
    )
    .await;
    Ok(Json(saved))
}

/// Saves through the store (version-checked) and updates the library.
pub async fn store_screen(s: &WebState, screen: &Screen, by: &str) -> ApiResult<Screen> {
    let body =
        serde_json::to_value(screen).map_err(|e| ApiError::bad_request(format!("screen: {e}")))?;
    let rec = s
        .store
        .save_screen(
            &screen.id,
            &screen.name,
            &body,
            screen.version,
            by,
            s.clock.now(),
        )
        .await
        .map_err(|e| match e {
            StoreError::Conflict(m) => ApiError::new(StatusCode::CONFLICT, "conflict", m),
            other => other.into(),
        })?;
    let saved = Screen {
        version: rec.version,
        ..screen.clone()
    };
    s.screens.put(saved.clone());
    Ok(saved)
}

#[utoipa::path(delete, path = "/api/screens/{id}", tag = "screens",
    summary = "Delete a screen (and its access grants)",
    params(("id" = String, Path, description = SCREEN_ID, min_length = 1)),
    responses((status = 204, description = "Deleted"), (status = 404, description = "No such thing"), (status = 503, description = "Its audit record could be neither stored nor spooled")))]
pub async fn remove(
    State(s): State<WebState>,
    Extension(who): Extension<Principal>,
    Path(id): Path<String>,
) -> ApiResult<StatusCode> {
    // The change is audited through the audit trail: not unless durable.
    crate::api::audit_ready(&s).await?;
    if !screen::valid_id(&id) {
        return Err(no_such(&id));
    }
    let access_id = format!("{}{id}", screen::CUSTOM_PREFIX);
    if !s.store.delete_screen(&id, &access_id).await? {
        return Err(no_such(&id));
    }
    s.screens.remove(&id);
    audit(
        &s,
        &who,
        "config",
        "screens",
        format!("{} deleted screen '{id}'", who.audit_name()),
    )
    .await;
    Ok(StatusCode::NO_CONTENT)
}

/// Loads the screens saved in the store into the library. A stored screen
/// this version cannot read is skipped with a warning in the result.
pub async fn load_library(s: &WebState) -> Result<Vec<String>, StoreError> {
    let mut warnings = vec![];
    for rec in s.store.screens().await? {
        match serde_json::from_value::<Screen>(rec.body) {
            Ok(sc) if sc.id == rec.id => s.screens.put(Screen {
                version: rec.version,
                ..sc
            }),
            Ok(_) => warnings.push(format!(
                "stored screen '{}': its body names another id",
                rec.id
            )),
            Err(e) => warnings.push(format!("stored screen '{}': {e}", rec.id)),
        }
    }
    Ok(warnings)
}

/// Takes the screens of a plant's `screens/` folder into the store: a file
/// whose screen differs from the stored one (or is new) is saved as the next
/// version, and audited. Returns the ids taken in, or every problem, each
/// naming its file (and element and field); nothing is saved when a file
/// is wrong.
pub async fn sync_folder(s: &WebState, dir: &std::path::Path) -> Result<Vec<String>, Vec<String>> {
    let (files, mut errors) = screen::read_folder(dir);
    for (path, sc) in &files {
        if let Err(errs) = check(s, sc) {
            errors.extend(errs.into_iter().map(|e| format!("{}: {e}", path.display())));
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    let mut taken = vec![];
    for (path, sc) in files {
        let current = s.screens.get(&sc.id);
        let unchanged = current.as_ref().is_some_and(|c| {
            Screen {
                version: 0,
                ..(**c).clone()
            } == Screen {
                version: 0,
                ..sc.clone()
            }
        });
        if unchanged {
            continue;
        }
        let sc = Screen {
            version: current.map(|c| c.version).unwrap_or(0),
            ..sc
        };
        let by = format!("file {}", path.display());
        match store_screen(s, &sc, &by).await {
            Ok(saved) => {
                audit(
                    s,
                    &Principal::anonymous(),
                    "config",
                    "screens",
                    format!(
                        "screen '{}' ({}) loaded from {} as version {}",
                        saved.id,
                        saved.name,
                        path.display(),
                        saved.version
                    ),
                )
                .await;
                taken.push(saved.id);
            }
            Err(e) => return Err(vec![format!("{}: {}", path.display(), e.detail)]),
        }
    }
    Ok(taken)
}
