-- When each evaluation worker was last seen alive: it beats when it polls the queue, claims a
-- job and renews a lease. The newest beat tells the pages whether any worker is running (a
-- queued submission with none would otherwise be promised scores that never come) and gives
-- operators the age to alert on. A worker's name holds its host and process, so a restarted
-- process beats under a new name; rows of workers gone for long are pruned by the workers.
CREATE TABLE worker_beats (
    worker TEXT PRIMARY KEY,
    beat_at BIGINT NOT NULL
);
