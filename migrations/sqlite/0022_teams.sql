-- Teams: several accounts submitting one method together, as on EvalAI and Codabench. A team
-- has a unique name (it is shown as the owner of its methods and appears in URLs), the account
-- that created it (who may remove members), its members, and the invitations that wait for
-- the invited account to accept.
CREATE TABLE teams (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL UNIQUE,
    creator_id INTEGER NOT NULL REFERENCES users(id),
    created_at INTEGER NOT NULL
);

CREATE TABLE team_members (
    team_id INTEGER NOT NULL REFERENCES teams(id),
    user_id INTEGER NOT NULL REFERENCES users(id),
    joined_at INTEGER NOT NULL,
    PRIMARY KEY (team_id, user_id)
);

CREATE TABLE team_invitations (
    team_id INTEGER NOT NULL REFERENCES teams(id),
    user_id INTEGER NOT NULL REFERENCES users(id),
    invited_by INTEGER NOT NULL REFERENCES users(id),
    created_at INTEGER NOT NULL,
    PRIMARY KEY (team_id, user_id)
);

-- A team's method belongs to the team, not to the member who first submitted it: its
-- `owner_id` is NULL and `team_id` names the team, so that whoever leaves the team leaves the
-- method with it. Its names are unique per team as a personal method's are per account
-- (NULLs are distinct in a unique index, so personal methods are not constrained by this one).
ALTER TABLE methods ADD COLUMN team_id INTEGER REFERENCES teams(id);
CREATE UNIQUE INDEX methods_team_name ON methods (team_id, name);
CREATE INDEX team_members_user ON team_members (user_id);
CREATE INDEX team_invitations_user ON team_invitations (user_id);
