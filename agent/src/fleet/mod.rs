//! A fleet that only its own robots can join.
//!
//! The fleet directory holds the fleet's trust:
//!
//! ```text
//! DIR/fleet.toml            the roster: members, roles, public keys, revocations (public)
//! DIR/ca.crt                the fleet's CA certificate (public, on every host)
//! DIR/ca.key                the CA's key (0600; only where members are admitted)
//! DIR/members/<name>.crt    a member's certificate, common name = its name (public)
//! DIR/members/<name>.key    its Ed25519 key (0600; only on that member's host)
//! ```
//!
//! [`authority`] makes and changes it (`spwi-agent fleet init | add | revoke`);
//! [`credentials`] loads and checks one member's part before a process connects;
//! [`secure`] turns a Zenoh config into mutual TLS plus access control from the roster;
//! [`signed_votes`] signs this robot's votes and checks those relayed for others.
//! Without a fleet directory a process runs open (development) and says so loudly.

pub mod authority;
pub mod cli;
pub mod credentials;
pub mod roster;
pub mod secure;
pub mod signed_votes;

pub use credentials::Credentials;
pub use roster::{Member, Role, Roster};

use std::path::{Path, PathBuf};

/// The paths of a fleet directory.
#[derive(Debug, Clone)]
pub struct FleetDir {
    pub root: PathBuf,
}

impl FleetDir {
    pub fn new(root: impl Into<PathBuf>) -> FleetDir {
        FleetDir { root: root.into() }
    }
    pub fn roster(&self) -> PathBuf {
        self.root.join("fleet.toml")
    }
    pub fn ca_cert(&self) -> PathBuf {
        self.root.join("ca.crt")
    }
    pub fn ca_key(&self) -> PathBuf {
        self.root.join("ca.key")
    }
    pub fn members(&self) -> PathBuf {
        self.root.join("members")
    }
    pub fn member_cert(&self, name: &str) -> PathBuf {
        self.members().join(format!("{name}.crt"))
    }
    pub fn member_key(&self, name: &str) -> PathBuf {
        self.members().join(format!("{name}.key"))
    }
}

/// Secures `zenoh` for `identity` of the fleet in `dir`, or warns that the fleet is open.
/// Returns the credentials (their roster names the fleet).
pub fn secure_or_warn(
    zenoh: &mut zenoh::Config,
    dir: Option<&Path>,
    identity: &str,
    program: &str,
) -> anyhow::Result<Option<std::sync::Arc<Credentials>>> {
    let Some(dir) = dir else {
        tracing::warn!(
            "{program} runs an OPEN fleet: any process that reaches this network can join, vote and publish \
             detections; give --fleet-dir to admit only the fleet's members (deploy/README.md)"
        );
        return Ok(None);
    };
    let creds = Credentials::load(&FleetDir::new(dir), identity)?;
    secure::apply(zenoh, &creds)?;
    tracing::info!(
        identity,
        role = creds.identity.role.as_str(),
        fleet = %creds.roster.fleet,
        members = creds.roster.admitted().count(),
        "secured fleet: mutual TLS, access control from the roster"
    );
    Ok(Some(std::sync::Arc::new(creds)))
}
