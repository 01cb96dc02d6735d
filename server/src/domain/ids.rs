//! The ids of the service's records, one type each. Every record is keyed by a database
//! integer; as bare `i64`s a method's id could be handed where a submission's is meant and the
//! compiler would not notice (the store has functions taking both side by side). As types they
//! keep their role from the row they are read from, through the services, to the URL they are
//! written into. They read and write as the plain integer in the database, JSON, URLs and
//! templates, so nothing outside the process sees a difference.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

macro_rules! id_type {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(
            Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize,
            sqlx::Type,
        )]
        #[serde(transparent)]
        #[sqlx(transparent)]
        pub struct $name(i64);

        impl $name {
            /// The id of a row as the database numbers it. Ids come from the database (read
            /// back from a row) or from a request (parsed); this is for the few places that
            /// hold a number from elsewhere, such as a test's or the command line's.
            pub const fn new(raw: i64) -> Self {
                $name(raw)
            }

            /// The number, for arithmetic-free uses such as a metric label or an audit target.
            pub const fn get(self) -> i64 {
                self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                fmt::Display::fmt(&self.0, f)
            }
        }

        impl FromStr for $name {
            type Err = std::num::ParseIntError;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                s.parse().map($name)
            }
        }
    };
}

id_type!(
    /// A submission: one uploaded file for one method and dataset.
    SubmissionId
);
id_type!(
    /// A method: a name under an account, with its details.
    MethodId
);
id_type!(
    /// A registered dataset.
    DatasetId
);
id_type!(
    /// An account.
    UserId
);
id_type!(
    /// A snapshot of the leaderboards, taken to be cited.
    SnapshotId
);
id_type!(
    /// A team: accounts that submit methods together.
    TeamId
);
id_type!(
    /// A challenge: boards with a deadline and awards.
    ChallengeId
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_read_and_write_as_the_plain_number() {
        let id: SubmissionId = serde_json::from_str("42").unwrap();
        assert_eq!(id, SubmissionId::new(42));
        assert_eq!(serde_json::to_string(&id).unwrap(), "42");
        assert_eq!(id.to_string(), "42");
        assert_eq!("42".parse::<SubmissionId>().unwrap(), id);
        assert!("4x".parse::<MethodId>().is_err());
    }
}
