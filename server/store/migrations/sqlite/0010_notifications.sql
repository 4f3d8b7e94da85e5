-- Alarm notifications (email, webhook) on their way out, so that delivery
-- is retried across a restart, and what was sent, for the record. `message`
-- is the rendered message as JSON (opaque to the store); `alarm_key` is
-- NULL for a flood summary. `level` is the step of the escalation chain.
-- `status`: pending, sent or failed (given up).
-- Keep in step with the other backend's 0010_notifications.sql.
CREATE TABLE IF NOT EXISTS notifications (
    id           INTEGER PRIMARY KEY AUTOINCREMENT,
    created_at   INTEGER NOT NULL,
    route        TEXT NOT NULL,
    contact      TEXT NOT NULL,
    address      TEXT NOT NULL,
    alarm_key    TEXT,
    level        INTEGER NOT NULL,
    subject      TEXT NOT NULL,
    message      TEXT NOT NULL,
    status       TEXT NOT NULL,
    attempts     INTEGER NOT NULL DEFAULT 0,
    next_attempt INTEGER NOT NULL,
    give_up_at   INTEGER NOT NULL,
    last_error   TEXT,
    done_at      INTEGER
);
CREATE INDEX IF NOT EXISTS notifications_due ON notifications (status, next_attempt);
CREATE INDEX IF NOT EXISTS notifications_by_alarm ON notifications (route, alarm_key, created_at);

-- An alarm taken out of service until a set time returns by itself then
-- (NULL: only by hand).
ALTER TABLE alarm_states ADD COLUMN out_of_service_until INTEGER;
