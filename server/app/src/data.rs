//! The data folder: where the database and local state live, private to
//! the server's user. Shared by the server (`runtime`), the user commands
//! (`users`) and replay.

use std::path::Path;

use anyhow::Context;
use gridscada_config::Plant;
use gridscada_store::{OpenOptions, Store};

/// Opens (and migrates) the plant's store, as the plant's site. A relative
/// SQLite path lives in the data folder.
pub async fn open_store(plant: &Plant, data: &Path) -> anyhow::Result<Store> {
    std::fs::create_dir_all(data)
        .with_context(|| format!("cannot create the data folder {}", data.display()))?;
    // The folder holds the database (password hashes, audit log) and the
    // demo's credentials: its owner's only, whatever the umask.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(data, std::fs::Permissions::from_mode(0o700))
            .with_context(|| format!("cannot restrict the data folder {}", data.display()))?;
    }
    let url = plant.storage.url.get_ref();
    // Every row this server writes names its site (`[server] site`).
    let options = OpenOptions {
        site: plant.server.site().to_string(),
        ..OpenOptions::new(data)
    };
    let store = Store::open(url, &options).await.map_err(|e| {
        let why = e.to_string();
        let hint = if why.contains("invalid peer certificate") {
            "; the database server's TLS certificate was refused: with sslmode=verify-ca or \
                 verify-full it must be signed by the sslrootcert= certificate (or a public CA), \
                 and with verify-full name the URL's host"
        } else {
            ""
        };
        anyhow::Error::new(e).context(format!("opening the database {url}{hint}"))
    })?;
    store.migrate().await.context("migrating the database")?;
    Ok(store)
}
