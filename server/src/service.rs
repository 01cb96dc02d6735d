//! The use cases: what a user, an administrator or the command line can do (accounts, teams,
//! methods, submissions, publishing, moderation, re-scoring, snapshots, challenges), what each page reads (the
//! leaderboards and their ranking, a submission's details, the inspection of its targets, the
//! public lists, an owner's downloads), each a function over the store that checks the rules of
//! the benchmark. Handlers, the worker and the command line call these; this layer knows nothing
//! of HTTP, so a rule holds whichever way it is reached, and the web layer never reaches the
//! store itself.

pub mod accounts;
pub mod catalogue;
pub mod challenges;
pub mod datasets;
pub mod downloads;
pub mod groups;
pub mod inspection;
pub mod leaderboard;
pub mod methods;
pub mod moderation;
pub mod publishing;
pub mod ranking;
pub mod rescoring;
pub mod snapshots;
pub mod submission_details;
pub mod submissions;
pub mod teams;
pub mod visibility;
