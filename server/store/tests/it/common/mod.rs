//! Test harness: every store test runs on SQLite (a temp file) and on
//! PostgreSQL (a fresh schema in the database of `GRIDSCADA_TEST_PG_URL`), so
//! tests are isolated and can run in parallel.
#![allow(dead_code)]

use std::sync::atomic::{AtomicU32, Ordering};

use gridscada_store::{OpenOptions, Store};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    Sqlite,
    Postgres,
}

pub struct TestDb {
    pub store: Store,
    pub url: String,
    pub options: OpenOptions,
    pub engine: Engine,
    pub dir: tempfile::TempDir,
}

static SEQ: AtomicU32 = AtomicU32::new(0);

/// The PostgreSQL URL, or None (with a loud notice) to skip. Fails instead
/// when `GRIDSCADA_REQUIRE_PG=1`.
pub fn pg_url(test: &str) -> Option<String> {
    match std::env::var("GRIDSCADA_TEST_PG_URL") {
        Ok(u) if !u.is_empty() => Some(u),
        _ => {
            if std::env::var("GRIDSCADA_REQUIRE_PG").as_deref() == Ok("1") {
                panic!("{test}: GRIDSCADA_REQUIRE_PG=1 but GRIDSCADA_TEST_PG_URL is not set; run scripts/pg-test-cluster.sh");
            }
            // Straight to fd 2: the test harness captures eprintln! of passing
            // tests, and this notice must be seen.
            use std::io::Write;
            let _ = std::io::stderr().write_all(
                format!(
                    "\n!!!!!!!! SKIPPED PostgreSQL variant of {test}: GRIDSCADA_TEST_PG_URL is not set \
                     (eval \"$(scripts/pg-test-cluster.sh)\" to get one) !!!!!!!!\n"
                )
                .as_bytes(),
            );
            None
        }
    }
}

impl TestDb {
    pub async fn new(engine: Engine, test: &str) -> Option<TestDb> {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut options = OpenOptions::new(dir.path());
        let url = match engine {
            Engine::Sqlite => "sqlite://store.db".to_string(),
            Engine::Postgres => {
                let url = pg_url(test)?;
                let schema = format!(
                    "gs_test_{}_{}_{}",
                    std::process::id(),
                    SEQ.fetch_add(1, Ordering::Relaxed),
                    rand::random::<u32>()
                );
                options.pg_schema = Some(schema);
                url
            }
        };
        let store = Store::open(&url, &options)
            .await
            .unwrap_or_else(|e| panic!("{test}: opening {url}: {e}"));
        Some(TestDb {
            store,
            url,
            options,
            engine,
            dir,
        })
    }

    /// Closes and opens the store again, as a restart would.
    pub async fn reopen(&mut self) {
        self.store.close().await;
        self.store = Store::open(&self.url, &self.options)
            .await
            .expect("reopening the store");
    }

    /// Drops the test schema (PostgreSQL); the SQLite file goes with the temp dir.
    pub async fn cleanup(self) {
        self.store.close().await;
        if let (Engine::Postgres, Some(schema)) = (self.engine, &self.options.pg_schema) {
            use sqlx::Connection;
            if let Ok(mut c) = sqlx::PgConnection::connect(&self.url).await {
                let _ = sqlx::query(&format!("DROP SCHEMA IF EXISTS {schema} CASCADE"))
                    .execute(&mut c)
                    .await;
            }
        }
    }

    /// A count (`SELECT count(*) ...`) read over a connection of its own,
    /// for what the store's API does not list.
    pub async fn count(&self, sql: &str) -> i64 {
        use sqlx::Connection;
        match self.engine {
            Engine::Sqlite => {
                let path = self.dir.path().join("store.db");
                let mut c =
                    sqlx::SqliteConnection::connect(&format!("sqlite://{}", path.display()))
                        .await
                        .expect("second SQLite connection");
                sqlx::query_scalar(sql).fetch_one(&mut c).await.unwrap()
            }
            Engine::Postgres => {
                let mut c = sqlx::PgConnection::connect(&self.url)
                    .await
                    .expect("second PG connection");
                let schema = self.options.pg_schema.as_deref().unwrap();
                sqlx::query(&format!("SET search_path TO {schema}"))
                    .execute(&mut c)
                    .await
                    .unwrap();
                sqlx::query_scalar(sql).fetch_one(&mut c).await.unwrap()
            }
        }
    }

    /// Holds an exclusive lock on the samples table from another connection,
    /// as a slow or stuck database would. Released when the guard is dropped
    /// or `release`d.
    pub async fn lock_samples(&self) -> SampleLock {
        use sqlx::Connection;
        match self.engine {
            Engine::Sqlite => {
                let path = self.dir.path().join("store.db");
                let mut c =
                    sqlx::SqliteConnection::connect(&format!("sqlite://{}", path.display()))
                        .await
                        .expect("second SQLite connection");
                sqlx::query("BEGIN IMMEDIATE")
                    .execute(&mut c)
                    .await
                    .expect("lock");
                SampleLock::Sqlite(c)
            }
            Engine::Postgres => {
                let mut c = sqlx::PgConnection::connect(&self.url)
                    .await
                    .expect("second PG connection");
                let schema = self.options.pg_schema.as_deref().unwrap();
                sqlx::query(&format!("SET search_path TO {schema}"))
                    .execute(&mut c)
                    .await
                    .unwrap();
                sqlx::query("BEGIN").execute(&mut c).await.unwrap();
                sqlx::query("LOCK TABLE samples IN ACCESS EXCLUSIVE MODE")
                    .execute(&mut c)
                    .await
                    .expect("lock");
                SampleLock::Postgres(c)
            }
        }
    }
}

pub enum SampleLock {
    Sqlite(sqlx::SqliteConnection),
    Postgres(sqlx::PgConnection),
}

impl SampleLock {
    pub async fn release(self) {
        match self {
            SampleLock::Sqlite(mut c) => {
                sqlx::query("ROLLBACK").execute(&mut c).await.unwrap();
            }
            SampleLock::Postgres(mut c) => {
                sqlx::query("ROLLBACK").execute(&mut c).await.unwrap();
            }
        }
    }
}

/// Defines `NAME::sqlite` and `NAME::postgres` tests running `body(db)`.
#[macro_export]
macro_rules! both_backends {
    ($name:ident, $body:path) => {
        mod $name {
            use super::*;
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn sqlite() {
                let db = common::TestDb::new(common::Engine::Sqlite, stringify!($name))
                    .await
                    .unwrap();
                $body(db).await;
            }
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn postgres() {
                if let Some(db) =
                    common::TestDb::new(common::Engine::Postgres, stringify!($name)).await
                {
                    $body(db).await;
                }
            }
        }
    };
}
