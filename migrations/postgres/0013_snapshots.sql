-- Dated snapshots of every leaderboard, taken by administrators so that a paper can cite a board
-- that will not change under it. Each board (protocol x all datasets or one dataset, as HTML
-- and as JSON) is stored as the bytes the live page served at that moment, gzip-compressed, and
-- served back unchanged. A snapshot is written in two steps (its row first, for the id its pages
-- name in their banner; its boards and `complete` then, in one transaction), so a snapshot whose
-- boards are not all stored is never shown.
CREATE TABLE snapshots (
    id BIGSERIAL PRIMARY KEY,
    taken_at BIGINT NOT NULL,
    taken_by BIGINT NOT NULL REFERENCES users(id),
    complete BIGINT NOT NULL DEFAULT 0
);
CREATE TABLE snapshot_boards (
    snapshot_id BIGINT NOT NULL REFERENCES snapshots(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    -- '' for the board of all datasets.
    dataset TEXT NOT NULL,
    -- 'html' or 'json'.
    format TEXT NOT NULL,
    gzip BYTEA NOT NULL,
    PRIMARY KEY (snapshot_id, protocol, dataset, format)
);
