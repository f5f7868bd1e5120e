//! What happens to a robot ([`Input`]) and what it publishes ([`Output`]), and the one
//! mapping between them and the wire: which topic each travels on, its bytes (and its
//! JSON, as recordings hold it), and which topics a robot reads at all. The daemon, the
//! recorder and the evaluation's simulated bus all go through here.

use spwi_proto::keys::Topic;
use spwi_proto::*;

/// Everything that can happen to a robot.
// Each input is made once and moved into the engine once: a share's 336 bytes beside a
// membership's few cost nothing worth a box on every message.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    Frame(DetectionFrame),
    /// A peer's share of a tick, its vote inside.
    Embedding(EmbeddingMsg),
    /// The ballots a peer holds for a tick.
    Ballots(BallotsMsg),
    /// Where a member's map puts the stations (sent when a robot joins).
    Map(MapMsg),
    /// The lessons a member learned lately (sent when a robot joins).
    History(HistoryMsg),
    MemberJoined(RobotId),
    MemberLeft(RobotId),
    /// Time passed: deadlines may have expired.
    Poll,
}

impl Input {
    /// The tick the input is for, if it names one.
    pub fn tick(&self) -> Option<u64> {
        match self {
            Input::Frame(f) => Some(f.tick()),
            Input::Embedding(e) => Some(e.tick),
            Input::Ballots(b) => Some(b.tick),
            Input::Map(_) | Input::History(_) | Input::MemberJoined(_) | Input::MemberLeft(_) | Input::Poll => None,
        }
    }
}

/// What the robot publishes.
#[allow(clippy::large_enum_variant)] // as for `Input`: made once, published once
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Our share of a tick, our vote inside.
    Embedding(EmbeddingMsg),
    /// Our vote again, alone, for observers (peers read it in our share).
    Vote(VoteMsg),
    Ballots(BallotsMsg),
    Decision(DecisionMsg),
    /// Our team map, for a robot that just joined.
    Map(MapMsg),
    /// The lessons we learned lately, for a robot that just joined.
    History(HistoryMsg),
}

/// The topics a robot reads: its own detections, and its peers' shares, ballots, maps
/// and histories. Votes alone and decisions are for observers: a robot reads both in
/// its peers' shares (the vote inside, the verdict in brief).
pub const TOPICS_READ: [Topic; 5] = [Topic::Detections, Topic::Embedding, Topic::Ballots, Topic::Map, Topic::History];

/// How a message is written down: on the wire (the codec's bytes) or in a recording
/// (JSON, which a viewer reads). One mapping of messages to topics serves both.
#[derive(Debug, Clone, Copy)]
enum Form {
    Wire,
    Recording,
}

impl Form {
    fn write<M: Message>(self, m: &M) -> Vec<u8> {
        match self {
            Form::Wire => encode(m),
            Form::Recording => to_json(m),
        }
    }

    /// A message of this form; on the wire, one `from` published must name it.
    fn read<M: Message>(self, bytes: &[u8], from: Option<&RobotId>) -> Result<M, DecodeError> {
        match (self, from) {
            (Form::Wire, Some(robot)) => decode_from(bytes, robot),
            (Form::Wire, None) => decode(bytes),
            (Form::Recording, _) => from_json(bytes),
        }
    }
}

impl Input {
    /// A message that `from` published on `topic`, as the engine takes it; the message
    /// must name `from` as its robot. `Ok(None)` for a topic robots do not read
    /// ([`TOPICS_READ`]).
    pub fn from_peer(topic: Topic, from: &RobotId, bytes: &[u8]) -> Result<Option<Input>, DecodeError> {
        Input::read(Form::Wire, topic, bytes, Some(from))
    }

    /// A message input as a recording holds it: JSON ([`to_json`]; its origin was
    /// checked on arrival).
    pub fn from_recording(topic: Topic, json: &[u8]) -> Result<Option<Input>, DecodeError> {
        Input::read(Form::Recording, topic, json, None)
    }

    /// The topic and bytes of a message input; `None` for membership and polls.
    pub fn to_wire(&self) -> Option<(Topic, Vec<u8>)> {
        self.write(Form::Wire)
    }

    /// The topic and JSON of a message input, as a recording holds it; `None` for
    /// membership and polls.
    pub fn to_recording(&self) -> Option<(Topic, Vec<u8>)> {
        self.write(Form::Recording)
    }

    fn read(form: Form, topic: Topic, bytes: &[u8], from: Option<&RobotId>) -> Result<Option<Input>, DecodeError> {
        Ok(Some(match topic {
            Topic::Detections => Input::Frame(form.read(bytes, from)?),
            Topic::Embedding => Input::Embedding(form.read(bytes, from)?),
            Topic::Ballots => Input::Ballots(form.read(bytes, from)?),
            Topic::Map => Input::Map(form.read(bytes, from)?),
            Topic::History => Input::History(form.read(bytes, from)?),
            Topic::Vote | Topic::Decision => return Ok(None),
        }))
    }

    fn write(&self, form: Form) -> Option<(Topic, Vec<u8>)> {
        Some(match self {
            Input::Frame(m) => (Topic::Detections, form.write(m)),
            Input::Embedding(m) => (Topic::Embedding, form.write(m)),
            Input::Ballots(m) => (Topic::Ballots, form.write(m)),
            Input::Map(m) => (Topic::Map, form.write(m)),
            Input::History(m) => (Topic::History, form.write(m)),
            Input::MemberJoined(_) | Input::MemberLeft(_) | Input::Poll => return None,
        })
    }
}

impl Output {
    /// The topic it is published on, and its bytes.
    pub fn to_wire(&self) -> (Topic, Vec<u8>) {
        self.write(Form::Wire)
    }

    /// The topic it is published on, and its JSON, as a recording holds it.
    pub fn to_recording(&self) -> (Topic, Vec<u8>) {
        self.write(Form::Recording)
    }

    /// An output as a recording holds it (JSON). `Ok(None)` for a topic robots do not
    /// publish (detections).
    pub fn from_recording(topic: Topic, json: &[u8]) -> Result<Option<Output>, DecodeError> {
        let form = Form::Recording;
        Ok(Some(match topic {
            Topic::Embedding => Output::Embedding(form.read(json, None)?),
            Topic::Vote => Output::Vote(form.read(json, None)?),
            Topic::Ballots => Output::Ballots(form.read(json, None)?),
            Topic::Decision => Output::Decision(form.read(json, None)?),
            Topic::Map => Output::Map(form.read(json, None)?),
            Topic::History => Output::History(form.read(json, None)?),
            Topic::Detections => return Ok(None),
        }))
    }

    fn write(&self, form: Form) -> (Topic, Vec<u8>) {
        match self {
            Output::Embedding(m) => (Topic::Embedding, form.write(m)),
            Output::Vote(m) => (Topic::Vote, form.write(m)),
            Output::Ballots(m) => (Topic::Ballots, form.write(m)),
            Output::Decision(m) => (Topic::Decision, form.write(m)),
            Output::Map(m) => (Topic::Map, form.write(m)),
            Output::History(m) => (Topic::History, form.write(m)),
        }
    }

    /// What a peer takes in of it: `None` for votes alone and decisions, which robots
    /// do not read ([`TOPICS_READ`]).
    pub fn to_peer(&self) -> Option<Input> {
        match self {
            Output::Embedding(m) => Some(Input::Embedding(m.clone())),
            Output::Ballots(m) => Some(Input::Ballots(m.clone())),
            Output::Map(m) => Some(Input::Map(m.clone())),
            Output::History(m) => Some(Input::History(m.clone())),
            Output::Vote(_) | Output::Decision(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every output a robot publishes on a topic robots read comes back as the input
    /// its peers take; the others are read by no robot.
    #[test]
    fn what_robots_publish_and_read_round_trips_through_the_wire() {
        let robot = RobotId::new("r1").unwrap();
        let outputs = [
            Output::Map(MapMsg { robot: robot.clone(), instance: 7, stations: Default::default() }),
            Output::Ballots(BallotsMsg { robot: robot.clone(), instance: 7, tick: 3, votes: vec![] }),
            Output::History(HistoryMsg { robot: robot.clone(), instance: 7, lessons: vec![] }),
        ];
        for o in outputs {
            let (topic, bytes) = o.to_wire();
            assert!(TOPICS_READ.contains(&topic));
            assert_eq!(Input::from_peer(topic, &robot, &bytes).unwrap(), o.to_peer());
            let (same, json) = o.to_recording();
            assert_eq!((same, Output::from_recording(topic, &json).unwrap()), (topic, Some(o.clone())));
            let other = RobotId::new("r2").unwrap();
            assert!(Input::from_peer(topic, &other, &bytes).is_err(), "a message must name its publisher");
        }
        for topic in [Topic::Vote, Topic::Decision] {
            assert!(!TOPICS_READ.contains(&topic));
            assert_eq!(Input::from_peer(topic, &robot, b"anything").unwrap(), None);
        }
    }
}
