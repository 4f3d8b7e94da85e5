-- Several sites on one database: every row a server writes for its plant
-- names the site (`[server] site`), so each server reads and writes its own
-- site's rows and may read another's history. Users, sessions and
-- user-drawn screens stay shared by the whole database. Keep in step with
-- ../sqlite/0011_sites.sql.
--
-- Rows written before this migration belong to the database's one site: the
-- site that holds the lease if exactly one does (a redundant pair), else
-- the default site `main`.

ALTER TABLE tags ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE events ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE alarm_states ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE alarm_history ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE dispatches ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE panel_states ADD COLUMN site TEXT NOT NULL DEFAULT 'main';
ALTER TABLE notifications ADD COLUMN site TEXT NOT NULL DEFAULT 'main';

UPDATE tags SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;
UPDATE events SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;
UPDATE alarm_states SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;
UPDATE alarm_history SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;
UPDATE dispatches SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;
UPDATE panel_states SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;
UPDATE notifications SET site = l.site FROM (SELECT min(site) AS site FROM leadership HAVING count(*) = 1) l;

-- A tag name, an alarm and a panel are one site's: two copies of one plant
-- on one database keep apart. Samples and roll-ups follow their tag's id.
ALTER TABLE tags DROP CONSTRAINT tags_name_key;
ALTER TABLE tags ADD CONSTRAINT tags_site_name UNIQUE (site, name);
ALTER TABLE alarm_states DROP CONSTRAINT alarm_states_pkey;
ALTER TABLE alarm_states ADD PRIMARY KEY (site, alarm_key);
ALTER TABLE panel_states DROP CONSTRAINT panel_states_pkey;
ALTER TABLE panel_states ADD PRIMARY KEY (site, panel_id);

-- Each site's audit trail numbers its own records.
DROP INDEX IF EXISTS events_audit_id;
CREATE UNIQUE INDEX IF NOT EXISTS events_audit_id ON events (site, audit_id);
DROP INDEX IF EXISTS alarm_history_audit_id;
CREATE UNIQUE INDEX IF NOT EXISTS alarm_history_audit_id ON alarm_history (site, audit_id);

CREATE INDEX IF NOT EXISTS events_site_ts ON events (site, ts);
CREATE INDEX IF NOT EXISTS alarm_history_site_ts ON alarm_history (site, ts);
CREATE INDEX IF NOT EXISTS dispatches_site_ts ON dispatches (site, ts);
