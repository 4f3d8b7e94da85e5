-- Why each alarm transition happened (the alarm engine's TransitionCause:
-- activate, return, ack, shelve, unshelve, shelve_expired, suppress,
-- unsuppress, out_of_service, in_service). The states alone do not tell an
-- activation from a return while an alarm is suppressed, shelved or out of
-- service (both read "Suppressed -> Suppressed"). NULL on rows recorded
-- before this column existed.
ALTER TABLE alarm_history ADD COLUMN cause TEXT;
-- The tag's value at the alarm's latest activation (the value its message
-- shows), with its type ("b:true", "i:-5", "u:18446744073709551615",
-- "f:230.5", "s:text"), so the alarm list can label it beside the value now
-- also after a restart. NULL when unknown.
-- Keep in step with the other backend's 0005_alarm_cause.sql.
ALTER TABLE alarm_states ADD COLUMN activation_value TEXT;
