-- The 2D tasks' scores get what the 6D scores have (migrations 0014 and 0016): the bootstrap
-- 95 % interval of the AP with its replicates (little-endian f64s, in replicate order), and
-- the reproducibility record (evaluator version, COCOeval's parameters, the content hash of
-- the dataset copy evaluated against). NULL for 2D scores stored before.
ALTER TABLE coco_scores ADD COLUMN ci_low DOUBLE PRECISION;
ALTER TABLE coco_scores ADD COLUMN ci_high DOUBLE PRECISION;
ALTER TABLE coco_scores ADD COLUMN replicates BYTEA;
ALTER TABLE coco_scores ADD COLUMN evaluator_version TEXT;
ALTER TABLE coco_scores ADD COLUMN parameters_json TEXT;
ALTER TABLE coco_scores ADD COLUMN dataset_hash TEXT;
UPDATE coco_scores SET evaluator_version = report_json::json ->> 'evaluator_version';
