-- The scores of BOP'24 6D detection (`bop24`): one row per submission, apart from `scores`,
-- whose columns are the localization protocols' recalls. A bop24 submission is marked by
-- `bop24` in `submissions.protocols`. `map` (bop24_mAP) is what the board ranks by, NULL
-- when no ground-truth instance was counted; the whole DetectionReport (every key, the
-- per-object AP per error and threshold, the precision-recall curves) is kept as JSON.
CREATE TABLE bop24_scores (
    id BIGSERIAL PRIMARY KEY,
    submission_id BIGINT NOT NULL UNIQUE REFERENCES submissions(id) ON DELETE CASCADE,
    map DOUBLE PRECISION,
    map_mssd DOUBLE PRECISION,
    map_mssd_mm DOUBLE PRECISION,
    map_mspd DOUBLE PRECISION,
    time_avg DOUBLE PRECISION,
    estimates_evaluated BIGINT NOT NULL,
    report_json TEXT NOT NULL,
    created_at BIGINT NOT NULL
);
CREATE INDEX bop24_scores_map ON bop24_scores (map);
