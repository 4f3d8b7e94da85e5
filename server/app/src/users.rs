//! Accounts from the command line: the demo's generated credentials and
//! `gridscada user add`. There are no default passwords, ever.

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

/// `gridscada user add NAME --role ROLE`: the password comes from standard
/// input when it is piped, or is generated and printed once.
pub async fn add(
    name: String,
    role: Role,
    group: Option<String>,
    target: Target,
) -> anyhow::Result<()> {
    gridscada_web::api::users::check_user_name(&name).map_err(|e| anyhow!("{}", e.detail))?;
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
    // A password piped in is used; a terminal, or nothing on stdin (e.g.
    // </dev/null in a provisioning script), gets a generated one, printed once.
    let piped = if std::io::stdin().is_terminal() {
        String::new()
    } else {
        let mut text = String::new();
        std::io::stdin()
            .read_to_string(&mut text)
            .context("reading the password from stdin")?;
        text.lines().next().unwrap_or("").to_string()
    };
    let (password, generated) = if piped.is_empty() {
        (gridscada_web::auth::generate_password(), true)
    } else {
        gridscada_web::auth::check_password_strength(&piped).map_err(|e| anyhow!(e))?;
        (piped, false)
    };
    let store = crate::data::open_store(&plant, &data).await?;
    let hash = gridscada_web::auth::hash_password(password.clone())
        .await
        .map_err(|e| anyhow!("hashing the password: {e}"))?;
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
    store
        .insert_event(&gridscada_store::NewEvent {
            ts: SystemClock.now(),
            user: None,
            source: "cli".into(),
            kind: "user".into(),
            message: format!(
                "user '{name}' created as {} from the command line",
                role.label()
            ),
        })
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
