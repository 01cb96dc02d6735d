-- Datasets served by this instance (one row per BOP dataset folder).
CREATE TABLE datasets (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL UNIQUE,
    path TEXT NOT NULL,
    objects_count INTEGER NOT NULL,
    scenes_count INTEGER NOT NULL,
    images_count INTEGER NOT NULL,
    targets_count INTEGER NOT NULL,
    instances_count INTEGER NOT NULL,
    image_width INTEGER NOT NULL,
    image_height INTEGER NOT NULL,
    added_at INTEGER NOT NULL,
    retired INTEGER NOT NULL DEFAULT 0
);

CREATE TABLE methods (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL UNIQUE,
    description TEXT NOT NULL DEFAULT '',
    paper_url TEXT NOT NULL DEFAULT '',
    code_url TEXT NOT NULL DEFAULT '',
    public INTEGER NOT NULL DEFAULT 1,
    created_at INTEGER NOT NULL
);

-- A submission is also its evaluation job: the row is the truth about its state.
CREATE TABLE submissions (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    method_id INTEGER NOT NULL REFERENCES methods(id),
    dataset_id INTEGER NOT NULL REFERENCES datasets(id),
    protocols TEXT NOT NULL,
    public INTEGER NOT NULL DEFAULT 1,
    file_name TEXT NOT NULL,
    file_sha256 TEXT NOT NULL,
    file_size INTEGER NOT NULL,
    estimates_count INTEGER NOT NULL,
    preflight_json TEXT NOT NULL,
    status TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    error TEXT,
    fault TEXT,
    attempts INTEGER NOT NULL DEFAULT 0,
    worker TEXT,
    lease_until INTEGER,
    created_at INTEGER NOT NULL,
    started_at INTEGER,
    finished_at INTEGER,
    evaluator_version TEXT
);
CREATE INDEX submissions_queue ON submissions (status, id);
CREATE INDEX submissions_method ON submissions (method_id);
CREATE UNIQUE INDEX submissions_same_file ON submissions (method_id, dataset_id, file_sha256, protocols);

-- One row per submission and protocol; details in normalised child tables.
CREATE TABLE scores (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    submission_id INTEGER NOT NULL REFERENCES submissions(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    score REAL NOT NULL,
    recall REAL,
    ar_vsd REAL,
    ar_mssd REAL,
    ar_mspd REAL,
    time_avg REAL,
    targets_count INTEGER,
    tp_count INTEGER,
    estimates_evaluated INTEGER NOT NULL,
    estimates_ignored INTEGER NOT NULL,
    report_json TEXT NOT NULL,
    created_at INTEGER NOT NULL,
    UNIQUE (submission_id, protocol)
);

CREATE TABLE object_scores (
    score_id INTEGER NOT NULL REFERENCES scores(id) ON DELETE CASCADE,
    obj_id INTEGER NOT NULL,
    value REAL NOT NULL,
    PRIMARY KEY (score_id, obj_id)
);

CREATE TABLE scene_scores (
    score_id INTEGER NOT NULL REFERENCES scores(id) ON DELETE CASCADE,
    scene_id INTEGER NOT NULL,
    value REAL NOT NULL,
    PRIMARY KEY (score_id, scene_id)
);

-- Curve points: recall vs theta per tau (series = tau), recall vs visible fraction (series = 0).
CREATE TABLE curve_points (
    score_id INTEGER NOT NULL REFERENCES scores(id) ON DELETE CASCADE,
    curve TEXT NOT NULL,
    series REAL NOT NULL,
    x REAL NOT NULL,
    y REAL NOT NULL,
    PRIMARY KEY (score_id, curve, series, x)
);
