-- A redundant pair's failover tickets, a kind of their own: a ticket is not
-- a session (no cookie lookup reads this table), it is claimed once (the
-- claim deletes its row), it never outlives the session it was issued from
-- (`expires_at` is at most `session_expires_at`) and dies with it (a claim
-- finds the issuing session's row or fails: a logout, a revocation or the
-- sweep deleting that row ends its tickets). The session a claim starts
-- inherits `session_expires_at` (NULL: never), never a fresh lifetime.
-- Only the SHA-256 of a ticket is kept, as for sessions. Tickets issued
-- before this migration were rows of `sessions`; they expire within their
-- three minutes. Keep in step with ../postgres/0012_handover_tickets.sql.
CREATE TABLE IF NOT EXISTS handover_tickets (
    ticket_hash        TEXT PRIMARY KEY,
    session_hash       TEXT NOT NULL,
    user_name          TEXT NOT NULL,
    role               TEXT NOT NULL,
    created_at         INTEGER NOT NULL,
    expires_at         INTEGER NOT NULL,
    session_expires_at INTEGER
);
CREATE INDEX IF NOT EXISTS handover_tickets_by_session ON handover_tickets (session_hash);
