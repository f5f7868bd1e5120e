//! The one encoder and the one decoder of spwi messages.
//!
//! Layout: `version: u16` then the message, both bincode 2 (serde mode, standard
//! config: little-endian, varint lengths). The version is read first so that a peer
//! running another protocol is told apart from garbage. Decoding is bounded by
//! [`MAX_MESSAGE_BYTES`] before anything is allocated, refuses trailing bytes, and
//! validates the result ([`Validate`]).

use crate::id::RobotId;
use crate::messages::*;
use serde::de::DeserializeOwned;
use serde::Serialize;

/// The protocol this build speaks, first in every message. Bumped on every
/// incompatible change of any payload: a message of another version is refused and
/// counted (`DecodeError::UnknownVersion`), never misread.
pub const PROTOCOL_VERSION: u16 = 11;

/// Largest message accepted. A full detection frame (64 objects × 512 floats) is
/// about 135 KB.
pub const MAX_MESSAGE_BYTES: usize = 256 * 1024;

type Config = bincode::config::Configuration<
    bincode::config::LittleEndian,
    bincode::config::Varint,
    bincode::config::Limit<MAX_MESSAGE_BYTES>,
>;

const CONFIG: Config = bincode::config::standard().with_limit::<MAX_MESSAGE_BYTES>();

/// A payload that travels on one of the keys of [`crate::keys`].
pub trait Message: Serialize + DeserializeOwned + Validate {
    /// Name used in errors, logs and metrics.
    const KIND: &'static str;
    /// The robot the payload claims to come from, if it names one.
    fn robot(&self) -> Option<&RobotId>;
}

macro_rules! message {
    ($t:ty, $kind:literal, robot) => {
        impl Message for $t {
            const KIND: &'static str = $kind;
            fn robot(&self) -> Option<&RobotId> {
                Some(&self.robot)
            }
        }
    };
    ($t:ty, $kind:literal) => {
        impl Message for $t {
            const KIND: &'static str = $kind;
            fn robot(&self) -> Option<&RobotId> {
                None
            }
        }
    };
}
message!(DetectionFrame, "detections", robot);
message!(EmbeddingMsg, "embedding", robot);
// A vote travels inside embedding and ballots messages, and alone for observers.
message!(VoteMsg, "vote", robot);
message!(DecisionMsg, "decision", robot);
message!(BallotsMsg, "ballots", robot);
message!(MapMsg, "map", robot);
message!(HistoryMsg, "history", robot);
message!(TruthMsg, "truth");

/// A message as JSON, the form recordings hold it in (a viewer such as Foxglove reads
/// it, with the message's JSON Schema, from `schemars`, on its channel). serde_json writes each `f32` in the fewest
/// digits that read back to the same value, so [`from_json`] returns exactly the
/// message (`tests::json_gives_back_every_f32_exactly`).
pub fn to_json<M: Message>(msg: &M) -> Vec<u8> {
    serde_json::to_vec(msg).expect("a message serialises to JSON")
}

/// A message from its JSON, checked as a decoded one is.
pub fn from_json<M: Message>(bytes: &[u8]) -> Result<M, DecodeError> {
    let msg: M =
        serde_json::from_slice(bytes).map_err(|e| DecodeError::Malformed { kind: M::KIND, reason: e.to_string() })?;
    msg.validate().map_err(|cause| DecodeError::Invalid { kind: M::KIND, cause })?;
    Ok(msg)
}

/// Why bytes were refused. Every variant names what was wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("{kind}: {len} bytes exceeds the limit of {MAX_MESSAGE_BYTES}")]
    TooLarge { kind: &'static str, len: usize },
    #[error("{kind}: protocol version {got}, this build speaks {PROTOCOL_VERSION}")]
    UnknownVersion { kind: &'static str, got: u16 },
    #[error("{kind}: malformed: {reason}")]
    Malformed { kind: &'static str, reason: String },
    #[error("{kind}: {extra} trailing bytes after the message")]
    TrailingBytes { kind: &'static str, extra: usize },
    #[error("{kind}: {cause}")]
    Invalid { kind: &'static str, cause: Invalid },
    #[error("{kind}: published on robot {key:?}'s key but claims to be from {payload:?}")]
    RobotMismatch { kind: &'static str, key: RobotId, payload: RobotId },
}

/// Encodes a message with the protocol version in front.
pub fn encode<M: Message>(msg: &M) -> Vec<u8> {
    // Encoding into a Vec only fails if a serde impl reports an error, which derived
    // impls of these plain structs never do; the limit is not applied on encode.
    bincode::serde::encode_to_vec((PROTOCOL_VERSION, msg), CONFIG).expect("spwi messages always encode")
}

/// Decodes and validates a message.
pub fn decode<M: Message>(bytes: &[u8]) -> Result<M, DecodeError> {
    let kind = M::KIND;
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(DecodeError::TooLarge { kind, len: bytes.len() });
    }
    let malformed = |e: bincode::error::DecodeError| DecodeError::Malformed { kind, reason: e.to_string() };
    let (version, n): (u16, usize) = bincode::serde::decode_from_slice(bytes, CONFIG).map_err(malformed)?;
    if version != PROTOCOL_VERSION {
        return Err(DecodeError::UnknownVersion { kind, got: version });
    }
    let (msg, m): (M, usize) = bincode::serde::decode_from_slice(&bytes[n..], CONFIG).map_err(malformed)?;
    if n + m != bytes.len() {
        return Err(DecodeError::TrailingBytes { kind, extra: bytes.len() - n - m });
    }
    msg.validate().map_err(|cause| DecodeError::Invalid { kind, cause })?;
    Ok(msg)
}

/// Decodes a message received on robot `key_robot`'s key, refusing one whose payload
/// names another robot (a spoofed or misrouted message).
pub fn decode_from<M: Message>(bytes: &[u8], key_robot: &RobotId) -> Result<M, DecodeError> {
    let msg: M = decode(bytes)?;
    match msg.robot() {
        Some(r) if r != key_robot => {
            Err(DecodeError::RobotMismatch { kind: M::KIND, key: key_robot.clone(), payload: r.clone() })
        }
        _ => Ok(msg),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::station::Station;
    use crate::WorkerId;

    /// Recordings hold messages as JSON and replay them bit for bit: every f32 must
    /// come back from serde_json's text as the same bits. Half a million values, spread
    /// over every exponent and mantissa (a step coprime to 2^32 through the bit space).
    #[test]
    fn json_gives_back_every_f32_exactly() {
        let mut bits = 0u32;
        for _ in 0..500_000 {
            bits = bits.wrapping_add(0x9E37_79B9);
            let x = f32::from_bits(bits);
            if !x.is_finite() {
                continue;
            }
            let back: f32 = serde_json::from_str(&serde_json::to_string(&x).unwrap()).unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x:e} came back as {back:e}");
        }
    }

    #[test]
    fn a_message_round_trips_through_json_and_a_bad_one_is_refused_naming_it() {
        let v = vote();
        assert_eq!(from_json::<VoteMsg>(&to_json(&v)).unwrap(), v);
        let bad = String::from_utf8(to_json(&v)).unwrap().replace("\"quality\":0.5", "\"quality\":2.0");
        let e = from_json::<VoteMsg>(bad.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("quality"), "{e}");
        let schema = serde_json::to_value(schemars::schema_for!(VoteMsg)).unwrap();
        assert_eq!(schema["title"], "VoteMsg");
        assert!(schema["properties"]["worker"].is_object(), "{schema}");
    }

    fn vote() -> VoteMsg {
        VoteMsg {
            robot: RobotId::new("r1").unwrap(),
            instance: 7,
            tick: 42,
            steps: vec![StepVote { class: Station::Assembly, confidence: 0.75 }; 21],
            visibility: 5,
            quality: 0.5,
            worker: None,
            signature: Vec::new(),
        }
    }

    /// The worked example of docs/PROTOCOL.md, byte for byte: if the encoding
    /// changes, that page (and every client built from it) must change with it.
    #[test]
    fn the_worked_example_of_the_protocol_page_is_what_the_codec_writes() {
        let map =
            MapMsg { robot: RobotId::new("r1").unwrap(), instance: 7, stations: [Some([1.0, 2.0]), None, None, None] };
        let bytes = encode(&map);
        let expected: Vec<u8> =
            vec![0x0b, 0x02, 0x72, 0x31, 0x07, 0x01, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00];
        assert_eq!(bytes, expected);
        assert_eq!(PROTOCOL_VERSION, 11, "docs/PROTOCOL.md names version 11 and its first byte");
        assert_eq!(decode::<MapMsg>(&bytes).unwrap(), map);
    }

    #[test]
    fn round_trip() {
        let v = vote();
        assert_eq!(decode::<VoteMsg>(&encode(&v)).unwrap(), v);
    }

    #[test]
    fn refuses_trailing_bytes() {
        let mut b = encode(&vote());
        b.push(0);
        assert!(matches!(decode::<VoteMsg>(&b), Err(DecodeError::TrailingBytes { extra: 1, .. })));
    }

    #[test]
    fn refuses_truncation_at_every_length() {
        let b = encode(&vote());
        for n in 0..b.len() {
            assert!(decode::<VoteMsg>(&b[..n]).is_err(), "accepted {n} of {} bytes", b.len());
        }
    }

    #[test]
    fn refuses_other_versions() {
        let b = bincode::serde::encode_to_vec((PROTOCOL_VERSION + 1, vote()), CONFIG).unwrap();
        assert!(
            matches!(decode::<VoteMsg>(&b), Err(DecodeError::UnknownVersion { got, .. }) if got == PROTOCOL_VERSION + 1)
        );
    }

    #[test]
    fn an_old_version_embedding_is_refused_never_misread() {
        // Version 1's embedding message, before the worker estimate and landmarks.
        #[derive(serde::Serialize)]
        struct EmbeddingV1 {
            robot: RobotId,
            instance: u64,
            tick: u64,
            embedding: Option<Vec<f32>>,
            visibility: u32,
        }
        let old =
            EmbeddingV1 { robot: RobotId::new("r1").unwrap(), instance: 1, tick: 9, embedding: None, visibility: 3 };
        let b = bincode::serde::encode_to_vec((1u16, old), CONFIG).unwrap();
        let e = decode::<EmbeddingMsg>(&b).unwrap_err();
        assert!(matches!(e, DecodeError::UnknownVersion { got: 1, .. }), "{e}");
        assert!(e.to_string().contains("protocol version 1"), "{e}");
    }

    /// A current embedding message of robot r1 for tick 9, with nothing in it.
    fn embedding() -> EmbeddingMsg {
        EmbeddingMsg {
            robot: RobotId::new("r1").unwrap(),
            instance: 1,
            tick: 9,
            embedding: None,
            visibility: 3,
            vote: None,
            worker: None,
            facing: None,
            landmarks: Vec::new(),
            verdict: None,
            people: Vec::new(),
        }
    }

    #[test]
    fn people_are_bounded_named_once_and_their_estimates_checked() {
        let at = |x: f32| WorkerEstimate { position: [x, 1.0], velocity: [0.0; 2], covariance: [0.1, 0.0, 0.1] };
        let person = |id: u64, x: f32| PersonShare { worker: WorkerId(id), estimate: at(x) };
        let now = EmbeddingMsg { people: (0..8).map(|i| person(i, i as f32)).collect(), ..embedding() };
        assert_eq!(decode::<EmbeddingMsg>(&encode(&now)).unwrap(), now);
        let refused = |people: Vec<PersonShare>| {
            decode::<EmbeddingMsg>(&encode(&EmbeddingMsg { people, ..embedding() })).unwrap_err().to_string()
        };
        let e = refused((0..9).map(|i| person(i, i as f32)).collect());
        assert!(e.contains("field `people`") && e.contains("9 people, at most 8"), "{e}");
        let e = refused(vec![person(3, 1.0), person(4, 2.0), person(3, 5.0)]);
        assert!(e.contains("field `people.worker`") && e.contains("named twice"), "{e}");
        let mut bad = person(1, 1.0);
        bad.estimate.covariance = [-1.0, 0.0, 0.1];
        let e = refused(vec![bad]);
        assert!(e.contains("field `people.estimate.covariance`"), "{e}");
    }

    #[test]
    fn a_version_10_embedding_without_people_is_refused() {
        #[derive(serde::Serialize)]
        struct EmbeddingV10 {
            robot: RobotId,
            instance: u64,
            tick: u64,
            embedding: Option<Vec<f32>>,
            visibility: u32,
            vote: Option<VoteMsg>,
            worker: Option<WorkerEstimate>,
            facing: Option<f32>,
            landmarks: Vec<Landmark>,
            verdict: Option<Verdict>,
        }
        let e = embedding();
        let old = EmbeddingV10 {
            robot: e.robot,
            instance: e.instance,
            tick: e.tick,
            embedding: None,
            visibility: 3,
            vote: None,
            worker: None,
            facing: None,
            landmarks: Vec::new(),
            verdict: None,
        };
        let b = bincode::serde::encode_to_vec((10u16, old), CONFIG).unwrap();
        let e = decode::<EmbeddingMsg>(&b).unwrap_err();
        assert!(matches!(e, DecodeError::UnknownVersion { got: 10, .. }), "{e}");
    }

    #[test]
    fn a_facing_must_be_finite() {
        let mut now = EmbeddingMsg { facing: Some(-2.5), ..embedding() };
        assert_eq!(decode::<EmbeddingMsg>(&encode(&now)).unwrap(), now);
        now.facing = Some(f32::NAN);
        let e = decode::<EmbeddingMsg>(&encode(&now)).unwrap_err().to_string();
        assert!(e.contains("field `facing`") && e.contains("NaN"), "{e}");
    }

    #[test]
    fn a_version_7_embedding_without_the_vote_is_refused_and_a_verdict_names_its_voters_in_order() {
        #[derive(serde::Serialize)]
        struct EmbeddingV7 {
            robot: RobotId,
            instance: u64,
            tick: u64,
            embedding: Option<Vec<f32>>,
            visibility: u32,
            votes: bool,
            worker: Option<WorkerEstimate>,
            facing: Option<f32>,
            landmarks: Vec<Landmark>,
            verdict: Option<Verdict>,
        }
        let r = |s: &str| RobotId::new(s).unwrap();
        let old = EmbeddingV7 {
            robot: r("r1"),
            instance: 1,
            tick: 9,
            embedding: None,
            visibility: 3,
            votes: false,
            worker: None,
            facing: None,
            landmarks: Vec::new(),
            verdict: None,
        };
        let b = bincode::serde::encode_to_vec((7u16, old), CONFIG).unwrap();
        assert!(matches!(decode::<EmbeddingMsg>(&b), Err(DecodeError::UnknownVersion { got: 7, .. })));
        let verdict = Verdict { tick: 8, class: Some(Station::Assembly), voters: vec![r("r1"), r("r2")], digest: 77 };
        let mut now = EmbeddingMsg { verdict: Some(verdict.clone()), ..embedding() };
        assert_eq!(decode::<EmbeddingMsg>(&encode(&now)).unwrap(), now);
        for voters in [vec![r("r2"), r("r1")], vec![r("r1"), r("r1")]] {
            now.verdict = Some(Verdict { voters, ..verdict.clone() });
            let e = decode::<EmbeddingMsg>(&encode(&now)).unwrap_err().to_string();
            assert!(e.contains("field `verdict.voters`") && e.contains("must be sorted, each once"), "{e}");
        }
    }

    #[test]
    fn the_vote_in_an_embedding_message_is_its_robots_for_its_tick_and_valid() {
        let ours = VoteMsg { instance: 1, tick: 9, ..vote() };
        let now = EmbeddingMsg { vote: Some(ours.clone()), ..embedding() };
        assert_eq!(decode::<EmbeddingMsg>(&encode(&now)).unwrap(), now);
        for other in [
            VoteMsg { tick: 8, ..ours.clone() },
            VoteMsg { instance: 2, ..ours.clone() },
            VoteMsg { robot: RobotId::new("r2").unwrap(), ..ours.clone() },
        ] {
            let e = decode::<EmbeddingMsg>(&encode(&EmbeddingMsg { vote: Some(other), ..embedding() }))
                .unwrap_err()
                .to_string();
            assert!(e.contains("field `vote`") && e.contains("in r1's message of tick 9"), "{e}");
        }
        let bad = VoteMsg { quality: 2.0, ..ours };
        let e = decode::<EmbeddingMsg>(&encode(&EmbeddingMsg { vote: Some(bad), ..embedding() })).unwrap_err();
        assert!(e.to_string().contains("field `quality`"), "{e}");
    }

    #[test]
    fn relayed_ballots_must_be_of_their_tick_and_one_per_origin() {
        let ballots = |votes| BallotsMsg { robot: RobotId::new("r2").unwrap(), instance: 3, tick: 42, votes };
        let ok = ballots(vec![vote(), VoteMsg { robot: RobotId::new("r2").unwrap(), ..vote() }]);
        assert_eq!(decode_from::<BallotsMsg>(&encode(&ok), &ok.robot).unwrap(), ok);
        let other_tick = ballots(vec![VoteMsg { tick: 41, ..vote() }]);
        let e = decode::<BallotsMsg>(&encode(&other_tick)).unwrap_err().to_string();
        assert!(e.contains("votes.tick") && e.contains("tick 41"), "{e}");
        let twice = ballots(vec![vote(), vote()]);
        let e = decode::<BallotsMsg>(&encode(&twice)).unwrap_err().to_string();
        assert!(e.contains("two votes from r1"), "{e}");
        let mut bad = ballots(vec![vote()]);
        bad.votes[0].steps[0].confidence = 1.5;
        assert!(matches!(decode::<BallotsMsg>(&encode(&bad)), Err(DecodeError::Invalid { .. })));
    }

    #[test]
    fn refuses_nan_and_bad_values() {
        let mut v = vote();
        v.steps[3].confidence = f32::NAN;
        assert!(matches!(decode::<VoteMsg>(&encode(&v)), Err(DecodeError::Invalid { .. })));
        let e = decode::<VoteMsg>(&encode(&VoteMsg { quality: 1.5, ..vote() })).unwrap_err().to_string();
        assert!(e.contains("quality") && e.contains("1.5 not in [0, 1]"), "{e}");
        let e = decode::<VoteMsg>(&encode(&VoteMsg { quality: f32::NAN, ..vote() })).unwrap_err().to_string();
        assert!(e.contains("quality"), "{e}");
        let e = decode::<VoteMsg>(&encode(&VoteMsg { signature: vec![1; 10], ..vote() })).unwrap_err().to_string();
        assert!(e.contains("signature") && e.contains("10 bytes"), "{e}");
        let map = |p: [f32; 2]| MapMsg {
            robot: RobotId::new("r1").unwrap(),
            instance: 1,
            stations: [None, Some(p), None, None],
        };
        assert_eq!(decode::<MapMsg>(&encode(&map([3.0, -4.0]))), Ok(map([3.0, -4.0])));
        for bad in [[f32::INFINITY, 0.0], [0.0, 2e4]] {
            let e = decode::<MapMsg>(&encode(&map(bad))).unwrap_err().to_string();
            assert!(e.contains("stations"), "{e}");
        }
    }

    /// A vote as protocol 5 carried it before [`Station`] existed: the class a bare byte.
    #[derive(serde::Serialize)]
    struct VoteWithByteClasses {
        robot: RobotId,
        instance: u64,
        tick: u64,
        steps: Vec<(u8, f32)>,
        visibility: u32,
        quality: f32,
        worker: Option<WorkerEstimate>,
        signature: Vec<u8>,
    }

    fn with_byte_classes(v: &VoteMsg, class: impl Fn(Station) -> u8) -> Vec<u8> {
        let old = VoteWithByteClasses {
            robot: v.robot.clone(),
            instance: v.instance,
            tick: v.tick,
            steps: v.steps.iter().map(|s| (class(s.class), s.confidence)).collect(),
            visibility: v.visibility,
            quality: v.quality,
            worker: v.worker,
            signature: v.signature.clone(),
        };
        bincode::serde::encode_to_vec((PROTOCOL_VERSION, old), CONFIG).unwrap()
    }

    #[test]
    fn a_station_is_the_byte_it_always_was_and_a_byte_naming_none_is_refused() {
        let mut v = vote();
        for (step, s) in v.steps.iter_mut().zip(Station::ALL.into_iter().cycle()) {
            step.class = s;
        }
        let old = with_byte_classes(&v, u8::from);
        assert_eq!(encode(&v), old, "the same bytes as a u8 class");
        assert_eq!(decode::<VoteMsg>(&old).unwrap(), v);
        let e = decode::<VoteMsg>(&with_byte_classes(&v, |s| if s == Station::Manufacturing { 4 } else { s.into() }))
            .unwrap_err();
        assert!(matches!(e, DecodeError::Malformed { .. }), "{e}");
        assert!(e.to_string().contains("station 4 out of range 0..4"), "{e}");
    }

    #[test]
    fn refuses_oversized_and_hostile_lengths() {
        assert!(matches!(decode::<VoteMsg>(&vec![0u8; MAX_MESSAGE_BYTES + 1]), Err(DecodeError::TooLarge { .. })));
        // version 1, robot id with a length prefix of u64::MAX: must fail, not allocate.
        let mut b = bincode::serde::encode_to_vec(PROTOCOL_VERSION, CONFIG).unwrap();
        b.extend([0xfd, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff]);
        assert!(matches!(decode::<VoteMsg>(&b), Err(DecodeError::Malformed { .. })));
    }

    #[test]
    fn refuses_invalid_robot_id_in_payload() {
        let b = bincode::serde::encode_to_vec((PROTOCOL_VERSION, "a/b", 1u64), CONFIG).unwrap();
        assert!(decode::<VoteMsg>(&b).is_err());
    }

    #[test]
    fn refuses_spoofed_robot() {
        let b = encode(&vote());
        let other = RobotId::new("r2").unwrap();
        assert!(matches!(decode_from::<VoteMsg>(&b, &other), Err(DecodeError::RobotMismatch { .. })));
        assert!(decode_from::<VoteMsg>(&b, &RobotId::new("r1").unwrap()).is_ok());
    }
}
