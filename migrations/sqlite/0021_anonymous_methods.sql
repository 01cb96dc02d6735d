-- A method under double-blind review: every public page, board, export, snapshot and feed
-- names its owner "anonymous" and leaves out its authors, paper and code links, until the
-- owner reveals it (0 again). Its owner and the administrators see everything meanwhile.
ALTER TABLE methods ADD COLUMN anonymous INTEGER NOT NULL DEFAULT 0;
