-- What the BOP site asks of a method: training data and input modality; and per submission,
-- the hardware its reported times come from.
ALTER TABLE methods ADD COLUMN training_data TEXT NOT NULL DEFAULT '';
ALTER TABLE methods ADD COLUMN modality TEXT NOT NULL DEFAULT '';
ALTER TABLE submissions ADD COLUMN hardware TEXT NOT NULL DEFAULT '';
