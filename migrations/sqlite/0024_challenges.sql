-- Challenges (issue 28): an administrator names a set of boards (tasks x dataset groups,
-- narrowed to one category of methods if asked) and a deadline in UTC. At the deadline the
-- service takes a snapshot of the boards by itself, dated at the deadline, and freezes the rows
-- the awards are decided on with the method fields as they were, so that later edits of a
-- method do not change an award.
--
-- Exactly once across every process on the database: a process claims the challenge with a
-- conditional update of `claimed_until` (epoch ms; 0: never claimed), and records
-- `snapshot_id` in the transaction that stores the snapshot, only while it is still NULL.
CREATE TABLE challenges (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    slug TEXT NOT NULL UNIQUE,
    name TEXT NOT NULL,
    -- Board protocols separated by commas, in the order the page shows them.
    tasks TEXT NOT NULL,
    -- Dataset group names separated by commas; the awards are decided on the first.
    board_groups TEXT NOT NULL,
    -- The categories filter; '' for any.
    objects TEXT NOT NULL DEFAULT '',
    onboarding TEXT NOT NULL DEFAULT '',
    deadline INTEGER NOT NULL,
    -- Seconds per image under which a method is fast (the fast award).
    fast_seconds REAL NOT NULL,
    -- The awards given, separated by commas.
    awards TEXT NOT NULL,
    created_by INTEGER NOT NULL REFERENCES users(id),
    created_at INTEGER NOT NULL,
    claimed_until INTEGER NOT NULL DEFAULT 0,
    snapshot_id INTEGER REFERENCES snapshots(id)
);
-- The rows of each task's board over the first group at the deadline, with the method fields
-- as they were then (copied, not joined: a method edited or deleted later changes nothing).
CREATE TABLE challenge_entries (
    challenge_id INTEGER NOT NULL REFERENCES challenges(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    method_id INTEGER NOT NULL,
    method TEXT NOT NULL,
    -- As the public saw it ('anonymous' for a method under double-blind review).
    owner TEXT NOT NULL,
    average REAL,
    mean_time REAL,
    training_data TEXT NOT NULL,
    detection_modality TEXT NOT NULL,
    modality TEXT NOT NULL,
    code_url TEXT NOT NULL,
    model_scope TEXT NOT NULL,
    detections TEXT NOT NULL,
    PRIMARY KEY (challenge_id, protocol, method_id)
);
-- An organiser's decision on an award, in place of its rule's winner (method_id NULL: not
-- awarded), with the note the page shows; every one is also in the audit log.
CREATE TABLE challenge_award_overrides (
    challenge_id INTEGER NOT NULL REFERENCES challenges(id) ON DELETE CASCADE,
    protocol TEXT NOT NULL,
    award TEXT NOT NULL,
    method_id INTEGER,
    note TEXT NOT NULL,
    set_by INTEGER NOT NULL REFERENCES users(id),
    set_at INTEGER NOT NULL,
    PRIMARY KEY (challenge_id, protocol, award)
);
