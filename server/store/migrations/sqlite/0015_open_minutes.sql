-- The SQLite historian keeps each tag's open minute roll-up in memory
-- (store/src/open_minutes.rs) and writes it once the minute is over.
-- Per site (each server writes its own site's tags): `closed_through`, every
-- minute bucket that starts before it is written, in both roll-up tables;
-- after a crash, the roll-ups of the samples at or after it are rebuilt
-- from the raw rows. Moved in the transaction that writes the buckets it
-- closes. `clean`: 1 when no minute was open at the last stop (a clean
-- shutdown writes them all), so a start has nothing to rebuild.
-- Keep in step with the other backend's 0015.
CREATE TABLE IF NOT EXISTS historian_rollup_state (
    site           TEXT PRIMARY KEY,
    closed_through BIGINT NOT NULL,
    clean          INTEGER NOT NULL
);
-- An upgraded database: every roll-up written so far is complete (they were
-- written with their samples), so the watermark starts after the newest
-- one, but not beyond an hour from now (a sample stamped in the future by a
-- wrong clock is written at once, whatever the watermark).
INSERT OR IGNORE INTO historian_rollup_state (site, closed_through, clean)
SELECT t.site,
       MIN(COALESCE(MAX(m.bucket) + 60000, -9223372036854775807),
           CAST((julianday('now') - 2440587.5) * 86400000 AS INTEGER) + 3600000),
       1
FROM tags t LEFT JOIN samples_minute m ON m.tag_id = t.id
GROUP BY t.site;
