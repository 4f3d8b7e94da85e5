//! Opening the database: the storage URL, the two backends, migrations, and the
//! historian's tag-name cache.
//!
//! **Owns:** connection pools and their settings (WAL, synchronous, busy
//! timeout, search_path). **Must not touch:** table contents; queries live in the
//! module of each table family.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::postgres::{PgConnectOptions, PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};
use sqlx::QueryBuilder;

use crate::error::db;
use crate::{Result, StoreError};

/// Which engine a [`Store`] runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    Sqlite,
    Postgres,
}

/// SQLite's `synchronous` setting (WAL mode). See the crate docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SqliteSync {
    /// Durable across process crashes; the last commits may be lost on power
    /// loss (never corrupted). The default.
    #[default]
    Normal,
    /// Every commit is fsynced: durable across power loss, slower commits.
    Full,
}

/// How to open a store.
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// Folder that relative `sqlite://` paths are resolved in.
    pub data_dir: PathBuf,
    /// SQLite durability; ignored for PostgreSQL.
    pub sqlite_sync: SqliteSync,
    /// Connections of the SQLite read pool, or of the PostgreSQL pool.
    pub max_connections: u32,
    /// PostgreSQL only: work in this schema (created if missing) instead of
    /// `public`, e.g. several sites in one database, or one schema per test.
    /// Lowercase letters, digits and `_` only.
    pub pg_schema: Option<String>,
    /// How long to wait for a connection or a lock before failing a call.
    pub acquire_timeout: Duration,
    /// The site this server writes as (`[server] site`): every row of a
    /// plant's history names it, so several sites can share one database.
    pub site: String,
}

/// The site of a store opened without one (the configuration's default).
pub const DEFAULT_SITE: &str = "main";

impl OpenOptions {
    pub fn new(data_dir: impl Into<PathBuf>) -> Self {
        OpenOptions {
            data_dir: data_dir.into(),
            sqlite_sync: SqliteSync::Normal,
            max_connections: 4,
            pg_schema: None,
            acquire_timeout: Duration::from_secs(30),
            site: DEFAULT_SITE.to_string(),
        }
    }
}

/// The SQLite backend: one writer connection (SQLite allows one writer at a
/// time; queuing on our side beats `SQLITE_BUSY` retries) and a read pool that
/// WAL lets run beside it.
pub(crate) struct SqliteBackend {
    write: SqlitePool,
    read: SqlitePool,
}

impl SqliteBackend {
    pub(crate) fn writer(&self) -> &SqlitePool {
        &self.write
    }
    pub(crate) fn reader(&self) -> &SqlitePool {
        &self.read
    }
}

pub(crate) enum Backend {
    Sqlite(SqliteBackend),
    Postgres(PgPool),
}

pub(crate) struct Inner {
    pub(crate) backend: Backend,
    /// Historian tag name -> id. Ids never change once given, so the cache
    /// never goes stale, even with several servers on one PostgreSQL database.
    pub(crate) tag_ids: Mutex<HashMap<Arc<str>, i64>>,
    /// Whether `tag_ids` holds every name this site had registered when the
    /// historian first wrote (loaded once, in one query: asking per batch
    /// would make a restarted server with a million tags ask for them all).
    pub(crate) tag_ids_loaded: tokio::sync::OnceCell<()>,
    /// SQLite: each tag's open minute roll-up (`open_minutes.rs`).
    pub(crate) open_minutes: Mutex<crate::open_minutes::OpenMinutes>,
    /// Held by whatever changes the open minutes, across its transaction.
    pub(crate) open_gate: tokio::sync::Mutex<()>,
    description: String,
}

/// The database. Cheap to clone (shared pools).
///
/// A store reads and writes the rows of one site ([`Store::site`]);
/// [`Store::site_reader`] gives a read-only view of another site's.
#[derive(Clone)]
pub struct Store {
    pub(crate) inner: Arc<Inner>,
    /// The site whose rows this handle reads (and, unless a view, writes).
    pub(crate) site: Arc<str>,
    /// A view of another site: it refuses every write.
    pub(crate) view: bool,
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Store({}, site {})", self.inner.description, self.site)
    }
}

const SQLITE_MIGRATIONS: &[(i64, &str, &str)] = &[
    (
        1,
        "initial",
        include_str!("../migrations/sqlite/0001_initial.sql"),
    ),
    (
        2,
        "panel states",
        include_str!("../migrations/sqlite/0002_panel_states.sql"),
    ),
    (
        3,
        "user screens",
        include_str!("../migrations/sqlite/0003_user_screens.sql"),
    ),
    (
        4,
        "exact integers",
        include_str!("../migrations/sqlite/0004_exact_integers.sql"),
    ),
    (
        5,
        "alarm causes",
        include_str!("../migrations/sqlite/0005_alarm_cause.sql"),
    ),
    (
        6,
        "sessions",
        include_str!("../migrations/sqlite/0006_sessions.sql"),
    ),
    (
        7,
        "audit ids",
        include_str!("../migrations/sqlite/0007_audit_ids.sql"),
    ),
    (
        8,
        "leadership",
        include_str!("../migrations/sqlite/0008_leadership.sql"),
    ),
    (
        9,
        "historian roll-ups",
        include_str!("../migrations/sqlite/0009_rollups.sql"),
    ),
    (
        10,
        "notifications, out-of-service ends",
        include_str!("../migrations/sqlite/0010_notifications.sql"),
    ),
    (
        11,
        "several sites on one database",
        include_str!("../migrations/sqlite/0011_sites.sql"),
    ),
    (
        12,
        "failover tickets of their own",
        include_str!("../migrations/sqlite/0012_handover_tickets.sql"),
    ),
    (
        13,
        "safety tags",
        include_str!("../migrations/sqlite/0013_safety_tags.sql"),
    ),
    (
        14,
        "switching programmes",
        include_str!("../migrations/sqlite/0014_switching_programmes.sql"),
    ),
    (
        15,
        "open minute roll-ups",
        include_str!("../migrations/sqlite/0015_open_minutes.sql"),
    ),
];
const POSTGRES_MIGRATIONS: &[(i64, &str, &str)] = &[
    (
        1,
        "initial",
        include_str!("../migrations/postgres/0001_initial.sql"),
    ),
    (
        2,
        "panel states",
        include_str!("../migrations/postgres/0002_panel_states.sql"),
    ),
    (
        3,
        "user screens",
        include_str!("../migrations/postgres/0003_user_screens.sql"),
    ),
    (
        4,
        "exact integers",
        include_str!("../migrations/postgres/0004_exact_integers.sql"),
    ),
    (
        5,
        "alarm causes",
        include_str!("../migrations/postgres/0005_alarm_cause.sql"),
    ),
    (
        6,
        "sessions",
        include_str!("../migrations/postgres/0006_sessions.sql"),
    ),
    (
        7,
        "audit ids",
        include_str!("../migrations/postgres/0007_audit_ids.sql"),
    ),
    (
        8,
        "leadership",
        include_str!("../migrations/postgres/0008_leadership.sql"),
    ),
    (
        9,
        "historian roll-ups",
        include_str!("../migrations/postgres/0009_rollups.sql"),
    ),
    (
        10,
        "notifications, out-of-service ends",
        include_str!("../migrations/postgres/0010_notifications.sql"),
    ),
    (
        11,
        "several sites on one database",
        include_str!("../migrations/postgres/0011_sites.sql"),
    ),
    (
        12,
        "failover tickets of their own",
        include_str!("../migrations/postgres/0012_handover_tickets.sql"),
    ),
    (
        13,
        "safety tags",
        include_str!("../migrations/postgres/0013_safety_tags.sql"),
    ),
    (
        14,
        "switching programmes",
        include_str!("../migrations/postgres/0014_switching_programmes.sql"),
    ),
    (
        15,
        "open minute roll-ups",
        include_str!("../migrations/postgres/0015_open_minutes.sql"),
    ),
];

/// The database holds password hashes and the audit log: it is created
/// readable by its owner only (0600), whatever the umask, and an existing
/// one is narrowed to that. SQLite gives its `-wal` and `-shm` files the
/// database file's mode.
fn private_file(path: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .mode(0o600)
            .open(path)?;
        for suffix in ["", "-wal", "-shm"] {
            let mut p = path.as_os_str().to_owned();
            p.push(suffix);
            match std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o600)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
                _ => {}
            }
        }
    }
    #[cfg(not(unix))]
    let _ = path;
    Ok(())
}

fn migrator(list: &[(i64, &'static str, &'static str)]) -> Migrator {
    let migrations = list
        .iter()
        .map(|&(version, description, sql)| {
            Migration::new(
                version,
                Cow::Borrowed(description),
                MigrationType::Simple,
                Cow::Borrowed(sql),
                false,
            )
        })
        .collect::<Vec<_>>();
    Migrator {
        migrations: Cow::Owned(migrations),
        ..Migrator::DEFAULT
    }
}

fn open_err(what: impl Into<String>) -> impl FnOnce(sqlx::Error) -> StoreError {
    let what = what.into();
    move |e| StoreError::Open {
        what,
        source: Box::new(e),
    }
}

/// Where a `sqlite://` URL points, relative paths inside `data_dir`.
fn sqlite_path(url: &str, rest: &str, data_dir: &Path) -> Result<PathBuf> {
    // Drop URL query parameters: options are ours to set.
    let path = rest.split('?').next().unwrap_or_default();
    if path.is_empty() || path == ":memory:" || path.starts_with(":memory:") {
        return Err(StoreError::Url {
            url: url.into(),
            reason: "needs a file path (an in-memory database would lose everything on restart)"
                .into(),
        });
    }
    let p = Path::new(path);
    Ok(if p.is_absolute() {
        p.to_path_buf()
    } else {
        data_dir.join(p)
    })
}

fn valid_schema(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 63
        && s.bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
        && !s.as_bytes()[0].is_ascii_digit()
}

/// Hides the password of a URL for logs and errors.
fn redact(url: &str) -> String {
    match (url.find("://"), url.rfind('@')) {
        (Some(s), Some(at)) if at > s => {
            let cred = &url[s + 3..at];
            match cred.find(':') {
                Some(c) => format!("{}{}:***{}", &url[..s + 3], &cred[..c], &url[at..]),
                None => url.into(),
            }
        }
        _ => url.into(),
    }
}

impl Store {
    /// Opens (creating if needed) the database named by `url` and applies the
    /// migrations of its backend:
    /// - `sqlite://PATH`: a file, relative paths inside `options.data_dir`
    ///   (created if missing);
    /// - `postgres://user:pass@host:port/db` (or `postgresql://`).
    pub async fn open(url: &str, options: &OpenOptions) -> Result<Store> {
        let shown = redact(url);
        if let Some(rest) = url.strip_prefix("sqlite://") {
            let path = sqlite_path(&shown, rest, &options.data_dir)?;
            Self::open_sqlite(&path, options).await
        } else if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            Self::open_postgres(url, &shown, options).await
        } else {
            Err(StoreError::Url {
                url: shown,
                reason: "expected sqlite://PATH or postgres://...".into(),
            })
        }
    }

    async fn open_sqlite(path: &Path, options: &OpenOptions) -> Result<Store> {
        let shown = path.display().to_string();
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| StoreError::Open {
                what: format!("data folder {}", dir.display()),
                source: Box::new(e),
            })?;
        }
        private_file(path).map_err(|e| StoreError::Open {
            what: format!("SQLite database {shown}"),
            source: Box::new(e),
        })?;
        let sync = match options.sqlite_sync {
            SqliteSync::Normal => SqliteSynchronous::Normal,
            SqliteSync::Full => SqliteSynchronous::Full,
        };
        let base = SqliteConnectOptions::new()
            .filename(path)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(sync)
            .busy_timeout(options.acquire_timeout)
            .foreign_keys(true);
        let write = SqlitePoolOptions::new()
            .max_connections(1)
            .min_connections(1)
            .acquire_timeout(options.acquire_timeout)
            .connect_with(base.clone().create_if_missing(true))
            .await
            .map_err(open_err(format!("SQLite database {shown}")))?;
        migrator(SQLITE_MIGRATIONS)
            .run(&write)
            .await
            .map_err(|e| StoreError::Open {
                what: format!("migrations of SQLite database {shown}"),
                source: Box::new(e),
            })?;
        let read = SqlitePoolOptions::new()
            .max_connections(options.max_connections.max(1))
            .acquire_timeout(options.acquire_timeout)
            .connect_with(base.read_only(true))
            .await
            .map_err(open_err(format!("SQLite database {shown} (readers)")))?;
        tracing::info!(path = %shown, sync = ?options.sqlite_sync, "opened SQLite store");
        check_site(&options.site)?;
        Ok(Store {
            site: options.site.as_str().into(),
            view: false,
            inner: Arc::new(Inner {
                backend: Backend::Sqlite(SqliteBackend { write, read }),
                tag_ids: Mutex::new(HashMap::new()),
                tag_ids_loaded: tokio::sync::OnceCell::new(),
                open_minutes: Mutex::new(Default::default()),
                open_gate: tokio::sync::Mutex::new(()),
                description: format!("sqlite {shown}"),
            }),
        })
    }

    async fn open_postgres(url: &str, shown: &str, options: &OpenOptions) -> Result<Store> {
        let mut connect = PgConnectOptions::from_str(url).map_err(|e| StoreError::Url {
            url: shown.into(),
            reason: e.to_string(),
        })?;
        if let Some(schema) = &options.pg_schema {
            if !valid_schema(schema) {
                return Err(StoreError::Invalid(format!(
                    "PostgreSQL schema name '{schema}': use lowercase letters, digits and _"
                )));
            }
            // Create it over a plain connection first: search_path must name an
            // existing schema for the migrations to land in it.
            let pool = PgPoolOptions::new()
                .max_connections(1)
                .acquire_timeout(options.acquire_timeout)
                .connect_with(connect.clone())
                .await
                .map_err(open_err(format!("PostgreSQL database {shown}")))?;
            sqlx::query(&format!("CREATE SCHEMA IF NOT EXISTS {schema}"))
                .execute(&pool)
                .await
                .map_err(open_err(format!("schema {schema} in {shown}")))?;
            pool.close().await;
            connect = connect.options([("search_path", schema.as_str())]);
        }
        let pool = PgPoolOptions::new()
            .max_connections(options.max_connections.max(2))
            .acquire_timeout(options.acquire_timeout)
            .connect_with(connect)
            .await
            .map_err(open_err(format!("PostgreSQL database {shown}")))?;
        // The migrator takes an advisory lock, so several servers starting at
        // once on one database do not race.
        migrator(POSTGRES_MIGRATIONS)
            .run(&pool)
            .await
            .map_err(|e| StoreError::Open {
                what: format!("migrations of PostgreSQL database {shown}"),
                source: Box::new(e),
            })?;
        tracing::info!(url = %shown, schema = ?options.pg_schema, "opened PostgreSQL store");
        check_site(&options.site)?;
        Ok(Store {
            site: options.site.as_str().into(),
            view: false,
            inner: Arc::new(Inner {
                backend: Backend::Postgres(pool),
                tag_ids: Mutex::new(HashMap::new()),
                tag_ids_loaded: tokio::sync::OnceCell::new(),
                open_minutes: Mutex::new(Default::default()),
                open_gate: tokio::sync::Mutex::new(()),
                description: format!(
                    "postgres {shown}{}",
                    options
                        .pg_schema
                        .as_deref()
                        .map(|s| format!(" schema {s}"))
                        .unwrap_or_default()
                ),
            }),
        })
    }

    /// The site whose rows this store reads and writes.
    pub fn site(&self) -> &str {
        &self.site
    }

    /// A read-only view of `site`'s rows (events, alarm history, trends,
    /// dispatches) on the same database and pools, for an operator of this
    /// site looking at another's history. Every write through it is
    /// refused. `site` equal to this store's gives this store itself.
    pub fn site_reader(&self, site: &str) -> Result<Store> {
        check_site(site)?;
        if site == &*self.site {
            return Ok(self.clone());
        }
        Ok(Store {
            inner: self.inner.clone(),
            site: site.into(),
            view: true,
        })
    }

    /// Refuses a write through a view of another site.
    pub(crate) fn writable(&self, what: &str) -> Result<()> {
        if self.view {
            return Err(StoreError::Invalid(format!(
                "{what}: site '{}' is read-only from here (another site's history)",
                self.site
            )));
        }
        Ok(())
    }

    /// Every site with rows in this database (historian tags, alarm or
    /// panel states, a lease or a pair's server), sorted. Small tables
    /// only: the long histories are not scanned.
    pub async fn sites(&self) -> Result<Vec<String>> {
        Ok(on_backend!(self, reader, |p| {
            sqlx::query_scalar(
                "SELECT site FROM tags UNION SELECT site FROM alarm_states \
                 UNION SELECT site FROM panel_states UNION SELECT site FROM leadership \
                 UNION SELECT site FROM pair_servers ORDER BY 1",
            )
            .fetch_all(p)
            .await
            .map_err(db("listing the sites"))?
        }))
    }

    pub fn backend(&self) -> BackendKind {
        match self.inner.backend {
            Backend::Sqlite(_) => BackendKind::Sqlite,
            Backend::Postgres(_) => BackendKind::Postgres,
        }
    }

    /// Applies any migrations not yet applied (idempotent; `open` already did).
    pub async fn migrate(&self) -> Result<()> {
        let res = match &self.inner.backend {
            Backend::Sqlite(s) => migrator(SQLITE_MIGRATIONS).run(s.writer()).await,
            Backend::Postgres(p) => migrator(POSTGRES_MIGRATIONS).run(p).await,
        };
        res.map_err(|e| StoreError::Open {
            what: format!("migrations of {}", self.inner.description),
            source: Box::new(e),
        })
    }

    /// The schema as the database has it: one line per table with its
    /// columns (`table events: id, kind, ...`) and one per explicit index
    /// (`index events_ts on events`), sorted, without the migration
    /// bookkeeping and without indexes that back a key constraint. The two
    /// backends must give the same lines (see the migration tests).
    pub async fn schema_summary(&self) -> Result<Vec<String>> {
        type Pairs = Vec<(String, String)>;
        let (columns, indexes): (Pairs, Pairs) = match &self.inner.backend {
            Backend::Sqlite(s) => {
                let p = s.reader();
                let cols = sqlx::query_as(
                        "SELECT m.name, c.name FROM sqlite_master m, pragma_table_info(m.name) c \
                         WHERE m.type = 'table' AND m.name NOT LIKE 'sqlite_%' AND m.name NOT LIKE '_sqlx%'",
                    )
                    .fetch_all(p)
                    .await
                    .map_err(db("reading the schema"))?;
                let idx = sqlx::query_as(
                        "SELECT name, tbl_name FROM sqlite_master WHERE type = 'index' AND sql IS NOT NULL",
                    )
                    .fetch_all(p)
                    .await
                    .map_err(db("reading the schema"))?;
                (cols, idx)
            }
            Backend::Postgres(p) => {
                let cols = sqlx::query_as(
                    "SELECT table_name::text, column_name::text FROM information_schema.columns \
                         WHERE table_schema = current_schema() AND table_name NOT LIKE '\\_sqlx%'",
                )
                .fetch_all(p)
                .await
                .map_err(db("reading the schema"))?;
                let idx = sqlx::query_as(
                        "SELECT i.relname::text, t.relname::text FROM pg_index x \
                         JOIN pg_class i ON i.oid = x.indexrelid \
                         JOIN pg_class t ON t.oid = x.indrelid \
                         JOIN pg_namespace n ON n.oid = t.relnamespace \
                         WHERE n.nspname = current_schema() AND t.relname NOT LIKE '\\_sqlx%' \
                         AND NOT EXISTS (SELECT 1 FROM pg_constraint c WHERE c.conindid = x.indexrelid)",
                    )
                    .fetch_all(p)
                    .await
                    .map_err(db("reading the schema"))?;
                (cols, idx)
            }
        };
        let mut tables: std::collections::BTreeMap<String, Vec<String>> = Default::default();
        for (t, c) in columns {
            tables.entry(t).or_default().push(c);
        }
        let mut out: Vec<String> = tables
            .into_iter()
            .map(|(t, mut cols)| {
                cols.sort();
                format!("table {t}: {}", cols.join(", "))
            })
            .collect();
        out.extend(
            indexes
                .into_iter()
                .map(|(i, t)| format!("index {i} on {t}")),
        );
        out.sort();
        Ok(out)
    }

    /// Checks the database answers (for a health endpoint).
    pub async fn ping(&self) -> Result<()> {
        on_backend!(self, reader, |p| {
            sqlx::query("SELECT 1")
                .execute(p)
                .await
                .map_err(db("pinging the database"))?;
        });
        Ok(())
    }

    /// Closes the pools, waiting for queries in flight. In SQLite this also
    /// writes the open minute roll-ups (for at most 10 s; the next start
    /// rebuilds the rest) and checkpoints the WAL into the
    /// main file.
    pub async fn close(&self) {
        if let Err(e) = self
            .close_open_minutes_within(Some(crate::writer::STOP_BUDGET))
            .await
        {
            tracing::warn!(error = %e,
                "historian: could not write the open minute roll-ups; the next start rebuilds them");
        }
        match &self.inner.backend {
            Backend::Sqlite(s) => {
                s.read.close().await;
                s.write.close().await;
            }
            Backend::Postgres(p) => p.close().await,
        }
    }

    /// The ids of historian tags, creating the missing ones when `create`.
    /// Tags not found (and not created) are absent from the map.
    pub(crate) async fn tag_ids(
        &self,
        names: &[&str],
        create: bool,
    ) -> Result<HashMap<Arc<str>, i64>> {
        let mut found = HashMap::with_capacity(names.len());
        let mut missing: Vec<&str> = Vec::new();
        if create {
            self.writable("registering historian tags")?;
            if !self.view {
                self.inner
                    .tag_ids_loaded
                    .get_or_try_init(|| self.load_tag_ids())
                    .await?;
            }
        }
        if self.view {
            // Another site's ids: looked up each time, not mixed into the
            // cache of this site's.
            missing.extend(names.iter().copied());
        } else {
            let cache = self.inner.tag_ids.lock();
            for &n in names {
                match cache.get_key_value(n) {
                    Some((k, &id)) => {
                        found.insert(k.clone(), id);
                    }
                    None => missing.push(n),
                }
            }
        }
        if missing.is_empty() {
            return Ok(found);
        }
        missing.sort_unstable();
        missing.dedup();
        for n in &missing {
            validate_tag_name(n)?;
        }
        // In chunks, a statement each (not two per name): the first scan of a
        // large plant brings every tag's first row within seconds.
        let resolved: Vec<(String, i64)> = on_backend!(self, if create => writer else reader, |p| {
            let mut out = Vec::with_capacity(missing.len());
            let mut tx = p.begin().await.map_err(db("registering historian tags"))?;
            for chunk in missing.chunks(TAG_NAMES_PER_STATEMENT) {
                let mut unresolved: Vec<&str> = chunk.to_vec();
                if create {
                    let mut qb = QueryBuilder::new("INSERT INTO tags (site, name) ");
                    qb.push_values(chunk, |mut b, n| {
                        b.push_bind(&*self.site).push_bind(*n);
                    });
                    qb.push(" ON CONFLICT (site, name) DO NOTHING RETURNING name, id");
                    let created: Vec<(String, i64)> = qb
                        .build_query_as()
                        .fetch_all(&mut *tx)
                        .await
                        .map_err(db("registering historian tags"))?;
                    // Registered by someone else meanwhile: looked up below.
                    let made: std::collections::HashSet<&str> =
                        created.iter().map(|(n, _)| n.as_str()).collect();
                    unresolved.retain(|n| !made.contains(n));
                    out.extend(created);
                }
                if unresolved.is_empty() {
                    continue;
                }
                let mut qb = QueryBuilder::new("SELECT name, id FROM tags WHERE site = ");
                qb.push_bind(&*self.site).push(" AND name IN (");
                let mut names = qb.separated(", ");
                for n in &unresolved {
                    names.push_bind(*n);
                }
                qb.push(")");
                let rows: Vec<(String, i64)> = qb
                    .build_query_as()
                    .fetch_all(&mut *tx)
                    .await
                    .map_err(db("looking up historian tags"))?;
                out.extend(rows);
            }
            tx.commit().await.map_err(db("registering historian tags"))?;
            out
        });
        if self.view {
            for (n, id) in resolved {
                found.insert(n.into(), id);
            }
            return Ok(found);
        }
        let mut cache = self.inner.tag_ids.lock();
        for (n, id) in resolved {
            let k: Arc<str> = n.into();
            cache.insert(k.clone(), id);
            found.insert(k, id);
        }
        Ok(found)
    }

    /// Every historian tag of this site into the name cache, in one query.
    async fn load_tag_ids(&self) -> Result<()> {
        let all: Vec<(String, i64)> = on_backend!(self, writer, |p| {
            sqlx::query_as("SELECT name, id FROM tags WHERE site = $1")
                .bind(&*self.site)
                .fetch_all(p)
                .await
                .map_err(db("loading historian tag ids"))?
        });
        let mut cache = self.inner.tag_ids.lock();
        cache.reserve(all.len());
        for (name, id) in all {
            cache.insert(name.into(), id);
        }
        Ok(())
    }
}

/// Names registered or looked up per statement (well under SQLite's
/// 32,766 bound parameters).
const TAG_NAMES_PER_STATEMENT: usize = 1000;

/// A site id as the configuration allows it: 1..64 letters, digits, `-`, `_`.
pub(crate) fn check_site(site: &str) -> Result<()> {
    if site.is_empty()
        || site.len() > 64
        || !site
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
    {
        return Err(StoreError::Invalid(format!(
            "site '{}' must be 1..64 letters, digits, '-' or '_'",
            site.escape_debug()
        )));
    }
    Ok(())
}

pub(crate) fn validate_tag_name(n: &str) -> Result<()> {
    if n.is_empty() || n.len() > 256 || n.chars().any(char::is_control) {
        return Err(StoreError::Invalid(format!(
            "historian tag name '{}' must be 1..256 printable characters",
            n.escape_debug()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqlite_paths_resolve_in_the_data_dir() {
        let d = Path::new("/var/lib/gs");
        assert_eq!(
            sqlite_path("u", "gridscada.db", d).unwrap(),
            PathBuf::from("/var/lib/gs/gridscada.db")
        );
        assert_eq!(
            sqlite_path("u", "/abs/x.db?mode=rwc", d).unwrap(),
            PathBuf::from("/abs/x.db")
        );
        assert!(sqlite_path("u", ":memory:", d).is_err());
        assert!(sqlite_path("u", "", d).is_err());
    }

    #[test]
    fn passwords_are_hidden() {
        assert_eq!(
            redact("postgres://scada:secret@db:5432/gs"),
            "postgres://scada:***@db:5432/gs"
        );
        assert_eq!(redact("postgres://db/gs"), "postgres://db/gs");
    }

    #[test]
    fn schema_names_are_checked() {
        assert!(valid_schema("site_1"));
        assert!(!valid_schema("Site"));
        assert!(!valid_schema("a;drop"));
        assert!(!valid_schema("1a"));
    }
}

#[cfg(test)]
mod migration_lists {
    use super::*;

    /// The migrations compiled in are exactly the files of each folder, in
    /// version order, with the same text.
    #[test]
    fn the_lists_match_the_folders() {
        for (folder, list) in [
            ("sqlite", SQLITE_MIGRATIONS),
            ("postgres", POSTGRES_MIGRATIONS),
        ] {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("migrations")
                .join(folder);
            let mut files: Vec<(i64, String)> = std::fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|x| x == "sql"))
                .map(|p| {
                    let name = p.file_name().unwrap().to_string_lossy().to_string();
                    let version: i64 = name
                        .split('_')
                        .next()
                        .and_then(|v| v.parse().ok())
                        .unwrap_or_else(|| panic!("{folder}/{name}: no version number"));
                    (version, std::fs::read_to_string(&p).unwrap())
                })
                .collect();
            files.sort();
            let listed: Vec<(i64, String)> = list
                .iter()
                .map(|(v, _, sql)| (*v, sql.to_string()))
                .collect();
            assert_eq!(
                files.iter().map(|f| f.0).collect::<Vec<_>>(),
                listed.iter().map(|f| f.0).collect::<Vec<_>>(),
                "{folder}: the folder's versions and the list in store.rs differ"
            );
            assert_eq!(
                files, listed,
                "{folder}: a listed migration's text is not its file's"
            );
        }
        assert_eq!(
            SQLITE_MIGRATIONS
                .iter()
                .map(|m| (m.0, m.1))
                .collect::<Vec<_>>(),
            POSTGRES_MIGRATIONS
                .iter()
                .map(|m| (m.0, m.1))
                .collect::<Vec<_>>(),
            "the two backends have different migrations"
        );
    }
}
