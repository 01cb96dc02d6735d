-- Uploaded result files live in the database, gzip-compressed, one row per content hash (several
-- submissions may share one file), so that a worker on another machine needs nothing but the
-- database and its own copy of the datasets.
CREATE TABLE submission_files (
    sha256 TEXT PRIMARY KEY,
    size BIGINT NOT NULL,
    gzip BYTEA NOT NULL,
    created_at BIGINT NOT NULL
);
-- The content hash of the files that decide a dataset's scores, recorded when the server
-- registers it; a worker whose copy hashes differently refuses its jobs. NULL until the server
-- registers the dataset again.
ALTER TABLE datasets ADD COLUMN content_hash TEXT;
