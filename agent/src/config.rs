//! The agent's configuration: a TOML file with defaults for everything, then
//! environment overrides (`SPWI_*`), then [`AgentConfig::validate`], which names the
//! field and the allowed range of anything out of bounds. Zenoh's own settings are not
//! here: they stay Zenoh's (see [`crate::zenoh_config`]).

use crate::floor::CameraCalibration;
use crate::model::Backend;
use crate::temporal::TemporalModel;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AgentConfig {
    pub tick: TickConfig,
    /// The robot's camera: what back-projection onto the floor needs.
    pub camera: CameraCalibration,
    pub models: ModelsConfig,
    pub http: HttpConfig,
    pub log: LogConfig,
}

/// When a robot stops waiting for its peers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TickConfig {
    /// Which GRU the robot runs.
    pub temporal: TemporalModel,
    /// Decide with the votes at hand this long after a tick starts (ms).
    pub decision_deadline_ms: u64,
    /// Relay the ballots held for a tick this long after it starts (ms; 0: never).
    pub relay_ms: u64,
    /// How many members relay each tick's ballots: a different few each tick, every
    /// member when the fleet has no more (`agent/src/engine.rs`, `Engine::relays`).
    pub relayers: u32,
    /// How many times between the relay time and the deadline a robot still waiting
    /// for a member's vote sends the ballots it holds, which asks the tick's relayers
    /// for the missing vote; also the most answers a robot gives a tick (0: neither).
    pub ask_rounds: u32,
    /// A camera showing the same worker detection this many frames in a row is frozen:
    /// set aside until it changes (0: never).
    pub stale_after_frames: u32,
    /// How votes become the decision: "paper" (normalised shares of visibility and
    /// confidence) or "trust" (evidence weighted by each voter's record and view).
    pub consensus: ConsensusRule,
    /// Weight of visibility in the paper's rule; default: the model manifest's.
    pub alpha: Option<f32>,
    /// Weight of confidence in the paper's rule; default: the model manifest's.
    pub beta: Option<f32>,
    /// Decided ticks over which a voter's agreement with the others is averaged.
    pub trust_window_ticks: u32,
    /// Least trust a voter keeps, so that it can earn its trust back.
    pub trust_floor: f32,
    /// Peers trusted less than this leave the fusion of embeddings and worker tracks.
    pub fuse_min_trust: f32,
    /// Voters trusted less than this are not counted while a voter trusted more is,
    /// and never decide a tick alone while a trusted member is live.
    pub count_min_trust: f32,
    /// How many ticks behind our clock's a frame or a peer's message is still taken
    /// (late ones); the window must reach past the decision deadline.
    pub accept_past_ticks: u64,
    /// How many ticks ahead of our clock's a frame or a peer's message is taken (hosts
    /// whose clocks run a little ahead).
    pub accept_ahead_ticks: u64,
    /// Shifts this robot's clock (ms). 0 on a real robot, whose host clock chrony or
    /// PTP keeps in step; tests and benchmarks shift one robot to see what it costs.
    pub clock_offset_ms: i64,
    /// Most ticks in flight at once.
    pub max_open_ticks: usize,
    /// Capacity of the event queue between Zenoh and the tick loop.
    pub event_queue: usize,
}

/// The consensus rule (`crate::consensus`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConsensusRule {
    Paper,
    Trust,
}

impl ConsensusRule {
    /// The name the config file uses.
    pub fn name(self) -> &'static str {
        match self {
            ConsensusRule::Paper => "paper",
            ConsensusRule::Trust => "trust",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelsConfig {
    /// Folder of the model set (holding `manifest.json`).
    pub dir: PathBuf,
    pub backend: Backend,
    /// `libonnxruntime.so` for the ort backend; default: `ORT_DYLIB_PATH`.
    pub ort_library: Option<PathBuf>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HttpConfig {
    /// Address for `/healthz`, `/status` and `/metrics`; none to serve nothing.
    pub listen: Option<SocketAddr>,
    /// `/healthz` answers 503 when frames arrive but no tick was decided for this long
    /// (ms), so that an orchestrator can restart the robot's daemon or raise an alert.
    pub unhealthy_after_ms: u64,
}

impl Default for HttpConfig {
    fn default() -> Self {
        HttpConfig { listen: None, unhealthy_after_ms: 3000 }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    #[default]
    Human,
    Json,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    pub format: LogFormat,
}

impl Default for TickConfig {
    fn default() -> Self {
        TickConfig {
            temporal: TemporalModel::Collective,
            decision_deadline_ms: 60,
            relay_ms: 40,
            relayers: 4,
            ask_rounds: 2,
            stale_after_frames: 5,
            consensus: ConsensusRule::Trust,
            alpha: None,
            beta: None,
            trust_window_ticks: 100,
            trust_floor: 0.1,
            fuse_min_trust: 0.5,
            count_min_trust: 0.5,
            accept_past_ticks: 5,
            accept_ahead_ticks: 2,
            clock_offset_ms: 0,
            max_open_ticks: 64,
            event_queue: 1024,
        }
    }
}

impl Default for ModelsConfig {
    fn default() -> Self {
        ModelsConfig { dir: PathBuf::from("models/default"), backend: Backend::Tract, ort_library: None }
    }
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig { format: LogFormat::Human }
    }
}

/// The environment variables that override the file, and the field each sets.
pub const ENV_OVERRIDES: [(&str, &str); 8] = [
    ("SPWI_MODELS_DIR", "models.dir"),
    ("SPWI_BACKEND", "models.backend"),
    ("SPWI_ORT_LIBRARY", "models.ort_library"),
    ("SPWI_HTTP", "http.listen"),
    ("SPWI_TEMPORAL", "tick.temporal"),
    ("SPWI_DECISION_DEADLINE_MS", "tick.decision_deadline_ms"),
    ("SPWI_LOG_FORMAT", "log.format"),
    ("SPWI_CLOCK_OFFSET_MS", "tick.clock_offset_ms"),
];

impl AgentConfig {
    /// Defaults, overlaid by `file` if given, then by the environment.
    pub fn load(file: Option<&Path>) -> Result<AgentConfig> {
        let mut cfg = match file {
            Some(p) => AgentConfig::from_file(p)?,
            None => AgentConfig::default(),
        };
        cfg.apply_env(|k| std::env::var(k).ok())?;
        Ok(cfg)
    }

    /// Defaults overlaid by `file` alone (no environment), not yet validated.
    pub fn from_file(file: &Path) -> Result<AgentConfig> {
        let text = std::fs::read_to_string(file).with_context(|| format!("cannot read config {}", file.display()))?;
        toml::from_str(&text).with_context(|| format!("config {} is not valid", file.display()))
    }

    /// Applies `SPWI_*` overrides read through `get`.
    pub fn apply_env(&mut self, get: impl Fn(&str) -> Option<String>) -> Result<()> {
        fn parse<T: std::str::FromStr>(var: &str, v: &str) -> Result<T>
        where
            T::Err: std::fmt::Display,
        {
            v.parse().map_err(|e| anyhow::anyhow!("environment variable {var}={v:?}: {e}"))
        }
        fn enum_value<T: serde::de::DeserializeOwned>(var: &str, v: &str) -> Result<T> {
            serde_json::from_value(serde_json::Value::String(v.to_owned()))
                .map_err(|e| anyhow::anyhow!("environment variable {var}={v:?}: {e}"))
        }
        for (var, _) in ENV_OVERRIDES {
            let Some(v) = get(var) else { continue };
            match var {
                "SPWI_MODELS_DIR" => self.models.dir = PathBuf::from(v),
                "SPWI_BACKEND" => self.models.backend = parse(var, &v)?,
                "SPWI_ORT_LIBRARY" => self.models.ort_library = Some(PathBuf::from(v)),
                "SPWI_HTTP" => self.http.listen = if v.is_empty() { None } else { Some(parse(var, &v)?) },
                "SPWI_TEMPORAL" => self.tick.temporal = enum_value(var, &v)?,
                "SPWI_DECISION_DEADLINE_MS" => self.tick.decision_deadline_ms = parse(var, &v)?,
                "SPWI_LOG_FORMAT" => self.log.format = enum_value(var, &v)?,
                "SPWI_CLOCK_OFFSET_MS" => self.tick.clock_offset_ms = parse(var, &v)?,
                _ => unreachable!("every override is handled"),
            }
        }
        Ok(())
    }

    /// Refuses values out of range, naming the field and the range.
    pub fn validate(&self) -> Result<()> {
        let t = &self.tick;
        if !(1..=1000).contains(&t.decision_deadline_ms) {
            bail!("tick.decision_deadline_ms = {}: must be within 1..=1000 (a tick is 100 ms)", t.decision_deadline_ms);
        }
        if t.relay_ms >= t.decision_deadline_ms {
            bail!(
                "tick.relay_ms = {}: must be below tick.decision_deadline_ms ({}) for relays to arrive in time; 0 relays nothing",
                t.relay_ms,
                t.decision_deadline_ms
            );
        }
        if !(1..=1024).contains(&t.relayers) {
            bail!("tick.relayers = {}: must be within 1..=1024 (tick.relay_ms = 0 relays nothing)", t.relayers);
        }
        if t.ask_rounds > 10 {
            bail!("tick.ask_rounds = {}: must be within 0..=10 (0: robots never ask for a missing vote)", t.ask_rounds);
        }
        for (name, v) in [("tick.alpha", t.alpha), ("tick.beta", t.beta)] {
            if let Some(v) = v {
                if !(v.is_finite() && (0.0..=1000.0).contains(&v)) {
                    bail!("{name} = {v}: must be a finite number within 0..=1000");
                }
            }
        }
        if t.alpha == Some(0.0) && t.beta == Some(0.0) {
            bail!("tick.alpha and tick.beta are both 0: at least one must weigh the votes");
        }
        if !(1..=100_000).contains(&t.trust_window_ticks) {
            bail!("tick.trust_window_ticks = {}: must be within 1..=100000", t.trust_window_ticks);
        }
        for (name, v) in [
            ("tick.trust_floor", t.trust_floor),
            ("tick.fuse_min_trust", t.fuse_min_trust),
            ("tick.count_min_trust", t.count_min_trust),
        ] {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                bail!("{name} = {v}: must be within 0..=1");
            }
        }
        if !(1..=600).contains(&t.accept_past_ticks) {
            bail!("tick.accept_past_ticks = {}: must be within 1..=600", t.accept_past_ticks);
        }
        if t.accept_ahead_ticks > 600 {
            bail!("tick.accept_ahead_ticks = {}: must be within 0..=600", t.accept_ahead_ticks);
        }
        let reach_ms = t.accept_past_ticks * spwi_proto::TICK_PERIOD.as_millis() as u64;
        if t.decision_deadline_ms >= reach_ms {
            bail!(
                "tick.accept_past_ticks = {}: the window reaches {reach_ms} ms back, not past tick.decision_deadline_ms ({}): a tick would leave the window before its deadline",
                t.accept_past_ticks,
                t.decision_deadline_ms
            );
        }
        if t.clock_offset_ms.unsigned_abs() > 3_600_000 {
            bail!("tick.clock_offset_ms = {}: must be within ±3600000 (one hour)", t.clock_offset_ms);
        }
        if !(100..=3_600_000).contains(&self.http.unhealthy_after_ms) {
            bail!("http.unhealthy_after_ms = {}: must be within 100..=3600000", self.http.unhealthy_after_ms);
        }
        if !(1..=10_000).contains(&t.max_open_ticks) {
            bail!("tick.max_open_ticks = {}: must be within 1..=10000", t.max_open_ticks);
        }
        if !(16..=1_000_000).contains(&t.event_queue) {
            bail!("tick.event_queue = {}: must be within 16..=1000000", t.event_queue);
        }
        if let Some(problem) = self.camera.problem() {
            bail!("{problem}");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_a_file_overrides_them() {
        AgentConfig::default().validate().unwrap();
        let cfg: AgentConfig = toml::from_str("[tick]\ntemporal = \"ego\"\ndecision_deadline_ms = 80\n").unwrap();
        assert_eq!(cfg.tick.temporal, TemporalModel::Ego);
        assert_eq!(cfg.tick.decision_deadline_ms, 80);
        assert_eq!(cfg.tick.relay_ms, 40);
        // Robots no longer wait for peers' embeddings before voting (protocol 8).
        let e = toml::from_str::<AgentConfig>("[tick]\nembedding_wait_ms = 30\n").unwrap_err().to_string();
        assert!(e.contains("unknown field `embedding_wait_ms`"), "{e}");
    }

    #[test]
    fn unknown_fields_are_refused() {
        let e = toml::from_str::<AgentConfig>("[tick]\ndeadline = 5\n").unwrap_err().to_string();
        assert!(e.contains("deadline"), "{e}");
    }

    #[test]
    fn validate_names_the_field_and_the_range() {
        let mut c = AgentConfig::default();
        c.tick.decision_deadline_ms = 0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("tick.decision_deadline_ms") && e.contains("1..=1000"), "{e}");
        let mut c = AgentConfig::default();
        c.tick.alpha = Some(f32::NAN);
        assert!(c.validate().unwrap_err().to_string().contains("tick.alpha"));
        let c: AgentConfig = toml::from_str("[tick]\ndecision_deadline_ms = 40\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("tick.relay_ms = 40") && e.contains("below tick.decision_deadline_ms (40)"), "{e}");
        let c: AgentConfig = toml::from_str("[tick]\ndecision_deadline_ms = 40\nrelay_ms = 0\n").unwrap();
        c.validate().expect("relaying nothing is allowed");
        let c: AgentConfig = toml::from_str("[tick]\nrelayers = 0\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("tick.relayers = 0") && e.contains("1..=1024"), "{e}");
        let c: AgentConfig = toml::from_str("[tick]\nask_rounds = 11\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("tick.ask_rounds = 11") && e.contains("0..=10"), "{e}");
        let c: AgentConfig = toml::from_str("[tick]\naccept_past_ticks = 1\ndecision_deadline_ms = 150\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("tick.accept_past_ticks = 1") && e.contains("not past tick.decision_deadline_ms (150)"),
            "{e}"
        );
        let c: AgentConfig = toml::from_str("[tick]\nask_rounds = 0\n").unwrap();
        c.validate().expect("never asking is allowed");
        let c: AgentConfig = toml::from_str("[tick]\ntrust_floor = 1.5\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("tick.trust_floor = 1.5") && e.contains("0..=1"), "{e}");
        let c: AgentConfig = toml::from_str("[tick]\nconsensus = \"paper\"\n").unwrap();
        assert_eq!(c.tick.consensus, ConsensusRule::Paper);
        assert_eq!(c.tick.consensus.name(), "paper", "the name the file uses");
        let e = toml::from_str::<AgentConfig>("[tick]\nconsensus = \"loudest\"\n").unwrap_err().to_string();
        assert!(e.contains("consensus") && e.contains("paper") && e.contains("trust"), "{e}");
        let c: AgentConfig = toml::from_str("[camera]\nheight_m = 0.02\n").unwrap();
        assert_eq!(c.camera.fov_deg, 90.0, "unset camera fields keep their defaults");
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("camera.height_m") && e.contains("0.1..=5"), "{e}");
    }

    #[test]
    fn environment_overrides_and_bad_values_name_the_variable() {
        let mut c = AgentConfig::default();
        let env = |k: &str| match k {
            "SPWI_BACKEND" => Some("ort".to_owned()),
            "SPWI_TEMPORAL" => Some("ego".to_owned()),
            "SPWI_HTTP" => Some("127.0.0.1:9000".to_owned()),
            _ => None,
        };
        c.apply_env(env).unwrap();
        assert_eq!(c.models.backend, Backend::Ort);
        assert_eq!(c.tick.temporal, TemporalModel::Ego);
        assert_eq!(c.http.listen, Some("127.0.0.1:9000".parse().unwrap()));
        let e = c.apply_env(|k| (k == "SPWI_DECISION_DEADLINE_MS").then(|| "soon".to_owned())).unwrap_err();
        assert!(e.to_string().contains("SPWI_DECISION_DEADLINE_MS"), "{e}");
    }
}
