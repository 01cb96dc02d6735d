-- Failed sign-ins, per account (`user:NAME`) and per address (`addr:IP`), for rate limiting.
CREATE TABLE login_failures (
    key TEXT NOT NULL,
    at INTEGER NOT NULL
);
CREATE INDEX login_failures_key ON login_failures (key, at);
