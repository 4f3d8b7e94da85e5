-- Historian roll-ups: per tag, per minute and per hour, what a trend needs
-- (count, min, max, sum, first, last) and the Bad time, so a trend over a
-- month or a year reads a few thousand rows instead of millions. Kept up to
-- date as samples are written (store/src/rollup.rs); a bucket is keyed by its
-- start in ms since the epoch, aligned to whole minutes / hours UTC.
-- n: samples in the bucket; n_value: those with a value (min, max, sum are
-- over these). bad_ms: time the tag was Bad, each sample held until the next
-- sample in the same bucket or the bucket's end.
-- Keep in step with the other backend's 0009_rollups.sql.

CREATE TABLE IF NOT EXISTS samples_minute (
    tag_id       INTEGER NOT NULL,
    bucket       INTEGER NOT NULL,
    n            INTEGER NOT NULL,
    n_value      INTEGER NOT NULL,
    min_value    REAL,
    max_value    REAL,
    sum_value    REAL,
    first_ts     INTEGER NOT NULL,
    first_value  REAL,
    last_ts      INTEGER NOT NULL,
    last_value   REAL,
    last_quality INTEGER NOT NULL,
    bad_ms       INTEGER NOT NULL,
    PRIMARY KEY (tag_id, bucket)
) WITHOUT ROWID;

-- Existing samples, rolled up once (a full scan, at this upgrade only).
INSERT INTO samples_minute (tag_id, bucket, n, n_value, min_value, max_value, sum_value,
                first_ts, first_value, last_ts, last_value, last_quality, bad_ms)
SELECT tag_id, bucket, count(*), count(value), min(value), max(value), sum(value),
       min(ts), max(CASE WHEN rn_first = 1 THEN value END),
       max(ts), max(CASE WHEN rn_last = 1 THEN value END),
       max(CASE WHEN rn_last = 1 THEN quality END),
       sum(CASE WHEN quality NOT IN (0, 1)
                THEN coalesce(next_ts, bucket + 60000) - ts ELSE 0 END)
FROM (SELECT tag_id, ts, value, quality, bucket,
             row_number() OVER (PARTITION BY tag_id, bucket ORDER BY ts) AS rn_first,
             row_number() OVER (PARTITION BY tag_id, bucket ORDER BY ts DESC) AS rn_last,
             lead(ts) OVER (PARTITION BY tag_id, bucket ORDER BY ts) AS next_ts
      FROM (SELECT tag_id, ts, value, quality,
                   ts - (((ts % 60000) + 60000) % 60000) AS bucket
            FROM samples) s) w
GROUP BY tag_id, bucket;

CREATE TABLE IF NOT EXISTS samples_hour (
    tag_id       INTEGER NOT NULL,
    bucket       INTEGER NOT NULL,
    n            INTEGER NOT NULL,
    n_value      INTEGER NOT NULL,
    min_value    REAL,
    max_value    REAL,
    sum_value    REAL,
    first_ts     INTEGER NOT NULL,
    first_value  REAL,
    last_ts      INTEGER NOT NULL,
    last_value   REAL,
    last_quality INTEGER NOT NULL,
    bad_ms       INTEGER NOT NULL,
    PRIMARY KEY (tag_id, bucket)
) WITHOUT ROWID;

-- Existing samples, rolled up once (a full scan, at this upgrade only).
INSERT INTO samples_hour (tag_id, bucket, n, n_value, min_value, max_value, sum_value,
                first_ts, first_value, last_ts, last_value, last_quality, bad_ms)
SELECT tag_id, bucket, count(*), count(value), min(value), max(value), sum(value),
       min(ts), max(CASE WHEN rn_first = 1 THEN value END),
       max(ts), max(CASE WHEN rn_last = 1 THEN value END),
       max(CASE WHEN rn_last = 1 THEN quality END),
       sum(CASE WHEN quality NOT IN (0, 1)
                THEN coalesce(next_ts, bucket + 3600000) - ts ELSE 0 END)
FROM (SELECT tag_id, ts, value, quality, bucket,
             row_number() OVER (PARTITION BY tag_id, bucket ORDER BY ts) AS rn_first,
             row_number() OVER (PARTITION BY tag_id, bucket ORDER BY ts DESC) AS rn_last,
             lead(ts) OVER (PARTITION BY tag_id, bucket ORDER BY ts) AS next_ts
      FROM (SELECT tag_id, ts, value, quality,
                   ts - (((ts % 3600000) + 3600000) % 3600000) AS bucket
            FROM samples) s) w
GROUP BY tag_id, bucket;
