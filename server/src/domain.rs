//! Values that come from outside, parsed and checked once at the edge (`intake::domain`,
//! which the fuzz targets reach without the server), and the ids of the service's records.

mod ids;

pub use ids::{ChallengeId, DatasetId, MethodId, SnapshotId, SubmissionId, TeamId, UserId};
pub use intake::domain::*;
