-- bop24 scores get the interval the other boards have (migrations 0014 and 0019): the
-- bootstrap 95 % interval of bop24_mAP with its replicates (little-endian f64s, in replicate
-- order), so that a bop24 cell and the average over datasets show one as the 6D and 2D ones
-- do. NULL for bop24 scores stored before, and where no interval was drawn (nothing counted).
ALTER TABLE bop24_scores ADD COLUMN ci_low REAL;
ALTER TABLE bop24_scores ADD COLUMN ci_high REAL;
ALTER TABLE bop24_scores ADD COLUMN replicates BLOB;
