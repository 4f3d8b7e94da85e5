-- Several sites on one database: every row a server writes for its plant
-- names the site (`[server] site`). SQLite carries one server, so every
-- existing row is the default site's (`main`). Keep in step with
-- ../postgres/0011_sites.sql: same columns and keys. SQLite cannot change a
-- table's key in place, so tags, alarm_states and panel_states are rebuilt
-- (ids kept: samples refer to tags by id).

ALTER TABLE events ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE alarm_history ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE dispatches ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE notifications ADD COLUMN site TEXT NOT NULL DEFAULT 'main';

CREATE TABLE tags_by_site (
    id   INTEGER PRIMARY KEY,
    name TEXT NOT NULL,
    site TEXT NOT NULL DEFAULT 'main',
    UNIQUE (site, name)
);
INSERT INTO tags_by_site (id, name) SELECT id, name FROM tags;
DROP TABLE tags;
ALTER TABLE tags_by_site RENAME TO tags;

CREATE TABLE alarm_states_by_site (
    site                  TEXT NOT NULL DEFAULT 'main',
    alarm_key             TEXT NOT NULL,
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
    out_of_service_reason TEXT,
    activation_value      TEXT,
    out_of_service_until  INTEGER,
    PRIMARY KEY (site, alarm_key)
);
INSERT INTO alarm_states_by_site (alarm_key, kind, state, active, acked, active_since,
        last_change, message, priority, selection, shelved_by, shelved_at, shelved_until,
        shelve_reason, out_of_service, out_of_service_by, out_of_service_since,
        out_of_service_reason, activation_value, out_of_service_until)
    SELECT alarm_key, kind, state, active, acked, active_since,
        last_change, message, priority, selection, shelved_by, shelved_at, shelved_until,
        shelve_reason, out_of_service, out_of_service_by, out_of_service_since,
        out_of_service_reason, activation_value, out_of_service_until
    FROM alarm_states;
DROP TABLE alarm_states;
ALTER TABLE alarm_states_by_site RENAME TO alarm_states;

CREATE TABLE panel_states_by_site (
    site       TEXT NOT NULL DEFAULT 'main',
    panel_id   TEXT NOT NULL,
    state_json TEXT NOT NULL,
    updated_at INTEGER NOT NULL,
    PRIMARY KEY (site, panel_id)
);
INSERT INTO panel_states_by_site (panel_id, state_json, updated_at)
    SELECT panel_id, state_json, updated_at FROM panel_states;
DROP TABLE panel_states;
ALTER TABLE panel_states_by_site RENAME TO panel_states;

-- Each site's audit trail numbers its own records.
DROP INDEX IF EXISTS events_audit_id;
CREATE UNIQUE INDEX IF NOT EXISTS events_audit_id ON events (site, audit_id);
DROP INDEX IF EXISTS alarm_history_audit_id;
CREATE UNIQUE INDEX IF NOT EXISTS alarm_history_audit_id ON alarm_history (site, audit_id);

CREATE INDEX IF NOT EXISTS events_site_ts ON events (site, ts);
CREATE INDEX IF NOT EXISTS alarm_history_site_ts ON alarm_history (site, ts);
CREATE INDEX IF NOT EXISTS dispatches_site_ts ON dispatches (site, ts);
