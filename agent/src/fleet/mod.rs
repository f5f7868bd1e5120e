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
//! [`signed_votes`] signs this robot's votes and checks those relayed for others;
//! [`live`] takes a newer roster while the process runs.
//! Without a fleet directory a process runs open (development) and says so loudly.

pub mod authority;
pub mod cli;
pub mod credentials;
pub mod live;
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

/// The fleet to join: the fleet directory's, which `--fleet` may repeat but not
/// contradict; `default` for an open fleet without `--fleet`.
pub fn fleet_id(
    given: Option<spwi_proto::FleetId>,
    credentials: Option<&Credentials>,
) -> anyhow::Result<spwi_proto::FleetId> {
    match (given, credentials) {
        (Some(f), Some(c)) if f != c.roster.fleet => {
            anyhow::bail!("--fleet {f}, but the fleet directory is for fleet {}", c.roster.fleet)
        }
        (_, Some(c)) => Ok(c.roster.fleet.clone()),
        (Some(f), None) => Ok(f),
        (None, None) => Ok(spwi_proto::FleetId::new("default").expect("a valid id")),
    }
}

/// Secures `zenoh` for `identity` of the fleet in `dir`, which must be a member of
/// `role` (the role decides what the others accept from it), or warns that the fleet
/// is open. Returns the credentials (their roster names the fleet).
pub fn secure_or_warn(
    zenoh: &mut zenoh::Config,
    dir: Option<&Path>,
    identity: &str,
    role: Role,
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
    if creds.identity.role != role {
        anyhow::bail!(
            "{identity} is a {} in {}; {program} presents the certificate of a {}",
            creds.identity.role.as_str(),
            FleetDir::new(dir).roster().display(),
            role.as_str()
        );
    }
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

#[cfg(test)]
mod tests {
    use super::authority::ThrowawayFleet;
    use super::*;
    use spwi_proto::FleetId;

    #[test]
    fn a_process_presents_a_member_of_its_own_role_of_its_own_fleet() {
        let members = [("world", Role::World), ("r1", Role::Robot)];
        let fleet = ThrowawayFleet::create("role", &FleetId::new("plant7").unwrap(), &members).unwrap();
        let root = &fleet.dir.root;
        let mut z = zenoh::Config::default();
        let e = secure_or_warn(&mut z, Some(root), "world", Role::Robot, "spwi-agent").unwrap_err().to_string();
        assert!(e.contains("world is a world") && e.contains("a robot"), "{e}");
        let creds = secure_or_warn(&mut z, Some(root), "r1", Role::Robot, "spwi-agent").unwrap().unwrap();
        assert_eq!(z.get_json("transport/link/protocols").unwrap(), r#"["tls","quic"]"#);
        assert_eq!(fleet_id(None, Some(&creds)).unwrap().as_str(), "plant7");
        let e = fleet_id(Some(FleetId::new("other").unwrap()), Some(&creds)).unwrap_err().to_string();
        assert!(e.contains("--fleet other, but the fleet directory is for fleet plant7"), "{e}");
        assert!(secure_or_warn(&mut zenoh::Config::default(), None, "r1", Role::Robot, "x").unwrap().is_none());
    }
}
