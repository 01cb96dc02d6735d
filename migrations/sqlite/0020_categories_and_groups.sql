-- Issue 28: the categories of the BOP site's separate boards, and named groups of datasets.
--
-- A method declares how it onboards the test objects (`model-based` or `model-free`) and
-- whether it was trained on them (`seen`) or onboards them at test time (`unseen`); '' is not
-- given, and such a method matches no filter on that field (it shows on the unfiltered board).
ALTER TABLE methods ADD COLUMN onboarding TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN objects TEXT NOT NULL DEFAULT '';

-- A group of datasets is a board's columns: a method is ranked by its mean over the group's
-- served, non-retired members. Members are dataset names, not ids, so that a group may name a
-- dataset this server does not serve yet (BOP's groups are fixed; a server serves some of
-- them). The default group, `core`, is not stored here: it is the datasets' `core` flags and
-- their default rule (migration 0011), which `--core-datasets` and the core toggle set.
CREATE TABLE dataset_groups (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL UNIQUE,
    created_at INTEGER NOT NULL
);
CREATE TABLE dataset_group_members (
    group_id INTEGER NOT NULL REFERENCES dataset_groups(id) ON DELETE CASCADE,
    dataset TEXT NOT NULL,
    PRIMARY KEY (group_id, dataset)
);

-- The BOP Challenge's groups, by BOP's dataset folder names.
INSERT INTO dataset_groups (name, created_at) VALUES
    ('BOP-Classic-Core', 0), ('BOP-Industrial', 0), ('BOP-H3', 0);
INSERT INTO dataset_group_members (group_id, dataset)
    SELECT g.id, d.name FROM dataset_groups g, (
        SELECT 'BOP-Classic-Core' AS grp, 'lmo' AS name
        UNION ALL SELECT 'BOP-Classic-Core', 'tless'
        UNION ALL SELECT 'BOP-Classic-Core', 'tudl'
        UNION ALL SELECT 'BOP-Classic-Core', 'icbin'
        UNION ALL SELECT 'BOP-Classic-Core', 'itodd'
        UNION ALL SELECT 'BOP-Classic-Core', 'hb'
        UNION ALL SELECT 'BOP-Classic-Core', 'ycbv'
        UNION ALL SELECT 'BOP-Industrial', 'ipd'
        UNION ALL SELECT 'BOP-Industrial', 'xyzibd'
        UNION ALL SELECT 'BOP-Industrial', 'itoddmv'
        UNION ALL SELECT 'BOP-H3', 'hot3d'
        UNION ALL SELECT 'BOP-H3', 'hopev2'
        UNION ALL SELECT 'BOP-H3', 'handal'
    ) d WHERE g.name = d.grp;
