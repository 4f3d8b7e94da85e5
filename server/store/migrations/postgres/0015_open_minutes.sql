-- The SQLite historian's watermark of its open minute roll-ups (see the other
-- backend's 0015). PostgreSQL writes every roll-up with its samples (a pair
-- shares the database and takes over at any moment), so here the table
-- stays empty; it keeps the two schemas one.
CREATE TABLE IF NOT EXISTS historian_rollup_state (
    site           TEXT PRIMARY KEY,
    closed_through BIGINT NOT NULL,
    clean          INTEGER NOT NULL
);
