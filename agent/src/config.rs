//! The agent's configuration: a TOML file with defaults for everything, then
//! environment overrides (`SPWI_*`), then [`AgentConfig::validate`], which names the
//! field and the allowed range of anything out of bounds. Zenoh's own settings are not
//! here: they stay Zenoh's (see [`crate::zenoh_config`]).

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use spwi_core::floor::{CameraCalibration, FloorPlan};
use spwi_core::model::Backend;
pub use spwi_core::settings::{ConsensusRule, TickConfig};
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
    pub floor: FloorConfig,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FloorConfig {
    /// The factory's floor plan (TOML, `spwi_core::floor::plan`): where its stations
    /// stand, seeding the station map; none to map them from detections alone.
    pub plan: Option<PathBuf>,
}

impl FloorConfig {
    /// Reads the floor plan named, if any; the error names the file and what is wrong.
    pub fn load_plan(&self) -> Result<Option<FloorPlan>> {
        let Some(path) = &self.plan else { return Ok(None) };
        let text = std::fs::read_to_string(path).with_context(|| format!("floor plan {}", path.display()))?;
        let plan = FloorPlan::parse(&text).map_err(|e| anyhow::anyhow!("floor plan {}: {e}", path.display()))?;
        Ok(Some(plan))
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelsConfig {
    /// Folder of the model set (holding `manifest.json`); default: the set `default`
    /// where `spwi_core::model::locate` finds it (the current directory's `models/`,
    /// beside the executable, an installed data directory, …).
    pub dir: Option<PathBuf>,
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

impl Default for ModelsConfig {
    fn default() -> Self {
        ModelsConfig { dir: None, backend: Backend::Tract, ort_library: None }
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
                "SPWI_MODELS_DIR" => self.models.dir = Some(PathBuf::from(v)),
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
        self.tick.validate()?;
        if !(100..=3_600_000).contains(&self.http.unhealthy_after_ms) {
            bail!("http.unhealthy_after_ms = {}: must be within 100..=3600000", self.http.unhealthy_after_ms);
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
    use spwi_core::temporal::TemporalModel;

    #[test]
    fn defaults_are_valid_and_a_file_overrides_them() {
        AgentConfig::default().validate().unwrap();
        let cfg: AgentConfig = toml::from_str("[tick]\ntemporal = \"ego\"\ndecision_deadline_ms = 80\n").unwrap();
        assert_eq!(cfg.tick.temporal, TemporalModel::Ego);
        assert_eq!(cfg.tick.decision_deadline_ms, 80);
        assert_eq!(cfg.tick.relay_ms, 40);
        // A setting this build does not know is refused, naming it.
        let e = toml::from_str::<AgentConfig>("[tick]\nembedding_wait_ms = 30\n").unwrap_err().to_string();
        assert!(e.contains("unknown field `embedding_wait_ms`"), "{e}");
    }

    #[test]
    fn a_floor_plan_is_read_and_a_bad_one_named() {
        let dir = std::env::temp_dir().join(format!("spwi-plan-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("plan.toml");
        std::fs::write(&good, "[stations.storage]\nposition = [1.0, 2.0]\nuncertainty_m = 0.5\n").unwrap();
        let cfg: AgentConfig = toml::from_str(&format!("[floor]\nplan = {:?}\n", good.display().to_string())).unwrap();
        assert_eq!(cfg.floor.load_plan().unwrap().map(|p| p.len()), Some(1));
        assert_eq!(AgentConfig::default().floor.load_plan().unwrap(), None, "no plan: detections alone");

        let missing = FloorConfig { plan: Some(dir.join("nowhere.toml")) };
        let e = format!("{:#}", missing.load_plan().unwrap_err());
        assert!(e.contains("nowhere.toml"), "{e}");
        let bad = dir.join("bad.toml");
        std::fs::write(&bad, "[stations.kitchen]\nposition = [1.0, 2.0]\nuncertainty_m = 0.5\n").unwrap();
        let e = FloorConfig { plan: Some(bad) }.load_plan().unwrap_err().to_string();
        assert!(e.contains("bad.toml") && e.contains("stations.kitchen"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
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
