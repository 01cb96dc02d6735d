-- no-transaction
-- Method names are unique per account, not across the service: a taken name must not reveal
-- that another account's (possibly private) method exists. The unused `public` column goes too
-- (a method is public when it has a public submission). SQLite cannot drop a UNIQUE column
-- constraint, so the table is rebuilt, with foreign keys off as SQLite's documentation asks.
PRAGMA foreign_keys = OFF;
BEGIN;
CREATE TABLE methods_new (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL,
    description TEXT NOT NULL DEFAULT '',
    paper_url TEXT NOT NULL DEFAULT '',
    code_url TEXT NOT NULL DEFAULT '',
    created_at INTEGER NOT NULL,
    training_data TEXT NOT NULL DEFAULT '',
    modality TEXT NOT NULL DEFAULT '',
    owner_id INTEGER REFERENCES users(id)
);
INSERT INTO methods_new (id, name, description, paper_url, code_url, created_at, training_data, modality, owner_id)
    SELECT id, name, description, paper_url, code_url, created_at, training_data, modality, owner_id FROM methods;
DROP TABLE methods;
ALTER TABLE methods_new RENAME TO methods;
CREATE UNIQUE INDEX methods_owner_name ON methods (owner_id, name);
COMMIT;
PRAGMA foreign_keys = ON;
