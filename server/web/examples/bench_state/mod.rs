//! The web state the web benches run against: a one-device plant, a
//! SQLite store in a temporary folder, and an operator session (an
//! operator's screens include the tag browser, so every tag is readable).

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use gridscada_config::Role;
use gridscada_store::{NewUser, OpenOptions, Store};
use gridscada_tagdb::{SystemClock, TagDb, Timestamp};
use gridscada_web::auth::{self, SessionPolicy};
use gridscada_web::{Auth, Components, WebState};

const MAIN: &str = "tag_files = [\"tags.toml\"]\n";
const TAGS: &str = "[[device]]\nname = \"D1\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:1502\"\n";

/// The state over `db`, and the session cookie of the bench's user.
pub async fn web_state(db: Arc<TagDb>, dir: &Path) -> (WebState, String) {
    let read = |p: &Path| -> std::io::Result<String> {
        match p.file_name().and_then(|f| f.to_str()) {
            // LIVE_MERGE_MS sets `[server] live_merge_ms` (the ws_fanout bench).
            Some("gridscada.toml") => Ok(match std::env::var("LIVE_MERGE_MS") {
                Ok(ms) => format!("{MAIN}[server]\nlive_merge_ms = {ms}\n"),
                Err(_) => MAIN.into(),
            }),
            Some("tags.toml") => Ok(TAGS.into()),
            _ => Err(std::io::ErrorKind::NotFound.into()),
        }
    };
    let plant = gridscada_config::load_with(Path::new("/bench/gridscada.toml"), &read)
        .expect("bench plant");
    let store = Store::open("sqlite://bench.db", &OpenOptions::new(dir))
        .await
        .expect("store");
    store.migrate().await.expect("migrate");
    store
        .create_user(&NewUser {
            name: "bench".into(),
            // An operator's screens include the tag browser, so every tag is
            // readable (a Guest would only read the tags of its screens).
            role: Role::Operator,
            password_hash: auth::hash_password("bench password".into()).await.unwrap(),
            group: "operator".into(),
            created_at: Timestamp::now_utc(),
        })
        .await
        .expect("user");
    let auth = Auth::new(SessionPolicy::default(), false, store.clone()).await;
    let token = auth
        .sessions
        .create(
            "bench",
            gridscada_config::Role::Operator,
            None,
            Default::default(),
        )
        .await
        .expect("session");
    let state = WebState {
        db,
        plant: Arc::new(plant),
        store,
        auth,
        audit: None,
        clock: Arc::new(SystemClock),
        writer: None,
        started: Instant::now(),
        components: Components::default(),
        sim: None,
        http_metrics: Default::default(),
        metrics: None,
        screens: Default::default(),
        devices: None,
        tls: false,
        live: Default::default(),
        connections: Default::default(),
    };
    (state, format!("{}={token}", auth::COOKIE))
}
