//! The operator's two gates that do not depend on HTTP: a confirmed tag
//! write (role and area checks, audit record durable before the device is
//! asked, the device's read-back, the outcome on record) and the credential check of a
//! login (throttling, Argon2, a failed attempt audited). The HTTP API and
//! every other northbound door (OPC UA) go through these, so a command is
//! checked and recorded the same way whichever door it came in by.

use std::net::IpAddr;
use std::time::Duration;

use gridscada_store::command::CommandError;
use gridscada_store::{StoreError, User};
use gridscada_tagdb::{Sample, Value, WriteError};

use crate::api::audit;
use crate::auth::Principal;
use crate::WebState;

/// Why a write did not reach the device, or what the device said.
#[derive(Debug)]
pub enum WriteRefused {
    UnknownTag(String),
    /// The tag is read-only, the caller's role is below the tag's write
    /// role, or the tag is outside the caller's area. The refusal is on
    /// record (`write_refused`).
    Forbidden(String),
    /// The value does not fit the tag's kind (on record as refused too).
    BadValue(String),
    /// No field I/O runs (`check`-like stacks).
    NoFieldIo,
    /// Its audit record could be neither stored nor spooled, so the command
    /// did not go out.
    Unaudited(String),
    /// The device refused it, timed out, or read back something else.
    Failed(WriteError),
}

/// Writes `value` to tag `name` for `who`, and answers with the confirmed
/// sample once the device's read-back agrees. `door` names where the command
/// came in for the audit message ("" for the HMI, "OPC UA").
pub async fn write_tag(
    s: &WebState,
    who: &Principal,
    name: &str,
    value: Value,
    door: &str,
) -> Result<Sample, WriteRefused> {
    let via = if door.is_empty() {
        String::new()
    } else {
        format!(" via {door}")
    };
    let id =
        s.db.id(name)
            .ok_or_else(|| WriteRefused::UnknownTag(format!("no tag named '{name}'")))?;
    let meta =
        s.db.meta(id)
            .cloned()
            .ok_or_else(|| WriteRefused::UnknownTag(format!("no tag named '{name}'")))?;
    let commander = gridscada_store::command::Commander {
        user: who.user.clone(),
        label: format!("{}{via}", who.audit_name()),
    };
    // A refusal is audited too, in the words of every door's refusals: who
    // tried to command what, and why not.
    let refuse = |why: String| async {
        let record = gridscada_store::command::refused_event(s.clock.now(), &commander, name, &why);
        audit(s, who, &record.kind, name, record.message).await;
        why
    };
    let Some(required) = s.write_role(name) else {
        return Err(WriteRefused::Forbidden(
            refuse(format!("tag '{name}' is read-only")).await,
        ));
    };
    if who.role < required {
        return Err(WriteRefused::Forbidden(
            refuse(format!(
                "writing '{name}' needs the {} role or above; you are {}",
                required.label(),
                who.role.label()
            ))
            .await,
        ));
    }
    // Areas of responsibility: a user writes what their screens show, and
    // what the configuration grants their group besides (docs/ACCESS.md).
    if !s.in_write_area(who, name) {
        let group = who.group.as_deref().unwrap_or_default();
        return Err(WriteRefused::Forbidden(
            refuse(format!(
                "'{name}' is outside your area: no screen of group '{group}' shows it, \
                 and [server.access.{group}] write does not name it"
            ))
            .await,
        ));
    }
    let Some(value) = value.coerce(meta.kind) else {
        return Err(WriteRefused::BadValue(
            refuse(format!(
                "{value} is not a valid {:?} value for '{name}'",
                meta.kind
            ))
            .await,
        ));
    };
    let writer = s.writer.clone().ok_or(WriteRefused::NoFieldIo)?;
    let old =
        s.db.get(id)
            .map(|o| o.value.to_string())
            .unwrap_or_default();
    // The request is on record before it goes to the device, and its outcome
    // after: the one audited write of every door (a Sparkplug DCMD too).
    gridscada_store::command::audited_write(
        &crate::api::WebAudit(s),
        writer.as_ref(),
        || s.clock.now(),
        &commander,
        name,
        &old,
        value,
    )
    .await
    .map_err(|e| match e {
        CommandError::Unaudited(why) => WriteRefused::Unaudited(why),
        CommandError::Write(e) => WriteRefused::Failed(e),
    })
}

/// Why a login was refused. `Invalid` is the one answer for an unknown user,
/// a wrong password and a blocked user, so that a refusal does not reveal
/// which names exist.
#[derive(Debug)]
pub enum LoginRefused {
    Invalid,
    /// Too many failed attempts: try again after this long.
    Throttled(Duration),
    /// The password pool is full.
    Busy,
    Store(StoreError),
}

/// Checks `name` and `password` against the store's users, as the web login
/// does: throttled per user and address before the (Argon2) check, a decoy
/// hash for unknown names, and a failed attempt on record (`login_failed`,
/// from `door`, e.g. "web" or "opcua"). Answers the user on success; the
/// caller records the login itself once it has done what a login means to it.
pub async fn check_login(
    s: &WebState,
    name: &str,
    password: String,
    ip: IpAddr,
    door: &str,
) -> Result<User, LoginRefused> {
    let name = name.trim();
    if name.is_empty()
        || name.len() > 128
        || name.chars().any(char::is_control)
        || password.len() > 1024
    {
        return Err(LoginRefused::Invalid);
    }
    // Counted before the password is checked, so a burst cannot get past
    // the limit (auth::Throttle).
    let attempt = s
        .auth
        .throttle
        .reserve(name, ip)
        .map_err(LoginRefused::Throttled)?;
    let user = match s.store.user(name).await {
        Ok(u) => u,
        Err(e) => {
            s.auth.throttle.cancel(attempt);
            return Err(LoginRefused::Store(e));
        }
    };
    let hash = user
        .as_ref()
        .map(|u| u.password_hash.clone())
        .unwrap_or_else(|| s.auth.decoy_hash.to_string());
    let Ok(password_ok) = s.auth.passwords.verify(password, hash).await else {
        s.auth.throttle.cancel(attempt);
        return Err(LoginRefused::Busy);
    };
    match user {
        Some(u) if password_ok && !u.blocked => {
            s.auth.throttle.success(attempt);
            Ok(u)
        }
        other => {
            // The reserved attempt stays counted as a failure.
            drop(attempt);
            let why = match other {
                Some(u) if u.blocked && password_ok => "user is blocked",
                Some(_) => "wrong password",
                None => "unknown user",
            };
            // A door that cannot tell the peer's address passes an
            // unspecified one.
            let from = if ip.is_unspecified() {
                format!("via {door}")
            } else {
                format!("from {ip}")
            };
            audit(
                s,
                &Principal::anonymous(),
                "login_failed",
                door,
                format!("failed login as '{name}' {from}: {why}"),
            )
            .await;
            Err(LoginRefused::Invalid)
        }
    }
}
