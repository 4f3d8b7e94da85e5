-- The SQLite historian's watermark of its open minute roll-ups (see the other
-- backend's 0015). PostgreSQL writes every roll-up with its samples (a pair
-- shares the database and takes over at any moment), so here the row is
-- never read; the table keeps the two schemas one.
CREATE TABLE IF NOT EXISTS historian_rollup_state (
    id             INTEGER PRIMARY KEY CHECK (id = 1),
    closed_through BIGINT NOT NULL,
    clean          INTEGER NOT NULL
);
INSERT INTO historian_rollup_state (id, closed_through, clean)
VALUES (1, -9223372036854775807, 1) ON CONFLICT (id) DO NOTHING;
