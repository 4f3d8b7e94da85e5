//! Accounts from the command line: the demo's generated credentials and
//! `gridscada user add|list|password|block|unblock|role|delete`, for the
//! administrator of an installed server (e.g. the first account, or a lost
//! administrator password). There are no default passwords, ever. Each change
//! is an event, and the store ends the sessions it must in the same
//! transaction; a running server notices within its session re-check.

use std::io::{IsTerminal, Read};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use gridscada_config::Role;
use gridscada_store::{NewUser, Store};
use gridscada_tagdb::{Clock, SystemClock};

pub struct Credentials {
    pub file: PathBuf,
    pub accounts: Vec<(&'static str, &'static str, String)>,
}

/// Gives the demo's three accounts fresh random passwords (creating them on
/// first run) and writes them to DATA/credentials.txt, readable by the owner
/// only, one line per user: `ROLE USERNAME PASSWORD`.
pub async fn demo_credentials(
    store: &Store,
    data: &Path,
    clock: &dyn Clock,
) -> anyhow::Result<Credentials> {
    let accounts = [
        ("administrator", "admin", Role::Administrator),
        ("supervisor", "supervisor", Role::Supervisor),
        ("operator", "operator", Role::Operator),
    ];
    let mut out = Vec::new();
    for (label, name, role) in accounts {
        let password = gridscada_web::auth::generate_password();
        let hash = gridscada_web::auth::hash_password(password.clone())
            .await
            .map_err(|e| anyhow!("hashing a password: {e}"))?;
        match store.user(name).await? {
            Some(_) => {
                // The new password ends the account's sessions.
                store
                    .set_password_hash(name, &hash, clock.now(), None)
                    .await?;
                store.set_user_blocked(name, false).await?;
                store.set_user_role(name, role).await?;
            }
            None => {
                store
                    .create_user(&NewUser {
                        name: name.to_string(),
                        role,
                        password_hash: hash,
                        group: role.label().to_string(),
                        created_at: clock.now(),
                    })
                    .await?;
            }
        }
        out.push((label, name, password));
    }
    let file = data.join("credentials.txt");
    let text: String = out
        .iter()
        .map(|(role, user, pw)| format!("{role} {user} {pw}\n"))
        .collect();
    write_private(&file, &text).with_context(|| format!("writing {}", file.display()))?;
    Ok(Credentials {
        file,
        accounts: out,
    })
}

/// `serve` with no administrator says how to create one.
pub async fn warn_if_no_administrator(store: &Store, config: &Path) -> anyhow::Result<()> {
    let admins = store
        .users()
        .await?
        .into_iter()
        .filter(|u| u.role == Role::Administrator && !u.blocked)
        .count();
    if admins == 0 {
        println!(
            "No administrator can log in yet. Create one with:\n  gridscada user add NAME --role administrator --config {}",
            config.display()
        );
    }
    Ok(())
}

/// Writes a file that only its owner may read (mode 0600).
fn write_private(path: &Path, text: &str) -> std::io::Result<()> {
    use std::io::Write;
    #[cfg(unix)]
    use std::os::unix::fs::OpenOptionsExt;
    let _ = std::fs::remove_file(path);
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true).create_new(true);
    #[cfg(unix)]
    opts.mode(0o600);
    let mut f = opts.open(path)?;
    f.write_all(text.as_bytes())
}

/// Where `user add` finds the user table.
pub enum Target {
    /// A plant configuration: its storage URL and data folder.
    Config(PathBuf),
    /// The demo's data folder.
    DemoData(PathBuf),
}

/// Opens the user table that `serve` (or the demo) uses.
async fn open(target: Target) -> anyhow::Result<Store> {
    Ok(open_with_plant(target).await?.0)
}

/// Opens the store of `target`, with its plant and data folder.
pub async fn open_with_plant(
    target: Target,
) -> anyhow::Result<(Store, gridscada_config::Plant, std::path::PathBuf)> {
    let (plant, data) = match target {
        Target::Config(path) => {
            // The same database `serve` opens: the same files and environment.
            let plant = crate::settings::load_for_server(&path)?;
            let data = plant.data_dir.clone();
            (plant, data)
        }
        Target::DemoData(data) => {
            let plant = crate::demo_plant::load()
                .map_err(|_| anyhow!("the embedded demo plant is invalid"))?;
            (plant, data)
        }
    };
    let store = crate::data::open_store(&plant, &data).await?;
    Ok((store, plant, data))
}

/// A password piped in on standard input (checked for strength), or, from a
/// terminal or with nothing on stdin (e.g. `</dev/null` in a provisioning
/// script), a generated one; `true` when generated, to be printed once.
fn read_or_generate_password() -> anyhow::Result<(String, bool)> {
    let piped = if std::io::stdin().is_terminal() {
        String::new()
    } else {
        let mut text = String::new();
        std::io::stdin()
            .read_to_string(&mut text)
            .context("reading the password from stdin")?;
        text.lines().next().unwrap_or("").to_string()
    };
    if piped.is_empty() {
        Ok((gridscada_web::auth::generate_password(), true))
    } else {
        gridscada_web::auth::check_password_strength(&piped).map_err(|e| anyhow!(e))?;
        Ok((piped, false))
    }
}

async fn hash(password: &str) -> anyhow::Result<String> {
    gridscada_web::auth::hash_password(password.to_string())
        .await
        .map_err(|e| anyhow!("hashing the password: {e}"))
}

/// Records what the command line did in the event log.
async fn log_event(store: &Store, message: String) -> anyhow::Result<()> {
    store
        .insert_event(&gridscada_store::NewEvent {
            ts: SystemClock.now(),
            user: None,
            source: "cli".into(),
            kind: "user".into(),
            message,
        })
        .await?;
    Ok(())
}

/// `gridscada user add NAME --role ROLE`: the password comes from standard
/// input when it is piped, or is generated and printed once.
pub async fn add(
    name: String,
    role: Role,
    group: Option<String>,
    target: Target,
) -> anyhow::Result<()> {
    gridscada_web::api::users::check_user_name(&name).map_err(|e| anyhow!("{}", e.detail))?;
    let (password, generated) = read_or_generate_password()?;
    let store = open(target).await?;
    let hash = hash(&password).await?;
    store
        .create_user(&NewUser {
            name: name.clone(),
            role,
            password_hash: hash,
            group: group.unwrap_or_else(|| role.label().to_string()),
            created_at: SystemClock.now(),
        })
        .await
        .with_context(|| format!("creating user '{name}'"))?;
    log_event(
        &store,
        format!(
            "user '{name}' created as {} from the command line",
            role.label()
        ),
    )
    .await?;
    store.close().await;
    if generated {
        println!(
            "Created user '{name}' ({}). Password (shown once): {password}",
            role.label()
        );
    } else {
        println!("Created user '{name}' ({}).", role.label());
    }
    Ok(())
}

/// `gridscada user list`: name, role, group, and whether blocked.
pub async fn list(target: Target) -> anyhow::Result<()> {
    let store = open(target).await?;
    let users = store.users().await?;
    store.close().await;
    if users.is_empty() {
        println!("No users.");
    }
    for u in users {
        println!(
            "{:<24} {:<14} group {:<16}{}",
            u.name,
            u.role.label(),
            u.group,
            if u.blocked { " BLOCKED" } else { "" }
        );
    }
    Ok(())
}

/// What `gridscada user password|block|unblock|role|delete` changes.
pub enum Change {
    /// A new password (piped in, or generated and printed once).
    Password,
    Blocked(bool),
    Role(Role),
    Delete,
}

/// Changes an existing user. Every change but unblocking ends the sessions
/// it must (all of them; for a role change, those of the old role).
pub async fn change(name: String, change: Change, target: Target) -> anyhow::Result<()> {
    let new_password = match change {
        Change::Password => Some(read_or_generate_password()?),
        _ => None,
    };
    let store = open(target).await?;
    let result = apply(&store, &name, change, new_password).await;
    store.close().await;
    println!("{}", result?);
    Ok(())
}

async fn apply(
    store: &Store,
    name: &str,
    change: Change,
    new_password: Option<(String, bool)>,
) -> anyhow::Result<String> {
    if store.user(name).await?.is_none() {
        anyhow::bail!("there is no user '{name}' (see `gridscada user list`)");
    }
    let (event, said) = match change {
        Change::Password => {
            let (password, generated) = new_password.expect("read before opening the store");
            store
                .set_password_hash(name, &hash(&password).await?, SystemClock.now(), None)
                .await?;
            let said = if generated {
                format!("New password for '{name}' (shown once): {password}")
            } else {
                format!("Password of '{name}' changed.")
            };
            (
                format!("password of user '{name}' changed from the command line"),
                said,
            )
        }
        Change::Blocked(true) => {
            store.set_user_blocked(name, true).await?;
            (
                format!("user '{name}' blocked from the command line"),
                format!("Blocked '{name}'; their sessions have ended."),
            )
        }
        Change::Blocked(false) => {
            store.set_user_blocked(name, false).await?;
            (
                format!("user '{name}' unblocked from the command line"),
                format!("Unblocked '{name}'."),
            )
        }
        Change::Role(role) => {
            store.set_user_role(name, role).await?;
            (
                format!(
                    "role of user '{name}' set to {} from the command line",
                    role.label()
                ),
                format!("'{name}' is now {}.", role.label()),
            )
        }
        Change::Delete => {
            store.delete_user(name).await?;
            (
                format!("user '{name}' deleted from the command line"),
                format!("Deleted '{name}'."),
            )
        }
    };
    log_event(store, event).await?;
    Ok(said)
}
