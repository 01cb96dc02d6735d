-- How far each evaluating host has prepared each dataset (its decoded depth and ground-truth
-- renders, kept in files beside the worker): the workers write it, the datasets page of any
-- server reads it, so a dataset's preparation shows wherever the page is served. One row per
-- dataset and prepared folder of a host; `detail` says why a preparation failed, or what one
-- under way waits for.
CREATE TABLE dataset_preparations (
    dataset_id INTEGER NOT NULL REFERENCES datasets(id),
    host TEXT NOT NULL,
    folder TEXT NOT NULL,
    state TEXT NOT NULL,
    images_done INTEGER NOT NULL,
    images_total INTEGER NOT NULL,
    detail TEXT,
    updated_at INTEGER NOT NULL,
    PRIMARY KEY (dataset_id, host, folder)
);
