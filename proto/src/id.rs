//! Validated identifiers. A robot or fleet id becomes one segment of a Zenoh key
//! expression, so it must never contain `/`, `*`, `$` or anything else Zenoh gives a
//! meaning to: only `[A-Za-z0-9_-]{1,64}` is accepted, at parse time and when decoding
//! a message, so an id that made it into a value is safe to put into a key.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Longest id accepted, in bytes.
pub const MAX_ID_LEN: usize = 64;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IdError {
    #[error("{kind} id is empty; use 1 to {MAX_ID_LEN} characters of [A-Za-z0-9_-]")]
    Empty { kind: &'static str },
    #[error("{kind} id is {len} bytes long; at most {MAX_ID_LEN} are allowed")]
    TooLong { kind: &'static str, len: usize },
    #[error("{kind} id {id:?} contains {bad:?}; only [A-Za-z0-9_-] are allowed")]
    BadChar { kind: &'static str, id: String, bad: char },
}

fn check(kind: &'static str, s: &str) -> Result<(), IdError> {
    if s.is_empty() {
        return Err(IdError::Empty { kind });
    }
    if s.len() > MAX_ID_LEN {
        return Err(IdError::TooLong { kind, len: s.len() });
    }
    if let Some(bad) = s.chars().find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-')) {
        return Err(IdError::BadChar { kind, id: s.to_owned(), bad });
    }
    Ok(())
}

macro_rules! id_type {
    ($name:ident, $kind:literal) => {
        #[doc = concat!("A validated ", $kind, " id: one key segment of `[A-Za-z0-9_-]{1,64}`.")]
        #[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
        #[serde(try_from = "String", into = "String")]
        pub struct $name(String);

        impl $name {
            pub fn new(s: impl Into<String>) -> Result<Self, IdError> {
                let s = s.into();
                check($kind, &s)?;
                Ok(Self(s))
            }
            pub fn as_str(&self) -> &str {
                &self.0
            }
        }
        impl FromStr for $name {
            type Err = IdError;
            fn from_str(s: &str) -> Result<Self, IdError> {
                Self::new(s)
            }
        }
        impl TryFrom<String> for $name {
            type Error = IdError;
            fn try_from(s: String) -> Result<Self, IdError> {
                Self::new(s)
            }
        }
        impl From<$name> for String {
            fn from(id: $name) -> String {
                id.0
            }
        }
        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }
        impl schemars::JsonSchema for $name {
            fn schema_name() -> std::borrow::Cow<'static, str> {
                stringify!($name).into()
            }
            fn json_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
                schemars::json_schema!({
                    "type": "string",
                    "pattern": "^[A-Za-z0-9_-]{1,64}$",
                    "description": concat!("A ", $kind, " id"),
                })
            }
        }
    };
}

id_type!(RobotId, "robot");
id_type!(FleetId, "fleet");

/// A worker's id in the team: the same on every robot that tracks the worker, so that
/// what each robot shares of a person names the same person for all. The robot that
/// first tracks a person no peer names mints it from its own robot id, instance and
/// track; robots that see the same person adopt it, and of two ids that turn out to
/// name one person the smaller survives (`spwi_core::floor::team_workers`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(transparent)]
pub struct WorkerId(pub u64);

impl fmt::Display for WorkerId {
    /// The last 16 bits in hex: short enough for a terminal, a log line or a page.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "w{:04x}", self.0 & 0xffff)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_plain_ids() {
        assert_eq!(RobotId::new("robot-7_a").unwrap().as_str(), "robot-7_a");
        assert!(FleetId::new("a".repeat(64)).is_ok());
    }

    #[test]
    fn refuses_anything_zenoh_would_interpret() {
        for bad in ["", "a/b", "*", "**", "a$b", "caf\u{e9}", "a b", "x?y"] {
            assert!(RobotId::new(bad).is_err(), "{bad:?} accepted");
        }
        assert!(matches!(FleetId::new("a".repeat(65)), Err(IdError::TooLong { len: 65, .. })));
    }

    #[test]
    fn error_names_the_kind_and_the_character() {
        let e = RobotId::new("r/1").unwrap_err().to_string();
        assert!(e.contains("robot") && e.contains("'/'"), "{e}");
    }
}
