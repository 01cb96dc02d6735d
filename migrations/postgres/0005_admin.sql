-- Administrators can hide submissions (kept, but shown to nobody else) and every action of
-- theirs is recorded.
ALTER TABLE submissions ADD COLUMN hidden BIGINT NOT NULL DEFAULT 0;

CREATE TABLE audit_log (
    id BIGSERIAL PRIMARY KEY,
    actor_id BIGINT NOT NULL REFERENCES users(id),
    action TEXT NOT NULL,
    target TEXT NOT NULL,
    at BIGINT NOT NULL
);
