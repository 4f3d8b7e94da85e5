-- gridscada schema, SQLite flavour. Keep in step with ../postgres/0001_initial.sql:
-- same tables, columns and meaning; only the types differ.

-- Historian tag names; samples refer to them by id to keep rows small.
CREATE TABLE IF NOT EXISTS tags (
    id   INTEGER PRIMARY KEY,
    name TEXT NOT NULL UNIQUE
);

-- One row per logged sample. Clustered on (tag, time) so a trend query reads one
-- contiguous range. No foreign key: it would cost a lookup per ingested row, and
-- tags are never deleted. value is NULL for a reading with no finite number.
-- quality: 0 good, 1 uncertain, 2 bad.
CREATE TABLE IF NOT EXISTS samples (
    tag_id  INTEGER NOT NULL,
    ts      INTEGER NOT NULL,
    value   REAL,
    quality INTEGER NOT NULL,
    PRIMARY KEY (tag_id, ts)
) WITHOUT ROWID;

CREATE TABLE IF NOT EXISTS events (
    id        INTEGER PRIMARY KEY AUTOINCREMENT,
    ts        INTEGER NOT NULL,
    user_name TEXT,
    source    TEXT NOT NULL,
    kind      TEXT NOT NULL,
    message   TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS events_ts ON events (ts);

-- The current state of every alarm that is not plain normal, so acknowledgements,
-- shelving and out-of-service survive a restart.
CREATE TABLE IF NOT EXISTS alarm_states (
    alarm_key             TEXT PRIMARY KEY,
    kind                  TEXT NOT NULL,
    state                 TEXT NOT NULL,
    active                INTEGER NOT NULL,
    acked                 INTEGER NOT NULL,
    active_since          INTEGER,
    last_change           INTEGER NOT NULL,
    message               TEXT NOT NULL,
    priority              INTEGER NOT NULL,
    selection             TEXT NOT NULL,
    shelved_by            TEXT,
    shelved_at            INTEGER,
    shelved_until         INTEGER,
    shelve_reason         TEXT,
    out_of_service        INTEGER NOT NULL,
    out_of_service_by     TEXT,
    out_of_service_since  INTEGER,
    out_of_service_reason TEXT
);

-- Every alarm state transition. activation = 1 marks the transitions the alarm
-- engine counts as an annunciated activation (ISA-18.2 alarm rate metrics).
CREATE TABLE IF NOT EXISTS alarm_history (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    ts          INTEGER NOT NULL,
    alarm_key   TEXT NOT NULL,
    tag         TEXT NOT NULL,
    kind        TEXT NOT NULL,
    from_state  TEXT NOT NULL,
    to_state    TEXT NOT NULL,
    activation  INTEGER NOT NULL,
    value       REAL,
    limit_value REAL,
    user_name   TEXT,
    message     TEXT NOT NULL,
    priority    INTEGER NOT NULL,
    selection   TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS alarm_history_ts ON alarm_history (ts);
CREATE INDEX IF NOT EXISTS alarm_history_activation ON alarm_history (activation, ts);

CREATE TABLE IF NOT EXISTS users (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    name                TEXT NOT NULL UNIQUE,
    role                TEXT NOT NULL,
    password_hash       TEXT NOT NULL,
    blocked             INTEGER NOT NULL DEFAULT 0,
    group_name          TEXT NOT NULL,
    created_at          INTEGER NOT NULL,
    password_changed_at INTEGER NOT NULL
);

CREATE TABLE IF NOT EXISTS group_screens (
    group_name TEXT NOT NULL,
    screen     TEXT NOT NULL,
    PRIMARY KEY (group_name, screen)
);

CREATE TABLE IF NOT EXISTS dispatches (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    ts            INTEGER NOT NULL,
    status        TEXT NOT NULL,
    mode          TEXT NOT NULL,
    objective     REAL,
    solve_ms      REAL NOT NULL,
    inputs_json   TEXT NOT NULL,
    setpoints_json TEXT NOT NULL,
    reason        TEXT
);
CREATE INDEX IF NOT EXISTS dispatches_ts ON dispatches (ts);
