//! `spwi-agent fleet …`: the operator's commands on a fleet directory.

use super::authority::{self, Validity};
use super::{FleetDir, Role};
use anyhow::Result;
use clap::{ArgGroup, Subcommand};
use spwi_proto::{FleetId, RobotId};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum FleetCommand {
    /// Create a fleet: its certificate authority and an empty roster in a new directory.
    Init {
        /// The fleet's id (what agents take as --fleet).
        #[arg(long)]
        fleet: FleetId,
        /// The fleet directory to create.
        #[arg(long)]
        out: PathBuf,
        /// Validity of the CA certificate, in days.
        #[arg(long, default_value_t = 3650)]
        days: u32,
    },
    /// Admit a member: an Ed25519 key, a certificate signed by the fleet's CA, a roster
    /// entry. Copy the roster, ca.crt and the member's two files to its host.
    #[command(group(ArgGroup::new("member").required(true).args(["robot", "world", "router", "observer"])))]
    Add {
        /// A robot (may publish only under its own name).
        #[arg(long)]
        robot: Option<RobotId>,
        /// The world or detector service (publishes detections for every robot).
        #[arg(long)]
        world: Option<RobotId>,
        /// A Zenoh router (spwi-router; forwards anything of the fleet).
        #[arg(long)]
        router: Option<RobotId>,
        /// An observer (a dashboard, a planner, the Python client): may follow
        /// everything of the fleet and publish nothing.
        #[arg(long)]
        observer: Option<RobotId>,
        /// The fleet directory (holding ca.key).
        #[arg(long)]
        dir: PathBuf,
        /// Validity of the certificate, in days.
        #[arg(long, default_value_t = 365)]
        days: u32,
    },
    /// Revoke a member: every process that adopts the new roster (from its copy of
    /// fleet.toml, or from `fleet publish`) denies it everything. The name is never
    /// admitted again.
    Revoke {
        /// The member's name (robot id, or the world's or router's name).
        #[arg(long)]
        robot: RobotId,
        #[arg(long)]
        dir: PathBuf,
    },
    /// Say the roster of DIR on a running fleet: every process holding an older one
    /// adopts it (and writes it to its fleet.toml), without restarting.
    Publish {
        /// The fleet directory whose roster to say.
        #[arg(long)]
        dir: PathBuf,
        /// Whose certificate to present: a robot or the world of DIR (an observer may
        /// say nothing). Its key must be in DIR.
        #[arg(long = "as", default_value = "world")]
        identity: String,
        /// Where to reach the fleet (Zenoh endpoint, e.g. tcp/10.0.0.5:7447; `tcp/` is
        /// taken as `tls/`), repeatable; without it, multicast scouting.
        #[arg(long)]
        connect: Vec<String>,
        /// Zenoh's own config file (json5).
        #[arg(long, env = "ZENOH_CONFIG")]
        zenoh_config: Option<PathBuf>,
        /// Zenoh setting override KEY:VALUE (VALUE in json5), repeatable.
        #[arg(long = "cfg", value_name = "KEY:VALUE")]
        cfg: Vec<String>,
    },
    /// Print the roster.
    List {
        #[arg(long)]
        dir: PathBuf,
    },
}

/// Runs one fleet command; what it did goes to stdout, never a key.
pub async fn run(cmd: FleetCommand) -> Result<()> {
    match cmd {
        FleetCommand::Init { fleet, out, days } => {
            let dir = FleetDir::new(out);
            authority::init(&dir, &fleet, Validity::days(days))?;
            println!("fleet {fleet}: CA and roster in {} (keep ca.key there only)", dir.root.display());
        }
        FleetCommand::Add { robot, world, router, observer, dir, days } => {
            let (name, role) = match (robot, world, router, observer) {
                (Some(n), ..) => (n, Role::Robot),
                (_, Some(n), ..) => (n, Role::World),
                (_, _, Some(n), _) => (n, Role::Router),
                (.., Some(n)) => (n, Role::Observer),
                _ => unreachable!("clap requires one of --robot, --world, --router, --observer"),
            };
            let dir = FleetDir::new(dir);
            let m = authority::add(&dir, &name, role, Validity::days(days))?;
            println!(
                "{} {name} admitted until {}: {} and {}",
                role.as_str(),
                m.not_after,
                dir.member_cert(name.as_str()).display(),
                dir.member_key(name.as_str()).display()
            );
        }
        FleetCommand::Revoke { robot, dir } => {
            let dir = FleetDir::new(dir);
            authority::revoke(&dir, robot.as_str())?;
            println!(
                "{robot} revoked in {}; copy it to every host, or say it on the fleet with `spwi-agent fleet publish`",
                dir.roster().display()
            );
        }
        FleetCommand::Publish { dir, identity, connect, zenoh_config, cfg } => {
            let mut overrides = cfg;
            if !connect.is_empty() {
                overrides.push(format!("connect/endpoints:{}", serde_json::to_string(&connect)?));
            }
            let mut zenoh = crate::zenoh_config::build(zenoh_config.as_deref(), &overrides)?;
            // A process that only speaks: no listening, no scouting answers needed.
            zenoh.insert_json5("listen/endpoints", "[]").map_err(|e| anyhow::anyhow!("{e}"))?;
            let version = publish(&dir, &identity, zenoh).await?;
            println!("roster version {version} said on the fleet as {identity}");
        }
        FleetCommand::List { dir } => {
            let roster = super::credentials::load_roster(&FleetDir::new(dir))?;
            println!("fleet {} (roster version {}, signed by its CA)", roster.fleet, roster.version);
            for m in &roster.members {
                let state = if m.revoked { "REVOKED" } else { "admitted" };
                println!("  {:<24} {:<6} {state:<8} until {}", m.name.as_str(), m.role.as_str(), m.not_after);
            }
        }
    }
    Ok(())
}

/// How long `publish` waits for the fleet's subscriptions to reach it, and how many
/// times it says the roster (a process that missed one takes the next).
const PUBLISH_SETTLE: std::time::Duration = std::time::Duration::from_millis(1500);
const PUBLISH_TIMES: u32 = 3;

/// Says the roster of `dir` on the fleet as `identity` (a robot or the world of
/// `dir`); returns its version.
pub async fn publish(dir: &std::path::Path, identity: &str, mut zenoh: zenoh::Config) -> Result<u64> {
    let creds = super::Credentials::load(&FleetDir::new(dir), identity)?;
    if !matches!(creds.identity.role, Role::Robot | Role::World) {
        anyhow::bail!("{identity} is a {}: only a robot or the world may say the roster", creds.identity.role.as_str());
    }
    super::secure::apply(&mut zenoh, &creds)?;
    let session = zenoh::open(zenoh).await.map_err(|e| anyhow::anyhow!("cannot open the Zenoh session: {e}"))?;
    let key = spwi_proto::keys::roster(&creds.roster.fleet, &creds.identity.name);
    let said = creds.roster.said();
    for _ in 0..PUBLISH_TIMES {
        tokio::time::sleep(PUBLISH_SETTLE / PUBLISH_TIMES).await;
        session.put(&key, said.clone()).await.map_err(|e| anyhow::anyhow!("saying the roster on {key}: {e}"))?;
    }
    tokio::time::sleep(PUBLISH_SETTLE / PUBLISH_TIMES).await; // let the last one leave
    session.close().await.map_err(|e| anyhow::anyhow!("closing the session: {e}"))?;
    Ok(creds.roster.version)
}
