-- Datasets served by this instance (one row per BOP dataset folder).
CREATE TABLE datasets (
    id BIGSERIAL PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    path TEXT NOT NULL,
    objects_count BIGINT NOT NULL,
    scenes_count BIGINT NOT NULL,
    images_count BIGINT NOT NULL,
    targets_count BIGINT NOT NULL,
    instances_count BIGINT NOT NULL,
    image_width BIGINT NOT NULL,
    image_height BIGINT NOT NULL,
    added_at BIGINT NOT NULL,
    retired BIGINT NOT NULL DEFAULT 0
);

CREATE TABLE methods (
    id BIGSERIAL PRIMARY KEY,
    name TEXT NOT NULL UNIQUE,
    description TEXT NOT NULL DEFAULT '',
    paper_url TEXT NOT NULL DEFAULT '',
    code_url TEXT NOT NULL DEFAULT '',
    public BIGINT NOT NULL DEFAULT 1,
    created_at BIGINT NOT NULL
);

-- A submission is also its evaluation job: the row is the truth about its state.
CREATE TABLE submissions (
    id BIGSERIAL PRIMARY KEY,
    method_id BIGINT NOT NULL REFERENCES methods(id),
    dataset_id BIGINT NOT NULL REFERENCES datasets(id),
    protocols TEXT NOT NULL,
    public BIGINT NOT NULL DEFAULT 1,
    file_name TEXT NOT NULL,
    file_sha256 TEXT NOT NULL,
    file_size BIGINT NOT NULL,
    estimates_count BIGINT NOT NULL,
    preflight_json TEXT NOT NULL,
    status TEXT NOT NULL,
    progress DOUBLE PRECISION NOT NULL DEFAULT 0,
    error TEXT,
    fault TEXT,
    attempts BIGINT NOT NULL DEFAULT 0,
    worker TEXT,
    lease_until BIGINT,
    created_at BIGINT NOT NULL,
    started_at BIGINT,
    finished_at BIGINT,
    evaluator_version TEXT
);
CREATE INDEX submissions_queue ON submissions (status, id);
CREATE INDEX submissions_method ON submissions (method_id);
CREATE UNIQUE INDEX submissions_same_file ON submissions (method_id, dataset_id, file_sha256, protocols);

-- One row per submission and protocol; details in normalised child tables.
CREATE TABLE scores (
    id BIGSERIAL PRIMARY KEY,
    submission_id BIGINT NOT NULL REFERENCES submissions(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    score DOUBLE PRECISION NOT NULL,
    recall DOUBLE PRECISION,
    ar_vsd DOUBLE PRECISION,
    ar_mssd DOUBLE PRECISION,
    ar_mspd DOUBLE PRECISION,
    time_avg DOUBLE PRECISION,
    targets_count BIGINT,
    tp_count BIGINT,
    estimates_evaluated BIGINT NOT NULL,
    estimates_ignored BIGINT NOT NULL,
    report_json TEXT NOT NULL,
    created_at BIGINT NOT NULL,
    UNIQUE (submission_id, protocol)
);

CREATE TABLE object_scores (
    score_id BIGINT NOT NULL REFERENCES scores(id) ON DELETE CASCADE,
    obj_id BIGINT NOT NULL,
    value DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (score_id, obj_id)
);

CREATE TABLE scene_scores (
    score_id BIGINT NOT NULL REFERENCES scores(id) ON DELETE CASCADE,
    scene_id BIGINT NOT NULL,
    value DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (score_id, scene_id)
);

-- Curve points: recall vs theta per tau (series = tau), recall vs visible fraction (series = 0).
CREATE TABLE curve_points (
    score_id BIGINT NOT NULL REFERENCES scores(id) ON DELETE CASCADE,
    curve TEXT NOT NULL,
    series DOUBLE PRECISION NOT NULL,
    x DOUBLE PRECISION NOT NULL,
    y DOUBLE PRECISION NOT NULL,
    PRIMARY KEY (score_id, curve, series, x)
);
