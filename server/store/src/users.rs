//! Users and screen access.
//!
//! **Owns:** the `users` and `group_screens` tables; a change that ends a
//! user's sessions (block, delete, password, role) deletes them from
//! `sessions` in the same transaction. **Must not touch:**
//! password hashing and login policy (the web layer hashes; this stores the
//! hash string as given and never sees a password).

use gridscada_config::Role;
use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::error::{db, is_unique_violation};
use crate::events::check_text;
use crate::sessions::{Revoke, SessionKey};
use crate::{Result, Store, StoreError};

/// A user to create.
#[derive(Debug, Clone)]
pub struct NewUser {
    pub name: String,
    pub role: Role,
    /// A slow salted hash (e.g. argon2 PHC string), never a password.
    pub password_hash: String,
    pub group: String,
    pub created_at: Timestamp,
}

/// A stored user. Not `Serialize` on purpose: it carries the password hash.
#[derive(Debug, Clone, PartialEq)]
pub struct User {
    pub id: i64,
    pub name: String,
    pub role: Role,
    pub password_hash: String,
    pub blocked: bool,
    pub group: String,
    pub created_at: Timestamp,
    pub password_changed_at: Timestamp,
}

/// A user without the hash, for listings sent to a browser.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UserSummary {
    pub name: String,
    pub role: Role,
    pub blocked: bool,
    pub group: String,
    pub created_at: Timestamp,
    pub password_changed_at: Timestamp,
}

impl User {
    pub fn summary(&self) -> UserSummary {
        UserSummary {
            name: self.name.clone(),
            role: self.role,
            blocked: self.blocked,
            group: self.group.clone(),
            created_at: self.created_at,
            password_changed_at: self.password_changed_at,
        }
    }
}

fn role_from(s: &str) -> Result<Role> {
    Role::parse(s).ok_or_else(|| {
        StoreError::Corrupt(format!(
            "user role '{s}' is not one of display, guest, operator, supervisor, administrator"
        ))
    })
}

fn check_name(what: &str, s: &str) -> Result<()> {
    if s.trim().is_empty() || s.len() > 128 || s.chars().any(char::is_control) {
        return Err(StoreError::Invalid(format!(
            "{what} '{}' must be 1..128 printable characters",
            s.escape_debug()
        )));
    }
    Ok(())
}

type UserRow = (i64, String, String, String, bool, String, i64, i64);

fn user(r: UserRow) -> Result<User> {
    Ok(User {
        id: r.0,
        role: role_from(&r.2)?,
        name: r.1,
        password_hash: r.3,
        blocked: r.4,
        group: r.5,
        created_at: Timestamp::from_millis(r.6),
        password_changed_at: Timestamp::from_millis(r.7),
    })
}

const USER_COLS: &str =
    "id, name, role, password_hash, blocked, group_name, created_at, password_changed_at";

impl Store {
    /// Creates a user; [`StoreError::Conflict`] if the name is taken.
    pub async fn create_user(&self, u: &NewUser) -> Result<User> {
        check_name("user name", &u.name)?;
        check_name("user group", &u.group)?;
        check_text("password hash", &u.password_hash, 1024)?;
        let res: std::result::Result<UserRow, sqlx::Error> = on_backend!(self, writer, |p| {
            sqlx::query_as(&format!(
                "INSERT INTO users (name, role, password_hash, blocked, group_name, created_at, \
                   password_changed_at) VALUES ($1, $2, $3, FALSE, $4, $5, $5) \
                 RETURNING {USER_COLS}"
            ))
            .bind(&u.name)
            .bind(u.role.label())
            .bind(&u.password_hash)
            .bind(&u.group)
            .bind(u.created_at.as_millis())
            .fetch_one(p)
            .await
        });
        match res {
            Ok(r) => user(r),
            Err(e) if is_unique_violation(&e) => {
                Err(StoreError::Conflict(format!("user '{}'", u.name)))
            }
            Err(e) => Err(db("creating a user")(e)),
        }
    }

    /// The user of that name, if any.
    pub async fn user(&self, name: &str) -> Result<Option<User>> {
        let row: Option<UserRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!("SELECT {USER_COLS} FROM users WHERE name = $1"))
                .bind(name)
                .fetch_optional(p)
                .await
                .map_err(db("reading a user"))?
        });
        row.map(user).transpose()
    }

    /// Every user, by name.
    pub async fn users(&self) -> Result<Vec<User>> {
        let rows: Vec<UserRow> = on_backend!(self, reader, |p| {
            sqlx::query_as(&format!("SELECT {USER_COLS} FROM users ORDER BY name"))
                .fetch_all(p)
                .await
                .map_err(db("listing users"))?
        });
        rows.into_iter().map(user).collect()
    }

    /// Runs one `UPDATE users ... WHERE name = $1` and ends the sessions
    /// `revoke` names, in one transaction.
    async fn update_user(
        &self,
        name: &str,
        sql: &str,
        bind: UserUpdate<'_>,
        revoke: Revoke<'_>,
    ) -> Result<()> {
        let n = on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("changing a user"))?;
            let q = sqlx::query(sql).bind(name);
            let q = match bind {
                UserUpdate::Text(s) => q.bind(s),
                UserUpdate::Flag(b) => q.bind(b),
                UserUpdate::Hash(h, at) => q.bind(h).bind(at),
            };
            let n = q
                .execute(&mut *tx)
                .await
                .map_err(db("changing a user"))?
                .rows_affected();
            if n > 0 {
                let ended: std::result::Result<u64, sqlx::Error> =
                    revoke_on!(&mut *tx, name, revoke);
                ended.map_err(db("ending a user's sessions"))?;
                tx.commit().await.map_err(db("changing a user"))?;
            }
            n
        });
        if n == 0 {
            return Err(StoreError::NotFound(format!("user '{name}'")));
        }
        Ok(())
    }

    /// Replaces a user's password hash and stamps the change. Every session
    /// of the user ends with it but `keep` (the one that changed its own
    /// password).
    pub async fn set_password_hash(
        &self,
        name: &str,
        hash: &str,
        at: Timestamp,
        keep: Option<&SessionKey>,
    ) -> Result<()> {
        check_text("password hash", hash, 1024)?;
        self.update_user(
            name,
            "UPDATE users SET password_hash = $2, password_changed_at = $3 WHERE name = $1",
            UserUpdate::Hash(hash, at.as_millis()),
            Revoke::AllBut(keep),
        )
        .await
    }

    /// Blocks (a blocked user cannot log in, and their sessions end) or
    /// unblocks a user.
    pub async fn set_user_blocked(&self, name: &str, blocked: bool) -> Result<()> {
        self.update_user(
            name,
            "UPDATE users SET blocked = $2 WHERE name = $1",
            UserUpdate::Flag(blocked),
            if blocked { Revoke::All } else { Revoke::None },
        )
        .await
    }

    /// Changes a user's role; the sessions started under another role end.
    pub async fn set_user_role(&self, name: &str, role: Role) -> Result<()> {
        self.update_user(
            name,
            "UPDATE users SET role = $2 WHERE name = $1",
            UserUpdate::Text(role.label()),
            Revoke::RoleNot(role),
        )
        .await
    }

    pub async fn set_user_group(&self, name: &str, group: &str) -> Result<()> {
        check_name("user group", group)?;
        self.update_user(
            name,
            "UPDATE users SET group_name = $2 WHERE name = $1",
            UserUpdate::Text(group),
            Revoke::None,
        )
        .await
    }

    /// Deletes a user and their sessions; returns whether it existed.
    pub async fn delete_user(&self, name: &str) -> Result<bool> {
        Ok(on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("deleting a user"))?;
            let ended: std::result::Result<u64, sqlx::Error> =
                revoke_on!(&mut *tx, name, Revoke::All);
            ended.map_err(db("ending a user's sessions"))?;
            let n = sqlx::query("DELETE FROM users WHERE name = $1")
                .bind(name)
                .execute(&mut *tx)
                .await
                .map_err(db("deleting a user"))?
                .rows_affected();
            tx.commit().await.map_err(db("deleting a user"))?;
            n > 0
        }))
    }

    /// Replaces the screens a user group may see.
    pub async fn set_group_screens(&self, group: &str, screens: &[String]) -> Result<()> {
        check_name("user group", group)?;
        for s in screens {
            check_name("screen", s)?;
        }
        on_backend!(self, writer, |p| {
            let mut tx = p.begin().await.map_err(db("saving screen access"))?;
            sqlx::query("DELETE FROM group_screens WHERE group_name = $1")
                .bind(group)
                .execute(&mut *tx)
                .await
                .map_err(db("saving screen access"))?;
            for s in screens {
                sqlx::query(
                    "INSERT INTO group_screens (group_name, screen) VALUES ($1, $2) \
                     ON CONFLICT DO NOTHING",
                )
                .bind(group)
                .bind(s)
                .execute(&mut *tx)
                .await
                .map_err(db("saving screen access"))?;
            }
            tx.commit().await.map_err(db("saving screen access"))?;
        });
        Ok(())
    }

    /// The screens a user group may see, sorted.
    pub async fn group_screens(&self, group: &str) -> Result<Vec<String>> {
        Ok(on_backend!(self, reader, |p| {
            sqlx::query_scalar(
                "SELECT screen FROM group_screens WHERE group_name = $1 ORDER BY screen",
            )
            .bind(group)
            .fetch_all(p)
            .await
            .map_err(db("reading screen access"))?
        }))
    }

    /// Every group and its screens, by group name.
    pub async fn all_group_screens(&self) -> Result<Vec<(String, Vec<String>)>> {
        let rows: Vec<(String, String)> = on_backend!(self, reader, |p| {
            sqlx::query_as(
                "SELECT group_name, screen FROM group_screens ORDER BY group_name, screen",
            )
            .fetch_all(p)
            .await
            .map_err(db("reading screen access"))?
        });
        let mut out: Vec<(String, Vec<String>)> = Vec::new();
        for (g, s) in rows {
            match out.last_mut() {
                Some((lg, list)) if *lg == g => list.push(s),
                _ => out.push((g, vec![s])),
            }
        }
        Ok(out)
    }
}

enum UserUpdate<'a> {
    Text(&'a str),
    Flag(bool),
    Hash(&'a str, i64),
}
