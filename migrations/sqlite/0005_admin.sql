-- Administrators can hide submissions (kept, but shown to nobody else) and every action of
-- theirs is recorded.
ALTER TABLE submissions ADD COLUMN hidden INTEGER NOT NULL DEFAULT 0;

CREATE TABLE audit_log (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    actor_id INTEGER NOT NULL REFERENCES users(id),
    action TEXT NOT NULL,
    target TEXT NOT NULL,
    at INTEGER NOT NULL
);
