-- Publishing, the owner's downloads and live progress (issue 12).
--
-- `held`: the owner asked for publication, but the pre-flight check raised red flags (metres,
-- most targets without an estimate, objects the dataset lacks): the submission stays private
-- until its owner confirms.
ALTER TABLE submissions ADD COLUMN held BIGINT NOT NULL DEFAULT 0;
-- `work`: estimate evaluations the job takes (evaluated estimates summed over its protocols):
-- the pre-flight's count at upload, the evaluator's once done. `work_done` is written by the
-- worker while it runs, `eval_ms` once it is done: together the speed measured on this server.
ALTER TABLE submissions ADD COLUMN work BIGINT NOT NULL DEFAULT 0;
ALTER TABLE submissions ADD COLUMN work_done BIGINT NOT NULL DEFAULT 0;
ALTER TABLE submissions ADD COLUMN eval_ms BIGINT;
-- Every evaluated estimate's errors against each ground-truth instance (the layout of
-- `poseboard eval --errors-out`), gzip-compressed JSON, one row per submission and protocol,
-- written with the scores.
CREATE TABLE estimate_errors (
    submission_id BIGINT NOT NULL REFERENCES submissions(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    rows_count BIGINT NOT NULL,
    gzip BYTEA NOT NULL,
    created_at BIGINT NOT NULL,
    PRIMARY KEY (submission_id, protocol)
);
