-- Each score's reproducibility record: the evaluator version and the protocol parameters it
-- was computed with, and the content hash of the dataset copy the worker evaluated against
-- (the file's hash is the submission's `file_sha256`). Scores stored before this migration take
-- the version and parameters from their report; their dataset hash was not recorded (NULL).
ALTER TABLE scores ADD COLUMN evaluator_version TEXT;
ALTER TABLE scores ADD COLUMN parameters_json TEXT;
ALTER TABLE scores ADD COLUMN dataset_hash TEXT;
UPDATE scores SET evaluator_version = report_json::json ->> 'evaluator_version',
    parameters_json = (report_json::json -> 'parameters')::text;
