//! An agent in this process: the daemon's own code (`spwi_agent::daemon::run`) with a
//! Zenoh session of its own, connected to the hub like any robot. The demo runs its
//! fleet this way, and the tests that need no real process.

use super::Hub;
use anyhow::{anyhow, Context, Result};
use spwi_agent::config::AgentConfig;
use spwi_agent::daemon::{self, Options, Started};
use spwi_core::model::ModelSet;
use spwi_proto::RobotId;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;
use tokio::task::JoinHandle;

/// How long starting (sessions opened, subscriptions declared) or stopping may take.
const WITHIN: Duration = Duration::from_secs(10);

pub struct InProcessAgent {
    pub robot: RobotId,
    /// What the daemon reported once ready (its status, its HTTP address).
    pub started: Started,
    shutdown: watch::Sender<bool>,
    task: JoinHandle<Result<()>>,
}

impl InProcessAgent {
    /// `robot` joining the hub's fleet (secured when the hub is) with `config`.
    pub async fn start(
        hub: &Hub,
        robot: &RobotId,
        models: &Arc<ModelSet>,
        config: AgentConfig,
    ) -> Result<InProcessAgent> {
        Self::start_recording(hub, robot, models, config, None).await
    }

    /// The same, recording its engine's inputs and outputs to `record`.
    pub async fn start_recording(
        hub: &Hub,
        robot: &RobotId,
        models: &Arc<ModelSet>,
        config: AgentConfig,
        record: Option<PathBuf>,
    ) -> Result<InProcessAgent> {
        let (zenoh, credentials) = hub.member_config(robot.as_str())?;
        let opts = Options { robot: robot.clone(), fleet: hub.fleet.clone(), config, zenoh, record, credentials };
        Self::start_with(opts, models).await
    }

    /// An agent with options of the caller's own making (another identity's
    /// certificate, a stale roster); returns once it is ready.
    pub async fn start_with(opts: Options, models: &Arc<ModelSet>) -> Result<InProcessAgent> {
        let robot = opts.robot.clone();
        let (shutdown, rx) = watch::channel(false);
        let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(daemon::run(opts, models.clone(), rx, Some(ready_tx)));
        let started = match tokio::time::timeout(WITHIN, ready_rx).await {
            Ok(Ok(started)) => started,
            Ok(Err(_)) => {
                let failed = task.await.map_err(|e| anyhow!(e))?.err();
                return Err(failed
                    .unwrap_or_else(|| anyhow!("ended before it was ready"))
                    .context(format!("agent {robot} failed to start")));
            }
            Err(_) => {
                task.abort();
                anyhow::bail!("agent {robot} not ready within {WITHIN:?}");
            }
        };
        Ok(InProcessAgent { robot, started, shutdown, task })
    }

    /// Whether the daemon has ended (it may leave on its own: revoked, or on an error).
    pub fn finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Leaves the fleet cleanly (token undeclared, session closed) and returns what the
    /// daemon returned.
    pub async fn stop(self) -> Result<()> {
        let _ = self.shutdown.send(true);
        tokio::time::timeout(WITHIN, self.task)
            .await
            .with_context(|| format!("agent {} did not stop within {WITHIN:?}", self.robot))?
            .map_err(|e| anyhow!(e))?
    }
}
