-- Method names are unique per account, not across the service: a taken name must not reveal
-- that another account's (possibly private) method exists. The unused `public` column goes too
-- (a method is public when it has a public submission).
ALTER TABLE methods DROP CONSTRAINT methods_name_key;
ALTER TABLE methods DROP COLUMN public;
CREATE UNIQUE INDEX methods_owner_name ON methods (owner_id, name);
