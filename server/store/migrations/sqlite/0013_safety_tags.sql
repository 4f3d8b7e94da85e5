-- Safety tags (lockout/tagout) on switching devices of the network: a
-- "do not operate", "do not close" or "information" tag placed with a reason
-- and a work reference, and removed with a reason. Removal is an update, so
-- the history stays. Keep in step with the other backend's
-- 0013_safety_tags.sql: same columns and keys.
CREATE TABLE IF NOT EXISTS safety_tags (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    site           TEXT NOT NULL DEFAULT 'main',
    device         TEXT NOT NULL,
    kind           TEXT NOT NULL,
    reason         TEXT NOT NULL,
    work_ref       TEXT NOT NULL DEFAULT '',
    placed_by      TEXT NOT NULL,
    placed_at      INTEGER NOT NULL,
    removed_by     TEXT,
    removed_at     INTEGER,
    removal_reason TEXT
);
CREATE INDEX IF NOT EXISTS safety_tags_by_device ON safety_tags (site, device, removed_at);
