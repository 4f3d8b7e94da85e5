-- What each panel's fault-isolation sequence must carry across a restart
-- (mode, faulty zones, lockout), as the control crate's JSON. Keep in step
-- with ../sqlite/0002_panel_states.sql.
CREATE TABLE IF NOT EXISTS panel_states (
    panel_id   TEXT PRIMARY KEY,
    state_json TEXT NOT NULL,
    updated_at BIGINT NOT NULL
);
