-- The SQLite historian keeps each tag's open minute roll-up in memory
-- (store/src/open_minutes.rs) and writes it once the minute is over.
-- `closed_through`: every minute bucket that starts before it is written, in
-- both roll-up tables; after a crash, the roll-ups of the samples at or after
-- it are rebuilt from the raw rows. Moved in the transaction that writes the
-- buckets it closes. `clean`: 1 when no minute was open at the last stop
-- (a clean shutdown writes them all), so a start has nothing to rebuild.
-- Keep in step with the other backend's 0015.
CREATE TABLE IF NOT EXISTS historian_rollup_state (
    id             INTEGER PRIMARY KEY CHECK (id = 1),
    closed_through BIGINT NOT NULL,
    clean          INTEGER NOT NULL
);
-- An upgraded database: every roll-up written so far is complete (they were
-- written with their samples), so the watermark starts after the newest one.
INSERT OR IGNORE INTO historian_rollup_state (id, closed_through, clean)
SELECT 1, COALESCE(MAX(bucket) + 60000, -9223372036854775807), 1 FROM samples_minute;
