-- Bootstrap 95 % intervals (issue 14): per score, the interval of its headline and its
-- replicates (little-endian f64s, in replicate order), from which the interval of an average
-- over datasets is drawn replicate by replicate. NULL for scores stored before.
ALTER TABLE scores ADD COLUMN ci_low DOUBLE PRECISION;
ALTER TABLE scores ADD COLUMN ci_high DOUBLE PRECISION;
ALTER TABLE scores ADD COLUMN replicates BYTEA;

-- Background re-scoring: a finished submission whose scores an older evaluator computed (or
-- that lack replicates) is flagged `rescore` at start; a worker with nothing else to do takes it
-- with a lease of its own (the submission stays done and on the boards meanwhile), evaluates it
-- again and swaps the scores in one transaction.
ALTER TABLE submissions ADD COLUMN rescore BIGINT NOT NULL DEFAULT 0;
ALTER TABLE submissions ADD COLUMN rescore_worker TEXT;
ALTER TABLE submissions ADD COLUMN rescore_lease_until BIGINT;
ALTER TABLE submissions ADD COLUMN rescore_attempts BIGINT NOT NULL DEFAULT 0;
CREATE INDEX submissions_rescore ON submissions (rescore, id);

-- Every score a re-scoring changed: `score_key` is `score`, `recall`, `ar_vsd`, `ar_mssd`, `ar_mspd`,
-- `time` or `obj_N`; `old_value` or `new_value` is NULL when the number was absent then.
CREATE TABLE score_changes (
    id BIGSERIAL PRIMARY KEY,
    submission_id BIGINT NOT NULL REFERENCES submissions(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    score_key TEXT NOT NULL,
    old_value DOUBLE PRECISION,
    new_value DOUBLE PRECISION,
    old_version TEXT NOT NULL,
    new_version TEXT NOT NULL,
    changed_at BIGINT NOT NULL
);
CREATE INDEX score_changes_submission ON score_changes (submission_id);
