-- Rate limits as one counter row per key (`signin-addr:IP`, `signin-user:NAME`, `register:IP`),
-- changed only by compare-and-set, so parallel requests are each counted exactly once before any
-- password is hashed. Replaces the failure log, which was read before it was written.
DROP TABLE login_failures;
CREATE TABLE rate_counters (
    key TEXT PRIMARY KEY,
    attempts INTEGER NOT NULL,
    since INTEGER NOT NULL,
    next_at INTEGER NOT NULL
);
-- Addresses an account has signed in from: they skip the account's delay, so failed guesses from
-- elsewhere cannot keep the owner out.
CREATE TABLE sign_in_addresses (
    name TEXT NOT NULL,
    addr TEXT NOT NULL,
    at INTEGER NOT NULL,
    PRIMARY KEY (name, addr)
);
