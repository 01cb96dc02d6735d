-- Curves and per-scene scores are read from the stored report (`scores.report_json`), which the
-- evaluator writes with typed curves; these copies were never read back.
DROP TABLE curve_points;
DROP TABLE scene_scores;
