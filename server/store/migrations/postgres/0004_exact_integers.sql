-- Integers outside ±2^53 (a u64 counter, an i64 energy register) lose digits
-- in the REAL/float8 value column. Such a sample also keeps its exact decimal
-- digits here; NULL for every other sample, so it costs nothing there.
-- Keep in step with the other backend's 0004_exact_integers.sql.
ALTER TABLE samples ADD COLUMN exact TEXT;
