//! The use cases: what a user, an administrator or the command line can do (accounts, methods,
//! submissions, publishing, moderation, re-scoring), each a function over the store that
//! checks the rules of the benchmark. Handlers, the worker and the command line call these; this
//! layer knows nothing of HTTP, so a rule holds whichever way it is reached.

pub mod accounts;
pub mod datasets;
pub mod methods;
pub mod moderation;
pub mod publishing;
pub mod rescoring;
pub mod submissions;
pub mod visibility;
