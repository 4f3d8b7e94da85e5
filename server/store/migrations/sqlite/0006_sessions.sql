-- Login sessions, so they survive a restart and every server on one
-- database sees the same ones. Only the SHA-256 of the cookie's token is
-- kept (hex): a copy of this table opens no session. `idle_ms` and
-- `expires_at` are fixed at login from the role's policy (NULL: never);
-- `last_seen` is written through at a bounded rate (see the web layer's
-- sessions), so it may trail the last activity by that bound.
-- Keep in step with the other backend's 0006_sessions.sql.
CREATE TABLE IF NOT EXISTS sessions (
    token_hash TEXT PRIMARY KEY,
    user_name  TEXT NOT NULL,
    role       TEXT NOT NULL,
    created_at INTEGER NOT NULL,
    last_seen  INTEGER NOT NULL,
    idle_ms    INTEGER,
    expires_at INTEGER,
    client     TEXT,
    user_agent TEXT
);
CREATE INDEX IF NOT EXISTS sessions_by_user ON sessions (user_name);
