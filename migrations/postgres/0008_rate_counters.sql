-- Rate limits as one counter row per key (`signin-addr:IP`, `signin-user:NAME`, `register:IP`),
-- changed only by compare-and-set, so parallel requests are each counted exactly once before any
-- password is hashed. Replaces the failure log, which was read before it was written.
DROP TABLE login_failures;
CREATE TABLE rate_counters (
    key TEXT PRIMARY KEY,
    attempts BIGINT NOT NULL,
    since BIGINT NOT NULL,
    next_at BIGINT NOT NULL
);
-- Addresses an account has signed in from: they skip the account's delay, so failed guesses from
-- elsewhere cannot keep the owner out.
CREATE TABLE sign_in_addresses (
    name TEXT NOT NULL,
    addr TEXT NOT NULL,
    at BIGINT NOT NULL,
    PRIMARY KEY (name, addr)
);
