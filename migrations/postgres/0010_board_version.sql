-- The version of everything a leaderboard shows: bumped in the same transaction as every change
-- that can alter a board (a job finishing, a submission hidden, shown, re-run or deleted, a
-- method's metadata, a dataset registered, retired or revived). Servers keep rendered boards in
-- memory and compare this one number to know when theirs are stale, whichever process (another
-- server, a worker on another machine) made the change.
CREATE TABLE board_version (
    id BIGINT PRIMARY KEY CHECK (id = 1),
    version BIGINT NOT NULL
);
INSERT INTO board_version (id, version) VALUES (1, 0);
