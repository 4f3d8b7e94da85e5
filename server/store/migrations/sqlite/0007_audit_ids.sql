-- The audit trail's record id: a number unique over the site's life, given
-- to each event and alarm transition before it is written, so a record
-- replayed from the audit spool after a crash (between the database's commit
-- and the spool's trim) is recognised and not stored twice
-- (INSERT ... ON CONFLICT (audit_id) DO NOTHING). NULL on rows recorded
-- before this column existed, and on rows written outside the audit trail;
-- a unique index admits any number of NULLs.
-- Keep in step with the other backend's 0006_audit_ids.sql.
ALTER TABLE events ADD COLUMN audit_id INTEGER;
CREATE UNIQUE INDEX IF NOT EXISTS events_audit_id ON events (audit_id);
ALTER TABLE alarm_history ADD COLUMN audit_id INTEGER;
CREATE UNIQUE INDEX IF NOT EXISTS alarm_history_audit_id ON alarm_history (audit_id);
