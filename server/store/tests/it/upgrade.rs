//! Migration 0011 (several sites on one database) on a database that holds
//! rows already, as an upgrade meets it: nothing is lost, every row belongs
//! to the database's one site, and the new keys hold. The migrations are run
//! as files in order, so the rows can go in between 0010 and 0011.

use crate::common;

use sqlx::Connection;

const SQLITE: &[&str] = &[
    include_str!("../../migrations/sqlite/0001_initial.sql"),
    include_str!("../../migrations/sqlite/0002_panel_states.sql"),
    include_str!("../../migrations/sqlite/0003_user_screens.sql"),
    include_str!("../../migrations/sqlite/0004_exact_integers.sql"),
    include_str!("../../migrations/sqlite/0005_alarm_cause.sql"),
    include_str!("../../migrations/sqlite/0006_sessions.sql"),
    include_str!("../../migrations/sqlite/0007_audit_ids.sql"),
    include_str!("../../migrations/sqlite/0008_leadership.sql"),
    include_str!("../../migrations/sqlite/0009_rollups.sql"),
    include_str!("../../migrations/sqlite/0010_notifications.sql"),
];
const SQLITE_SITES: &str = include_str!("../../migrations/sqlite/0011_sites.sql");
const POSTGRES: &[&str] = &[
    include_str!("../../migrations/postgres/0001_initial.sql"),
    include_str!("../../migrations/postgres/0002_panel_states.sql"),
    include_str!("../../migrations/postgres/0003_user_screens.sql"),
    include_str!("../../migrations/postgres/0004_exact_integers.sql"),
    include_str!("../../migrations/postgres/0005_alarm_cause.sql"),
    include_str!("../../migrations/postgres/0006_sessions.sql"),
    include_str!("../../migrations/postgres/0007_audit_ids.sql"),
    include_str!("../../migrations/postgres/0008_leadership.sql"),
    include_str!("../../migrations/postgres/0009_rollups.sql"),
    include_str!("../../migrations/postgres/0010_notifications.sql"),
];
const POSTGRES_SITES: &str = include_str!("../../migrations/postgres/0011_sites.sql");

/// Rows of every table 0011 keys by site, as version 10 held them.
const ROWS: &str = "
INSERT INTO tags (id, name) VALUES (7, 'SS1.PA.V_L1');
INSERT INTO samples (tag_id, ts, value, quality) VALUES (7, 1000, 230.5, 0), (7, 2000, 231.0, 0);
INSERT INTO events (ts, user_name, source, kind, message, audit_id) VALUES (1000, 'op', 'web', 'login', 'op logged in', 5);
INSERT INTO alarm_history (ts, alarm_key, tag, kind, from_state, to_state, activation, value, limit_value,
    user_name, message, priority, selection, cause, audit_id)
  VALUES (1000, 'SS1.PA.V_L1:hi', 'SS1.PA.V_L1', 'hi', 'normal', 'unack_alarm', TRUE, 260.0, 250.0,
    NULL, 'high voltage', 500, 'SS1', 'activate', 6);
INSERT INTO alarm_states (alarm_key, kind, state, active, acked, active_since, last_change, message,
    priority, selection, out_of_service, activation_value, out_of_service_until)
  VALUES ('SS1.PA.V_L1:hi', 'hi', 'unack_alarm', TRUE, FALSE, 1000, 1000, 'high voltage', 500, 'SS1',
    FALSE, 'f:260', NULL);
INSERT INTO panel_states (panel_id, state_json, updated_at) VALUES ('ss1', '{\"mode\":\"auto\"}', 1000);
INSERT INTO dispatches (ts, status, mode, objective, solve_ms, inputs_json, setpoints_json)
  VALUES (1000, 'optimal', 'auto', 1.5, 2.0, '{}', '{}');
INSERT INTO notifications (created_at, route, contact, address, level, subject, message, status,
    next_attempt, give_up_at) VALUES (1000, 'ops', 'ann', 'ann@example.org', 0, 's', 'm', 'pending', 1000, 9000);
";

const CHECKS: &[(&str, &str)] = &[
    (
        "SELECT site || ' ' || id || ' ' || name FROM tags",
        "7 SS1.PA.V_L1",
    ),
    (
        "SELECT CAST(count(*) AS TEXT) FROM samples WHERE tag_id = 7",
        "2",
    ),
    (
        "SELECT site || ' ' || message FROM events WHERE audit_id = 5",
        "op logged in",
    ),
    (
        "SELECT site || ' ' || alarm_key FROM alarm_history WHERE audit_id = 6",
        "SS1.PA.V_L1:hi",
    ),
    (
        "SELECT site || ' ' || state || ' ' || activation_value FROM alarm_states",
        "unack_alarm f:260",
    ),
    (
        "SELECT site || ' ' || panel_id || ' ' || state_json FROM panel_states",
        "ss1 {\"mode\":\"auto\"}",
    ),
    ("SELECT site || ' ' || status FROM dispatches", "optimal"),
    ("SELECT site || ' ' || route FROM notifications", "ops"),
];

/// After 0011: every row is `site`'s, and the same names at another site
/// are rows of their own.
const OTHER_SITE: &str = "
INSERT INTO tags (site, name) VALUES ('south', 'SS1.PA.V_L1');
INSERT INTO alarm_states (site, alarm_key, kind, state, active, acked, last_change, message, priority,
    selection, out_of_service) VALUES ('south', 'SS1.PA.V_L1:hi', 'hi', 'normal', FALSE, TRUE, 2000, 'm', 500, 'SS1', FALSE);
INSERT INTO panel_states (site, panel_id, state_json, updated_at) VALUES ('south', 'ss1', '{}', 2000);
INSERT INTO events (site, ts, source, kind, message, audit_id) VALUES ('south', 2000, 'web', 'login', 'x', 5);
";

#[tokio::test]
async fn sqlite_rows_survive_and_become_the_main_sites() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.db");
    std::fs::File::create(&path).unwrap();
    let mut c = sqlx::SqliteConnection::connect(&format!("sqlite://{}", path.display()))
        .await
        .unwrap();
    for m in SQLITE {
        sqlx::raw_sql(m).execute(&mut c).await.unwrap();
    }
    sqlx::raw_sql(ROWS).execute(&mut c).await.unwrap();
    sqlx::raw_sql(SQLITE_SITES).execute(&mut c).await.unwrap();
    for (sql, want) in CHECKS {
        let got: String = sqlx::query_scalar(sql).fetch_one(&mut c).await.unwrap();
        let want = if sql.contains("count(*)") {
            want.to_string()
        } else {
            format!("main {want}")
        };
        assert_eq!(got, want, "{sql}");
    }
    sqlx::raw_sql(OTHER_SITE).execute(&mut c).await.unwrap();
    // The same audit id at the same site is still refused.
    assert!(sqlx::raw_sql(
        "INSERT INTO events (site, ts, source, kind, message, audit_id) VALUES ('south', 3000, 'web', 'login', 'y', 5)"
    )
    .execute(&mut c)
    .await
    .is_err());
}

#[tokio::test]
async fn postgres_rows_survive_and_become_the_pairs_site() {
    let Some(url) = common::pg_url("upgrade") else {
        return;
    };
    let schema = format!(
        "gs_upgrade_{}_{}",
        std::process::id(),
        rand::random::<u32>()
    );
    let mut c = sqlx::PgConnection::connect(&url).await.unwrap();
    sqlx::raw_sql(&format!(
        "CREATE SCHEMA {schema}; SET search_path TO {schema}"
    ))
    .execute(&mut c)
    .await
    .unwrap();
    for m in POSTGRES {
        sqlx::raw_sql(m).execute(&mut c).await.unwrap();
    }
    sqlx::raw_sql(ROWS).execute(&mut c).await.unwrap();
    // A pair ran on this database: its site's lease is the one row.
    sqlx::raw_sql(
        "INSERT INTO leadership (site, holder, epoch, expires_ms, taken_ms) VALUES ('north-1', 'a', 3, 0, 0)",
    )
    .execute(&mut c)
    .await
    .unwrap();
    sqlx::raw_sql(POSTGRES_SITES).execute(&mut c).await.unwrap();
    for (sql, want) in CHECKS {
        let got: String = sqlx::query_scalar(sql).fetch_one(&mut c).await.unwrap();
        let want = if sql.contains("count(*)") {
            want.to_string()
        } else {
            format!("north-1 {want}")
        };
        assert_eq!(got, want, "{sql}");
    }
    sqlx::raw_sql(OTHER_SITE).execute(&mut c).await.unwrap();
    assert!(sqlx::raw_sql(
        "INSERT INTO events (site, ts, source, kind, message, audit_id) VALUES ('south', 3000, 'web', 'login', 'y', 5)"
    )
    .execute(&mut c)
    .await
    .is_err());
    sqlx::raw_sql(&format!("DROP SCHEMA {schema} CASCADE"))
        .execute(&mut c)
        .await
        .unwrap();
}
