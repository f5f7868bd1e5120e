//! The wire protocol of spwi: what robots say to each other over Zenoh, and how.
//!
//! Every byte that crosses the network goes through this crate, so that the agent, the
//! simulated world and the tests cannot disagree about the format:
//!
//! ```text
//! id.rs        RobotId / FleetId: validated, one key segment, no wildcards; WorkerId
//! keys.rs      every key expression, built and parsed in one place
//! station.rs   the four stations: what is predicted, voted and decided
//! messages.rs  the payloads (detection frame, embedding, vote, decision, truth)
//! codec.rs     the one `encode` / `decode` pair: version, size limit, validation
//! ```
//!
//! Decoding never panics and never trusts the sender: a hostile length prefix fails
//! without allocating, trailing bytes are refused, every dimension is checked and every
//! float must be finite. A message whose robot id differs from the one in its key is
//! refused too (see [`codec::decode_from`]).

pub mod codec;
pub mod id;
pub mod keys;
pub mod messages;
pub mod station;

pub use codec::{
    decode, decode_from, encode, from_json, to_json, DecodeError, Message, MAX_MESSAGE_BYTES, PROTOCOL_VERSION,
};
pub use id::{FleetId, IdError, RobotId, WorkerId};
pub use messages::*;
pub use station::{Station, UnknownStation, NUM_CLASSES};
