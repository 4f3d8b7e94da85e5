-- Screens drawn by users in the HMI's editor (or loaded from a plant's
-- screens/*.json), as the configuration crate's screen JSON. `version`
-- increases with every save, so two editors cannot overwrite each other
-- unknowingly. Keep in step with ../sqlite/0003_user_screens.sql.
CREATE TABLE IF NOT EXISTS user_screens (
    screen_id  TEXT PRIMARY KEY,
    name       TEXT NOT NULL,
    version    BIGINT NOT NULL,
    body_json  TEXT NOT NULL,
    updated_at BIGINT NOT NULL,
    updated_by TEXT NOT NULL
);
