//! An `spwi-agent` process joining a loopback fleet: the command line every agent of
//! the hub gets, and the handle to signal it (SIGTERM to leave, SIGSTOP to freeze,
//! SIGKILL to vanish) and to wait for its exit. Dropping the handle kills it.
//!
//! An agent whose warnings are not shown (benchmarks) still keeps them: its stderr goes
//! to an unlinked file only this handle reads, so an agent that dies on start is
//! reported with its own words ([`AgentProcess::exited`]) instead of as a silent absence.

use super::Hub;
use anyhow::{bail, Context, Result};
use spwi_proto::RobotId;
use std::fs::File;
use std::io::{Read, Seek};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How one agent joins the hub's fleet.
pub struct Launch<'a> {
    pub hub: &'a Hub,
    pub robot: &'a RobotId,
    /// The Zenoh endpoint it listens on as a peer of the hub's mesh.
    pub listen: String,
    /// Routers to join as a Zenoh client instead, its home router first (see
    /// `Routers::connect_from`); empty: a peer of the mesh.
    pub routers: Vec<String>,
    /// Its model set (default: the daemon's own).
    pub models: Option<PathBuf>,
    /// Zenoh settings (`KEY:VALUE`) after the fleet's own.
    pub cfg: &'a [String],
    /// Its warnings on this process's stderr (tests), or kept aside and shown only if
    /// it exits (benchmarks).
    pub stderr: bool,
}

impl<'a> Launch<'a> {
    /// `robot` on loopback, an ephemeral port, its default models, warnings shown.
    pub fn new(hub: &'a Hub, robot: &'a RobotId) -> Launch<'a> {
        Launch {
            hub,
            robot,
            listen: "tcp/127.0.0.1:0".into(),
            routers: Vec::new(),
            models: None,
            cfg: &[],
            stderr: true,
        }
    }
}

pub struct AgentProcess {
    pub robot: RobotId,
    child: Child,
    /// Its stderr, when not shown (unlinked: gone with the handle).
    log: Option<File>,
}

impl AgentProcess {
    /// Starts the agent `command` runs (the agent binary itself, or a wrapper that ends
    /// by executing it, as `ip netns exec` does) with `launch`'s arguments.
    pub fn spawn(mut command: Command, launch: Launch) -> Result<AgentProcess> {
        let hub = launch.hub;
        command.args(["--robot-id", launch.robot.as_str(), "--fleet", hub.fleet.as_str()]);
        if launch.routers.is_empty() {
            command
                .args(["--cfg", r#"mode:"peer""#])
                .args(["--cfg", &format!(r#"listen/endpoints:["{}"]"#, launch.listen)])
                .args(["--cfg", &format!(r#"connect/endpoints:["{}"]"#, hub.locator)]);
        } else {
            let routers = serde_json::to_string(&launch.routers)?;
            command.args(["--cfg", r#"mode:"client""#]).args(["--cfg", &format!("connect/endpoints:{routers}")]);
        }
        command
            .args(["--cfg", "scouting/multicast/enabled:false"])
            .args(launch.cfg.iter().flat_map(|c| ["--cfg", c.as_str()]))
            .env("RUST_LOG", "warn,zenoh=error")
            .stdin(Stdio::null())
            .stdout(Stdio::null());
        let log = if launch.stderr { None } else { Some(unlinked_log(launch.robot)?) };
        match &log {
            Some(f) => command.stderr(f.try_clone()?),
            None => command.stderr(Stdio::inherit()),
        };
        if let Some(m) = &launch.models {
            command.arg("--models").arg(m);
        }
        if let Some(dir) = &hub.fleet_dir {
            command.arg("--fleet-dir").arg(dir);
        }
        let child =
            command.spawn().with_context(|| format!("starting {:?} for {}", command.get_program(), launch.robot))?;
        Ok(AgentProcess { robot: launch.robot.clone(), child, log })
    }

    /// If it has exited: how, with the end of what it wrote on stderr when that was
    /// kept aside.
    pub fn exited(&mut self) -> Result<Option<String>> {
        let Some(status) = self.child.try_wait()? else { return Ok(None) };
        let mut said = String::new();
        if let Some(f) = &mut self.log {
            f.rewind()?;
            f.read_to_string(&mut said)?;
        }
        let lines: Vec<&str> = said.lines().collect();
        let last = &lines[lines.len().saturating_sub(5)..];
        Ok(Some(match last.is_empty() {
            true => format!("{} exited ({status})", self.robot),
            false => format!("{} exited ({status}): {}", self.robot, last.join(" | ")),
        }))
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends `sig` ("TERM", "KILL", "STOP", "CONT").
    pub fn signal(&self, sig: &str) -> Result<()> {
        signal(self.pid(), sig)
    }

    /// Waits (polling) for the process to exit, at most `limit`.
    pub async fn wait_exit(&mut self, limit: Duration) -> Result<ExitStatus> {
        let deadline = Instant::now() + limit;
        loop {
            if let Some(s) = self.child.try_wait()? {
                return Ok(s);
            }
            if Instant::now() > deadline {
                bail!("{} did not exit within {limit:?}", self.robot);
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// Stops it as an operator would (SIGTERM: it leaves the fleet cleanly) and waits
    /// at most 10 s for it to exit.
    pub async fn stop(mut self) -> Result<ExitStatus> {
        self.signal("TERM")?;
        self.wait_exit(Duration::from_secs(10)).await
    }
}

impl Drop for AgentProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A file for `robot`'s stderr that no other process can open: created, then unlinked.
fn unlinked_log(robot: &RobotId) -> Result<File> {
    let path = std::env::temp_dir().join(format!("spwi-agent-{}-{robot}.log", std::process::id()));
    let file = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&path)
        .with_context(|| format!("{}: cannot create the agent's log", path.display()))?;
    std::fs::remove_file(&path)?;
    Ok(file)
}

fn signal(pid: u32, sig: &str) -> Result<()> {
    let ok = Command::new("kill").args([&format!("-{sig}"), &pid.to_string()]).status()?.success();
    if !ok {
        bail!("kill -{sig} {pid} failed");
    }
    Ok(())
}
