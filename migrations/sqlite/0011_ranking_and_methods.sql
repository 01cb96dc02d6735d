-- Ranking as on the BOP site. A dataset is core (a column of the main table, counted in the
-- average) when `core` is 1, not when 0; NULL means not decided, and the default rule holds
-- (every dataset but the demo one once another is served). `--core-datasets` given at start
-- sets every dataset's flag; the administrator's toggle changes one.
ALTER TABLE datasets ADD COLUMN core INTEGER;

-- What the BOP site shows of a method, edited by its owner. `modality` stays the input of the
-- pose stage; `detection_modality` is the input of the detection stage.
ALTER TABLE methods ADD COLUMN authors TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN year INTEGER;
ALTER TABLE methods ADD COLUMN detection_modality TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN refinement TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN detections TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN model_scope TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN hardware TEXT NOT NULL DEFAULT '';

-- Hardware belongs to the method now: each method takes the latest hardware its submissions
-- gave.
UPDATE methods SET hardware = (SELECT s.hardware FROM submissions s
    WHERE s.method_id = methods.id AND s.hardware <> '' ORDER BY s.id DESC LIMIT 1)
WHERE EXISTS (SELECT 1 FROM submissions s WHERE s.method_id = methods.id AND s.hardware <> '');

-- A method's entry on a dataset is its best public finished submission there, unless its
-- owner pins another: one pin per method and dataset, for every protocol.
CREATE TABLE entry_pins (
    method_id INTEGER NOT NULL REFERENCES methods(id),
    dataset_id INTEGER NOT NULL REFERENCES datasets(id),
    submission_id INTEGER NOT NULL REFERENCES submissions(id) ON DELETE CASCADE,
    PRIMARY KEY (method_id, dataset_id)
);
