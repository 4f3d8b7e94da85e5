-- Switching programmes: an ordered list of switching steps (JSON, as the
-- network crate writes them), prepared by a supervisor, approved, then
-- executed one step at a time. `next_step` counts the steps done; `version`
-- guards every change (two operators cannot both do step 3). Keep in step
-- with the other backend's 0014_switching_programmes.sql.
CREATE TABLE IF NOT EXISTS switching_programmes (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    site        TEXT NOT NULL DEFAULT 'main',
    name        TEXT NOT NULL,
    steps       TEXT NOT NULL,
    state       TEXT NOT NULL,
    next_step   INTEGER NOT NULL DEFAULT 0,
    created_by  TEXT NOT NULL,
    created_at  INTEGER NOT NULL,
    approved_by TEXT,
    approved_at INTEGER,
    updated_at  INTEGER NOT NULL,
    version     INTEGER NOT NULL DEFAULT 1,
    note        TEXT NOT NULL DEFAULT ''
);
CREATE INDEX IF NOT EXISTS switching_programmes_by_site ON switching_programmes (site, id);
