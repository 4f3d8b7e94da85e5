-- The lease of a redundant pair (one row per site): which server is active,
-- under which fencing epoch, and until when by the database's clock (ms
-- since 1970). A server takes the row only once it has expired, and each
-- taking raises the epoch, which never goes down. SQLite carries the table
-- for one schema; a pair needs PostgreSQL (`[redundancy]` refuses SQLite).
-- Keep in step with the other backend's 0008_leadership.sql.
CREATE TABLE IF NOT EXISTS leadership (
    site       TEXT PRIMARY KEY,
    holder     TEXT NOT NULL,
    epoch      BIGINT NOT NULL,
    expires_ms BIGINT NOT NULL,
    taken_ms   BIGINT NOT NULL
);

-- Each server of a pair reports itself here with every lease claim, so the
-- HMI can show whether the pair is whole (seen_ms: database clock).
CREATE TABLE IF NOT EXISTS pair_servers (
    site    TEXT NOT NULL,
    server  TEXT NOT NULL,
    url     TEXT NOT NULL,
    active  BOOLEAN NOT NULL,
    seen_ms BIGINT NOT NULL,
    PRIMARY KEY (site, server)
);
