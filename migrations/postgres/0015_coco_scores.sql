-- The scores of the BOP'22 2D tasks (`bop22-det`, `bop22-seg`): one row per submission, apart
-- from `scores`, whose columns and per-object table are the 6D protocols'. A 2D submission is
-- marked by its task in `submissions.protocols`. `ap` is what the boards rank by; the whole
-- CocoReport (the twelve AP/AR numbers and the precision-recall curves) is kept as JSON.
CREATE TABLE coco_scores (
    id BIGSERIAL PRIMARY KEY,
    submission_id BIGINT NOT NULL UNIQUE REFERENCES submissions(id) ON DELETE CASCADE,
    task TEXT NOT NULL,
    ap DOUBLE PRECISION NOT NULL,
    time_avg DOUBLE PRECISION,
    entries_evaluated BIGINT NOT NULL,
    report_json TEXT NOT NULL,
    created_at BIGINT NOT NULL
);
CREATE INDEX coco_scores_task ON coco_scores (task, ap);
