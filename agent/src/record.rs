//! Record and replay. `--record FILE` writes everything the engine saw and said to an
//! MCAP file (the log format Foxglove Studio and ROS 2 tools open): each input with the
//! engine time it was handled at, each output, and the engine's configuration. Replay
//! feeds the recorded inputs, at their recorded times, to a fresh engine with the same
//! models: the engine is deterministic, so it must say exactly what was recorded — a
//! way to reproduce a field incident on a desk, bit for bit, its judgement of its peers
//! (trust, frozen feeds) included.
//!
//! Every channel's messages are JSON, and every channel carries the JSON Schema of what
//! it holds (schema encoding `jsonschema`, named after the message type), so a viewer
//! decodes each message by field: Foxglove's raw-message, plot and state panels show a
//! robot's decisions, votes, membership and where it places the worker. The messages
//! are the wire protocol's (docs/PROTOCOL.md) as JSON: stations as numbers, enums by
//! name, `null` for none; each `f32` reads back to the same bits, so replay is exact.
//!
//! | topic | payload (schema) |
//! |---|---|
//! | `/spwi/config` | the engine configuration and model set name (`RecordedConfig`, once) |
//! | `/spwi/in/detections`, `/spwi/in/embedding`, `/spwi/in/ballots`, `/spwi/in/map`, `/spwi/in/history` | a received message (`DetectionFrame`, `EmbeddingMsg`, `BallotsMsg`, `MapMsg`, `HistoryMsg`) |
//! | `/spwi/in/membership` | `{"robot": …, "alive": …}` (`Membership`) |
//! | `/spwi/in/poll` | `{}`: time passed (`Poll`) |
//! | `/spwi/out/embedding`, `/spwi/out/vote`, `/spwi/out/ballots`, `/spwi/out/decision`, `/spwi/out/map`, `/spwi/out/history` | a published message (`EmbeddingMsg`, `VoteMsg`, `BallotsMsg`, `DecisionMsg`, `MapMsg`, `HistoryMsg`) |
//! | `/spwi/state` | after each decision, whom the robot trusts and whose feed it sets aside (`PeerState`) |
//!
//! Log and publish times are nanoseconds of engine time: the fleet's clock, time since
//! the Unix epoch.

use anyhow::{anyhow, bail, Context, Result};
use serde::{Deserialize, Serialize};
use spwi_core::engine::io::TOPICS_READ;
use spwi_core::engine::{Engine, EngineConfig, Input, Output};
use spwi_core::model::ModelSet;
use spwi_proto::keys::Topic;
use spwi_proto::{BallotsMsg, DecisionMsg, DetectionFrame, EmbeddingMsg, HistoryMsg, MapMsg, VoteMsg};
use spwi_proto::{RobotId, PROTOCOL_VERSION};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// Every channel's message encoding, and its schemas' encoding.
const JSON: &str = "json";
const JSON_SCHEMA: &str = "jsonschema";

/// What `/spwi/config` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RecordedConfig {
    /// The wire protocol the run spoke ([`spwi_proto::PROTOCOL_VERSION`]): a recording
    /// of another protocol is refused rather than misread (absent before protocol 9).
    #[serde(default)]
    pub protocol: u16,
    /// The engine's configuration (`spwi_core::engine::EngineConfig`).
    #[schemars(with = "serde_json::Map<String, serde_json::Value>")]
    pub engine: EngineConfig,
    pub model_set: String,
}

/// The engine's judgement of its peers right after it decided `tick`: the trust it has
/// learned of each robot (itself included), whether its own camera is frozen, and whose
/// feeds it leaves out. Recorded so that a replay is checked on these too, and so that
/// a recording opened in Foxglove shows why a robot's vote weighed what it did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PeerState {
    pub tick: u64,
    pub trust: BTreeMap<RobotId, f32>,
    pub feed_stale: bool,
    pub stale_peers: Vec<RobotId>,
}

impl PeerState {
    pub fn of(engine: &Engine, tick: u64) -> PeerState {
        PeerState { tick, trust: engine.trust(), feed_stale: engine.feed_is_stale(), stale_peers: engine.stale_peers() }
    }

    /// One state per decision among `outputs`, as the engine stands after them.
    pub fn after(engine: &Engine, outputs: &[Output]) -> Vec<PeerState> {
        outputs
            .iter()
            .filter_map(|o| if let Output::Decision(d) = o { Some(PeerState::of(engine, d.tick)) } else { None })
            .collect()
    }
}

/// A member joined (`alive`) or left.
#[derive(Serialize, Deserialize, schemars::JsonSchema)]
#[schemars(rename = "Membership")]
struct MembershipRecord {
    robot: RobotId,
    alive: bool,
}

/// Time passed: the engine was polled (its deadlines checked).
#[derive(Serialize, Deserialize, schemars::JsonSchema)]
struct Poll {}

/// Writes a run to an MCAP file.
pub struct Recorder {
    writer: mcap::Writer<BufWriter<File>>,
    /// MCAP channel id of each [`Channel`], by its index.
    /// Each channel and its id in the file.
    channels: Vec<(Channel, u16)>,
    sequence: u32,
}

/// The channels of a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Channel {
    Config,
    /// A message the robot received on this topic.
    In(Topic),
    InMembership,
    InPoll,
    /// A message the robot published on this topic.
    Out(Topic),
    State,
}

impl Channel {
    /// Every channel, in the order a recording declares them.
    fn all() -> Vec<Channel> {
        let received = TOPICS_READ.into_iter().map(Channel::In);
        let published = Topic::ALL.into_iter().filter(|&t| t != Topic::Detections).map(Channel::Out);
        std::iter::once(Channel::Config)
            .chain(received)
            .chain([Channel::InMembership, Channel::InPoll])
            .chain(published)
            .chain(std::iter::once(Channel::State))
            .collect()
    }

    fn topic(self) -> String {
        match self {
            Channel::Config => "/spwi/config".into(),
            Channel::In(t) => format!("/spwi/in/{}", t.as_str()),
            Channel::InMembership => "/spwi/in/membership".into(),
            Channel::InPoll => "/spwi/in/poll".into(),
            Channel::Out(t) => format!("/spwi/out/{}", t.as_str()),
            Channel::State => "/spwi/state".into(),
        }
    }

    /// The name and JSON Schema of what the channel holds.
    fn schema(self) -> (String, Vec<u8>) {
        fn of<T: schemars::JsonSchema>() -> (String, Vec<u8>) {
            (T::schema_name().into_owned(), serde_json::to_vec(&schemars::schema_for!(T)).expect("a schema"))
        }
        match self {
            Channel::Config => of::<RecordedConfig>(),
            Channel::In(t) | Channel::Out(t) => match t {
                Topic::Detections => of::<DetectionFrame>(),
                Topic::Embedding => of::<EmbeddingMsg>(),
                Topic::Vote => of::<VoteMsg>(),
                Topic::Decision => of::<DecisionMsg>(),
                Topic::Ballots => of::<BallotsMsg>(),
                Topic::Map => of::<MapMsg>(),
                Topic::History => of::<HistoryMsg>(),
            },
            Channel::InMembership => of::<MembershipRecord>(),
            Channel::InPoll => of::<Poll>(),
            Channel::State => of::<PeerState>(),
        }
    }

    fn of_topic(topic: &str) -> Option<Channel> {
        Channel::all().into_iter().find(|c| c.topic() == topic)
    }
}

impl Recorder {
    pub fn create(path: &Path, config: &RecordedConfig) -> Result<Recorder> {
        let file = File::create(path).with_context(|| format!("cannot create recording {}", path.display()))?;
        let mut writer = mcap::WriteOptions::new()
            .profile("spwi")
            .chunk_size(Some(64 * 1024))
            .create(BufWriter::new(file))
            .map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let mut channels = Vec::new();
        for c in Channel::all() {
            let (name, schema) = c.schema();
            let schema = writer.add_schema(&name, JSON_SCHEMA, &schema)?;
            channels.push((c, writer.add_channel(schema, &c.topic(), JSON, &BTreeMap::new())?));
        }
        let mut r = Recorder { writer, channels, sequence: 0 };
        r.write(Channel::Config, Duration::ZERO, &serde_json::to_vec(config)?)?;
        Ok(r)
    }

    fn write(&mut self, channel: Channel, now: Duration, data: &[u8]) -> Result<()> {
        self.sequence += 1;
        let t = now.as_nanos() as u64;
        let header = mcap::records::MessageHeader {
            channel_id: self.channels.iter().find(|(c, _)| *c == channel).expect("every channel is declared").1,
            sequence: self.sequence,
            log_time: t,
            publish_time: t,
        };
        self.writer.write_to_known_channel(&header, data)?;
        Ok(())
    }

    pub fn input(&mut self, input: &Input, now: Duration) -> Result<()> {
        if let Some((topic, json)) = input.to_recording() {
            return self.write(Channel::In(topic), now, &json);
        }
        match input {
            Input::MemberJoined(r) | Input::MemberLeft(r) => {
                let alive = matches!(input, Input::MemberJoined(_));
                let json = serde_json::to_vec(&MembershipRecord { robot: r.clone(), alive })?;
                self.write(Channel::InMembership, now, &json)
            }
            _ => self.write(Channel::InPoll, now, &serde_json::to_vec(&Poll {})?),
        }
    }

    pub fn output(&mut self, output: &Output, now: Duration) -> Result<()> {
        let (topic, json) = output.to_recording();
        self.write(Channel::Out(topic), now, &json)
    }

    pub fn state(&mut self, state: &PeerState, now: Duration) -> Result<()> {
        self.write(Channel::State, now, &serde_json::to_vec(state)?)
    }

    /// Writes the summary and closes the file; a recording cut short (the process
    /// killed) loses at most its last unfinished chunk.
    pub fn finish(mut self) -> Result<()> {
        self.writer.finish()?;
        Ok(())
    }
}

/// A recording read back.
#[derive(Debug, Clone)]
pub struct Recording {
    pub config: RecordedConfig,
    pub inputs: Vec<(Duration, Input)>,
    pub outputs: Vec<Output>,
    pub states: Vec<PeerState>,
}

/// What a replay says: its outputs and its judgements of the peers.
#[derive(Debug, Clone, PartialEq)]
pub struct Replayed {
    pub outputs: Vec<Output>,
    pub states: Vec<PeerState>,
}

/// Reads a recording; any record that does not decode is an error naming its topic
/// and sequence number.
pub fn read(path: &Path) -> Result<Recording> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read recording {}", path.display()))?;
    let mut config = None;
    let (mut inputs, mut outputs, mut states) = (Vec::new(), Vec::new(), Vec::new());
    for m in mcap::MessageStream::new(&bytes).map_err(|e| anyhow!("{}: not an MCAP file: {e}", path.display()))? {
        let m = m.map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let now = Duration::from_nanos(m.log_time);
        let ctx = || format!("{}: record {} on {}", path.display(), m.sequence, m.channel.topic);
        let d = &m.data[..];
        if m.channel.message_encoding != JSON {
            bail!(
                "{}: channel {} holds {:?} messages, not JSON: recorded by an older build; replay it with the \
                 build that made it, or record again",
                path.display(),
                m.channel.topic,
                m.channel.message_encoding
            );
        }
        match Channel::of_topic(&m.channel.topic) {
            Some(Channel::Config) => {
                let raw: serde_json::Value = serde_json::from_slice(d).with_context(ctx)?;
                let protocol = raw.get("protocol").and_then(serde_json::Value::as_u64).unwrap_or(0);
                if protocol != u64::from(PROTOCOL_VERSION) {
                    bail!(
                        "{}: recorded by a build speaking protocol {}, this one speaks {PROTOCOL_VERSION} (ticks \
                         of the fleet's clock, trust observed by the receiver): it cannot replay as it ran; \
                         replay it with the build that made it, or record again",
                        path.display(),
                        if protocol == 0 { "8 or older".to_owned() } else { protocol.to_string() }
                    );
                }
                config = Some(serde_json::from_value(raw).with_context(ctx)?)
            }
            Some(Channel::In(topic)) => {
                let input = Input::from_recording(topic, d).with_context(ctx)?;
                inputs.push((now, input.with_context(ctx)?));
            }
            Some(Channel::InMembership) => {
                let r: MembershipRecord = serde_json::from_slice(d).with_context(ctx)?;
                inputs.push((now, if r.alive { Input::MemberJoined(r.robot) } else { Input::MemberLeft(r.robot) }));
            }
            Some(Channel::InPoll) => inputs.push((now, Input::Poll)),
            Some(Channel::Out(topic)) => {
                outputs.push(Output::from_recording(topic, d).with_context(ctx)?.with_context(ctx)?)
            }
            Some(Channel::State) => states.push(serde_json::from_slice(d).with_context(ctx)?),
            None => bail!("{}: unknown topic {:?} (not a spwi recording?)", path.display(), m.channel.topic),
        }
    }
    let config = config.with_context(|| format!("{}: no /spwi/config record", path.display()))?;
    Ok(Recording { config, inputs, outputs, states })
}

/// Runs the recorded inputs through a fresh engine and returns what it says.
pub fn replay(recording: &Recording, models: &Arc<ModelSet>) -> Result<Replayed> {
    if models.manifest.name != recording.config.model_set {
        bail!(
            "the recording was made with model set {:?}, not {:?}: replay with the same models",
            recording.config.model_set,
            models.manifest.name
        );
    }
    let cfg = recording.config.engine.clone();
    let mut engine = Engine::new(cfg.clone(), models.inference(cfg.temporal)?);
    let (mut outputs, mut states) = (Vec::new(), Vec::new());
    for (now, input) in &recording.inputs {
        let out = engine.handle(input.clone(), *now);
        states.extend(PeerState::after(&engine, &out));
        outputs.extend(out);
    }
    Ok(Replayed { outputs, states })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::TickConfig;
    use spwi_core::manifest::Manifest;

    #[test]
    fn a_recording_of_another_protocol_is_refused_saying_so() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
        let manifest = Manifest::load(&dir).unwrap();
        let engine =
            EngineConfig::new(RobotId::new("r1").unwrap(), 1, &TickConfig::default(), &Default::default(), &manifest);
        let path = std::env::temp_dir().join(format!("spwi-old-recording-{}.mcap", std::process::id()));
        let old = RecordedConfig { protocol: 0, engine, model_set: manifest.name.clone() };
        Recorder::create(&path, &old).unwrap().finish().unwrap();
        let e = format!("{:#}", read(&path).unwrap_err());
        assert!(e.contains("protocol 8 or older") && e.contains(&format!("speaks {PROTOCOL_VERSION}")), "{e}");
        let now = RecordedConfig { protocol: PROTOCOL_VERSION, ..old };
        Recorder::create(&path, &now).unwrap().finish().unwrap();
        assert_eq!(read(&path).unwrap().config, now);
        std::fs::remove_file(path).unwrap();
    }
}
