//! `spwi-agent fleet …`: the operator's commands on a fleet directory.

use super::authority::{self, Validity};
use super::{FleetDir, Role, Roster};
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
    #[command(group(ArgGroup::new("member").required(true).args(["robot", "world", "router"])))]
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
        /// The fleet directory (holding ca.key).
        #[arg(long)]
        dir: PathBuf,
        /// Validity of the certificate, in days.
        #[arg(long, default_value_t = 365)]
        days: u32,
    },
    /// Revoke a member: every process given the new roster denies it everything from
    /// its next start. The name is never admitted again.
    Revoke {
        /// The member's name (robot id, or the world's or router's name).
        #[arg(long)]
        robot: RobotId,
        #[arg(long)]
        dir: PathBuf,
    },
    /// Print the roster.
    List {
        #[arg(long)]
        dir: PathBuf,
    },
}

/// Runs one fleet command; what it did goes to stdout, never a key.
pub fn run(cmd: FleetCommand) -> Result<()> {
    match cmd {
        FleetCommand::Init { fleet, out, days } => {
            let dir = FleetDir::new(out);
            authority::init(&dir, &fleet, Validity::days(days))?;
            println!("fleet {fleet}: CA and roster in {} (keep ca.key there only)", dir.root.display());
        }
        FleetCommand::Add { robot, world, router, dir, days } => {
            let (name, role) = match (robot, world, router) {
                (Some(n), _, _) => (n, Role::Robot),
                (_, Some(n), _) => (n, Role::World),
                (_, _, Some(n)) => (n, Role::Router),
                _ => unreachable!("clap requires one of --robot, --world, --router"),
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
            println!("{robot} revoked in {}; copy it to every host and restart their daemons", dir.roster().display());
        }
        FleetCommand::List { dir } => {
            let roster = Roster::load(&FleetDir::new(dir).roster())?;
            println!("fleet {}", roster.fleet);
            for m in &roster.members {
                let state = if m.revoked { "REVOKED" } else { "admitted" };
                println!("  {:<24} {:<6} {state:<8} until {}", m.name.as_str(), m.role.as_str(), m.not_after);
            }
        }
    }
    Ok(())
}
